"""PCCAgent: the SB3 contract on a tiny Planar problem."""

from __future__ import annotations

import dataclasses
import tempfile

import gymnasium as gym
import numpy as np
import pytest
import torch
from stable_baselines3.common.callbacks import CheckpointCallback, EvalCallback
from stable_baselines3.common.evaluation import evaluate_policy

import pcc_envs  # noqa: F401
from pcc_agent import PCCAgent
from pcc_agent.agent import sb3_logger
from pcc_agent.checkpoint import CheckpointError
from pcc_agent.planning.config import PlannerConfig
from pcc_agent.presets import default_preset_for_spaces, get_preset
from pcc_envs.data import cache_path

ENV_ID = "pcc/Planar-v0"


def tiny_preset(epochs: int = 2):
    preset = get_preset(ENV_ID)
    return dataclasses.replace(
        preset,
        train=dataclasses.replace(preset.train, epochs=epochs, batch_size=64),
        planner=PlannerConfig(plan_length=5, iterations=2, mpc_iterations=1, num_candidates=2),
    )


@pytest.fixture(scope="module")
def trained(tmp_path_factory):
    cache = tmp_path_factory.mktemp("data")
    agent = PCCAgent(ENV_ID, method="pcc", preset=tiny_preset(), seed=3, data_cache_dir=cache)
    agent.learn(total_timesteps=300)
    return agent, cache


def test_learn_sets_goal_and_counts_timesteps(trained):
    agent, _ = trained
    assert agent.num_timesteps == 2 * 300  # SB3's samples trained on: 2 epochs of 300
    assert agent.goal_observation is not None
    assert agent.train_result is not None and agent.train_result.epochs == 2


def test_predict_single_and_batched_inside_action_space(trained):
    agent, _ = trained
    env = gym.make(ENV_ID)
    obs, _ = env.reset(seed=0)
    action, state = agent.predict(obs)
    assert action.shape == (2,) and env.action_space.contains(action)
    batch = np.stack([obs, obs])
    actions, states = agent.predict(batch, state=None, episode_start=np.array([True, True]))
    assert actions.shape == (2, 2) and states.shape == (2, 5, 2)
    assert np.all(np.abs(actions) <= 1.0)
    # Warm start carried in `state`, reset on episode_start.
    actions2, _ = agent.predict(batch, state=states, episode_start=np.array([False, True]))
    assert actions2.shape == (2, 2)


def test_predict_rejects_bad_observations(trained):
    agent, _ = trained
    with pytest.raises(ValueError, match="shape"):
        agent.predict(np.zeros((40, 40), dtype=np.uint8))
    with pytest.raises(ValueError, match="uint8"):
        agent.predict(np.zeros((1, 40, 40), dtype=np.float32))


def test_evaluate_policy_runs(trained):
    agent, _ = trained
    env = gym.make(ENV_ID)
    mean, std = evaluate_policy(agent, env, n_eval_episodes=1, warn=False)
    assert np.isfinite(mean) and np.isfinite(std)


def test_save_load_same_actions(trained, tmp_path):
    agent, _ = trained
    path = tmp_path / "agent.pt"
    agent.save(path)
    loaded = PCCAgent.load(path)
    obs, _ = gym.make(ENV_ID).reset(seed=5)
    a1, _ = PCCAgent.load(path).predict(obs)
    a2, _ = loaded.predict(obs)
    np.testing.assert_array_equal(a1, a2)
    # The reloaded agent plans exactly like the original one with a fresh planner RNG.
    agent.set_planner()
    a0, _ = agent.predict(obs)
    np.testing.assert_allclose(a0, a1, atol=1e-6)


def test_load_refuses_mismatched_env_and_corrupt_file(trained, tmp_path):
    agent, _ = trained
    path = tmp_path / "agent.pt"
    agent.save(path)
    with pytest.raises((CheckpointError, ValueError), match="shape|observations"):
        PCCAgent.load(path, env=gym.make("pcc/PendulumSwingUp-v0"))
    bad = tmp_path / "bad.pt"
    bad.write_bytes(path.read_bytes()[:1000])
    with pytest.raises(CheckpointError):
        PCCAgent.load(bad)


