"""Tests of the PyBullet lane-keeping environment (pcc/LaneKeeping-v0)."""

from __future__ import annotations

import gc
import subprocess
import sys

import gymnasium as gym
import numpy as np
import pytest
from gymnasium.utils.env_checker import check_env as gym_check_env

import pcc_envs  # noqa: F401
from pcc_envs.lane_keeping import LaneKeepingEnv, LaneKeepingParams

ENV_ID = "pcc/LaneKeeping-v0"
UNIT = 3.6 / 18.0


@pytest.fixture(scope="module")
def env() -> LaneKeepingEnv:
    environment = LaneKeepingEnv()
    yield environment
    environment.close()


def _rollout(env: LaneKeepingEnv, seed: int, num_steps: int) -> tuple[list, list]:
    obs, info = env.reset(seed=seed)
    env.action_space.seed(seed)
    observations, states = [obs], [info["state"]]
    for _ in range(num_steps):
        obs, _, _, _, info = env.step(env.action_space.sample())
        observations.append(obs)
        states.append(info["state"])
    return observations, states


def test_import_does_not_load_pybullet() -> None:
    code = (
        "import sys, pcc_envs, pcc_envs.lane_keeping; "
        "assert 'pybullet' not in sys.modules; assert 'torch' not in sys.modules"
    )
    subprocess.run([sys.executable, "-c", code], check=True)


def test_gymnasium_check_env(env: LaneKeepingEnv) -> None:
    gym_check_env(env, skip_render_check=True)


def test_sb3_check_env() -> None:
    from stable_baselines3.common.env_checker import check_env

    environment = gym.make(ENV_ID)
    check_env(environment, warn=True)
    environment.close()


def test_spaces_and_protocol(env: LaneKeepingEnv) -> None:
    assert env.observation_space.shape == (2, 80, 80)
    assert env.action_space.shape == (1,)
    assert not env.supports_oracle
    assert env.state_dim == 3
    assert np.all(env.state_low <= env.goal_state) and np.all(env.goal_state <= env.state_high)
    rng = np.random.default_rng(0)
    state = env.sample_state(rng)
    assert (
        state.shape == (3,) and np.all(state >= env.state_low) and np.all(state <= env.state_high)
    )
    assert env.in_goal(env.goal_state)
    assert not env.in_goal(np.array([1.1 * UNIT, 0.0, 2.0]))
    err = env.state_error(np.array([[0.1, 3.0, 2.0]]), np.array([0.0, -3.0, 2.0]))
    np.testing.assert_allclose(err, [[0.1, 6.0 - 2 * np.pi, 0.0]])
    goal_obs = env.goal_observation()
    assert goal_obs.shape == (2, 80, 80) and goal_obs.dtype == np.uint8


def test_seeded_determinism() -> None:
    first, second = LaneKeepingEnv(), LaneKeepingEnv()
    try:
        obs_a, states_a = _rollout(first, seed=3, num_steps=15)
        obs_b, states_b = _rollout(second, seed=3, num_steps=15)
        # Same env object again after other episodes: the snapshot makes it history-free.
        _rollout(first, seed=5, num_steps=5)
        obs_c, states_c = _rollout(first, seed=3, num_steps=15)
    finally:
        first.close()
        second.close()
    for a, b, c in zip(obs_a, obs_b, obs_c):
        np.testing.assert_array_equal(a, b)
        np.testing.assert_array_equal(a, c)
    np.testing.assert_array_equal(np.array(states_a), np.array(states_b))
    np.testing.assert_array_equal(np.array(states_a), np.array(states_c))


def test_observation_binary_and_not_constant(env: LaneKeepingEnv) -> None:
    obs, _ = env.reset(seed=0)
    assert obs.shape == (2, 80, 80) and obs.dtype == np.uint8
    assert set(np.unique(obs)) <= {0, 255}
    for frame in obs:
        assert 0.1 < np.mean(frame > 0) < 0.95
    assert np.any(obs[0] != obs[1]), "the two frames of a drifting car must differ"
    states = np.array([[0.0, 0.0, 2.0], [0.6, 0.0, 2.0], [0.0, 0.4, 2.0]])
    frames = env.render_states(states)
    assert frames.shape == (3, 80, 80) and frames.dtype == np.uint8
    assert np.any(frames[0] != frames[1]) and np.any(frames[0] != frames[2])


