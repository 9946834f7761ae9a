"""``PCCAgent``: learn a controllable embedding from images, control it with latent iLQR-MPC.

The agent follows Stable-Baselines3's public contract (``learn -> self``, ``predict(obs,
state, episode_start, deterministic) -> (action, state)``, ``save``, ``load``, ``get_env``,
``logger``, ``num_timesteps``) so that ``evaluate_policy``, ``EvalCallback`` and
``CheckpointCallback`` work on it unchanged.

Example:
    >>> import gymnasium as gym
    >>> import pcc_envs  # noqa: F401
    >>> from pcc_agent import PCCAgent
    >>> agent = PCCAgent("pcc/Planar-v0", method="pcc", seed=0)  # doctest: +SKIP
    >>> agent.learn(total_timesteps=5000)  # doctest: +SKIP
    >>> obs, _ = agent.env.reset(seed=1)  # doctest: +SKIP
    >>> action, state = agent.predict(obs)  # doctest: +SKIP
"""

from __future__ import annotations

import dataclasses
import itertools
import os
import warnings
from pathlib import Path
from typing import Any

import gymnasium as gym
import numpy as np
import torch
from stable_baselines3.common.logger import Logger
from stable_baselines3.common.vec_env import DummyVecEnv, VecEnv

from pcc_agent.agent_inputs import (
    ActionScaler,
    action_bounds,
    as_sb3_callback,
    check_episode_start,
    check_image_space,
    check_observations,
    collect_random_rollouts,
    resolve_preset,
)
from pcc_agent.checkpoint import CheckpointError, load_checkpoint, load_weights, save_checkpoint
from pcc_agent.config import EnvPreset, PlannerConfig
from pcc_agent.io import sb3_logger, versions
from pcc_agent.losses import METHODS, model_config_for_method
from pcc_agent.model import EmbeddingModel
from pcc_agent.planning import PLANNER_REVISION
from pcc_agent.planning.cost import QuadraticCost
from pcc_agent.planning.mpc import LatentMPC
from pcc_agent.training import (
    TrainResult,
    TransitionArrays,
    dataset_arrays,
    resolve_device,
    train_embedding,
)

__all__ = ["PCCAgent", "action_bounds", "collect_random_rollouts", "sb3_logger"]