def test_safetensors_round_trip_float32_exact_and_float16_rounded(trained, tmp_path):
    agent, _ = trained
    obs, _ = gym.make(ENV_ID).reset(seed=5)
    agent.set_planner()
    expected, _ = agent.predict(obs)
    full = tmp_path / "agent.safetensors"
    agent.save(full)
    agent.save(tmp_path / "half.safetensors", half=True)
    assert (tmp_path / "half.safetensors").stat().st_size < 0.6 * full.stat().st_size
    loaded, _ = PCCAgent.load(full).predict(obs)
    np.testing.assert_allclose(loaded, expected, atol=1e-6)
    half = PCCAgent.load(tmp_path / "half.safetensors")
    for name, value in agent.model.state_dict().items():
        got = half.model.state_dict()[name]
        assert got.dtype == value.dtype  # computed in float32 again
        if value.is_floating_point():
            torch.testing.assert_close(got, value.to(torch.float16).to(value.dtype),
                                       rtol=0, atol=0)
    assert agent._goal_obs is not None
    np.testing.assert_array_equal(half._goal_obs, agent._goal_obs)


def test_control_only_file_plans_the_same_and_refuses_training(trained, tmp_path):
    agent, _ = trained
    obs, _ = gym.make(ENV_ID).reset(seed=5)
    agent.set_planner()
    expected, _ = agent.predict(obs)
    whole, control = tmp_path / "whole.safetensors", tmp_path / "control.safetensors"
    agent.save(whole, half=True)
    agent.save(control, half=True, control_only=True)
    assert control.stat().st_size < 0.7 * whole.stat().st_size
    loaded = PCCAgent.load(control)
    assert loaded.control_only and not PCCAgent.load(whole).control_only
    np.testing.assert_array_equal(loaded.predict(obs)[0], PCCAgent.load(whole).predict(obs)[0])
    np.testing.assert_allclose(loaded.predict(obs)[0], expected, atol=0.05)  # float16 rounding
    with pytest.raises(RuntimeError, match="control-only"):
        loaded.learn(total_timesteps=100)
    with pytest.raises(ValueError, match="control_only=True"):
        loaded.save(tmp_path / "again.safetensors")
    loaded.save(tmp_path / "again.safetensors", control_only=True)
    with pytest.raises(ValueError, match="safetensors"):
        agent.save(tmp_path / "control.pt", control_only=True)


