"""Pure dynamics of the suite: frozen parameter dataclasses and continuous-time ``xdot``.

Every function here is pure numpy and batched: a state is an array ``(..., state_dim)`` and an
action an array ``(..., action_dim)`` in *physical* units (newton metres, newtons, world
units). The environment shells in :mod:`pcc_envs` scale normalized agent actions, integrate
``xdot`` with :func:`pcc_envs.core.rk4_step`, and wrap angles.

Conventions:

* Angles are measured from the upright vertical, positive clockwise in the rendered picture
  (the tip of a rod at angle ``theta`` is at ``(sin theta, cos theta)`` times its length with
  ``y`` pointing up). ``0`` is upright, ``pi`` hangs down. Angles are wrapped to
  ``[-pi, pi)`` after each control period.
* Rods are uniform: a rod of mass ``m`` and length ``l`` has its centre of mass at ``l / 2``
  and moment of inertia ``m l^2 / 12`` about its centre (``m l^2 / 3`` about an end).
* The ``*_energy`` functions return the total mechanical energy (kinetic + potential, in
  joules, zero potential at the pivot height); tests use them to check that the integrated
  dynamics conserve energy without torque or friction.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np

__all__ = [
    "ArmParams",
    "CartPoleParams",
    "PendulumParams",
    "PlanarParams",
    "arm_absolute_angles",
    "arm_energy",
    "arm_joint_positions",
    "arm_xdot",
    "arm_xdot_list",
    "cartpole_energy",
    "cartpole_xdot",
    "pendulum_energy",
    "pendulum_xdot",
    "planar_in_collision",
    "planar_move",
    "rk4_list",
]

GRAVITY = 9.81
"""Gravitational acceleration in m/s^2 used by every domain."""


# --------------------------------------------------------------------------- pendulum
@dataclass(frozen=True)
class PendulumParams:
    """Inverted pendulum: a uniform rod on a motorized pivot.

    Attributes:
        mass: Rod mass in kg (paper: 0.1).
        length: Rod length in m (paper: 0.5).
        gravity: Gravitational acceleration in m/s^2.
        max_torque: Torque in N m produced by the normalized action ``+1`` (spec default 1).
            The largest gravity torque is ``mass * gravity * length / 2 = 0.245`` N m, so the
            default can lift the rod directly; pass a value below 0.245 to force pumping.
        max_speed: Angular velocity is clipped to ``[-max_speed, max_speed]`` rad/s (3 pi).
        damping: Viscous friction coefficient in N m s/rad (0: frictionless).
    """

    mass: float = 0.1
    length: float = 0.5
    gravity: float = GRAVITY
    max_torque: float = 1.0
    max_speed: float = 3.0 * np.pi
    damping: float = 0.0

    @property
    def inertia(self) -> float:
        """Moment of inertia about the pivot, ``m l^2 / 3`` in kg m^2."""
        return self.mass * self.length**2 / 3.0


def pendulum_xdot(state: np.ndarray, torque: np.ndarray, params: PendulumParams) -> np.ndarray:
    """Time derivative of ``(theta, theta_dot)`` under a pivot torque (N m).

    ``I theta_ddot = m g (l / 2) sin(theta) - b theta_dot + tau`` with ``theta`` measured from
    upright, so the upright equilibrium is unstable.
    """
    theta, omega = state[..., 0], state[..., 1]
    p = params
    accel = (
        p.mass * p.gravity * 0.5 * p.length * np.sin(theta) - p.damping * omega + torque[..., 0]
    ) / p.inertia
    return np.stack([omega, accel], axis=-1)


def pendulum_energy(state: np.ndarray, params: PendulumParams) -> np.ndarray:
    """Total energy ``I omega^2 / 2 + m g (l / 2) cos(theta)`` in joules (batched)."""
    theta, omega = state[..., 0], state[..., 1]
    p = params
    return 0.5 * p.inertia * omega**2 + p.mass * p.gravity * 0.5 * p.length * np.cos(theta)


# --------------------------------------------------------------------------- cart-pole
@dataclass(frozen=True)
class CartPoleParams:
    """Cart-pole: a uniform pole hinged on a cart that moves on a horizontal track.

    Attributes:
        cart_mass: Cart mass in kg (1.0).
        pole_mass: Pole mass in kg (0.1).
        pole_half_length: Half the pole length in m (0.5; the pole is 1 m long).
        gravity: Gravitational acceleration in m/s^2.
        max_force: Horizontal force on the cart in N for the normalized action ``+1`` (10).
        track_limit: The track is ``[-track_limit, track_limit]`` m (2.4); leaving it ends the
            episode.
    """

    cart_mass: float = 1.0
    pole_mass: float = 0.1
    pole_half_length: float = 0.5
    gravity: float = GRAVITY
    max_force: float = 10.0
    track_limit: float = 2.4


def cartpole_xdot(state: np.ndarray, force: np.ndarray, params: CartPoleParams) -> np.ndarray:
    """Time derivative of ``(theta, theta_dot, x, x_dot)`` under a cart force (N).

    Frictionless equations of Barto, Sutton and Anderson (1983) as corrected by Florian
    (2007), for a uniform pole of half-length ``l`` (inertia ``m_p l^2 / 3`` about its centre):

    ``theta_ddot = (g sin(theta) - cos(theta) (F + m_p l theta_dot^2 sin(theta)) / M)
    / (l (4/3 - m_p cos(theta)^2 / M))`` and
    ``x_ddot = (F + m_p l (theta_dot^2 sin(theta) - theta_ddot cos(theta))) / M``
    with ``M = m_c + m_p``.
    """
    theta, omega, _, velocity = (state[..., i] for i in range(4))
    p = params
    total = p.cart_mass + p.pole_mass
    sin, cos = np.sin(theta), np.cos(theta)
    f = force[..., 0]
    temp = (f + p.pole_mass * p.pole_half_length * omega**2 * sin) / total
    theta_acc = (p.gravity * sin - cos * temp) / (
        p.pole_half_length * (4.0 / 3.0 - p.pole_mass * cos**2 / total)
    )
    x_acc = temp - p.pole_mass * p.pole_half_length * theta_acc * cos / total
    return np.stack([omega, theta_acc, velocity, x_acc], axis=-1)


def cartpole_energy(state: np.ndarray, params: CartPoleParams) -> np.ndarray:
    """Total energy of the cart-pole in joules (batched)."""
    theta, omega, _, v = (state[..., i] for i in range(4))
    p = params
    l = p.pole_half_length
    # Pole centre velocity: (v + l cos(theta) omega, -l sin(theta) omega).
    centre_speed2 = (v + l * np.cos(theta) * omega) ** 2 + (l * np.sin(theta) * omega) ** 2
    kinetic = 0.5 * p.cart_mass * v**2 + 0.5 * p.pole_mass * centre_speed2
    rotation = 0.5 * (p.pole_mass * l**2 / 3.0) * omega**2
    return kinetic + rotation + p.pole_mass * p.gravity * l * np.cos(theta)


# --------------------------------------------------------------------------- N-link arm
@dataclass(frozen=True)
class ArmParams:
    """Planar N-link arm of identical uniform rods with a motor at every joint.

    The state is ``(q_1..q_N, q_dot_1..q_dot_N)``: ``q_1`` is the first link's angle from
    upright, ``q_i`` (``i > 1``) the angle of link ``i`` relative to link ``i - 1``. The absolute
    angle of link ``i`` is ``phi_i = q_1 + ... + q_i``.

    Attributes:
        num_links: Number of links ``N`` (2 or 3 in the paper).
        link_mass: Mass of every rod in kg (0.1).
        link_length: Length of every rod in m (0.5).
        gravity: Gravitational acceleration in m/s^2.
        max_torque: Torque in N m at each joint for the normalized action ``+1`` (one value per
            joint, base joint first). ``None`` selects :meth:`default_max_torque`.
        max_speed: Joint velocities are clipped to ``[-max_speed, max_speed]`` rad/s (4 pi).
    """

    num_links: int = 3
    link_mass: float = 0.1
    link_length: float = 0.5
    gravity: float = GRAVITY
    max_torque: tuple[float, ...] | None = None
    max_speed: float = 4.0 * np.pi
    _coefficients: np.ndarray = field(init=False, repr=False, compare=False)
    _gravity: np.ndarray = field(init=False, repr=False, compare=False)
    _operators: tuple[np.ndarray, ...] = field(init=False, repr=False, compare=False)
    _lists: tuple[list, list] = field(init=False, repr=False, compare=False)

    def __post_init__(self) -> None:
        if self.num_links < 1:
            raise ValueError(f"num_links must be >= 1, got {self.num_links}")
        if self.max_torque is None:
            object.__setattr__(self, "max_torque", self.default_max_torque(self.num_links))
        torque = tuple(float(t) for t in self.max_torque)  # type: ignore[union-attr]
        if len(torque) != self.num_links or min(torque) <= 0:
            raise ValueError(
                f"max_torque needs {self.num_links} positive values (one per joint), got "
                f"{self.max_torque!r}"
            )
        object.__setattr__(self, "max_torque", torque)
        n = self.num_links
        idx = np.arange(n)
        outer = n - 1 - np.maximum(idx[:, None], idx[None, :])
        coeff = (outer + 0.5).astype(np.float64)
        coeff[idx, idx] = n - 1 - idx + 1.0 / 3.0
        object.__setattr__(self, "_coefficients", coeff * self.link_mass * self.link_length**2)
        gravity = self.link_mass * self.gravity * self.link_length * (n - idx - 0.5)
        object.__setattr__(self, "_gravity", gravity)
        # Row-vector operators: phi = q @ lower (cumulative sum), q_ddot = phi_ddot @ diff_op,
        # generalized force Q = tau @ torque_op (Q_i = tau_i - tau_{i+1}).
        lower = np.triu(np.ones((n, n)))
        diff_op = np.eye(n) - np.eye(n, k=1)
        torque_op = np.eye(n) - np.eye(n, k=-1)
        object.__setattr__(self, "_operators", (lower, diff_op, torque_op))
        object.__setattr__(self, "_lists", (self._coefficients.tolist(), gravity.tolist()))

    @staticmethod
    def default_max_torque(num_links: int) -> tuple[float, ...]:
        """Per-joint torque limits: 3/4 of the static torque holding the outer links level.

        The holding torque of joint ``j`` is ``m g l sum_k (k - 1/2)`` over the ``N - j + 1``
        links beyond it, stretched horizontally; the limit is 3/4 of it, rounded to 0.05 N m.

        Below the static holding torque no joint can lift its outer links quasi-statically
        through the horizontal, so swing-up needs pumping, while balancing near upright (where
        the gravity torque is small) stays easy. 2 links: ``(0.75, 0.2)``; 3 links:
        ``(1.65, 0.75, 0.2)`` N m for 0.1 kg, 0.5 m rods.
        """
        m, l = 0.1, 0.5
        torques = []
        for joint in range(num_links):
            outer = num_links - joint
            hold = m * GRAVITY * l * sum(k - 0.5 for k in range(1, outer + 1))
            torques.append(round(0.75 * hold / 0.05) * 0.05)
        return tuple(round(t, 2) for t in torques)

    @property
    def gravity_coefficients(self) -> np.ndarray:
        """``m g l (N - i + 1/2)`` for link ``i`` (1-based): gravity torque per ``sin(phi_i)``."""
        return self._gravity.copy()


def arm_absolute_angles(q: np.ndarray) -> np.ndarray:
    """Absolute link angles ``phi_i = q_1 + ... + q_i`` (batched, not wrapped)."""
    return np.cumsum(q, axis=-1)


def arm_joint_positions(q: np.ndarray, params: ArmParams) -> np.ndarray:
    """Positions ``(..., N, 2)`` of the far end of every link, ``(x, y)`` with ``y`` up, in m."""
    phi = arm_absolute_angles(q)
    steps = params.link_length * np.stack([np.sin(phi), np.cos(phi)], axis=-1)
    return np.cumsum(steps, axis=-2)


def arm_xdot(state: np.ndarray, torque: np.ndarray, params: ArmParams) -> np.ndarray:
    """Time derivative of ``(q, q_dot)`` from the Euler-Lagrange equations.

    The Lagrangian is written in absolute angles ``phi``, where the mass matrix is
    ``M_ij = a_ij cos(phi_i - phi_j)`` with ``a_ii = m l^2 (N - i + 1/3)`` and
    ``a_ij = m l^2 (N - max(i, j) + 1/2)`` (1-based), the velocity terms are
    ``C_i = sum_j a_ij sin(phi_i - phi_j) phi_dot_j^2`` and gravity
    ``G_i = -m g l (N - i + 1/2) sin(phi_i)``. The joint torque ``tau_i`` acts between link
    ``i - 1`` and link ``i`` so its generalized force is ``Q_i = tau_i - tau_{i+1}``.
    ``M phi_ddot = Q - C - G`` is solved with a batched ``np.linalg.solve`` and mapped back to
    relative coordinates, ``q_ddot_i = phi_ddot_i - phi_ddot_{i-1}``.
    """
    if state.ndim == 1 and np.ndim(torque) == 1:
        return _arm_xdot_single(state, torque, params)
    n = params.num_links
    lower, diff_op, torque_op = params._operators
    phi = state[..., :n] @ lower
    phi_dot = state[..., n:] @ lower
    diff = phi[..., :, None] - phi[..., None, :]
    a = params._coefficients
    mass_matrix = a * np.cos(diff)
    coriolis = ((a * np.sin(diff)) @ (phi_dot**2)[..., None])[..., 0]
    rhs = torque @ torque_op - coriolis + params._gravity * np.sin(phi)
    phi_ddot = np.linalg.solve(mass_matrix, rhs[..., None])[..., 0]
    return np.concatenate([state[..., n:], phi_ddot @ diff_op], axis=-1)


def _arm_xdot_single(state: np.ndarray, torque: np.ndarray, params: ArmParams) -> np.ndarray:
    """:func:`arm_xdot` for one state (see :func:`arm_xdot_list`)."""
    values = state.tolist()
    n = params.num_links
    return np.array(values[n:] + arm_xdot_list(values, torque.tolist(), params)[n:])


def arm_xdot_list(values: list[float], tau: list[float], params: ArmParams) -> list[float]:
    """:func:`arm_xdot` for one state given as a Python list, in plain Python floats.

    numpy's per-call overhead dominates for a 2 x 2 or 3 x 3 system and the env steps one
    state at a time, so the env's single-state integrator uses this (a test checks that it
    equals the batched numpy version).
    """
    n = params.num_links
    a, grav = params._lists
    phi, phi_dot = [], []
    total, rate = 0.0, 0.0
    for i in range(n):
        total += values[i]
        rate += values[n + i]
        phi.append(total)
        phi_dot.append(rate)
    sq = [w * w for w in phi_dot]
    matrix = [[0.0] * (n + 1) for _ in range(n)]
    for i in range(n):
        row = matrix[i]
        rhs = tau[i] - (tau[i + 1] if i + 1 < n else 0.0) + grav[i] * math.sin(phi[i])
        for j in range(n):
            d = phi[i] - phi[j]
            row[j] = a[i][j] * math.cos(d)
            rhs -= a[i][j] * math.sin(d) * sq[j]
        row[n] = rhs
    # Gaussian elimination without pivoting: the mass matrix is symmetric positive definite.
    for k in range(n):
        pivot = matrix[k]
        for i in range(k + 1, n):
            factor = matrix[i][k] / pivot[k]
            row = matrix[i]
            for j in range(k, n + 1):
                row[j] -= factor * pivot[j]
    acc = [0.0] * n
    for i in range(n - 1, -1, -1):
        row = matrix[i]
        acc[i] = (row[n] - sum(row[j] * acc[j] for j in range(i + 1, n))) / row[i]
    return values[n:] + [acc[0]] + [acc[i] - acc[i - 1] for i in range(1, n)]


def rk4_list(xdot, values: list[float], dt: float) -> list[float]:  # noqa: ANN001
    """One RK4 step of ``dv/dt = xdot(v)`` on a Python list (single-state fast path)."""
    k1 = xdot(values)
    k2 = xdot([v + 0.5 * dt * k for v, k in zip(values, k1)])
    k3 = xdot([v + 0.5 * dt * k for v, k in zip(values, k2)])
    k4 = xdot([v + dt * k for v, k in zip(values, k3)])
    return [
        v + (dt / 6.0) * (a + 2.0 * b + 2.0 * c + d)
        for v, a, b, c, d in zip(values, k1, k2, k3, k4)
    ]


def arm_energy(state: np.ndarray, params: ArmParams) -> np.ndarray:
    """Total energy ``phi_dot^T M phi_dot / 2 + sum_i m g l (N - i + 1/2) cos(phi_i)`` in J."""
    n = params.num_links
    phi = np.cumsum(state[..., :n], axis=-1)
    phi_dot = np.cumsum(state[..., n:], axis=-1)
    mass_matrix = params._coefficients * np.cos(phi[..., :, None] - phi[..., None, :])
    kinetic = 0.5 * np.einsum("...i,...ij,...j->...", phi_dot, mass_matrix, phi_dot)
    potential = np.sum(params.gravity_coefficients * np.cos(phi), axis=-1)
    return kinetic + potential


# --------------------------------------------------------------------------- planar
@dataclass(frozen=True)
class PlanarParams:
    """Planar navigation: a disk agent in a 40 x 40 walled world with six round obstacles.

    World units equal observation pixels; ``x`` is the column and ``y`` the row of the image
    (``(0, 0)`` is the top-left corner), so the goal ``(37, 37)`` is the bottom-right corner.

    Attributes:
        world_size: Side of the square world (40).
        agent_radius: Radius of the agent disk (1.5); its centre is clipped to
            ``[agent_radius, world_size - agent_radius]``.
        obstacle_radius: Radius of every obstacle disk (2.5).
        obstacles: Obstacle centres ``((x, y), ...)``.
        max_step: Largest displacement per step along each axis for the normalized action
            ``+-1`` (3).
        collision_clearance: Smallest allowed distance between the agent centre and an
            obstacle centre (1). The obstacles are drawn as disks of ``obstacle_radius`` but
            block only this small core, as in the paper's reference code (which refuses a move
            whose end point lies within 1 pixel, per axis, of an obstacle centre): with
            solid obstacles the straight way from the start corner (3, 37) is blocked, the
            true-state oracle reaches 60% in goal instead of 75%, and the paper's best PCC
            model (72.1%) would exceed it. ``agent_radius + obstacle_radius`` (4) makes the
            drawn disks solid, a harder variant.
    """

    world_size: float = 40.0
    agent_radius: float = 1.5
    obstacle_radius: float = 2.5
    obstacles: tuple[tuple[float, float], ...] = (
        (20.5, 5.5),
        (20.5, 13.5),
        (20.5, 27.5),
        (20.5, 35.5),
        (10.5, 20.5),
        (30.5, 20.5),
    )
    max_step: float = 3.0
    collision_clearance: float = 1.0

    def __post_init__(self) -> None:
        """Reject a clearance that is negative or not finite."""
        if not (math.isfinite(self.collision_clearance) and self.collision_clearance >= 0.0):
            raise ValueError(
                "collision_clearance must be a finite number >= 0, got "
                f"{self.collision_clearance!r}."
            )

    @property
    def low(self) -> float:
        """Smallest coordinate of the agent centre."""
        return self.agent_radius

    @property
    def high(self) -> float:
        """Largest coordinate of the agent centre."""
        return self.world_size - self.agent_radius

    @property
    def clearance(self) -> float:
        """Smallest allowed distance between the agent centre and an obstacle centre."""
        return self.collision_clearance


def planar_in_collision(position: np.ndarray, params: PlanarParams) -> np.ndarray:
    """Whether the agent centre at ``position`` (..., 2) is inside an obstacle's collision disk.

    A collision disk is the open disk of radius ``params.clearance`` around an obstacle centre.
    """
    centres = np.asarray(params.obstacles)
    dist2 = np.sum((position[..., None, :] - centres) ** 2, axis=-1)
    return np.any(dist2 < params.clearance**2, axis=-1)


def planar_move(position: np.ndarray, displacement: np.ndarray, params: PlanarParams) -> np.ndarray:
    """Collision-checked move of the agent (batched, deterministic).

    The target ``position + displacement`` is first clipped to the world box (the agent slides
    along a wall). The straight segment from ``position`` to that target is then swept against
    every obstacle's collision disk (radius ``params.clearance`` around its centre;
    closed-form segment/circle test); if it enters one, the agent stops at the first contact
    point. Moves that start in contact and point inward leave the agent where it is. The
    result is never in collision given a free ``position``.
    """
    position = np.asarray(position, dtype=np.float64)
    if position.ndim == 1 and np.ndim(displacement) == 1:
        return _planar_move_single(position, displacement, params)
    target = np.clip(position + displacement, params.low, params.high)
    delta = target - position
    centres = np.asarray(params.obstacles)
    rel = position[..., None, :] - centres  # (..., K, 2)
    a = np.sum(delta**2, axis=-1)[..., None]  # (..., 1)
    b = 2.0 * np.sum(rel * delta[..., None, :], axis=-1)
    c = np.sum(rel**2, axis=-1) - params.clearance**2
    disc = b**2 - 4.0 * a * c
    safe_a = np.where(a > 0.0, a, 1.0)
    sqrt_disc = np.sqrt(np.maximum(disc, 0.0))
    t_enter = (-b - sqrt_disc) / (2.0 * safe_a)
    t_exit = (-b + sqrt_disc) / (2.0 * safe_a)
    hits = (a > 0.0) & (disc > 0.0) & (t_exit > 0.0) & (t_enter < 1.0)
    t_stop = np.min(np.where(hits, np.clip(t_enter, 0.0, 1.0), 1.0), axis=-1)
    moved = position + t_stop[..., None] * delta
    # Rounding may leave the contact point a hair inside the inflated disk: then do not move.
    bad = planar_in_collision(moved, params)
    return np.where(bad[..., None], position, moved)


def _planar_move_single(
    position: np.ndarray, displacement: np.ndarray, params: PlanarParams
) -> np.ndarray:
    """:func:`planar_move` for one position in plain Python floats (same formulas)."""
    px, py = position.tolist()
    dx, dy = displacement.tolist()
    lo, hi = params.low, params.high
    tx, ty = min(max(px + dx, lo), hi), min(max(py + dy, lo), hi)
    dx, dy = tx - px, ty - py
    a = dx * dx + dy * dy
    r2 = params.clearance**2
    t_stop = 1.0
    if a > 0.0:
        for cx, cy in params.obstacles:
            rx, ry = px - cx, py - cy
            b = 2.0 * (rx * dx + ry * dy)
            c = (rx * rx + ry * ry) - r2
            disc = b * b - 4.0 * a * c
            if disc <= 0.0:
                continue
            root = math.sqrt(disc)
            t_enter, t_exit = (-b - root) / (2.0 * a), (-b + root) / (2.0 * a)
            if t_exit > 0.0 and t_enter < 1.0:
                t_stop = min(t_stop, min(max(t_enter, 0.0), 1.0))
    mx, my = px + t_stop * dx, py + t_stop * dy
    for cx, cy in params.obstacles:
        if (mx - cx) ** 2 + (my - cy) ** 2 < r2:
            return np.array([px, py])
    return np.array([mx, my])
