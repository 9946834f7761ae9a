"""The paper's uniform sampler and the dataset cache (:mod:`pcc_envs.data`)."""

from __future__ import annotations

import json

import gymnasium as gym
import numpy as np
import pytest

import pcc_envs
from pcc_envs.data import (
    TransitionDataset,
    cache_path,
    collect_transitions,
    load_or_collect,
    observations_for_states,
)

ORACLE = [e for e in pcc_envs.ENV_IDS if e != "pcc/LaneKeeping-v0"]


@pytest.mark.parametrize("env_id", ORACLE)
def test_transitions_follow_the_protocol(env_id):
    data = collect_transitions(env_id, 40, seed=0)
    env = gym.make(env_id).unwrapped
    assert data.obs.shape == (40, *env.observation_space.shape) and data.obs.dtype == np.uint8
    assert data.next_obs.shape == data.obs.shape
    assert data.action.dtype == np.float32 and np.all(np.abs(data.action) <= 1)
    # The newest frames show the stored states; the frame pairs overlap by one frame.
    np.testing.assert_array_equal(data.obs[:, -1], env.render_states(data.state))
    np.testing.assert_array_equal(data.next_obs[:, -1], env.render_states(data.next_state))
    if env.num_frames == 2:
        np.testing.assert_array_equal(data.obs[:, 1], data.next_obs[:, 0])
    # Without noise the next state is the true transition of the stored (float32) action.
    np.testing.assert_allclose(data.next_state, env.transition(data.state, data.action), atol=1e-12)
    assert data.metadata["env_id"] == env_id and data.metadata["num_samples"] == 40


def test_sampler_is_reproducible_from_the_seed():
    a = collect_transitions("pcc/CartPole-v0", 50, seed=7, noise_std=0.01)
    b = collect_transitions("pcc/CartPole-v0", 50, seed=7, noise_std=0.01)
    c = collect_transitions("pcc/CartPole-v0", 50, seed=8, noise_std=0.01)
    for name in ("obs", "action", "next_obs", "state", "next_state"):
        np.testing.assert_array_equal(getattr(a, name), getattr(b, name))
    assert not np.array_equal(a.state, c.state)


def test_noise_reaches_the_next_state():
    clean = collect_transitions("pcc/PendulumSwingUp-v0", 30, seed=1)
    noisy = collect_transitions("pcc/PendulumSwingUp-v0", 30, seed=1, noise_std=0.1)
    assert not np.allclose(clean.next_state, noisy.next_state)


def test_planar_samples_are_free_and_spread():
    from pcc_envs.physics import PlanarParams, planar_in_collision

    data = collect_transitions("pcc/Planar-v0", 3000, seed=2)
    assert not planar_in_collision(data.state, PlanarParams()).any()
    assert not planar_in_collision(data.next_state, PlanarParams()).any()
    assert data.state.min() < 3 and data.state.max() > 37


def test_env_kwargs_reach_the_env():
    weak = collect_transitions("pcc/PendulumSwingUp-v0", 20, 0, env_kwargs={"max_torque": 0.1})
    strong = collect_transitions("pcc/PendulumSwingUp-v0", 20, 0)
    assert not np.allclose(weak.next_state, strong.next_state)
    assert weak.metadata["env_kwargs"] == {"max_torque": 0.1}


def test_frame_gap_stacks_every_gth_state_of_the_chain():
    gap = 3
    data = collect_transitions("pcc/TwoLink-v0", 20, seed=0, env_kwargs={"frame_gap": gap})
    env = gym.make("pcc/TwoLink-v0", frame_gap=gap).unwrapped
    np.testing.assert_array_equal(data.obs[:, -1], env.render_states(data.state))
    np.testing.assert_array_equal(data.next_obs[:, -1], env.render_states(data.next_state))
    np.testing.assert_allclose(data.next_state, env.transition(data.state, data.action), atol=1e-12)
    # The older frame of the next observation is one period after the older frame of this one:
    # it is not this observation's newer frame, which lies gap periods later.
    assert np.any(data.obs[:, 1] != data.next_obs[:, 0])
    assert data.metadata["env_kwargs"] == {"frame_gap": gap}
    # A gap of 1 is the paper's protocol, sample for sample.
    plain = collect_transitions("pcc/TwoLink-v0", 20, seed=0)
    same = collect_transitions("pcc/TwoLink-v0", 20, seed=0, env_kwargs={"frame_gap": 1})
    np.testing.assert_array_equal(plain.obs, same.obs)
    np.testing.assert_array_equal(plain.next_state, same.next_state)


