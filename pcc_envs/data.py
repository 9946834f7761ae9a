"""The paper's data protocol: uniform transitions ``(x_t, u_t, x_{t+1})`` and an on-disk cache.

Appendix "Data Collection Process" of the paper: sample a true state uniformly, render its
observation, sample an action uniformly, step the true dynamics, add zero-mean Gaussian noise
of standard deviation ``noise_std`` to the next state, and render the next observation.

For environments whose observation stacks ``F`` frames (two for everything but Planar), one
frame does not show velocities, so a sample is a short random chain: ``s_0`` is drawn from
the state box (``env.sample_states``), random actions ``u_0 .. u_{F-1}`` give
``s_1 .. s_F`` (each step: ``env.transition`` then ``env.add_process_noise``), and

* ``obs = (render(s_0), ..., render(s_{F-1}))``, ``next_obs = (render(s_1), ..., render(s_F))``
  (built with :func:`pcc_envs.core.stack_frames`, oldest frame first, as the env does),
* ``state = s_{F-1}``, ``action = u_{F-1}``, ``next_state = s_F``.

With ``F = 2`` this is ``x_t = (s_0, s_1)``, ``x_{t+1} = (s_1, s_2)``, the stored action
``u_1``. Everything is vectorized over samples (batched dynamics and rendering, in chunks).
An env made with ``frame_gap = g > 1`` stacks every ``g``-th state of a chain of
``(F - 1) g + 1`` random steps: ``x_t = (s_0, s_g, ...)``, ``x_{t+1} = (s_1, s_{g+1}, ...)``,
the stored state, action and next state the chain's last step, as above.

With ``prediction_horizon = K > 1`` every chain goes on for ``K - 1`` more random steps, and a
sample also holds the observations ``x_{t+2} .. x_{t+K}`` after them (``future_obs``) and
their actions ``u_{t+1} .. u_{t+K-1}`` (``future_action``): the data of a multi-step
prediction term (``pcc_agent.config.TrainConfig.prediction_horizon``); the random draws
differ from those of ``K = 1``, so it is another data set.

Stored actions are the normalized ``float32`` actions in ``[-1, 1]``; the dynamics were
stepped with exactly these ``float32`` values.

>>> from pcc_envs.data import collect_transitions
>>> data = collect_transitions("pcc/PendulumSwingUp-v0", num_samples=8, seed=0)
>>> data.obs.shape, data.action.shape, data.next_state.shape
((8, 2, 48, 48), (8, 1), (8, 2))
>>> bool((data.obs[:, 1] == data.next_obs[:, 0]).all())
True
"""

from __future__ import annotations

import contextlib
import hashlib
import importlib.metadata
import json
import os
import re
import tempfile
import warnings
import zipfile
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import gymnasium as gym
import numpy as np

import pcc_envs  # noqa: F401  (registers the ids)
from pcc_envs.core import ImageControlEnv, stack_frames

__all__ = [
    "FORMAT_VERSION",
    "TransitionDataset",
    "cache_path",
    "collect_transitions",
    "default_cache_dir",
    "load_or_collect",
    "observations_for_states",
]

FORMAT_VERSION = 2
"""Version of the sampling protocol and file layout; part of every cache key (2: Planar
obstacles block only their cores, ``PlanarParams.collision_clearance``)."""

_ARRAYS = ("obs", "action", "next_obs", "state", "next_state")
#: Arrays only data sets with a prediction horizon above 1 hold.
_FUTURE_ARRAYS = ("future_action", "future_obs")
_CHUNK = 2048


def _package_version() -> str:
    try:
        return importlib.metadata.version("pcc-control")
    except importlib.metadata.PackageNotFoundError:  # pragma: no cover - source checkout
        return "unknown"