class PCCAgent:
    """Embed-to-control agent: an embedding model (PCC, E2C, RCE or an ablation) + latent MPC.

    Args:
        env: A Gymnasium env or a registered id (``"pcc/Planar-v0"``). Observations must be
            ``uint8`` images ``(frames, H, W)`` and actions a flat ``Box`` with finite bounds:
            the model and the planner work in actions scaled to ``[-1, 1]`` by that box (per
            dimension), so the agent plans over the env's whole action range
            (:meth:`scale_action`, :meth:`unscale_action`).
        method: ``"pcc"``, ``"e2c"``, ``"rce"``, ``"pcc-no-consistency"``,
            ``"pcc-no-curvature"`` or ``"pcc-amortized"``.
        preset: An :class:`~pcc_agent.presets.EnvPreset`, a variant name (``"paper"`` or
            ``"fast"``) of the env's preset, or None (the env's ``"paper"`` preset, or a
            default built from the spaces for a foreign env).
        seed: Seed of the model initialization, data set, training and planner; None draws one.
        device: ``"auto"`` (CUDA when available), ``"cpu"`` or ``"cuda"``.
        goal_obs: Observation of the goal; default ``env.unwrapped.goal_observation()``.
        planner: Overrides the preset's planner settings.
        env_kwargs: Keyword arguments of ``gym.make`` when ``env`` is an id.
        data_cache_dir: Data-set cache directory (default ``$PCC_DATA_DIR`` or
            ``~/.cache/pcc_control/datasets``).
        verbose: 0 silent, 1 progress messages.
        tensorboard_log: Directory of SB3 logger output (stdout, CSV, TensorBoard if installed).

    Attributes:
        num_timesteps: Transitions learned from so far, as in SB3 (the samples trained on):
            each training epoch, one callback step of :meth:`learn`, adds the data set size.
            Two epochs on 5,000 transitions make 10,000.
    """

    def __init__(
        self,
        env: gym.Env | str,
        method: str = "pcc",
        preset: EnvPreset | str | None = None,
        seed: int | None = None,
        device: str | torch.device = "auto",
        goal_obs: np.ndarray | None = None,
        planner: PlannerConfig | None = None,
        env_kwargs: dict[str, Any] | None = None,
        data_cache_dir: str | os.PathLike[str] | None = None,
        verbose: int = 0,
        tensorboard_log: str | None = None,
    ) -> None:
        if method not in METHODS:
            raise ValueError(f"Unknown method {method!r}; choose one of {sorted(METHODS)}.")
        self.env_kwargs = dict(env_kwargs or {})
        self.env: gym.Env | None = None
        self._vec_env: VecEnv | None = None
        self.method = method
        self.seed = int(np.random.SeedSequence().entropy % 2**31) if seed is None else int(seed)
        self.device = resolve_device(device)
        self.verbose = verbose
        self.tensorboard_log = tensorboard_log
        self.data_cache_dir = data_cache_dir
        self.num_timesteps = 0
        self.train_result: TrainResult | None = None
        #: Loaded from a control-only file: it plans, but cannot train, decode or be saved whole.
        self.control_only = False
        self._logger: Logger | None = None
        if env is None:
            raise ValueError("PCCAgent needs an environment (a gymnasium env or a registered id).")
        self.set_env(env)
        assert self.env is not None
        self.env_id = self.env.spec.id if self.env.spec is not None else "custom"
        self._preset = resolve_preset(preset, self.env, self.env_id)
        if planner is not None:
            self._preset = dataclasses.replace(self._preset, planner=planner)
        obs_shape = self.env.observation_space.shape
        self.obs_shape: tuple[int, ...] = tuple(int(s) for s in obs_shape)
        self.action_dim = int(self.env.action_space.shape[0])
        self._actions = ActionScaler(*action_bounds(self.env.action_space))
        model_config = model_config_for_method(self._preset.model, method)
        self._preset = dataclasses.replace(self._preset, model=model_config)
        with torch.random.fork_rng(devices=[]):
            torch.manual_seed(self.seed)
            self.model = EmbeddingModel(self.obs_shape, self.action_dim, model_config)
        self.model.to(self.device)
        self._goal_obs: np.ndarray | None = None
        self._goal_version = 0
        self._epochs_trained = 0  # bumped by learn() every epoch: part of the planner's key
        self._plan_generator = torch.Generator().manual_seed(self.seed)
        self._mpc: LatentMPC | None = None
        self._mpc_key: tuple[Any, ...] | None = None
        if goal_obs is not None:
            self.set_goal(goal_obs)

    # ------------------------------------------------------------------ settings
    @property
    def preset(self) -> EnvPreset:
        """The agent's settings: model, training, data and planner (read-only).

        Change the planner settings with :meth:`set_planner`.
        """
        return self._preset

    @preset.setter
    def preset(self, value: EnvPreset) -> None:
        raise AttributeError("PCCAgent.preset is read-only: change the planner settings with "
                             "agent.set_planner(config) or agent.set_planner(replan_every=...).")

    @property
    def planner(self) -> PlannerConfig:
        """The planner settings ``predict`` uses (change them with :meth:`set_planner`)."""
        return self._preset.planner

    def scale_action(self, action: np.ndarray) -> np.ndarray:
        """Env actions -> the ``[-1, 1]`` actions of the model and the planner (SB3's name).

        -1 and 1 are the env's ``Box`` low and high, per dimension (the identity for a
        ``[-1, 1]`` box). :meth:`learn` trains on scaled actions; the planner's
        ``action_low`` / ``action_high`` are in these units.
        """
        return self._actions.scale(action)

    def unscale_action(self, scaled: np.ndarray) -> np.ndarray:
        """The inverse of :meth:`scale_action`: ``[-1, 1]`` actions -> env actions."""
        return self._actions.unscale(scaled)

    def set_planner(self, config: PlannerConfig | None = None, **changes: Any) -> None:
        """Change the planner settings; the next :meth:`predict` plans with them.

        The planner's random draws (the initial candidate plans) restart from the agent's
        seed, so the agent then plans exactly as a freshly loaded one with these settings.
        ``set_planner()`` without arguments only restarts the draws.

        Args:
            config: The new settings; default: the current ones.
            **changes: Fields of :class:`~pcc_agent.planning.PlannerConfig` to change
                (``plan_length=20``, ``replan_every=5``, ...), applied on top of ``config``.

        Raises:
            TypeError: An unknown field name.
            ValueError: Inconsistent settings (from ``PlannerConfig``'s validation).

        Example:
            >>> agent.set_planner(plan_length=20, replan_every=5)  # doctest: +SKIP
        """
        base = self._preset.planner if config is None else config
        if not isinstance(base, PlannerConfig):
            raise TypeError(f"config must be a PlannerConfig, got {type(base).__name__}.")
        unknown = set(changes) - {f.name for f in dataclasses.fields(PlannerConfig)}
        if unknown:
            raise TypeError(f"Unknown planner settings {sorted(unknown)}; see PlannerConfig.")
        planner = dataclasses.replace(base, **changes)
        self._preset = dataclasses.replace(self._preset, planner=planner)
        self._plan_generator.manual_seed(self.seed)
        self._mpc = None

    # ------------------------------------------------------------------ set-up helpers
    def set_env(self, env: gym.Env | str) -> None:
        """Attach an environment (SB3 ``set_env``); it must have the model's spaces."""
        if isinstance(env, str):
            import pcc_envs  # noqa: F401  (registers the ids)

            env = gym.make(env, **self.env_kwargs)
        if isinstance(env, VecEnv):
            raise TypeError(
                "PCCAgent takes a single gymnasium env (it wraps it in a DummyVecEnv itself); "
                "pass env.envs[0] or the env id."
            )
        shape = check_image_space(env.observation_space)
        low, high = action_bounds(env.action_space)
        if hasattr(self, "_actions") and not (
            np.array_equal(low, self._actions.low) and np.array_equal(high, self._actions.high)
        ):
            raise ValueError(
                f"The env's action bounds are [{low.tolist()}, {high.tolist()}], the model was "
                f"built for [{self._actions.low.tolist()}, {self._actions.high.tolist()}] (it "
                "plans in actions scaled to them)."
            )
        if hasattr(self, "obs_shape") and shape != self.obs_shape:
            raise ValueError(
                f"The env's observations have shape {shape}, the model was built for "
                f"{self.obs_shape}."
            )
        self.env = env
        self._vec_env = DummyVecEnv([lambda: env])

    def get_env(self) -> VecEnv | None:
        """The training environment as a VecEnv (what SB3 callbacks expect)."""
        return self._vec_env

    def get_vec_normalize_env(self) -> None:
        """SB3 compatibility: the agent never normalizes observations."""
        return None

    @property
    def logger(self) -> Logger:
        """SB3 logger (stdout, plus CSV/TensorBoard under ``tensorboard_log``)."""
        if self._logger is None:
            formats = ["stdout"] if self.verbose else []
            if self.tensorboard_log:
                formats += ["csv", "tensorboard?"]  # TensorBoard when it is installed
            self._logger = sb3_logger(self.tensorboard_log or None, formats)
        return self._logger

    def set_logger(self, logger: Logger) -> None:
        """Use another SB3 logger."""
        self._logger = logger

    def dump_logs(self) -> None:
        """Write the logger's pending values (SB3 compatibility)."""
        self.logger.dump(self.num_timesteps)

    # ------------------------------------------------------------------ learning
    def _collect(self, num_samples: int) -> TransitionArrays:
        core = self.env.unwrapped
        horizon = self.preset.train.prediction_horizon
        if self.env_id.startswith("pcc/") and hasattr(core, "sample_state"):
            from pcc_envs.data import load_or_collect

            kwargs = {k: v for k, v in self.env_kwargs.items() if k != "noise_std"}
            data = load_or_collect(
                self.env_id,
                num_samples,
                seed=self.seed,
                noise_std=self.preset.data.noise_std,
                env_kwargs=kwargs or None,
                cache_dir=self.data_cache_dir,
                prediction_horizon=horizon,
            )
            return dataset_arrays(data)
        if horizon > 1:
            raise ValueError(
                f"prediction_horizon {horizon} needs {horizon} consecutive transitions per "
                f"sample, which only the pcc/ envs' sampler collects; pass them as learn("
                f"dataset=...) with future_action and future_obs, or use prediction_horizon 1.")
        return dataset_arrays(collect_random_rollouts(self.env, num_samples, self.seed))

    def learn(
        self,
        total_timesteps: int | None = None,
        callback: Any = None,
        log_interval: int = 1,
        progress_bar: bool = False,
        reset_num_timesteps: bool = True,
        dataset: Any = None,
        tb_log_name: str = "PCC",
        checkpoint_path: str | os.PathLike[str] | None = None,
        resume: bool = False,
        checkpoint_every: int = 1,
    ) -> PCCAgent:
        """Collect transitions, train the embedding, set the goal.

        The goal is ``goal_obs`` or the env's ``goal_observation()``. An env with neither gets
        a trained model and a warning: call :meth:`set_goal` before :meth:`predict`.

        Args:
            total_timesteps: Transitions to collect with the env's sampler (the paper's
                uniform protocol; random-policy rollouts for a foreign env): the data set size.
                Default: the preset's data size.
            callback: SB3 callback(s) or a function ``(locals, globals) -> bool``. One callback
                step is one training epoch, after which ``num_timesteps`` has grown by the data
                set size (so ``CheckpointCallback`` files and ``EvalCallback`` times differ
                from step to step); returning False stops training.
            log_interval: Epochs between logger dumps.
            progress_bar: Show a progress bar over epochs (training and validation loss, best
                so far) and, when training ends, one line on why it stopped.
            reset_num_timesteps: Start ``num_timesteps`` from 0 (else continue counting).
            dataset: Train on these transitions instead of collecting: a
                ``pcc_envs.data.TransitionDataset`` or a tuple ``(obs, action, next_obs)``,
                actions in the env's units (they are scaled to ``[-1, 1]`` by the env's box).
            tb_log_name: Unused, SB3 compatibility.
            checkpoint_path: Training checkpoint written atomically every ``checkpoint_every``
                epochs (weights, optimizer and RNG state; see :class:`pcc_agent.training.Trainer`).
                Not the agent file of :meth:`save`.
            resume: Continue the training saved at ``checkpoint_path`` (if it exists) exactly
                where it stopped: a training cut short (a crash, the end of a session) and
                resumed gives the weights of an uninterrupted one.
            checkpoint_every: Epochs between training checkpoints.

        Returns:
            self.
        """
        if self.control_only:
            raise RuntimeError(
                "This agent was loaded from a control-only file (encoder and latent dynamics "
                "only): it plans but cannot train. Train from a full checkpoint, or a new agent."
            )
        sb3_callback = as_sb3_callback(callback)  # refuse a wrong one before any work
        if dataset is not None:
            data = dataset_arrays(dataset)
        else:
            n = self.preset.data.num_samples if total_timesteps is None else int(total_timesteps)
            if n < 2:
                raise ValueError(f"total_timesteps must be >= 2, got {n}.")
            data = self._collect(n)
        obs = data.obs
        check_observations(obs[:1], self.obs_shape, single=False)
        if not self._actions.identity:
            data = dataclasses.replace(data, action=self._actions.scale(data.action), **(
                {} if data.future_action is None else
                {"future_action": self._actions.scale(data.future_action)}))
        if reset_num_timesteps:
            self.num_timesteps = 0
        # SB3's meaning: num_timesteps counts the transitions learned from and advances with
        # every callback step. One step here is one epoch, one pass over the whole data set.
        first_timestep, epoch_timesteps = self.num_timesteps, len(obs)
        if self._goal_obs is None and hasattr(self.env.unwrapped, "goal_observation"):
            self.set_goal(self.env.unwrapped.goal_observation())
        if sb3_callback is not None:
            sb3_callback.init_callback(self)  # type: ignore[arg-type]
            sb3_callback.on_training_start(locals(), globals())

        def on_epoch(epoch: int, metrics: dict[str, float]) -> bool:
            # ``epoch`` counts the epochs of a resumed training too: the same steps as unbroken.
            self._epochs_trained += 1  # the weights changed: the planner must be rebuilt
            self.num_timesteps = first_timestep + epoch * epoch_timesteps
            for key, value in metrics.items():
                self.logger.record(f"train/{key}", value)
            self.logger.record("train/epoch", epoch)
            self.logger.record("time/total_timesteps", self.num_timesteps)
            if log_interval and epoch % log_interval == 0:
                self.logger.dump(self.num_timesteps)
            if sb3_callback is None:
                return True
            sb3_callback.update_locals(locals())
            return bool(sb3_callback.on_step())

        self.train_result = train_embedding(
            self.model,
            data,
            self.preset.train,
            method=self.method,
            device=self.device,
            seed=self.seed,
            progress_bar=progress_bar,
            epoch_callback=on_epoch,
            checkpoint_path=checkpoint_path,
            resume=resume,
            checkpoint_every=checkpoint_every,
        )
        self.num_timesteps = first_timestep + self.train_result.epochs * epoch_timesteps
        if sb3_callback is not None:
            sb3_callback.on_training_end()
        if self._goal_obs is None:
            # The trained embedding serves any goal: keep it, and say what predict() needs.
            warnings.warn(
                "No goal yet: this env has no goal_observation() and no goal_obs= was given; "
                "call set_goal(goal_obs) before predict().",
                stacklevel=2,
            )
        return self

    # ------------------------------------------------------------------ control
    def set_goal(self, goal_obs: np.ndarray) -> None:
        """Set the goal the planner steers to, from an image.

        The goal is one observation as the env returns it: ``uint8`` of the model's
        observation shape ``(frames, H, W)`` (:attr:`obs_shape`), e.g. the goal state's
        frame repeated ``frames`` times, or an observation recorded at the goal. It is encoded
        once, at the next :meth:`predict`, and again only when the goal or the model's weights
        change.

        Raises:
            ValueError: Not a uint8 image of shape :attr:`obs_shape` (the message says which).
        """
        goal = np.asarray(goal_obs)
        if goal.dtype != np.uint8 or goal.shape != self.obs_shape:
            raise ValueError(
                f"set_goal(): the goal must be one observation, uint8 of shape {self.obs_shape} "
                f"(frames, H, W) like the env's; got {goal.dtype} {goal.shape}. Pass an "
                "observation recorded at the goal (not a batch, not normalized)."
            )
        self._goal_obs = goal.copy()
        self._goal_version += 1

    @property
    def goal_observation(self) -> np.ndarray | None:
        """The goal observation (a copy), or None before ``learn``."""
        return None if self._goal_obs is None else self._goal_obs.copy()

    def _weights_key(self) -> tuple[Any, ...]:
        """A cheap version of the model's weights.

        It changes with every epoch of :meth:`learn` and with any replaced tensor
        (``model.to``) or in-place update that bumps the tensors' version counters
        (``load_state_dict``, an optimizer without the fused kernel). The epoch count is needed
        because the fused Adam kernel that training uses updates the weights in place without
        bumping their version counters, so the counters alone kept the planner of the first
        epoch for the whole training.
        """
        return (self._epochs_trained, *(
            (id(t), t.data_ptr(), t._version)
            for t in itertools.chain(self.model.parameters(), self.model.buffers())))

    @property
    def mpc(self) -> LatentMPC:
        """The latent MPC that :meth:`predict` runs (model dynamics, encoded goal, settings).

        Built at first use and rebuilt only when the goal, the planner settings or the model's
        weights change (so the goal is encoded once, not at every step). Weights changes it
        sees: every epoch of :meth:`learn`, ``load_state_dict``, ``model.to``. After changing
        the weights in place some other way (an optimizer of your own), call
        :meth:`set_planner` to rebuild it.

        Raises:
            RuntimeError: No goal set yet.
        """
        if self._goal_obs is None:
            raise RuntimeError("No goal set: call set_goal(goal_obs) first (learn() sets it only "
                               "on an env with goal_observation()).")
        key = (self._weights_key(), self._goal_version, self._preset.planner)
        if self._mpc is None or key != self._mpc_key:
            self.model.eval()
            with torch.no_grad():
                goal, _ = self.model.encode(torch.as_tensor(self._goal_obs[None],
                                                            device=self.device))
            config = self._preset.planner
            cost = QuadraticCost.from_config(config, goal[0], self.action_dim)
            self._mpc = LatentMPC(self.model.planner_dynamics(), cost, config,
                                  generator=self._plan_generator)
            self._mpc_key = key
        return self._mpc

    @torch.no_grad()
    def predict(
        self,
        observation: np.ndarray,
        state: np.ndarray | tuple[np.ndarray, np.ndarray] | None = None,
        episode_start: np.ndarray | None = None,
        deterministic: bool = True,
    ) -> tuple[np.ndarray, np.ndarray | tuple[np.ndarray, np.ndarray]]:
        """Plan with latent iLQR-MPC and return the first action.

        Args:
            observation: One observation ``(frames, H, W)`` or a batch ``(n, frames, H, W)``.
            state: The MPC warm start returned by the previous call (shifted plans, float
                ``(n, T, action_dim)`` with ``T`` the planner's ``plan_length``; ``n`` is 1 for
                one observation), or None at the start. With the planner's ``replan_every``
                above 1 it is the pair ``(plans, steps_left)``: the carried plan is executed
                open loop while ``steps_left`` is positive, then refined.
            episode_start: Booleans (or 0/1) ``(n,)``: True where an episode starts (its warm
                start is dropped and it plans from scratch).
            deterministic: Unused: the MPC policy is deterministic given the seed.

        Returns:
            ``(action, state)``: actions inside the action space, ``(action_dim,)`` or
            ``(n, action_dim)``, and the warm start to pass back next call.

        Raises:
            ValueError: An observation, ``state`` or ``episode_start`` of the wrong shape or
                dtype (or a non-finite ``state``).
            RuntimeError: No goal set yet.
        """
        obs = check_observations(observation, self.obs_shape)
        single = obs.shape == self.obs_shape
        batch = obs[None] if single else obs
        n = batch.shape[0]
        starts = None if episode_start is None else check_episode_start(episode_start, n)
        mpc = self.mpc  # raises without a goal; encodes the goal when it or the weights changed
        self.model.eval()
        z0, _ = self.model.encode(torch.as_tensor(batch, device=self.device))
        u, next_state = mpc.step(z0, state, starts, caller="predict()")
        if not self._actions.identity:
            u = torch.as_tensor(self._actions.unscale(u.cpu().numpy()), device=self.device)
        low = torch.as_tensor(self.env.action_space.low, device=self.device)
        high = torch.as_tensor(self.env.action_space.high, device=self.device)
        actions = torch.clamp(u, low, high).cpu().numpy().astype(np.float32)
        return (actions[0] if single else actions), next_state

    # ------------------------------------------------------------------ persistence
    def config_dict(self) -> dict[str, Any]:
        """Everything that defines this agent, JSON-serializable."""
        return {
            "env_id": self.env_id,
            "method": self.method,
            "seed": self.seed,
            "env_kwargs": self.env_kwargs,
            "model": self.preset.model.to_dict(),
            "train": self.preset.train.to_dict(),
            "data": dataclasses.asdict(self.preset.data),
            "planner": dataclasses.asdict(self.preset.planner),
            "planner_revision": PLANNER_REVISION,
            "episode_length": getattr(self.env.spec, "max_episode_steps", None),
            "observation_shape": list(self.obs_shape),
            "action_dim": self.action_dim,
            "action_low": self.env.action_space.low.tolist(),
            "action_high": self.env.action_space.high.tolist(),
            "action_scaling": "box",  # actions scaled to [-1, 1] by the bounds above
        }

    def train_summary(self) -> dict[str, Any]:
        """Training outcome (epochs, wall time, best validation loss), JSON-serializable."""
        if self.train_result is None:
            return {}
        return self.train_result.summary()

    def save(self, path: str | os.PathLike[str], half: bool = False,
             control_only: bool = False) -> None:
        """Save weights, configuration, goal and versions to one file (atomic, safe to load).

        Args:
            path: The file; ``.pt`` is appended when it has no suffix. A ``.safetensors``
                suffix writes the safetensors format (see :mod:`pcc_agent.checkpoint`).
            half: Store the weights as float16 (``.safetensors`` only): half the size; the
                loaded agent computes with the rounded weights, so evaluate the loaded agent
                to know its score.
            control_only: Store only the encoder and the latent dynamics (``.safetensors``
                only): what :meth:`predict` uses, so the loaded agent plans exactly the same,
                in a file a third the size or less; it cannot be trained further.

        Raises:
            ValueError: A whole save of an agent loaded from a control-only file (its other
                weights were never loaded), or ``half`` / ``control_only`` with a ``.pt`` path.
        """
        if self.control_only and not control_only:
            raise ValueError(
                "This agent was loaded from a control-only file: save it with "
                "control_only=True (its decoder and backward model were never loaded)."
            )
        path = Path(path)
        if path.suffix == "":
            path = path.with_suffix(".pt")
        extra = {
            "versions": versions(),
            "num_timesteps": self.num_timesteps,
            "goal_obs": None if self._goal_obs is None else self._goal_obs.tolist(),
            "train_summary": self.train_summary(),
        }
        save_checkpoint(path, self.model, self.config_dict(), extra, half=half,
                        control_only=control_only)

    @classmethod
    def load(
        cls,
        path: str | os.PathLike[str],
        env: gym.Env | str | None = None,
        device: str | torch.device = "auto",
        **kwargs: Any,
    ) -> PCCAgent:
        """Load an agent saved by :meth:`save`.

        Args:
            path: The file, ``.pt`` or ``.safetensors`` (``.pt`` is appended when missing and
                the bare path does not exist).
            env: The environment to control; default: ``gym.make`` of the saved env id.
            device: Device of the model.
            **kwargs: Ignored SB3 arguments (``custom_objects``, ...).

        Raises:
            CheckpointError: Unreadable file, or an env whose spaces differ from the saved ones.
        """
        path = Path(path)
        if not path.exists() and path.with_suffix(".pt").exists():
            path = path.with_suffix(".pt")
        checkpoint = load_checkpoint(path)
        cfg = checkpoint.config
        try:
            env = cfg["env_id"] if env is None else env
            method = cfg["method"]
            preset = EnvPreset.from_dict(cfg)
        except (KeyError, TypeError, ValueError) as error:
            raise CheckpointError(f"{path} is not a PCCAgent checkpoint: {error}") from error
        agent = cls(
            env,
            method=method,
            preset=preset,
            seed=cfg.get("seed"),
            device=device,
            env_kwargs=cfg.get("env_kwargs"),
        )
        if list(agent.obs_shape) != list(cfg["observation_shape"]) or (
            agent.action_dim != cfg["action_dim"]
        ):
            raise CheckpointError(
                f"{path} was saved for observations {tuple(cfg['observation_shape'])} and "
                f"{cfg['action_dim']} actions; this env has {agent.obs_shape} and "
                f"{agent.action_dim}. Load it with the env it was trained on."
            )
        if not agent._actions.identity and cfg.get("action_scaling") != "box":
            # Saved before the agent scaled actions to the box: trained on raw actions.
            warnings.warn(
                f"{path} was saved by an older version that trained and planned in the env's "
                "raw action units (planner bounds [-1, 1]); it is loaded that way. Retrain it "
                "to plan over the env's whole action box.",
                stacklevel=2,
            )
            agent._actions = ActionScaler(agent._actions.low, agent._actions.high, enabled=False)
        load_weights(agent.model, checkpoint)
        agent.control_only = checkpoint.control_only
        agent.model.to(agent.device)
        goal = checkpoint.extra.get("goal_obs")
        if goal is not None:
            agent.set_goal(np.asarray(goal, dtype=np.uint8))
        agent.num_timesteps = int(checkpoint.extra.get("num_timesteps", 0))
        return agent

    def __repr__(self) -> str:
        return (
            f"PCCAgent(env={self.env_id!r}, method={self.method!r}, seed={self.seed}, "
            f"device={str(self.device)!r})"
        )
