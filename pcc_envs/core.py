"""The shell shared by every environment of the suite.

An environment of this suite is a set of pure functions (continuous-time dynamics, a renderer,
a goal test) wired into a Gymnasium environment by :class:`ImageControlEnv`. The base class
owns everything that must behave the same in every domain:

* action validation and scaling (the agent always sees ``Box(-1, 1)``; the env multiplies by
  ``action_scale`` to get the physical action),
* the RK4 integration of ``_xdot`` (domains with closed-form dynamics only write ``_xdot``),
* optional Gaussian process noise on the next true state,
* frame stacking (:func:`stack_frames`, also used by :mod:`pcc_envs.data`),
* the ``info`` keys (``state``, ``in_goal``, ``is_success``, ``goal_fraction``) and the reward,
* the protocol used by :mod:`pcc_agent` (``sample_state``, ``transition``, ``state_error``,
  ``goal_observation`` ...), documented in ``docs/ARCHITECTURE.md``.
"""

from __future__ import annotations

from collections.abc import Sequence
from typing import Any, ClassVar

import cv2
import gymnasium as gym
import numpy as np
from gymnasium import spaces

__all__ = ["ImageControlEnv", "rk4_step", "stack_frames", "wrap_angle"]


def wrap_angle(angle: np.ndarray | float) -> np.ndarray:
    """Wrap angles to ``[-pi, pi)``."""
    return (np.asarray(angle) + np.pi) % (2.0 * np.pi) - np.pi


def rk4_step(xdot: Any, state: np.ndarray, action: np.ndarray, dt: float) -> np.ndarray:
    """One classical Runge-Kutta (RK4) step of ``ds/dt = xdot(s, a)`` with ``a`` held fixed.

    Works on batches: ``state`` is ``(..., n)`` and ``action`` broadcasts against it.
    """
    k1 = xdot(state, action)
    k2 = xdot(state + 0.5 * dt * k1, action)
    k3 = xdot(state + 0.5 * dt * k2, action)
    k4 = xdot(state + dt * k3, action)
    return state + (dt / 6.0) * (k1 + 2.0 * k2 + 2.0 * k3 + k4)


def stack_frames(frames: Sequence[np.ndarray], out: np.ndarray | None = None) -> np.ndarray:
    """Stack frames, oldest first, into observations.

    This is the suite's single frame-stacking rule: the environment and the dataset sampler
    both build observations with it, so a model sees the same layout in training and control.

    Args:
        frames: ``num_frames`` arrays of shape ``(H, W)`` (one observation) or ``(N, H, W)``
            (a batch), ordered from oldest to newest.
        out: Optional ``uint8`` destination of the result's shape (the dataset sampler
            writes straight into its preallocated arrays).

    Returns:
        ``uint8`` array of shape ``(num_frames, H, W)`` or ``(N, num_frames, H, W)``.
    """
    if out is not None:
        return np.stack(frames, axis=-3, out=out, casting="unsafe")
    return np.stack(frames, axis=-3).astype(np.uint8, copy=False)


