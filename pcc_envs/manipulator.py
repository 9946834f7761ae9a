"""Planar N-link manipulator swing-up from pixels (paper, Appendix "Domains")."""

from __future__ import annotations

import math

import numpy as np

from pcc_envs.core import ImageControlEnv, wrap_angle
from pcc_envs.physics import ArmParams, arm_xdot, arm_xdot_list, rk4_list
from pcc_envs.rendering import ArmView, render_arm

__all__ = ["ManipulatorEnv", "start_angles"]

GOAL_ANGLE = np.pi / 6
"""Success when the last link's absolute angle is within ``pi / 6`` of upright ..."""
SAMPLER_SPEED = 2.0 * np.pi
"""The data sampler draws joint velocities in ``[-2 pi, 2 pi]`` rad/s."""
VALIDATION_ANGLE_SPREAD = np.pi / 8
"""Validation starts: every joint of :func:`start_angles` ``+ U(-pi/8, pi/8)`` rad, at rest."""


def start_angles(num_links: int) -> np.ndarray:
    """The paper's start configuration ``q_i = (N - i + 1) pi / N`` (relative angles).

    3 links: ``(pi, 2 pi/3, pi/3)`` as in the paper; 2 links, by the same rule: ``(pi, pi/2)``.
    The first link hangs down; the outer links fold back toward upright.
    """
    return wrap_angle(np.arange(num_links, 0, -1) * np.pi / num_links)