def test_cache_roundtrip_and_keys(tmp_path):
    first = load_or_collect("pcc/Planar-v0", 64, seed=0, cache_dir=tmp_path)
    files = sorted(tmp_path.iterdir())
    assert len(files) == 1 and files[0].name.startswith("pcc-Planar-v0_n64_s0_")
    again = load_or_collect("pcc/Planar-v0", 64, seed=0, cache_dir=tmp_path)
    np.testing.assert_array_equal(first.obs, again.obs)
    assert first.metadata == again.metadata
    # Noise 0 and 0.1 (and any other key) never share a file.
    paths = {
        cache_path("pcc/Planar-v0", 64, 0, 0.0, cache_dir=tmp_path),
        cache_path("pcc/Planar-v0", 64, 0, 0.1, cache_dir=tmp_path),
        cache_path("pcc/Planar-v0", 64, 0, 1e-17, cache_dir=tmp_path),
        cache_path("pcc/Planar-v0", 64, 1, 0.0, cache_dir=tmp_path),
        cache_path("pcc/Planar-v0", 65, 0, 0.0, cache_dir=tmp_path),
        cache_path("pcc/Planar-v0", 64, 0, 0.0, {"reward_type": "sparse"}, cache_dir=tmp_path),
    }
    assert len(paths) == 6
    load_or_collect("pcc/Planar-v0", 64, seed=0, noise_std=0.1, cache_dir=tmp_path)
    assert len(list(tmp_path.iterdir())) == 2
    assert not [p for p in tmp_path.iterdir() if p.name.endswith(".tmp")]


def test_the_registered_kwargs_are_part_of_the_key(tmp_path, monkeypatch):
    """An id re-registered with other arguments (a new data range) never reuses old data."""
    import gymnasium as gym

    before = cache_path("pcc/CartPole-v1", 64, 0, cache_dir=tmp_path)
    assert collect_transitions("pcc/CartPole-v1", 2, 0).metadata["registered_kwargs"] == dict(
        gym.spec("pcc/CartPole-v1").kwargs)
    assert "registered_kwargs" not in collect_transitions("pcc/Planar-v0", 2, 0).metadata
    spec = gym.spec("pcc/CartPole-v1")
    monkeypatch.setattr(spec, "kwargs", {**spec.kwargs, "sampler_angle": 0.1})
    assert cache_path("pcc/CartPole-v1", 64, 0, cache_dir=tmp_path) != before


def test_cache_dir_from_environment(tmp_path, monkeypatch):
    monkeypatch.setenv("PCC_DATA_DIR", str(tmp_path))
    assert cache_path("pcc/Planar-v0", 1, 0).parent == tmp_path


def test_cache_regenerates_a_mismatched_file(tmp_path):
    path = cache_path("pcc/Planar-v0", 16, 0, cache_dir=tmp_path)
    wrong = collect_transitions("pcc/Planar-v0", 16, seed=5)
    wrong.save(path)
    with pytest.warns(UserWarning, match="regenerating"):
        data = load_or_collect("pcc/Planar-v0", 16, seed=0, cache_dir=tmp_path)
    np.testing.assert_array_equal(data.state, collect_transitions("pcc/Planar-v0", 16, 0).state)
    assert TransitionDataset.load(path).metadata["seed"] == 0


def test_cache_regenerates_a_truncated_file(tmp_path):
    """A cache file cut short (a crash while copying it, a full disk) is rebuilt, not fatal."""
    path = cache_path("pcc/Planar-v0", 16, 0, cache_dir=tmp_path)
    collect_transitions("pcc/Planar-v0", 16, seed=0).save(path)
    path.write_bytes(path.read_bytes()[:300])
    with pytest.raises(ValueError, match="not a complete data set"):
        TransitionDataset.load(path)
    with pytest.warns(UserWarning, match="Unreadable dataset cache"):
        data = load_or_collect("pcc/Planar-v0", 16, seed=0, cache_dir=tmp_path)
    assert data.metadata["seed"] == 0 and TransitionDataset.load(path).metadata["seed"] == 0