class ImageControlEnv(gym.Env[np.ndarray, np.ndarray]):
    """Base class: a pixel-observation control task over a known true state.

    Subclasses set the class attributes below and implement :meth:`render_states`,
    :meth:`in_goal`, :meth:`_sample_start_state`, and either :meth:`_xdot` (continuous-time
    dynamics integrated by RK4 over ``dt`` with ``substeps``) or :meth:`_dynamics` (a
    discrete-time map, e.g. Planar's collision-checked displacement).

    Args:
        noise_std: Standard deviation of zero-mean Gaussian process noise added to every next
            true state (paper, Section 6). ``0`` gives deterministic dynamics.
        reward_type: ``"dense"`` (negative weighted squared state error to the goal, see
            :meth:`reward`) or ``"sparse"`` (``1`` when the true state is in the goal region).
        render_mode: ``None`` or ``"rgb_array"`` (a larger, human-friendly picture).
        frame_gap: Control periods between consecutive stacked frames (default 1: the
            paper's consecutive frames). A larger gap shows more motion between the frames
            (e.g. an arm's outer joints, which move under a pixel per 20 ms period), while
            the dynamics, tasks and goal stay the same; an observation then spans
            ``(num_frames - 1) * frame_gap`` periods. Only for domains with
            ``num_frames >= 2``.
    """

    metadata: ClassVar[dict[str, Any]] = {"render_modes": ["rgb_array"], "render_fps": 50}

    #: Number of stacked frames in one observation (1 for Planar, 2 for the others).
    num_frames: ClassVar[int] = 1
    #: ``(H, W)`` of one frame.
    frame_shape: ClassVar[tuple[int, int]] = (40, 40)
    #: Physical action = ``action_scale * action`` for an agent action in ``[-1, 1]``.
    action_scale: ClassVar[tuple[float, ...]] = (1.0,)
    #: Control period in seconds and integrator substeps per period.
    dt: ClassVar[float] = 0.02
    substeps: ClassVar[int] = 1
    #: Whether :meth:`transition` accepts batches and is cheap (used by the oracle planner).
    supports_oracle: ClassVar[bool] = True
    #: Upscaling factor of ``render_rgb`` (``render_mode="rgb_array"``) over one frame.
    render_scale: ClassVar[int] = 6

    def __init__(
        self,
        noise_std: float = 0.0,
        reward_type: str = "dense",
        render_mode: str | None = None,
        frame_gap: int = 1,
    ) -> None:
        if not np.isfinite(noise_std) or noise_std < 0:
            raise ValueError(f"noise_std must be a finite number >= 0, got {noise_std!r}")
        if reward_type not in ("dense", "sparse"):
            raise ValueError(f"reward_type must be 'dense' or 'sparse', got {reward_type!r}")
        if render_mode is not None and render_mode not in self.metadata["render_modes"]:
            raise ValueError(
                f"render_mode must be None or one of {self.metadata['render_modes']}, "
                f"got {render_mode!r}"
            )
        if isinstance(frame_gap, bool) or not isinstance(frame_gap, (int, np.integer)) or (
                frame_gap < 1):
            raise ValueError(f"frame_gap must be an integer >= 1, got {frame_gap!r}")
        if frame_gap > 1 and self.num_frames < 2:
            raise ValueError(f"frame_gap {frame_gap} needs stacked frames; "
                             f"{type(self).__name__} observes {self.num_frames} frame")
        self.frame_gap = int(frame_gap)
        #: Frames the env keeps: every period of the span of one observation.
        self.history_length = (self.num_frames - 1) * self.frame_gap + 1
        self.noise_std = float(noise_std)
        self.reward_type = reward_type
        self.render_mode = render_mode
        self.action_dim = len(self.action_scale)
        self._action_scale = np.asarray(self.action_scale, dtype=np.float64)
        self.action_space = spaces.Box(-1.0, 1.0, (self.action_dim,), dtype=np.float32)
        self.observation_space = spaces.Box(
            0, 255, (self.num_frames, *self.frame_shape), dtype=np.uint8
        )
        self.state_low = np.asarray(self.state_low, dtype=np.float64)
        self.state_high = np.asarray(self.state_high, dtype=np.float64)
        self.goal_state = np.asarray(self.goal_state, dtype=np.float64)
        self.state_dim = int(self.goal_state.shape[0])
        self._state: np.ndarray | None = None
        self._frames: list[np.ndarray] = []
        self._steps = 0
        self._steps_in_goal = 0

    # ------------------------------------------------------------------ domain hooks
    #: Box the paper's uniform sampler draws true states from; contains every start and goal.
    state_low: Any = None
    state_high: Any = None
    #: The true goal state.
    goal_state: Any = None
    #: Diagonal weights of the dense reward ``-sum(w * state_error**2)``.
    reward_weights: Any = None

    def _xdot(self, state: np.ndarray, action: np.ndarray) -> np.ndarray:
        """Continuous-time dynamics ``ds/dt`` for a physical action (batched)."""
        raise NotImplementedError

    def _postprocess(self, state: np.ndarray) -> np.ndarray:
        """Map an integrated state back to its canonical range (wrap angles, clip speeds)."""
        return state

    def _dynamics(self, state: np.ndarray, action: np.ndarray) -> np.ndarray:
        """Deterministic discrete-time map for a *physical* action (batched).

        The default integrates :meth:`_xdot` with ``substeps`` RK4 steps over ``dt``.
        """
        h = self.dt / self.substeps
        for _ in range(self.substeps):
            state = rk4_step(self._xdot, state, action, h)
        return self._postprocess(state)

    def _previous_state(self, state: np.ndarray) -> np.ndarray:
        """The state one control period before ``state`` under zero action.

        Used to give the first observation after ``reset`` a real frame history. The
        default integrates the dynamics backward in time (negative ``dt``).
        """
        h = -self.dt / self.substeps
        zero = np.zeros(self.action_dim)
        for _ in range(self.substeps):
            state = rk4_step(self._xdot, state, zero, h)
        return self._postprocess(state)

    def _sample_start_state(self, rng: np.random.Generator) -> np.ndarray:
        """Draw a task start state (the paper's start distribution for this domain)."""
        raise NotImplementedError

    def _sample_validation_start_state(self, rng: np.random.Generator) -> np.ndarray:
        """Draw a start state of a validation task (``reset(options={"start": "validation"})``).

        The task start distribution itself, except in domains whose tasks all start from one
        fixed state (swing-up, the arms): there, choosing anything on tasks from that state
        would be choosing on the evaluation task, so those domains perturb it. (Lane keeping
        perturbs its two starts in its own ``reset``: they come from a drift, not a draw.)
        """
        return self._sample_start_state(rng)

    def _is_terminal(self, state: np.ndarray) -> bool:
        """Whether the physics ends the episode (e.g. cart off the track)."""
        return False

    def render_states(self, states: np.ndarray) -> np.ndarray:
        """Render a batch of true states ``(N, state_dim)`` to ``uint8`` frames ``(N, H, W)``."""
        raise NotImplementedError

    def in_goal(self, state: np.ndarray) -> bool:
        """Whether the true state is inside the goal region."""
        raise NotImplementedError

    # ------------------------------------------------------------------ public protocol
    def sample_state(self, rng: np.random.Generator) -> np.ndarray:
        """Uniform sample from the state box (the paper's data protocol)."""
        return self.sample_states(rng, 1)[0]

    def sample_states(self, rng: np.random.Generator, num_states: int) -> np.ndarray:
        """``num_states`` independent draws of :meth:`sample_state`, shape ``(num, state_dim)``.

        Subclasses whose valid states are not a box (Planar's free space) override this one
        method; :meth:`sample_state` follows.
        """
        return rng.uniform(self.state_low, self.state_high, (num_states, self.state_dim))

    def sample_action(self, rng: np.random.Generator, size: int | None = None) -> np.ndarray:
        """Uniform normalized action(s) in ``[-1, 1]``."""
        shape = (self.action_dim,) if size is None else (size, self.action_dim)
        return rng.uniform(-1.0, 1.0, shape)

    def transition(self, state: np.ndarray, action: np.ndarray) -> np.ndarray:
        """Deterministic true dynamics for a *normalized* action (batched, no noise).

        This is a model of the env for planners (the oracle controller): actions are clipped
        to ``[-1, 1]`` here because finite differences may step over the bound. The env's
        :meth:`step` never clips: it rejects an out-of-range action.
        """
        state = np.asarray(state, dtype=np.float64)
        action = np.clip(np.asarray(action, dtype=np.float64), -1.0, 1.0)
        return self._dynamics(state, action * self._action_scale)

    def add_process_noise(self, state: np.ndarray, rng: np.random.Generator) -> np.ndarray:
        """Add the env's Gaussian process noise (``noise_std``) to a next state."""
        if self.noise_std == 0.0:
            return state
        return self._postprocess(state + self.noise_std * rng.standard_normal(state.shape))

    def state_error(self, state: np.ndarray, goal: np.ndarray | None = None) -> np.ndarray:
        """``state - goal`` with angular coordinates wrapped to ``[-pi, pi)`` (batched)."""
        goal = self.goal_state if goal is None else goal
        return np.asarray(state, dtype=np.float64) - goal

    def render_state(self, state: np.ndarray) -> np.ndarray:
        """Render one true state to one ``uint8`` frame ``(H, W)``."""
        return self.render_states(np.asarray(state, dtype=np.float64)[None])[0]

    def observation_of(self, state: np.ndarray) -> np.ndarray:
        """The observation an agent would see at ``state`` after a zero-action history.

        Earlier frames show the state integrated backward by ``frame_gap`` control periods
        per frame under zero action, so the frame pair carries the state's velocity.
        """
        return self.observations_of(np.asarray(state, dtype=np.float64)[None])[0]

    def observations_of(self, states: np.ndarray) -> np.ndarray:
        """Batched :meth:`observation_of`: ``(N, state_dim)`` -> ``uint8 (N, frames, H, W)``."""
        return stack_frames(self._history_frames(states)[:: self.frame_gap])

    def _history_frames(self, states: np.ndarray) -> list[np.ndarray]:
        """The ``history_length`` frames up to ``states`` under a zero-action past, oldest first."""
        history = [np.asarray(states, dtype=np.float64)]
        while len(history) < self.history_length:
            history.insert(0, self._previous_state(history[0]))
        return [self.render_states(s) for s in history]

    def goal_observation(self) -> np.ndarray:
        """Observation of the goal state: the planner's target."""
        return self.observation_of(self.goal_state)

    def reward(self, state: np.ndarray, in_goal: bool) -> float:
        """Dense: ``-sum(w * state_error(state)**2)``; sparse: ``1.0`` in goal else ``0``."""
        if self.reward_type == "sparse":
            return float(in_goal)
        err = self.state_error(state)
        if self.reward_weights is None:
            return -float(np.dot(err, err))
        return -float(np.dot(self.reward_weights, err * err))

    @property
    def state(self) -> np.ndarray:
        """A copy of the current true state."""
        if self._state is None:
            raise RuntimeError("Call reset() before reading the state.")
        return self._state.copy()

    # ------------------------------------------------------------------ gymnasium API
    def _validate_action(self, action: Any) -> np.ndarray:
        try:
            arr = np.asarray(action, dtype=np.float64)
        except (TypeError, ValueError) as exc:
            raise ValueError(f"Action must be numeric, got {action!r}") from exc
        if arr.shape != (self.action_dim,):
            if arr.size == self.action_dim and arr.ndim <= 1:
                arr = arr.reshape(self.action_dim)
            else:
                raise ValueError(
                    f"Action has shape {arr.shape}, expected ({self.action_dim},) for "
                    f"{type(self).__name__}; for several envs use a VecEnv."
                )
        low, high = float(arr.min()), float(arr.max())
        if -1.0 - 1e-6 <= low and high <= 1.0 + 1e-6:  # fast path; False for NaN
            return arr
        if not np.all(np.isfinite(arr)):
            raise ValueError(f"Action contains NaN or inf: {arr}")
        if np.any(np.abs(arr) > 1.0 + 1e-6):
            raise ValueError(
                f"Action {arr} is outside the action space [-1, 1]; actions are normalized "
                f"and scaled inside the env by {self.action_scale}."
            )
        return arr

    def _observation(self) -> np.ndarray:
        return stack_frames(self._frames[:: self.frame_gap])

    def _info(self, in_goal: bool) -> dict[str, Any]:
        return {
            "state": self.state,
            "in_goal": bool(in_goal),
            "is_success": bool(in_goal),
            "goal_fraction": self._steps_in_goal / max(self._steps, 1),
        }

    def reset(
        self, *, seed: int | None = None, options: dict[str, Any] | None = None
    ) -> tuple[np.ndarray, dict[str, Any]]:
        """Start an episode.

        ``options={"state": s}`` starts from the true state ``s`` instead of a draw from the
        start distribution; ``options={"start": "validation"}`` draws from the validation
        tasks' start distribution (:meth:`_sample_validation_start_state`), ``"task"`` (the
        default) from the task start distribution. The first observation carries a real frame
        history: earlier frames show the state one control period before, under zero action.
        """
        super().reset(seed=seed)
        start = _start_option(options)
        if start == "validation":
            state = np.asarray(self._sample_validation_start_state(self.np_random),
                               dtype=np.float64)
        elif options is not None and "state" in options:
            state = np.asarray(options["state"], dtype=np.float64).copy()
            if state.shape != (self.state_dim,) or not np.all(np.isfinite(state)):
                raise ValueError(
                    f"options['state'] must be a finite array of shape ({self.state_dim},), "
                    f"got {options['state']!r}"
                )
        else:
            state = np.asarray(self._sample_start_state(self.np_random), dtype=np.float64)
        self._state = state
        self._frames = [frames[0] for frames in self._history_frames(state[None])]
        self._steps = 0
        self._steps_in_goal = 0
        return self._observation(), self._info(self.in_goal(state))

    def step(
        self, action: np.ndarray
    ) -> tuple[np.ndarray, float, bool, bool, dict[str, Any]]:
        """Apply one normalized action for one control period."""
        if self._state is None:
            raise RuntimeError("Call reset() before step().")
        arr = self._validate_action(action)
        next_state = self._dynamics(self._state, arr * self._action_scale)
        next_state = self.add_process_noise(next_state, self.np_random)
        self._state = next_state
        self._frames = [*self._frames[1:], self.render_state(next_state)]
        in_goal = self.in_goal(next_state)
        self._steps += 1
        self._steps_in_goal += int(in_goal)
        terminated = self._is_terminal(next_state)
        return self._observation(), self.reward(next_state, in_goal), terminated, False, (
            self._info(in_goal)
        )

    def render_rgb(self, state: np.ndarray) -> np.ndarray:
        """A larger RGB picture of ``state`` (``render_scale`` times the observation frame)."""
        frame = self.render_state(state)
        h, w = frame.shape
        big = cv2.resize(
            frame, (w * self.render_scale, h * self.render_scale), interpolation=cv2.INTER_NEAREST
        )
        return np.repeat(big[:, :, None], 3, axis=2)

    def render(self) -> np.ndarray | None:
        """Return an RGB array of the current state when ``render_mode="rgb_array"``."""
        if self.render_mode is None:
            gym.logger.warn("render() called with render_mode=None; pass render_mode='rgb_array'.")
            return None
        return self.render_rgb(self.state)


_START_OPTIONS = ("task", "validation")


def _start_option(options: dict[str, Any] | None) -> str:
    """The ``"start"`` reset option, checked (``"task"`` when absent)."""
    start = (options or {}).get("start", "task")
    if start not in _START_OPTIONS:
        raise ValueError(f"options['start'] must be one of {_START_OPTIONS}, got {start!r}")
    if start == "validation" and "state" in (options or {}):
        raise ValueError("Pass either options['state'] or options['start'] = 'validation', "
                         "not both.")
    return str(start)