class ManipulatorEnv(ImageControlEnv):
    r"""Swing an N-link arm up and balance it from pixels (TwoLink-v0, ThreeLink-v0).

    ## Description
    ``num_links`` identical uniform rods (0.1 kg, 0.5 m, g = 9.81 m/s^2, no friction) are
    chained by motorized revolute joints, the first one on a fixed base. The Euler-Lagrange
    equations (:func:`pcc_envs.physics.arm_xdot`: mass matrix, velocity and gravity terms,
    ``np.linalg.solve``) are integrated by RK4 at 50 Hz (``dt = 0.02`` s, two substeps). The
    hidden state is ``(q_1..q_N, q_dot_1..q_dot_N)``: ``q_1`` is the first link's angle from
    upright, ``q_i`` the angle of link ``i`` relative to link ``i - 1``, all wrapped to
    ``[-pi, pi)``; velocities are clipped to ``[-4 pi, 4 pi]`` rad/s.

    ## Action Space
    ``Box(-1, 1, (N,), float32)``: joint torques ``max_torque * action`` N m, base joint first.
    Defaults (:meth:`pcc_envs.physics.ArmParams.default_max_torque`, 3/4 of the torque that
    holds the outer links horizontal, so swing-up needs pumping): 2 links ``(0.75, 0.2)``,
    3 links ``(1.65, 0.75, 0.2)``.

    ## Observation Space
    ``Box(0, 255, (2, 80, 80), uint8)``: previous and current frame, the base at the frame
    centre, the stretched arm 36 pixels long, each link a 3-pixel antialiased white rod
    (:func:`pcc_envs.rendering.render_arm`).

    ## Rewards
    Dense (default): ``-(sum_i q_i^2 + 0.1 sum_i q_dot_i^2)`` with the angles wrapped (0 when
    the arm stands straight up). Sparse: ``1`` in the goal region.

    ## Starting State
    At rest in the paper's configuration :func:`start_angles`: 3 links ``(pi, 2pi/3, pi/3)``,
    2 links ``(pi, pi/2)``. Validation tasks (``reset(options={"start": "validation"})``)
    perturb every joint of it by up to ``pi/8``, so that nothing is chosen on the one start
    of every evaluation task. The data sampler draws every angle uniformly in ``[-pi, pi]`` and
    every joint velocity in ``[-2 pi, 2 pi]``.

    Why these choices: the paper gives the start state and the goal, but neither the
    sampling ranges nor the torque limits. Full-circle angles are needed because a swing-up
    passes through every configuration; ``2 pi`` rad/s bounds the joint rates that the
    default torques reach in a swing-up. The torques (3/4 of the static holding torque, see
    Action Space) make swing-up a pumping task, as the paper's "swing up and balance"
    describes, rather than a straight lift; the 2-link arm's start ``(pi, pi/2)`` follows the
    paper's ``q_i = (N - i + 1) pi / N`` rule, which the paper states only for 3 links.

    ## Episode End
    Truncation after 400 steps. Never terminates. Success (``in_goal``): the last link's
    absolute angle ``q_1 + ... + q_N`` is within ``pi/6`` of upright *and* every joint and the
    tip are above the base (the paper's angle-sum test alone would count the start state,
    whose angles sum to ``2 pi``, as a success).

    ## Arguments
    ``num_links`` (2 or 3; any ``N >= 1`` works), ``max_torque`` (one value per joint, or
    ``None`` for the defaults), ``noise_std``, ``reward_type``, ``render_mode``,
    ``frame_gap`` (control periods between the two frames, default 1; see
    :class:`pcc_envs.core.ImageControlEnv`).

    >>> import gymnasium as gym
    >>> import pcc_envs  # noqa: F401
    >>> env = gym.make("pcc/ThreeLink-v0")
    >>> obs, info = env.reset(seed=0)
    >>> obs.shape, env.action_space.shape
    ((2, 80, 80), (3,))
    >>> info["in_goal"]
    False
    """

    num_frames = 2
    frame_shape = (80, 80)
    dt = 0.02
    substeps = 2
    render_scale = 4

    def __init__(
        self,
        num_links: int = 3,
        max_torque: tuple[float, ...] | None = None,
        noise_std: float = 0.0,
        reward_type: str = "dense",
        render_mode: str | None = None,
        frame_gap: int = 1,
    ) -> None:
        torque = None if max_torque is None else tuple(np.atleast_1d(max_torque).tolist())
        self.params = ArmParams(num_links=int(num_links), max_torque=torque)
        self.view = ArmView()
        self.num_links = self.params.num_links
        self.action_scale = self.params.max_torque  # type: ignore[assignment]
        n = self.num_links
        self.state_low = np.concatenate([np.full(n, -np.pi), np.full(n, -SAMPLER_SPEED)])
        self.state_high = -self.state_low
        self.goal_state = np.zeros(2 * n)
        self.reward_weights = np.concatenate([np.ones(n), np.full(n, 0.1)])
        super().__init__(noise_std=noise_std, reward_type=reward_type, render_mode=render_mode,
                         frame_gap=frame_gap)

    def _xdot(self, state: np.ndarray, action: np.ndarray) -> np.ndarray:
        return arm_xdot(state, action, self.params)

    def _dynamics(self, state: np.ndarray, action: np.ndarray) -> np.ndarray:
        if state.ndim > 1 or action.ndim > 1:
            return super()._dynamics(state, action)
        # One state (the env's step): the same RK4 in plain Python floats, 10x faster.
        tau = action.tolist()
        values = state.tolist()
        h = self.dt / self.substeps
        for _ in range(self.substeps):
            values = rk4_list(lambda v: arm_xdot_list(v, tau, self.params), values, h)
        return self._postprocess(np.array(values))

    def _postprocess(self, state: np.ndarray) -> np.ndarray:
        n = self.num_links
        out = np.array(state, dtype=np.float64)
        out[..., :n] = wrap_angle(out[..., :n])
        out[..., n:] = np.clip(out[..., n:], -self.params.max_speed, self.params.max_speed)
        return out

    def _sample_start_state(self, rng: np.random.Generator) -> np.ndarray:
        return np.concatenate([start_angles(self.num_links), np.zeros(self.num_links)])

    def _sample_validation_start_state(self, rng: np.random.Generator) -> np.ndarray:
        angles = start_angles(self.num_links) + rng.uniform(
            -VALIDATION_ANGLE_SPREAD, VALIDATION_ANGLE_SPREAD, self.num_links)
        return np.concatenate([wrap_angle(angles), np.zeros(self.num_links)])

    def state_error(self, state: np.ndarray, goal: np.ndarray | None = None) -> np.ndarray:
        """``state - goal`` with the joint angles wrapped to ``[-pi, pi)`` (batched)."""
        err = super().state_error(state, goal)
        err[..., : self.num_links] = wrap_angle(err[..., : self.num_links])
        return err

    def in_goal(self, state: np.ndarray) -> bool:
        """Last link within ``pi/6`` of upright and every joint and the tip above the base."""
        q = np.asarray(state, dtype=np.float64)[: self.num_links].tolist()
        height, phi = 0.0, 0.0
        for angle in q:
            phi += angle
            height += self.params.link_length * math.cos(phi)
            if height <= 0.0:
                return False
        return abs(float(wrap_angle(phi))) <= GOAL_ANGLE

    def render_states(self, states: np.ndarray) -> np.ndarray:
        """Render ``(N, 2 num_links)`` states to ``uint8 (N, 80, 80)`` frames."""
        return render_arm(states, self.params, self.view)
