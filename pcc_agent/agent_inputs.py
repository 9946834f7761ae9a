"""What a user hands :class:`~pcc_agent.agent.PCCAgent`, checked and converted.

The preset (an :class:`~pcc_agent.config.EnvPreset`, a variant name or none), the env's
spaces (uint8 image observations, a flat bounded ``Box`` of actions), the scaling of
actions between the env's box and the ``[-1, 1]`` units of the model and the planner,
observations and episode starts given to ``predict``, SB3 callbacks given to ``learn``, and
random-policy data for an env without the paper's state sampler. Every refusal says what was
expected.
"""

from __future__ import annotations

import dataclasses
from typing import Any

import gymnasium as gym
import numpy as np
from stable_baselines3.common.callbacks import BaseCallback, CallbackList, ConvertCallback

from pcc_agent.config import EnvPreset
from pcc_agent.presets import default_preset_for_spaces, get_preset

__all__ = [
    "ActionScaler",
    "action_bounds",
    "as_sb3_callback",
    "check_episode_start",
    "check_image_space",
    "check_observations",
    "collect_random_rollouts",
    "resolve_preset",
]


def action_bounds(action_space: gym.spaces.Space) -> tuple[np.ndarray, np.ndarray]:
    """The per-dimension bounds ``(low, high)`` of a flat, bounded ``Box`` action space.

    The agent plans in these bounds: its model and planner work in actions scaled to
    ``[-1, 1]`` (-1 is ``low``, 1 is ``high``, per dimension), and :meth:`PCCAgent.predict`
    returns them scaled back.

    Raises:
        ValueError: Not a ``Box``, not flat ``(n,)``, or a bound that is not finite or a
            dimension whose ``low`` is not below its ``high``; the message names the problem.
    """
    if not isinstance(action_space, gym.spaces.Box):
        raise ValueError(
            f"PCCAgent needs a continuous Box action space, got {action_space}: the planner "
            "optimizes real-valued actions inside their bounds."
        )
    if len(action_space.shape) != 1:
        raise ValueError(
            f"PCCAgent needs a flat Box action space of shape (n,), got shape "
            f"{action_space.shape}: wrap the env in an ActionWrapper that takes flat actions."
        )
    low = np.asarray(action_space.low, dtype=np.float64)
    high = np.asarray(action_space.high, dtype=np.float64)
    unbounded = np.flatnonzero(~(np.isfinite(low) & np.isfinite(high)))
    if unbounded.size:
        raise ValueError(
            f"PCCAgent plans inside the env's action bounds, but the action space {action_space} "
            f"is unbounded in dimension(s) {unbounded.tolist()}: give the env a Box with "
            "finite low and high (the range the actuator accepts), e.g. with an ActionWrapper."
        )
    empty = np.flatnonzero(~(low < high))
    if empty.size:
        raise ValueError(
            f"The action space {action_space} has low >= high in dimension(s) "
            f"{empty.tolist()}: nothing to plan there."
        )
    return low, high