@pytest.mark.parametrize("direction", [1, -1])
def test_forced_drift_moves_car_off_centre(env: LaneKeepingEnv, direction: int) -> None:
    _, info = env.reset(seed=0, options={"drift": direction})
    offset, heading, speed = info["state"]
    assert direction * offset > 2.5 * UNIT
    assert 0.2 < direction * heading < 0.7
    assert abs(speed - 2.0) < 0.15
    assert not info["in_goal"] and info["goal_fraction"] == 0.0
    assert abs(offset) < 0.5 * 3.6, "the drift must leave the car inside the lane"


def test_random_drift_direction_uses_seed(env: LaneKeepingEnv) -> None:
    signs = {np.sign(env.reset(seed=seed)[1]["state"][0]) for seed in range(8)}
    assert signs == {-1.0, 1.0}


def test_validation_starts_lie_near_not_at_the_two_task_starts(env: LaneKeepingEnv) -> None:
    tasks = {env.reset(options={"drift": d})[1]["state"].tobytes() for d in (-1, 1)}
    starts = [env.reset(seed=s, options={"start": "validation"})[1]["state"] for s in range(6)]
    again = env.reset(seed=3, options={"start": "validation"})[1]["state"]
    np.testing.assert_array_equal(again, starts[3])
    assert not tasks & {s.tobytes() for s in starts}
    offsets = np.abs([s[0] for s in starts])
    task_offset = abs(np.frombuffer(next(iter(tasks)))[0])
    assert np.all((offsets > 0.4 * task_offset) & (offsets < 2.0 * task_offset))
    assert np.all(offsets < 0.5 * 3.6), "validation starts must leave the car inside the lane"
    np.testing.assert_array_equal(env.reset(seed=3)[1]["state"],
                                  env.reset(seed=3, options={"start": "task"})[1]["state"])


@pytest.mark.parametrize("lengths", [(), (18, 20), (-1, 22)])
def test_validation_drift_lengths_must_leave_out_the_task_drift(lengths: tuple) -> None:
    with pytest.raises(ValueError, match="validation_drift_steps"):
        LaneKeepingParams(validation_drift_steps=lengths)


def test_centre_steering_stays_near_centre(env: LaneKeepingEnv) -> None:
    obs, info = env.reset(options={"state": np.array([0.0, 0.0, 2.0])})
    assert info["in_goal"]
    for _ in range(40):
        obs, reward, terminated, truncated, info = env.step(np.zeros(1, dtype=np.float32))
        assert info["in_goal"] and not terminated and not truncated
    assert abs(info["state"][1]) < 0.02
    assert info["goal_fraction"] == 1.0


def test_feedback_controller_recovers_from_drift(env: LaneKeepingEnv) -> None:
    for direction in (1, -1):
        _, info = env.reset(options={"drift": direction})
        for _ in range(120):
            offset, heading, _ = info["state"]
            action = np.clip([-2.0 * offset - 3.0 * heading], -1.0, 1.0).astype(np.float32)
            _, _, _, _, info = env.step(action)
            assert abs(info["state"][0]) < 0.5 * 3.6
        assert info["in_goal"]


def test_reset_via_state(env: LaneKeepingEnv) -> None:
    state = np.array([0.5, -0.2, 1.8])
    obs, info = env.reset(seed=1, options={"state": state})
    np.testing.assert_array_equal(info["state"], state)
    np.testing.assert_array_equal(obs, env.observation_of(state))
    _, _, _, _, info = env.step(np.array([0.5], dtype=np.float32))
    np.testing.assert_allclose(info["state"], env.transition(state, np.array([0.5])))
    assert info["state"][0] < state[0]  # heading right moves the car right


def test_transition_batches_match_single_states(env: LaneKeepingEnv) -> None:
    rng = np.random.default_rng(0)
    states = np.stack([env.sample_state(rng) for _ in range(3)])
    actions = env.sample_action(rng, 3)
    batch = env.transition(states, actions)
    assert batch.shape == (3, 3)
    for s, a, nxt in zip(states, actions, batch):
        np.testing.assert_array_equal(env.transition(s, a), nxt)
    np.testing.assert_allclose(env.transition(states, np.zeros(1))[:, 2], 2.0, atol=0.2)


