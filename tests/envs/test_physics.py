"""Oracles for the pure dynamics and renderers of :mod:`pcc_envs.physics` / ``rendering``."""

from __future__ import annotations

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from pcc_envs.core import rk4_step
from pcc_envs.physics import (
    ArmParams,
    CartPoleParams,
    PendulumParams,
    PlanarParams,
    arm_energy,
    arm_xdot,
    cartpole_energy,
    cartpole_xdot,
    pendulum_energy,
    pendulum_xdot,
    planar_in_collision,
    planar_move,
)
from pcc_envs.rendering import (
    PendulumView,
    render_arm,
    render_pendulum,
    render_planar,
    segment_coverage,
)


def _integrate(xdot, state, action, dt, substeps, seconds=2.0):
    h = dt / substeps
    for _ in range(int(round(seconds / h))):
        state = rk4_step(xdot, state, action, h)
    return state


def _energy_drift(energy, xdot, start, action_dim, dt, substeps):
    end = _integrate(xdot, start, np.zeros(action_dim), dt, substeps)
    return np.abs(energy(end) - energy(start))


def test_pendulum_conserves_energy():
    p = PendulumParams()
    rng = np.random.default_rng(0)
    start = np.stack([rng.uniform(-np.pi, np.pi, 64), rng.uniform(-3, 3, 64)], axis=-1)
    drift = _energy_drift(
        lambda s: pendulum_energy(s, p), lambda s, u: pendulum_xdot(s, u, p), start, 1, 0.02, 1
    )
    scale = p.mass * p.gravity * p.length  # 0.49 J, the potential energy range
    assert drift.max() < 1e-3 * scale


def test_cartpole_conserves_energy():
    p = CartPoleParams()
    rng = np.random.default_rng(1)
    start = np.stack(
        [
            rng.uniform(-np.pi, np.pi, 64),
            rng.uniform(-2, 2, 64),
            np.zeros(64),
            rng.uniform(-1, 1, 64),
        ],
        axis=-1,
    )
    drift = _energy_drift(
        lambda s: cartpole_energy(s, p), lambda s, u: cartpole_xdot(s, u, p), start, 1, 0.02, 1
    )
    scale = 2 * p.pole_mass * p.gravity * p.pole_half_length
    assert drift.max() < 1e-2 * scale


@pytest.mark.parametrize("num_links", [2, 3])
def test_arm_conserves_energy(num_links):
    p = ArmParams(num_links=num_links)
    rng = np.random.default_rng(2)
    # From rest in random configurations: the motion is chaotic and fast (tens of rad/s).
    start = np.concatenate(
        [rng.uniform(-np.pi, np.pi, (32, num_links)), np.zeros((32, num_links))], axis=-1
    )
    drift = _energy_drift(
        lambda s: arm_energy(s, p), lambda s, u: arm_xdot(s, u, p), start, num_links, 0.02, 2
    )
    scale = 2 * float(np.sum(p.gravity_coefficients))  # potential energy range
    assert np.median(drift) < 1e-3 * scale
    assert drift.max() < 0.1 * scale


def test_one_link_arm_is_the_pendulum():
    arm, pendulum = ArmParams(num_links=1, max_torque=(1.0,)), PendulumParams()
    rng = np.random.default_rng(3)
    states = rng.uniform(-3, 3, (16, 2))
    torque = rng.uniform(-1, 1, (16, 1))
    np.testing.assert_allclose(
        arm_xdot(states, torque, arm), pendulum_xdot(states, torque, pendulum)
    )


@pytest.mark.parametrize("num_links", [1, 2, 3])
def test_single_state_arm_path_matches_batched(num_links):
    p = ArmParams(num_links=num_links)
    rng = np.random.default_rng(4)
    states = rng.uniform(-3, 3, (8, 2 * num_links))
    torque = rng.uniform(-1, 1, (8, num_links))
    batch = arm_xdot(states, torque, p)
    for s, u, expected in zip(states, torque, batch):
        np.testing.assert_allclose(arm_xdot(s, u, p), expected, rtol=1e-10, atol=1e-10)


def test_gravity_pulls_away_from_upright():
    assert pendulum_xdot(np.array([0.1, 0.0]), np.zeros(1), PendulumParams())[1] > 0
    assert cartpole_xdot(np.array([0.1, 0, 0, 0]), np.zeros(1), CartPoleParams())[1] > 0
    # Pushing the cart right tips the pole left.
    assert cartpole_xdot(np.zeros(4), np.ones(1), CartPoleParams())[1] < 0


def test_default_arm_torques_cannot_hold_the_arm_level():
    for n in (2, 3):
        p = ArmParams(num_links=n)
        holding = [float(np.sum(p.gravity_coefficients[j:])) for j in range(n)]
        assert all(t < h for t, h in zip(p.max_torque, holding))