def test_failed_save_leaves_no_file(tmp_path, monkeypatch):
    data = collect_transitions("pcc/Planar-v0", 8, seed=0)

    def boom(*args, **kwargs):
        raise RuntimeError("disk full")

    monkeypatch.setattr(np, "savez", boom)
    with pytest.raises(RuntimeError):
        data.save(tmp_path / "x.npz")
    assert list(tmp_path.iterdir()) == []


def test_saved_file_loads_without_pickle(tmp_path):
    data = collect_transitions("pcc/TwoLink-v0", 8, seed=0)
    path = data.save(tmp_path / "d.npz")
    with np.load(path, allow_pickle=False) as raw:
        assert json.loads(str(raw["metadata"]))["env_id"] == "pcc/TwoLink-v0"
    loaded = TransitionDataset.load(path)
    np.testing.assert_array_equal(loaded.next_obs, data.next_obs)


def test_split_is_disjoint_and_complete():
    data = collect_transitions("pcc/Planar-v0", 50, seed=0)
    train, test = data.split(0.8, np.random.default_rng(0))
    assert len(train) == 40 and len(test) == 10
    both = np.concatenate([train.state, test.state])
    assert len(np.unique(both, axis=0)) == 50


def test_observations_for_states_matches_the_env():
    env = gym.make("pcc/ThreeLink-v0")
    states = env.unwrapped.sample_states(np.random.default_rng(0), 5)
    batch = observations_for_states(env, states)
    for s, obs in zip(states, batch):
        np.testing.assert_array_equal(obs, env.unwrapped.observation_of(s))


@pytest.mark.parametrize("env_id", ["pcc/CartPole-v1", "pcc/Planar-v0"])
def test_a_prediction_horizon_adds_the_chains_further_steps(env_id):
    data = collect_transitions(env_id, 30, seed=0, prediction_horizon=3)
    env = gym.make(env_id).unwrapped
    assert data.prediction_horizon == 3 and data.metadata["prediction_horizon"] == 3
    assert data.future_action.shape == (30, 2, env.action_dim)
    assert data.future_obs.shape == (30, 2, *data.obs.shape[1:])
    # Each further observation's newest frame shows the true transition of the state before.
    state = data.next_state
    for j in range(2):
        state = env.transition(state, data.future_action[:, j])
        np.testing.assert_array_equal(data.future_obs[:, j, -1], env.render_states(state))
    if env.num_frames == 2:
        np.testing.assert_array_equal(data.future_obs[:, 0, 0], data.next_obs[:, 1])
    one_step = collect_transitions(env_id, 30, seed=0)
    assert one_step.future_obs is None and one_step.prediction_horizon == 1
    assert "prediction_horizon" not in one_step.metadata


def test_multistep_data_keep_their_further_steps_in_the_cache_and_subsets(tmp_path):
    data = load_or_collect("pcc/Planar-v0", 32, seed=0, cache_dir=tmp_path, prediction_horizon=2)
    (path,) = tmp_path.iterdir()
    assert path == cache_path("pcc/Planar-v0", 32, 0, cache_dir=tmp_path, prediction_horizon=2)
    assert path != cache_path("pcc/Planar-v0", 32, 0, cache_dir=tmp_path)
    again = TransitionDataset.load(path)
    np.testing.assert_array_equal(again.future_obs, data.future_obs)
    np.testing.assert_array_equal(again.future_action, data.future_action)
    assert data.subset(np.arange(5)).future_obs.shape == (5, 1, 1, 40, 40)
    with pytest.raises(ValueError, match="prediction_horizon must be an integer >= 1, got 0"):
        collect_transitions("pcc/Planar-v0", 4, seed=0, prediction_horizon=0)
    with pytest.raises(ValueError, match="both or neither"):
        TransitionDataset(data.obs, data.action, data.next_obs, data.state, data.next_state,
                          future_action=data.future_action)
    with pytest.raises(ValueError, match="future_obs must be uint8"):
        TransitionDataset(data.obs, data.action, data.next_obs, data.state, data.next_state,
                          future_action=data.future_action, future_obs=data.future_obs[:, :, 0])
