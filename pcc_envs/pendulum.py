"""Inverted pendulum from pixels: swing-up and balance (paper, Appendix "Domains")."""

from __future__ import annotations

import numpy as np

from pcc_envs.core import ImageControlEnv, wrap_angle
from pcc_envs.physics import PendulumParams, pendulum_xdot
from pcc_envs.rendering import PendulumView, render_pendulum

__all__ = ["PendulumEnv"]

_TASKS = ("swingup", "balance")
GOAL_ANGLE = np.pi / 6
"""Success when ``|theta| <= pi / 6``."""
VALIDATION_ANGLE_SPREAD = np.pi / 8
"""Swing-up validation starts: hanging ``+ U(-pi/8, pi/8)`` rad ..."""
VALIDATION_RATE_SPREAD = 0.5
"""... moving at ``U(-0.5, 0.5)`` rad/s (every evaluation task starts exactly hanging at rest)."""


class PendulumEnv(ImageControlEnv):
    r"""Swing a rod up from pixels and balance it (PendulumSwingUp-v0, PendulumBalance-v0).

    ## Description
    A uniform rod (mass 0.1 kg, length 0.5 m, g = 9.81 m/s^2, no friction) turns about a
    motorized pivot: ``I theta_ddot = m g (l/2) sin(theta) + tau`` with ``I = m l^2 / 3``
    (:func:`pcc_envs.physics.pendulum_xdot`), integrated by RK4 at 50 Hz (``dt = 0.02`` s,
    one substep). The true state ``(theta, theta_dot)`` is hidden: ``theta`` is measured from
    upright, wrapped to ``[-pi, pi)``; ``theta_dot`` is clipped to ``[-3 pi, 3 pi]`` rad/s.

    ## Action Space
    ``Box(-1, 1, (1,), float32)``: the pivot torque is ``max_torque * action`` N m (default
    1 N m, the paper's range; the largest gravity torque is 0.245 N m, so pass
    ``max_torque < 0.245`` for a swing-up that needs pumping).

    ## Observation Space
    ``Box(0, 255, (2, 48, 48), uint8)``: the previous and the current frame, each a white
    3-pixel rod from the frame centre (20 pixels long) on black
    (:func:`pcc_envs.rendering.render_pendulum`).

    ## Rewards
    Dense (default): ``-(theta^2 + 0.1 theta_dot^2)`` with ``theta`` wrapped. Sparse: ``1``
    while ``|theta| <= pi/6``.

    ## Starting State
    Swing-up: hanging down at rest, ``(pi, 0)`` (stored wrapped, ``-pi``); its validation
    tasks (``reset(options={"start": "validation"})``) start within ``pi/8`` of hanging, at
    up to 0.5 rad/s. Balance: ``theta`` uniform in ``[-pi/6, pi/6]``, at rest. The data
    sampler draws ``theta`` uniform in ``[-pi, pi]`` and ``theta_dot`` uniform in ``[-3 pi, 3 pi]``.

    ## Episode End
    Truncation after 400 steps (8 s, set by the registration). Never terminates.

    ## Arguments
    ``task`` (``"swingup"`` | ``"balance"``), ``max_torque`` (N m), ``damping`` (N m s/rad),
    ``noise_std`` (process noise on the true state), ``reward_type`` (``"dense"`` |
    ``"sparse"``), ``render_mode`` (``None`` | ``"rgb_array"``).

    >>> import gymnasium as gym
    >>> import pcc_envs  # noqa: F401
    >>> env = gym.make("pcc/PendulumSwingUp-v0")
    >>> obs, info = env.reset(seed=0)
    >>> obs.shape, info["state"].round(3).tolist()
    ((2, 48, 48), [-3.142, 0.0])
    >>> obs, reward, terminated, truncated, info = env.step(env.action_space.sample())
    >>> info["in_goal"]
    False
    """

    num_frames = 2
    frame_shape = (48, 48)
    dt = 0.02
    substeps = 1
    reward_weights = np.array([1.0, 0.1])
    goal_state = np.zeros(2)

    def __init__(
        self,
        task: str = "swingup",
        max_torque: float = 1.0,
        damping: float = 0.0,
        noise_std: float = 0.0,
        reward_type: str = "dense",
        render_mode: str | None = None,
    ) -> None:
        if task not in _TASKS:
            raise ValueError(f"task must be one of {_TASKS}, got {task!r}")
        if not max_torque > 0:
            raise ValueError(f"max_torque must be > 0 N m, got {max_torque!r}")
        self.task = task
        self.params = PendulumParams(max_torque=float(max_torque), damping=float(damping))
        self.view = PendulumView()
        self.action_scale = (self.params.max_torque,)
        self.state_low = np.array([-np.pi, -self.params.max_speed])
        self.state_high = np.array([np.pi, self.params.max_speed])
        super().__init__(noise_std=noise_std, reward_type=reward_type, render_mode=render_mode)

    def _xdot(self, state: np.ndarray, action: np.ndarray) -> np.ndarray:
        return pendulum_xdot(state, action, self.params)

    def _postprocess(self, state: np.ndarray) -> np.ndarray:
        out = np.array(state, dtype=np.float64)
        out[..., 0] = wrap_angle(out[..., 0])
        out[..., 1] = np.clip(out[..., 1], -self.params.max_speed, self.params.max_speed)
        return out

    def _sample_start_state(self, rng: np.random.Generator) -> np.ndarray:
        if self.task == "balance":
            return np.array([rng.uniform(-GOAL_ANGLE, GOAL_ANGLE), 0.0])
        return np.array([wrap_angle(np.pi), 0.0])

    def _sample_validation_start_state(self, rng: np.random.Generator) -> np.ndarray:
        if self.task == "balance":
            return self._sample_start_state(rng)
        angle = np.pi + rng.uniform(-VALIDATION_ANGLE_SPREAD, VALIDATION_ANGLE_SPREAD)
        return np.array([wrap_angle(angle),
                         rng.uniform(-VALIDATION_RATE_SPREAD, VALIDATION_RATE_SPREAD)])

    def state_error(self, state: np.ndarray, goal: np.ndarray | None = None) -> np.ndarray:
        """``state - goal`` with the angle wrapped to ``[-pi, pi)`` (batched)."""
        err = super().state_error(state, goal)
        err[..., 0] = wrap_angle(err[..., 0])
        return err

    def in_goal(self, state: np.ndarray) -> bool:
        """Whether the rod is within ``pi/6`` of upright."""
        return bool(abs(wrap_angle(state[0])) <= GOAL_ANGLE)

    def render_states(self, states: np.ndarray) -> np.ndarray:
        """Render ``(N, 2)`` states to ``uint8 (N, 48, 48)`` frames."""
        return render_pendulum(states, self.params, self.view)

    def __repr__(self) -> str:
        return f"PendulumEnv(task={self.task!r}, params={self.params!r})"