def test_two_envs_in_one_process_are_independent() -> None:
    left, right = LaneKeepingEnv(), LaneKeepingEnv()
    alone = LaneKeepingEnv()
    try:
        assert left.physics_client_id != right.physics_client_id
        left.reset(options={"state": np.array([0.0, 0.0, 2.0])})
        right.reset(options={"state": np.array([0.0, 0.0, 2.0])})
        for _ in range(10):
            _, _, _, _, info_left = left.step(np.ones(1, dtype=np.float32))
            _, _, _, _, info_right = right.step(-np.ones(1, dtype=np.float32))
        alone.reset(options={"state": np.array([0.0, 0.0, 2.0])})
        for _ in range(10):
            _, _, _, _, info_alone = alone.step(np.ones(1, dtype=np.float32))
        np.testing.assert_array_equal(info_left["state"], info_alone["state"])
        assert info_left["state"][0] > 0 > info_right["state"][0]
    finally:
        for environment in (left, right, alone):
            environment.close()


def test_close_and_garbage_collection_disconnect() -> None:
    import pybullet

    environment = LaneKeepingEnv()
    client = environment.physics_client_id
    assert pybullet.isConnected(physicsClientId=client)
    environment.reset(seed=0)
    environment.close()
    environment.close()  # idempotent
    assert not pybullet.isConnected(physicsClientId=client)
    with pytest.raises(RuntimeError, match="closed"):
        environment.step(np.zeros(1, dtype=np.float32))

    collected = LaneKeepingEnv()
    client = collected.physics_client_id
    del collected
    gc.collect()
    assert not pybullet.isConnected(physicsClientId=client)


@pytest.mark.parametrize(
    "action", [np.array([1.5]), np.array([np.nan]), np.array([0.1, 0.2]), "left"]
)
def test_bad_actions_raise(env: LaneKeepingEnv, action: object) -> None:
    env.reset(seed=0)
    with pytest.raises(ValueError):
        env.step(action)


def test_bad_options_and_arguments_raise(env: LaneKeepingEnv) -> None:
    with pytest.raises(ValueError, match="drift"):
        env.reset(options={"drift": 0})
    with pytest.raises(ValueError, match="state"):
        env.reset(options={"state": np.array([0.0, 0.0])})
    with pytest.raises(ValueError, match="renderer"):
        LaneKeepingEnv(renderer="opengl")


def test_process_noise_is_seeded() -> None:
    noisy = LaneKeepingEnv(noise_std=0.02)
    try:
        _, states_a = _rollout(noisy, seed=4, num_steps=5)
        _, states_b = _rollout(noisy, seed=4, num_steps=5)
        np.testing.assert_array_equal(np.array(states_a), np.array(states_b))
        state = np.array([0.0, 0.0, 2.0])
        noisy.reset(seed=0, options={"state": state})
        _, _, _, _, info = noisy.step(np.zeros(1, dtype=np.float32))
        assert np.any(np.abs(info["state"] - noisy.transition(state, np.zeros(1))) > 1e-6)
    finally:
        noisy.close()


def test_analytic_masks_match_bullet_renderer(env: LaneKeepingEnv) -> None:
    bullet = LaneKeepingEnv(renderer="bullet")
    try:
        states = np.array([[0.0, 0.0, 2.0], [1.0, 0.3, 2.0], [-1.5, -0.6, 2.0]])
        analytic, rendered = env.render_states(states), bullet.render_states(states)
    finally:
        bullet.close()
    assert rendered.shape == analytic.shape == (3, 80, 80)
    for a, b in zip(analytic > 0, rendered > 0):
        assert np.sum(a & b) / np.sum(a | b) > 0.97


def test_render_rgb() -> None:
    environment = gym.make(ENV_ID, render_mode="rgb_array")
    try:
        environment.reset(seed=0)
        picture = environment.render()
    finally:
        environment.close()
    assert picture.shape == (240, 320, 3) and picture.dtype == np.uint8
    assert picture.std() > 10