@dataclass(frozen=True)
class TransitionDataset:
    """Transitions ``(obs, action, next_obs)`` with their true states.

    Attributes:
        obs: ``uint8 (N, F, H, W)`` observations ``x_t``.
        action: ``float32 (N, A)`` normalized actions ``u_t`` in ``[-1, 1]``.
        next_obs: ``uint8 (N, F, H, W)`` observations ``x_{t+1}``.
        state: ``float64 (N, d)`` true states behind the newest frame of ``obs``.
        next_state: ``float64 (N, d)`` true states behind the newest frame of ``next_obs``.
        metadata: ``env_id``, ``env_kwargs``, ``seed``, ``noise_std``, ``num_samples``,
            ``format_version``, ``package_version`` (JSON-serializable), and
            ``prediction_horizon`` where it is above 1.
        future_action: ``float32 (N, K - 1, A)`` actions ``u_{t+1} .. u_{t+K-1}``, or None.
        future_obs: ``uint8 (N, K - 1, F, H, W)`` observations ``x_{t+2} .. x_{t+K}``, or None.
    """

    obs: np.ndarray
    action: np.ndarray
    next_obs: np.ndarray
    state: np.ndarray
    next_state: np.ndarray
    metadata: dict[str, Any] = field(default_factory=dict)
    future_action: np.ndarray | None = None
    future_obs: np.ndarray | None = None

    @property
    def prediction_horizon(self) -> int:
        """``K``: the transitions each sample holds (1 without future arrays)."""
        return 1 if self.future_action is None else 1 + self.future_action.shape[1]

    def _arrays(self) -> tuple[str, ...]:
        return _ARRAYS + (() if self.future_action is None else _FUTURE_ARRAYS)

    def __post_init__(self) -> None:
        n = len(self.obs)
        if (self.future_action is None) != (self.future_obs is None):
            raise ValueError("future_action and future_obs come together (both or neither)")
        if self.future_obs is not None and (
                self.future_obs.shape[:2] != self.future_action.shape[:2]
                or self.future_obs.shape[2:] != self.obs.shape[1:]
                or self.future_obs.dtype != np.uint8):
            raise ValueError(
                f"future_obs must be uint8 (N, K - 1, *obs frame shape) matching future_action "
                f"(N, K - 1, A); got {self.future_obs.shape} ({self.future_obs.dtype}) and "
                f"{self.future_action.shape}")
        for name in self._arrays():
            if len(getattr(self, name)) != n:
                raise ValueError(
                    f"TransitionDataset arrays must have the same length; obs has {n}, "
                    f"{name} has {len(getattr(self, name))}"
                )
        if self.obs.dtype != np.uint8 or self.next_obs.dtype != np.uint8:
            raise ValueError("obs and next_obs must be uint8 (frames, H, W) images")

    def __len__(self) -> int:
        return len(self.obs)

    def subset(self, index: np.ndarray | slice) -> TransitionDataset:
        """The transitions at ``index`` (metadata gains ``subset_size``)."""
        arrays = {name: getattr(self, name)[index] for name in self._arrays()}
        meta = {**self.metadata, "subset_size": len(arrays["obs"])}
        return TransitionDataset(**arrays, metadata=meta)

    def split(
        self, fraction: float, rng: np.random.Generator
    ) -> tuple[TransitionDataset, TransitionDataset]:
        """Random disjoint split: ``round(fraction * N)`` transitions, then the rest.

        Args:
            fraction: Share of the first part, in ``[0, 1]``.
            rng: Generator for the permutation.
        """
        if not 0.0 <= fraction <= 1.0:
            raise ValueError(f"fraction must be in [0, 1], got {fraction!r}")
        order = rng.permutation(len(self))
        cut = int(round(fraction * len(self)))
        return self.subset(np.sort(order[:cut])), self.subset(np.sort(order[cut:]))

    def save(self, path: str | os.PathLike[str]) -> Path:
        """Write an uncompressed ``.npz`` atomically (temporary file + ``os.replace``).

        The metadata is stored as a JSON string so the file loads with
        ``allow_pickle=False``.
        """
        path = Path(path)
        path.parent.mkdir(parents=True, exist_ok=True)
        fd, tmp = tempfile.mkstemp(prefix=f".{path.name}.", suffix=".tmp", dir=path.parent)
        try:
            with os.fdopen(fd, "wb") as handle:
                np.savez(
                    handle,
                    metadata=np.array(json.dumps(self.metadata, sort_keys=True)),
                    **{name: getattr(self, name) for name in self._arrays()},
                )
            os.replace(tmp, path)
        except BaseException:
            with contextlib.suppress(FileNotFoundError):
                os.unlink(tmp)
            raise
        return path

    @classmethod
    def load(cls, path: str | os.PathLike[str]) -> TransitionDataset:
        """Read a file written by :meth:`save` (never unpickles).

        Raises:
            FileNotFoundError: No file at ``path``.
            ValueError: The file is not a complete data set written by :meth:`save`
                (truncated, corrupt, or missing arrays).
        """
        try:
            with np.load(path, allow_pickle=False) as data:
                arrays = {name: data[name] for name in _ARRAYS}
                arrays.update({name: data[name] for name in _FUTURE_ARRAYS if name in data})
                metadata = json.loads(str(data["metadata"]))
        except FileNotFoundError:
            raise
        except (OSError, EOFError, KeyError, ValueError, zipfile.BadZipFile) as exc:
            raise ValueError(
                f"{path} is not a complete data set written by TransitionDataset.save "
                f"({type(exc).__name__}: {exc})"
            ) from exc
        return cls(**arrays, metadata=metadata)