def collect_random_rollouts(
    env: gym.Env, num_samples: int, seed: int
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Transitions ``(obs, action, next_obs)`` from uniformly random actions.

    The fallback for environments that do not offer the paper's uniform state sampler.
    """
    rng = np.random.default_rng(seed)
    env.action_space.seed(int(rng.integers(2**31)))
    obs_list, act_list, next_list = [], [], []
    obs, _ = env.reset(seed=int(rng.integers(2**31)))
    while len(obs_list) < num_samples:
        action = env.action_space.sample()
        next_obs, _, terminated, truncated, _ = env.step(action)
        obs_list.append(obs)
        act_list.append(action)
        next_list.append(next_obs)
        obs = next_obs
        if terminated or truncated:
            obs, _ = env.reset()
    return (
        np.asarray(obs_list, dtype=np.uint8),
        np.asarray(act_list, dtype=np.float32),
        np.asarray(next_list, dtype=np.uint8),
    )


class ActionScaler:
    """Env actions <-> the ``[-1, 1]`` actions of the model and the planner, per dimension.

    -1 is the env's ``Box`` low and 1 its high. For a ``[-1, 1]`` box (every ``pcc/`` env) it
    is the identity and leaves the arrays untouched.

    Args:
        low: The box's lower bounds ``(n,)``.
        high: The box's upper bounds ``(n,)``.
        enabled: False makes it the identity whatever the bounds (agents saved before the
            scaling existed were trained on raw actions).
    """

    def __init__(self, low: np.ndarray, high: np.ndarray, enabled: bool = True) -> None:
        self.low = np.asarray(low, dtype=np.float64)
        self.high = np.asarray(high, dtype=np.float64)
        self.identity = not enabled or bool(np.all(self.low == -1.0) and np.all(self.high == 1.0))
        self._center = (self.high + self.low) / 2
        self._half = (self.high - self.low) / 2

    def scale(self, action: np.ndarray) -> np.ndarray:
        """Env actions -> ``[-1, 1]`` units (float32)."""
        action = np.asarray(action, dtype=np.float32)
        if self.identity:
            return action
        return ((action - self._center) / self._half).astype(np.float32)

    def unscale(self, scaled: np.ndarray) -> np.ndarray:
        """``[-1, 1]`` units -> env actions (float32)."""
        scaled = np.asarray(scaled, dtype=np.float32)
        if self.identity:
            return scaled
        return (self._center + self._half * scaled).astype(np.float32)


def check_image_space(obs_space: gym.spaces.Space) -> tuple[int, ...]:
    """The shape ``(frames, H, W)`` of a uint8 image ``Box``; ValueError for anything else."""
    if not (
        isinstance(obs_space, gym.spaces.Box)
        and obs_space.dtype == np.uint8
        and len(obs_space.shape) == 3
    ):
        raise ValueError(
            f"PCCAgent needs uint8 image observations (frames, H, W), got {obs_space}."
        )
    return tuple(int(s) for s in obs_space.shape)


def check_observations(
    observation: Any, obs_shape: tuple[int, ...], single: bool | None = None
) -> np.ndarray:
    """One observation ``obs_shape`` or a batch ``(n, *obs_shape)`` of uint8; else ValueError.

    Args:
        observation: What was given.
        obs_shape: The model's observation shape.
        single: True: only one observation; False: only a batch; None: either.
    """
    obs = np.asarray(observation)
    if obs.dtype != np.uint8:
        raise ValueError(
            f"Observations must be uint8 images in [0, 255] (got dtype {obs.dtype}); pass the "
            "env's observations unchanged (no normalization or float conversion)."
        )
    ok_single = obs.shape == obs_shape
    ok_batch = obs.ndim == len(obs_shape) + 1 and obs.shape[1:] == obs_shape
    if (
        (single is True and not ok_single)
        or (single is False and not ok_batch)
        or not (ok_single or ok_batch)
    ):
        raise ValueError(
            f"Observation has shape {obs.shape}; expected {obs_shape} or a batch "
            f"(n_envs, *{obs_shape}). Check the frame stacking and channel order "
            "(channels first)."
        )
    return obs


def check_episode_start(episode_start: Any, n: int) -> np.ndarray:
    """``episode_start`` as ``(n,)`` booleans, or ValueError."""
    starts = np.asarray(episode_start)
    if starts.dtype != bool and not (
        np.issubdtype(starts.dtype, np.integer) and np.isin(starts, (0, 1)).all()
    ):
        raise ValueError(
            f"predict(): episode_start must be booleans (or 0/1), got {starts.dtype} values "
            f"{starts.reshape(-1)[:4].tolist()}."
        )
    if starts.size != n:
        raise ValueError(
            f"predict(): episode_start has {starts.size} entries; expected {n}, one per "
            "observation of the batch."
        )
    return starts.reshape(-1).astype(bool)


def as_sb3_callback(callback: Any) -> BaseCallback | None:
    """An SB3 callback from a callback, a function ``(locals, globals) -> bool`` or a list.

    Raises:
        TypeError: Anything else (before any work is done).
    """
    if callback is None:
        return None
    if isinstance(callback, list):
        return CallbackList([_one_callback(c) for c in callback])
    return _one_callback(callback)


def _one_callback(callback: Any) -> BaseCallback:
    if isinstance(callback, BaseCallback):
        return callback
    if callable(callback):
        return ConvertCallback(callback)
    raise TypeError(
        f"callback must be an SB3 BaseCallback, a function (locals, globals) -> bool, or a "
        f"list of these; got {type(callback).__name__}."
    )


def resolve_preset(preset: EnvPreset | str | None, env: gym.Env, env_id: str) -> EnvPreset:
    """The agent's preset, its data noise set to the env's process noise.

    The one given, the env's row (``"paper"`` by default), or one made from the spaces of an
    env without a row. The data are sampled from the env, so saved configs then say how they
    were made.

    Raises:
        ValueError: An unknown variant, or a preset whose data noise disagrees with the env's.
    """
    if not isinstance(preset, EnvPreset):
        variant = preset or "paper"
        try:
            resolved = get_preset(env_id, variant)
        except ValueError:
            if preset is not None and env_id.startswith("pcc/"):
                raise
            resolved = default_preset_for_spaces(
                env.observation_space, env.action_space, env_id, variant=variant)
    else:
        resolved = preset
    env_noise = float(getattr(env.unwrapped, "noise_std", 0.0))
    if resolved.data.noise_std not in (0.0, env_noise):
        raise ValueError(
            f"The preset's data noise_std is {resolved.data.noise_std}, but the env's process "
            f"noise is {env_noise}: the training data are sampled from the env, so set "
            "the noise with env_kwargs={'noise_std': ...} instead."
        )
    return dataclasses.replace(resolved, data=dataclasses.replace(resolved.data,
                                                                  noise_std=env_noise))
