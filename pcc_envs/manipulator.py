"""Planar N-link manipulator swing-up from pixels (paper, Appendix "Domains")."""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from pcc_envs.core import ImageControlEnv, rk4_step, wrap_angle
from pcc_envs.physics import ArmParams, arm_xdot, arm_xdot_list, rk4_list
from pcc_envs.rendering import ArmView, render_arm

__all__ = ["ARM_DOMAINS", "ArmDomain", "ManipulatorEnv", "start_angles"]

GOAL_ANGLE = np.pi / 6
"""Success when the last link's absolute angle is within ``pi / 6`` of upright ..."""
SAMPLER_SPEED = 2.0 * np.pi
"""The data sampler draws joint velocities in ``[-2 pi, 2 pi]`` rad/s."""
VALIDATION_ANGLE_SPREAD = np.pi / 8
"""Validation starts: every joint of :func:`start_angles` ``+ U(-pi/8, pi/8)`` rad, at rest."""


@dataclass(frozen=True)
class ArmDomain:
    """The state space, limits, picture and goal of an arm domain (one row of :data:`ARM_DOMAINS`).

    Attributes:
        joint_limits: ``|q_i|`` bounds of the joints after the base (one per outer joint), or
            ``None`` for joints that turn freely (angles wrapped). A bounded joint stops at its
            bound: the angle is clipped and the rate into the stop set to zero.
        sampler_speed: The data sampler draws every joint rate in ``[-sampler_speed,
            sampler_speed]`` rad/s.
        max_speed: Joint rates are clipped to ``[-max_speed, max_speed]`` rad/s after each step.
        max_torque: Torque per joint for the action ``+1`` (N m), or ``None`` for
            :meth:`pcc_envs.physics.ArmParams.default_max_torque`.
        rod_width: Rod stroke width in pixels.
        outside_goal_dt_scale: The control period outside the goal region is ``dt`` times this
            (1: a fixed period).
        goal: ``"tip"``: the last link within ``pi/6`` of upright with every joint and the tip
            above the base; ``"every_link"``: every link's absolute angle within ``pi/6``.
    """

    joint_limits: tuple[float, ...] | None = None
    sampler_speed: float = SAMPLER_SPEED
    max_speed: float = 4.0 * np.pi
    max_torque: tuple[float, ...] | None = None
    rod_width: int = 3
    outside_goal_dt_scale: float = 1.0
    goal: str = "tip"

    def __post_init__(self) -> None:
        if self.goal not in ("tip", "every_link"):
            raise ValueError(f"goal must be 'tip' or 'every_link', got {self.goal!r}")
        if self.joint_limits is not None and not all(0 < b <= np.pi for b in self.joint_limits):
            raise ValueError(f"joint_limits must lie in (0, pi], got {self.joint_limits!r}")
        if not 0 < self.sampler_speed <= self.max_speed:
            raise ValueError(
                f"need 0 < sampler_speed <= max_speed, got {self.sampler_speed}, {self.max_speed}")
        if self.outside_goal_dt_scale <= 0 or self.rod_width < 1:
            raise ValueError("outside_goal_dt_scale must be positive and rod_width >= 1")


#: The arm domains by name. ``"full"`` (v0): joints turn freely, fast rates, a fixed 0.02 s step.
#: ``"pc3"`` (``pcc/ThreeLink-v1``): the 3-link domain of the PCC authors' code (their PC3
#: repository, read as a reference): outer joints within ``2 pi/3`` and ``pi/3``, rates within
#: ``pi/2`` rad/s, torque 1 N m on every joint, 5-pixel rods, a 0.05 s step outside the goal,
#: and the goal every link within ``pi/6`` of upright. One difference, on purpose: at a bound
#: their code wraps the joint to the opposite bound; ours stops there (a physical joint stop).
ARM_DOMAINS: dict[str, ArmDomain] = {
    "full": ArmDomain(),
    "pc3": ArmDomain(joint_limits=(2.0 * np.pi / 3.0, np.pi / 3.0), sampler_speed=np.pi / 2,
                     max_speed=np.pi / 2, max_torque=(1.0, 1.0, 1.0), rod_width=5,
                     outside_goal_dt_scale=2.5, goal="every_link"),
}