def _make_env(env_id: str, noise_std: float, env_kwargs: dict[str, Any] | None) -> Any:
    kwargs = dict(env_kwargs or {})
    if "noise_std" in kwargs:
        raise ValueError("Pass noise_std as its own argument, not inside env_kwargs.")
    return gym.make(env_id, noise_std=noise_std, **kwargs)


def collect_transitions(
    env_id: str,
    num_samples: int,
    seed: int,
    noise_std: float = 0.0,
    env_kwargs: dict[str, Any] | None = None,
    prediction_horizon: int = 1,
) -> TransitionDataset:
    """Sample ``num_samples`` transitions by the paper's uniform protocol (module docstring).

    Args:
        env_id: A registered id, e.g. ``"pcc/Planar-v0"``.
        num_samples: Number of transitions.
        seed: Seed of the ``np.random.Generator`` that draws states, actions and noise; the
            same arguments give identical arrays.
        noise_std: Standard deviation of the Gaussian process noise on next states.
        env_kwargs: Extra constructor arguments of the env (e.g. ``{"max_torque": 0.2}``).
        prediction_horizon: ``K``: consecutive transitions per sample (module docstring).

    Returns:
        The dataset, with its metadata.
    """
    if num_samples < 0:
        raise ValueError(f"num_samples must be >= 0, got {num_samples}")
    _check_horizon(prediction_horizon)
    rng = np.random.default_rng(seed)
    wrapped = _make_env(env_id, noise_std, env_kwargs)
    env: ImageControlEnv = wrapped.unwrapped
    try:
        gap = env.frame_gap
        steps = env.history_length  # the periods one observation spans, plus one
        arrays = {
            "obs": np.empty((num_samples, *env.observation_space.shape), dtype=np.uint8),
            "action": np.empty((num_samples, env.action_dim), dtype=np.float32),
            "state": np.empty((num_samples, env.state_dim)),
        }
        arrays["next_obs"] = np.empty_like(arrays["obs"])
        arrays["next_state"] = np.empty_like(arrays["state"])
        extra = prediction_horizon - 1
        if extra:
            arrays["future_action"] = np.empty((num_samples, extra, env.action_dim),
                                               dtype=np.float32)
            arrays["future_obs"] = np.empty((num_samples, extra, *env.observation_space.shape),
                                            dtype=np.uint8)
        for start in range(0, num_samples, _CHUNK):
            n = min(_CHUNK, num_samples - start)
            rows = slice(start, start + n)
            states = [env.sample_states(rng, n)]
            actions = []
            for _ in range(steps + extra):
                action = env.sample_action(rng, n).astype(np.float32)
                nxt = env.transition(states[-1], action.astype(np.float64))
                states.append(env.add_process_noise(nxt, rng))
                actions.append(action)
            images = [env.render_states(s) for s in states]
            # The observation k steps on stacks images[k : k + steps : gap].
            stack_frames(images[:steps:gap], out=arrays["obs"][rows])
            stack_frames(images[1:steps + 1:gap], out=arrays["next_obs"][rows])
            arrays["action"][rows] = actions[steps - 1]
            arrays["state"][rows] = states[steps - 1]
            arrays["next_state"][rows] = states[steps]
            for j in range(extra):
                arrays["future_action"][rows, j] = actions[steps + j]
                stack_frames(images[j + 2:j + 2 + steps:gap], out=arrays["future_obs"][rows, j])
    finally:
        wrapped.close()
    return TransitionDataset(**arrays, metadata=_metadata(
        env_id, num_samples, seed, noise_std, env_kwargs, prediction_horizon))


def _check_horizon(prediction_horizon: int) -> None:
    if isinstance(prediction_horizon, bool) or not isinstance(
            prediction_horizon, (int, np.integer)) or prediction_horizon < 1:
        raise ValueError(f"prediction_horizon must be an integer >= 1, got "
                         f"{prediction_horizon!r}")


def _metadata(
    env_id: str,
    num_samples: int,
    seed: int,
    noise_std: float,
    env_kwargs: dict[str, Any] | None,
    prediction_horizon: int = 1,
) -> dict[str, Any]:
    meta = {
        "env_id": env_id,
        "env_kwargs": json.loads(json.dumps(env_kwargs or {}, sort_keys=True)),
        "seed": int(seed),
        "noise_std": repr(float(noise_std)),
        "num_samples": int(num_samples),
        "format_version": FORMAT_VERSION,
        "package_version": _package_version(),
    }
    registered = _registered_kwargs(env_id)
    if registered:  # only where the id has some, so that other ids keep their cached files
        meta["registered_kwargs"] = registered
    if prediction_horizon > 1:  # likewise: one-step data keep their cached files
        meta["prediction_horizon"] = int(prediction_horizon)
    return meta