def test_safetensors_refuses_damaged_files_and_impossible_requests(trained, tmp_path):
    agent, _ = trained
    path = tmp_path / "agent.safetensors"
    agent.save(path, half=True)
    with pytest.raises(ValueError, match="safetensors"):
        agent.save(tmp_path / "agent.pt", half=True)
    cut = tmp_path / "cut.safetensors"
    cut.write_bytes(path.read_bytes()[: path.stat().st_size // 2])
    with pytest.raises(CheckpointError, match="truncated or corrupt"):
        PCCAgent.load(cut)
    empty = tmp_path / "empty.safetensors"
    empty.write_bytes(b"")
    with pytest.raises(CheckpointError, match="empty"):
        PCCAgent.load(empty)
    from safetensors.torch import save_file

    foreign = tmp_path / "foreign.safetensors"
    save_file({"w": torch.zeros(2)}, foreign)
    with pytest.raises(CheckpointError, match="not a pcc_agent checkpoint"):
        PCCAgent.load(foreign)
    with pytest.raises(CheckpointError, match="does not exist"):
        PCCAgent.load(tmp_path / "missing.safetensors")


def test_two_seeded_runs_give_same_actions(trained):
    agent, cache = trained
    other = PCCAgent(ENV_ID, method="pcc", preset=tiny_preset(), seed=3, data_cache_dir=cache)
    other.learn(total_timesteps=300)
    agent.set_planner()
    obs, _ = gym.make(ENV_ID).reset(seed=9)
    np.testing.assert_array_equal(agent.predict(obs)[0], other.predict(obs)[0])


def test_sb3_callbacks_see_distinct_steps_during_learn(tmp_path):
    """One callback step per epoch, and num_timesteps grows by the data set size each step (as
    an SB3 step grows it by n_envs): checkpoints do not overwrite each other and evaluations
    are logged at increasing times."""
    eval_env = gym.make(ENV_ID)
    agent = PCCAgent(
        ENV_ID, method="e2c", preset=tiny_preset(epochs=3), seed=0, data_cache_dir=tmp_path / "data"
    )
    seen = []

    def spy(locals_, globals_):
        seen.append(agent.num_timesteps)
        return True

    callbacks = [
        EvalCallback(
            eval_env, n_eval_episodes=1, eval_freq=1, log_path=str(tmp_path / "eval"), warn=False
        ),
        CheckpointCallback(save_freq=1, save_path=str(tmp_path / "ckpt")),
        spy,
    ]
    agent.learn(total_timesteps=200, callback=callbacks)
    assert seen == [200, 400, 600] and agent.num_timesteps == 600
    saved = sorted(p.name for p in (tmp_path / "ckpt").iterdir())
    assert saved == ["rl_model_200_steps.zip", "rl_model_400_steps.zip", "rl_model_600_steps.zip"]
    evaluations = np.load(tmp_path / "eval" / "evaluations.npz")
    assert evaluations["timesteps"].tolist() == [200, 400, 600]
    reloaded = PCCAgent.load(tmp_path / "ckpt" / "rl_model_400_steps.zip")
    assert reloaded.method == "e2c" and reloaded.num_timesteps == 400
    # Learning more continues the count unless told to reset it, as in SB3.
    agent.learn(total_timesteps=200, callback=spy, reset_num_timesteps=False)
    assert seen[3:] == [800, 1000, 1200] and agent.num_timesteps == 1200


def test_unknown_method_is_refused():
    with pytest.raises(ValueError, match="Unknown method"):
        PCCAgent(ENV_ID, method="pcx")


def test_config_reports_the_env_noise_its_data_are_sampled_with():
    noisy = PCCAgent(ENV_ID, preset=tiny_preset(), seed=0, env_kwargs={"noise_std": 0.5})
    assert noisy.config_dict()["data"]["noise_std"] == 0.5
    assert PCCAgent(ENV_ID, preset=tiny_preset(), seed=0).config_dict()["data"]["noise_std"] == 0
    preset = tiny_preset()
    wants_noise = dataclasses.replace(preset, data=dataclasses.replace(preset.data,
                                                                       noise_std=0.3))
    with pytest.raises(ValueError, match="data noise_std is 0.3, but the env's process noise"):
        PCCAgent(ENV_ID, preset=wants_noise, seed=0)


def test_logger_writes_csv_when_not_verbose(tmp_path):
    agent = PCCAgent(
        ENV_ID,
        preset=tiny_preset(epochs=2),
        seed=0,
        data_cache_dir=tmp_path / "data",
        tensorboard_log=str(tmp_path / "log"),
    )
    agent.learn(total_timesteps=200)
    lines = (tmp_path / "log" / "progress.csv").read_text().splitlines()
    assert len(lines) == 3 and "train/epoch" in lines[0]


def test_default_logger_makes_no_temp_directory(tmp_path, monkeypatch):
    # SB3's configure(None, ...) makes an empty tempdir/SB3-<date> per call; ours must not.
    temp = tmp_path / "temp"
    temp.mkdir()
    monkeypatch.setattr(tempfile, "tempdir", str(temp))
    monkeypatch.delenv("SB3_LOGDIR", raising=False)  # SB3 would write there instead
    agent = PCCAgent(ENV_ID, preset=tiny_preset(), seed=0, verbose=1,
                     data_cache_dir=tmp_path / "data")
    agent.logger.record("train/epoch", 1)
    agent.logger.dump(0)
    assert list(temp.glob("SB3-*")) == []
    assert len(sb3_logger(None, ["stdout"]).output_formats) == 1
    assert sb3_logger(None, []).output_formats == []
    with pytest.raises(ValueError, match="need a folder"):
        sb3_logger(None, ["csv"])


class DotEnv(gym.Env):
    """A user's own image env: a dot on a 16x16 grid, moved by the action; two frames."""

    def __init__(self, size: int = 16) -> None:
        self.size = size
        self.observation_space = gym.spaces.Box(0, 255, (2, size, size), np.uint8)
        self.action_space = gym.spaces.Box(-1.0, 1.0, (2,), np.float32)

    def frame(self, position: np.ndarray) -> np.ndarray:
        image = np.zeros((self.size, self.size), np.uint8)
        row, col = np.clip(np.round(position), 0, self.size - 1).astype(int)
        image[row, col] = 255
        return image

    def reset(self, seed=None, options=None):
        super().reset(seed=seed)
        self.position = self.np_random.uniform(0.0, self.size - 1.0, 2)
        return np.stack([self.frame(self.position)] * 2), {}

    def step(self, action):
        before = self.frame(self.position)
        self.position = np.clip(self.position + np.asarray(action, np.float64), 0.0,
                                self.size - 1.0)
        reward = -float(np.sum((self.position - self.size / 2) ** 2))
        return np.stack([before, self.frame(self.position)]), reward, False, False, {}


def test_own_image_env_trains_plans_and_reloads(tmp_path):
    dots = DotEnv()
    env = gym.wrappers.TimeLimit(dots, max_episode_steps=10)
    preset = default_preset_for_spaces(env.observation_space, env.action_space)
    preset = dataclasses.replace(
        preset, train=dataclasses.replace(preset.train, epochs=2, batch_size=64),
        planner=PlannerConfig(plan_length=5, iterations=2, mpc_iterations=1, num_candidates=2))
    agent = PCCAgent(env, preset=preset, seed=0)
    # No goal_observation() on this env: the trained model is kept, predict() waits for a goal.
    with pytest.warns(UserWarning, match="set_goal"):
        agent.learn(total_timesteps=300)
    assert agent.train_result is not None and agent.num_timesteps == 2 * 300
    obs, _ = env.reset(seed=1)
    with pytest.raises(RuntimeError, match="No goal set"):
        agent.predict(obs)
    goal = np.stack([dots.frame(np.array([8.0, 8.0]))] * 2)
    agent.set_goal(goal)
    action, _ = agent.predict(obs)
    assert action.shape == (2,) and env.action_space.contains(action)
    mean_reward, _ = evaluate_policy(agent, env, n_eval_episodes=1, warn=False)
    assert np.isfinite(mean_reward)
    agent.save(tmp_path / "dot.pt")
    loaded = PCCAgent.load(tmp_path / "dot.pt", env=env)
    np.testing.assert_array_equal(loaded.goal_observation, goal)
    np.testing.assert_array_equal(loaded.predict(obs)[0], PCCAgent.load(tmp_path / "dot.pt",
                                                                         env=env).predict(obs)[0])


def test_a_prediction_horizon_collects_its_further_steps_and_trains_the_term(tmp_path):
    preset = tiny_preset(epochs=1)
    preset = dataclasses.replace(preset, train=dataclasses.replace(preset.train,
                                                                   prediction_horizon=2))
    agent = PCCAgent(ENV_ID, preset=preset, seed=0, data_cache_dir=tmp_path)
    agent.learn(total_timesteps=200)
    assert agent.train_result.history[0]["train/multistep"] > 0
    (cached,) = tmp_path.iterdir()
    assert cached == cache_path(ENV_ID, 200, 0, cache_dir=tmp_path, prediction_horizon=2)
    # Only the pcc/ envs' sampler collects the further steps.
    env = gym.wrappers.TimeLimit(DotEnv(), max_episode_steps=10)
    foreign = default_preset_for_spaces(env.observation_space, env.action_space)
    foreign = dataclasses.replace(foreign, train=dataclasses.replace(foreign.train,
                                                                     prediction_horizon=2))
    with pytest.raises(ValueError, match="prediction_horizon 2 needs 2 consecutive "
                       "transitions per sample, which only the pcc/ envs' sampler collects"):
        PCCAgent(env, preset=foreign, seed=0).learn(total_timesteps=50)


def test_own_env_gets_the_asked_variant():
    env = DotEnv(size=64)  # above 48x48: a CNN, the paper's or the CPU-friendly one
    fast = default_preset_for_spaces(env.observation_space, env.action_space, variant="fast")
    paper = default_preset_for_spaces(env.observation_space, env.action_space)
    assert fast.model != paper.model
    assert PCCAgent(env, preset="fast", seed=0).preset.model.encoder_convs == (
        fast.model.encoder_convs)
    assert PCCAgent(env, seed=0).preset.model.encoder_convs == paper.model.encoder_convs
    for small_or_large in (env, DotEnv(size=16)):  # a typo is refused at any image size
        with pytest.raises(ValueError, match="variant"):
            PCCAgent(small_or_large, preset="huge", seed=0)


def test_replan_every_executes_the_carried_plan_between_replans(trained):
    agent, _ = trained
    original = agent.planner
    agent.set_planner(replan_every=3)
    try:
        obs, _ = gym.make(ENV_ID).reset(seed=0)
        action, (plans, left) = agent.predict(obs)
        assert plans.shape == (1, 5, 2) and left.tolist() == [2]
        # Open loop: the next two actions are the carried plan's, whatever the observation.
        other = np.zeros_like(obs)
        action2, (plans2, left2) = agent.predict(other, state=(plans, left))
        np.testing.assert_array_equal(action2, np.clip(plans[0, 0], -1, 1))
        assert left2.tolist() == [1]
        _, (_, left3) = agent.predict(other, state=(plans2, left2))
        assert left3.tolist() == [0]
        _, (_, left4) = agent.predict(obs, state=(plans2, np.array([0])))  # replans
        assert left4.tolist() == [2]
        with pytest.raises(ValueError, match="steps_left"):
            agent.predict(obs, state=(plans, np.array([3])))
        with pytest.raises(ValueError, match="pair"):
            agent.predict(obs, state=plans)
    finally:
        agent.set_planner(original)


def test_planner_settings_change_through_set_planner_only(trained):
    agent, _ = trained
    original = agent.planner
    with pytest.raises(AttributeError, match="set_planner"):
        agent.preset = agent.preset
    with pytest.raises(TypeError, match="Unknown planner settings"):
        agent.set_planner(horizon=3)
    with pytest.raises(ValueError, match="replan_every"):
        agent.set_planner(replan_every=99)
    assert agent.planner == original  # a refused change leaves the settings as they were
    try:
        agent.set_planner(plan_length=7)
        assert agent.planner.plan_length == 7 and agent.preset.planner.plan_length == 7
        assert agent.mpc.config.plan_length == 7
        obs, _ = gym.make(ENV_ID).reset(seed=0)
        assert agent.predict(obs)[1].shape == (1, 7, 2)
    finally:
        agent.set_planner(original)


def test_goal_latent_is_cached_until_the_goal_or_the_weights_change(trained):
    agent, cache = trained
    goal = agent.goal_observation
    mpc = agent.mpc
    obs, _ = gym.make(ENV_ID).reset(seed=4)
    agent.predict(obs)
    assert agent.mpc is mpc  # the goal is not encoded again at every step
    agent.set_goal(goal)
    assert agent.mpc is not mpc
    # Weights loaded into agent.model (as pcc_bench.time_to_control does) never leave a stale
    # goal latent or stale dynamics: the agent plans as a fresh one with those weights.
    fresh = PCCAgent(ENV_ID, method="pcc", preset=tiny_preset(), seed=3, data_cache_dir=cache)
    fresh.set_goal(goal)
    before = fresh.mpc.cost.goal.clone()
    fresh.model.load_state_dict(agent.model.state_dict())
    assert not torch.equal(fresh.mpc.cost.goal, before)
    torch.testing.assert_close(fresh.mpc.cost.goal, agent.mpc.cost.goal)
    agent.set_planner()
    np.testing.assert_array_equal(fresh.predict(obs)[0], agent.predict(obs)[0])


def test_set_goal_says_what_it_wants(trained):
    agent, _ = trained
    with pytest.raises(ValueError, match=r"uint8 of shape \(1, 40, 40\)"):
        agent.set_goal(np.zeros((40, 40), np.uint8))
    with pytest.raises(ValueError, match="not a batch"):
        agent.set_goal(np.zeros((2, 1, 40, 40), np.uint8))
    with pytest.raises(ValueError, match="float32"):
        agent.set_goal(np.zeros((1, 40, 40), np.float32))