def start_angles(num_links: int) -> np.ndarray:
    """The paper's start configuration ``q_i = (N - i + 1) pi / N`` (relative angles).

    3 links: ``(pi, 2 pi/3, pi/3)`` as in the paper; 2 links, by the same rule: ``(pi, pi/2)``.
    The first link hangs down; the outer links fold back toward upright.
    """
    return wrap_angle(np.arange(num_links, 0, -1) * np.pi / num_links)


class ManipulatorEnv(ImageControlEnv):
    r"""Swing an N-link arm up and balance it from pixels (TwoLink-v0, ThreeLink-v0 and -v1).

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
    :class:`pcc_envs.core.ImageControlEnv`), ``domain`` (a row of :data:`ARM_DOMAINS`:
    ``"full"``, described above, or ``"pc3"``, the PCC authors' bounded, slow 3-link domain of
    ``pcc/ThreeLink-v1``, which replaces the ranges, torques, rods, control period and goal
    above by its own; see :class:`ArmDomain`).

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
        domain: str = "full",
    ) -> None:
        if domain not in ARM_DOMAINS:
            raise ValueError(f"unknown arm domain {domain!r}; known: {sorted(ARM_DOMAINS)}")
        self.domain = ARM_DOMAINS[domain]
        limits = self.domain.joint_limits
        if limits is not None and len(limits) != int(num_links) - 1:
            raise ValueError(
                f"arm domain {domain!r} bounds {len(limits)} outer joints, so it needs "
                f"num_links={len(limits) + 1}, got {num_links}")
        if max_torque is None:
            max_torque = self.domain.max_torque
        torque = None if max_torque is None else tuple(np.atleast_1d(max_torque).tolist())
        self.params = ArmParams(num_links=int(num_links), max_torque=torque,
                                max_speed=self.domain.max_speed)
        self.view = ArmView(rod_width=self.domain.rod_width)
        self.num_links = self.params.num_links
        self.action_scale = self.params.max_torque  # type: ignore[assignment]
        n = self.num_links
        angle_bounds = np.full(n, np.pi) if limits is None else np.array([np.pi, *limits])
        self._joint_bounds = None if limits is None else np.asarray(limits, dtype=np.float64)
        self.state_low = np.concatenate([-angle_bounds, np.full(n, -self.domain.sampler_speed)])
        self.state_high = -self.state_low
        self.goal_state = np.zeros(2 * n)
        self.reward_weights = np.concatenate([np.ones(n), np.full(n, 0.1)])
        super().__init__(noise_std=noise_std, reward_type=reward_type, render_mode=render_mode,
                         frame_gap=frame_gap)

    def _xdot(self, state: np.ndarray, action: np.ndarray) -> np.ndarray:
        return arm_xdot(state, action, self.params)

    def _control_period(self, state: np.ndarray) -> np.ndarray | float:
        """``dt``, or ``dt * outside_goal_dt_scale`` outside the goal (batched: ``(N, 1)``)."""
        scale = self.domain.outside_goal_dt_scale
        if scale == 1.0:
            return self.dt
        if state.ndim == 1:  # the env's step: the plain-Python goal test
            return self.dt if self.in_goal(state) else self.dt * scale
        inside = self._goal_mask(np.asarray(state, dtype=np.float64))
        return np.where(inside, self.dt, self.dt * scale)[..., None]

    def _integrate(self, state: np.ndarray, action: np.ndarray, direction: float,
                   scalar_path: bool = True) -> np.ndarray:
        """RK4 over one control period, forward (``direction`` 1) or backward (-1)."""
        period = self._control_period(state)
        if scalar_path and state.ndim == 1 and action.ndim == 1:
            # One state (the env's step): the same RK4 in plain Python floats, 10x faster.
            tau = action.tolist()
            values = state.tolist()
            h = direction * float(period) / self.substeps
            for _ in range(self.substeps):
                values = rk4_list(lambda v: arm_xdot_list(v, tau, self.params), values, h)
            return self._postprocess(np.array(values))
        h = direction * np.asarray(period) / self.substeps
        for _ in range(self.substeps):
            state = rk4_step(self._xdot, state, action, h)
        return self._postprocess(state)

    def _dynamics(self, state: np.ndarray, action: np.ndarray) -> np.ndarray:
        return self._integrate(np.asarray(state, dtype=np.float64),
                               np.asarray(action, dtype=np.float64), 1.0)

    def _previous_state(self, state: np.ndarray) -> np.ndarray:
        state = np.asarray(state, dtype=np.float64)
        zero = np.zeros(state.shape[:-1] + (self.num_links,))
        return self._integrate(state, zero, -1.0, scalar_path=False)

    def _postprocess(self, state: np.ndarray) -> np.ndarray:
        n = self.num_links
        out = np.array(state, dtype=np.float64)
        if self._joint_bounds is None:
            out[..., :n] = wrap_angle(out[..., :n])
        else:
            out[..., 0] = wrap_angle(out[..., 0])
            bound = self._joint_bounds
            angles, rates = out[..., 1:n], out[..., n + 1:]
            # A joint stop: the angle stays at its bound, the rate into the stop is lost.
            rates[((angles >= bound) & (rates > 0)) | ((angles <= -bound) & (rates < 0))] = 0.0
            out[..., 1:n] = np.clip(angles, -bound, bound)
        out[..., n:] = np.clip(out[..., n:], -self.params.max_speed, self.params.max_speed)
        return out

    def _sample_start_state(self, rng: np.random.Generator) -> np.ndarray:
        return np.concatenate([start_angles(self.num_links), np.zeros(self.num_links)])

    def _sample_validation_start_state(self, rng: np.random.Generator) -> np.ndarray:
        angles = start_angles(self.num_links) + rng.uniform(
            -VALIDATION_ANGLE_SPREAD, VALIDATION_ANGLE_SPREAD, self.num_links)
        return self._postprocess(np.concatenate([angles, np.zeros(self.num_links)]))

    def state_error(self, state: np.ndarray, goal: np.ndarray | None = None) -> np.ndarray:
        """``state - goal`` with the joint angles wrapped to ``[-pi, pi)`` (batched)."""
        err = super().state_error(state, goal)
        err[..., : self.num_links] = wrap_angle(err[..., : self.num_links])
        return err

    def in_goal(self, state: np.ndarray) -> bool:
        """Whether ``state`` is in the domain's goal region (see :class:`ArmDomain`.goal)."""
        q = np.asarray(state, dtype=np.float64)[: self.num_links].tolist()
        if self.domain.goal == "every_link":
            phi = 0.0
            for angle in q:
                phi += angle
                if abs(float(wrap_angle(phi))) >= GOAL_ANGLE:
                    return False
            return True
        height, phi = 0.0, 0.0
        for angle in q:
            phi += angle
            height += self.params.link_length * math.cos(phi)
            if height <= 0.0:
                return False
        return abs(float(wrap_angle(phi))) <= GOAL_ANGLE

    def _goal_mask(self, states: np.ndarray) -> np.ndarray:
        """Batched :meth:`in_goal` (a bool array of the batch shape)."""
        phi = np.cumsum(states[..., : self.num_links], axis=-1)
        if self.domain.goal == "every_link":
            return np.all(np.abs(wrap_angle(phi)) < GOAL_ANGLE, axis=-1)
        heights = np.cumsum(np.cos(phi), axis=-1)
        return np.all(heights > 0.0, axis=-1) & (np.abs(wrap_angle(phi[..., -1])) <= GOAL_ANGLE)

    def render_states(self, states: np.ndarray) -> np.ndarray:
        """Render ``(N, 2 num_links)`` states to ``uint8 (N, 80, 80)`` frames."""
        return render_arm(states, self.params, self.view)