def _registered_kwargs(env_id: str) -> dict[str, Any]:
    """The constructor arguments the id is registered with (``gym.spec(env_id).kwargs``).

    Part of the cache key: a change to an id's registered arguments (e.g. a data range) must
    not reuse data sampled under the old ones.
    """
    try:
        kwargs = gym.spec(env_id).kwargs
    except gym.error.Error:  # not a registered id: make() will say so
        return {}
    return json.loads(json.dumps(kwargs, sort_keys=True, default=repr))


def default_cache_dir() -> Path:
    """``$PCC_DATA_DIR`` if set, else ``~/.cache/pcc_control/datasets``."""
    env = os.environ.get("PCC_DATA_DIR")
    return Path(env) if env else Path.home() / ".cache" / "pcc_control" / "datasets"


def cache_path(
    env_id: str,
    num_samples: int,
    seed: int,
    noise_std: float = 0.0,
    env_kwargs: dict[str, Any] | None = None,
    cache_dir: str | os.PathLike[str] | None = None,
    prediction_horizon: int = 1,
) -> Path:
    """The cache file of a dataset: a readable prefix plus the SHA-256 of its canonical key.

    The key is the canonical JSON of everything that changes the data: env id, env kwargs,
    the id's registered kwargs (where it has any), seed, the exact ``repr`` of ``noise_std``,
    ``num_samples``, the prediction horizon (where above 1), :data:`FORMAT_VERSION` and the
    package version.
    """
    meta = _metadata(env_id, num_samples, seed, noise_std, env_kwargs, prediction_horizon)
    digest = hashlib.sha256(
        json.dumps(meta, sort_keys=True, separators=(",", ":")).encode()
    ).hexdigest()
    slug = re.sub(r"[^A-Za-z0-9]+", "-", env_id).strip("-")
    directory = Path(cache_dir) if cache_dir is not None else default_cache_dir()
    return directory / f"{slug}_n{num_samples}_s{seed}_{digest[:20]}.npz"


def load_or_collect(
    env_id: str,
    num_samples: int,
    seed: int,
    noise_std: float = 0.0,
    env_kwargs: dict[str, Any] | None = None,
    cache_dir: str | os.PathLike[str] | None = None,
    prediction_horizon: int = 1,
) -> TransitionDataset:
    """:func:`collect_transitions` through the on-disk cache (see :func:`cache_path`).

    A cached file is used only if its stored metadata equals the requested one; a mismatched
    or unreadable file is regenerated (with a warning) and replaced atomically.
    """
    _check_horizon(prediction_horizon)
    path = cache_path(env_id, num_samples, seed, noise_std, env_kwargs, cache_dir,
                      prediction_horizon)
    expected = _metadata(env_id, num_samples, seed, noise_std, env_kwargs, prediction_horizon)
    if path.exists():
        try:
            data = TransitionDataset.load(path)
        except (OSError, ValueError) as exc:
            warnings.warn(f"Unreadable dataset cache {path} ({exc}); regenerating.", stacklevel=2)
        else:
            if data.metadata == expected:
                return data
            warnings.warn(
                f"Dataset cache {path} holds {data.metadata}, expected {expected}; regenerating.",
                stacklevel=2,
            )
    data = collect_transitions(env_id, num_samples, seed, noise_std, env_kwargs,
                               prediction_horizon)
    data.save(path)
    return data


def observations_for_states(env: gym.Env, states: np.ndarray, chunk_size: int = 4096) -> np.ndarray:
    """Observations ``uint8 (N, F, H, W)`` of true states ``(N, d)`` with a zero-action history.

    The batched :meth:`pcc_envs.core.ImageControlEnv.observations_of` (used e.g. to encode a
    grid of states for the latent maps of the paper's Figure 2).
    """
    base: ImageControlEnv = env.unwrapped  # type: ignore[assignment]
    states = np.asarray(states, dtype=np.float64).reshape(-1, base.state_dim)
    parts = [
        base.observations_of(states[i : i + chunk_size]) for i in range(0, len(states), chunk_size)
    ]
    if not parts:
        return np.zeros((0, *base.observation_space.shape), dtype=np.uint8)
    return np.concatenate(parts)