# --------------------------------------------------------------------------- planar
PLANAR = PlanarParams()
SOLID_PLANAR = PlanarParams(collision_clearance=4.0)
BOTH_GEOMETRIES = pytest.mark.parametrize("params", [PLANAR, SOLID_PLANAR], ids=["cores", "solid"])


@BOTH_GEOMETRIES
def test_planar_stops_at_the_first_contact(params):
    end = planar_move(np.array([16.5, 20.5]), np.array([-3.0, 0.0]), params)
    expected = max(16.5 - 3.0, 10.5 + params.clearance)
    np.testing.assert_allclose(end, [expected, 20.5], atol=1e-9)
    batch = planar_move(np.array([[16.5, 20.5]]), np.array([[-3.0, 0.0]]), params)
    np.testing.assert_array_equal(batch[0], end)
    start = np.array([10.5 + params.clearance + 0.5, 20.5])
    np.testing.assert_allclose(planar_move(start, np.array([-3.0, 0.0]), params),
                               [10.5 + params.clearance, 20.5], atol=1e-9)


def test_planar_obstacles_block_only_their_cores_by_default():
    # Along the bottom edge from the start corner (3, 37): the drawn disk at (20.5, 35.5)
    # reaches down to y = 38, but only a solid obstacle stops the agent.
    position = np.array([3.0, 37.0])
    for _ in range(12):
        position = planar_move(position, np.array([3.0, 0.0]), PLANAR)
    np.testing.assert_allclose(position, [38.5, 37.0])
    blocked = np.array([3.0, 37.0])
    for _ in range(12):
        blocked = planar_move(blocked, np.array([3.0, 0.0]), SOLID_PLANAR)
    assert blocked[0] < 20.5


@pytest.mark.parametrize("bad", [-1.0, float("nan"), float("inf")])
def test_planar_rejects_a_bad_clearance(bad):
    with pytest.raises(ValueError, match="collision_clearance"):
        PlanarParams(collision_clearance=bad)


def test_planar_clips_to_the_world():
    end = planar_move(np.array([2.0, 30.0]), np.array([-3.0, 0.0]), PLANAR)
    np.testing.assert_allclose(end, [1.5, 30.0])


@BOTH_GEOMETRIES
@settings(max_examples=60, deadline=None)
@given(
    start=st.tuples(st.floats(1.5, 38.5), st.floats(1.5, 38.5)),
    moves=st.lists(st.tuples(st.floats(-3, 3), st.floats(-3, 3)), min_size=1, max_size=30),
)
def test_planar_never_enters_an_obstacle(params, start, moves):
    position = np.array(start)
    if planar_in_collision(position, params):
        return
    for move in moves:
        position = planar_move(position, np.array(move), params)
        assert not planar_in_collision(position, params)
        assert np.all(position >= params.low) and np.all(position <= params.high)


@BOTH_GEOMETRIES
def test_planar_batched_random_walk_never_enters_an_obstacle(params):
    rng = np.random.default_rng(5)
    pos = rng.uniform(params.low, params.high, (4000, 2))
    pos = pos[~planar_in_collision(pos, params)]
    for _ in range(40):
        pos = planar_move(pos, rng.uniform(-3, 3, pos.shape), params)
        assert not planar_in_collision(pos, params).any()


# --------------------------------------------------------------------------- rendering
def test_pendulum_table_matches_exact_rendering():
    p, view = PendulumParams(), PendulumView()
    angles = np.linspace(-np.pi, np.pi, 13, endpoint=False) + 1e-4
    frames = render_pendulum(np.stack([angles, np.zeros_like(angles)], -1), p, view)
    rows, cols = np.mgrid[0:48, 0:48] + 0.5
    c, length = 24.0, p.length * view.pixels_per_metre
    end = np.stack([c + length * np.sin(angles), c - length * np.cos(angles)], -1)
    exact = segment_coverage(cols[None], rows[None], np.full_like(end, c), end, 1.5) * 255
    assert np.abs(frames.astype(float) - exact).max() < 8


def test_renderers_are_batched_and_uint8():
    rng = np.random.default_rng(6)
    arm = ArmParams(num_links=3)
    states = rng.uniform(-3, 3, (5, 6))
    frames = render_arm(states, arm)
    assert frames.shape == (5, 80, 80) and frames.dtype == np.uint8
    np.testing.assert_array_equal(frames[2], render_arm(states[2:3], arm)[0])
    planar = render_planar(np.array([[3.0, 3.0], [37.0, 37.0]]), PLANAR)
    assert planar[0, 3, 3] == 255 and planar[1, 37, 37] == 255
    assert planar[0, 20, 10] == 100  # an obstacle
