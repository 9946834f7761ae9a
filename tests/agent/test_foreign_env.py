"""A foreign Gymnasium image env: the agent plans in the env's own action bounds (#39)."""

from __future__ import annotations

import gymnasium as gym
import numpy as np
import pytest

import pcc_agent.agent as agent_module
from pcc_agent import PCCAgent
from pcc_agent.agent import action_bounds
from pcc_agent.planning import PlannerConfig
from pcc_agent.presets import default_preset_for_spaces


class WideDotEnv(gym.Env):
    """A dot on a 16x16 grid moved by actions in [-2, 2] (the torque range of Pendulum-v1)."""

    def __init__(self, action_space: gym.spaces.Space | None = None) -> None:
        self.observation_space = gym.spaces.Box(0, 255, (2, 16, 16), np.uint8)
        self.action_space = action_space or gym.spaces.Box(-2.0, 2.0, (2,), np.float32)

    def frame(self, position: np.ndarray) -> np.ndarray:
        image = np.zeros((16, 16), np.uint8)
        row, col = np.clip(np.round(position), 0, 15).astype(int)
        image[row, col] = 255
        return image

    def reset(self, seed=None, options=None):
        super().reset(seed=seed)
        self.position = self.np_random.uniform(0.0, 15.0, 2)
        return np.stack([self.frame(self.position)] * 2), {}

    def step(self, action):
        before = self.frame(self.position)
        self.position = np.clip(self.position + np.asarray(action, np.float64), 0.0, 15.0)
        return np.stack([before, self.frame(self.position)]), 0.0, False, False, {}


def agent_for(env: gym.Env, **planner: object) -> PCCAgent:
    preset = default_preset_for_spaces(env.observation_space, env.action_space)
    config = PlannerConfig(**{"plan_length": 5, "iterations": 3, "mpc_iterations": 1,
                              "num_candidates": 4, **planner})
    return PCCAgent(env, preset=preset, planner=config, seed=0, device="cpu")


@pytest.mark.parametrize(("space", "match"), [
    (gym.spaces.Discrete(3), "continuous Box"),
    (gym.spaces.Box(-1.0, 1.0, (2, 2), np.float32), r"flat Box .* shape \(n,\)"),
    (gym.spaces.Box(-np.inf, np.inf, (2,), np.float32), r"unbounded in dimension\(s\) \[0, 1\]"),
    (gym.spaces.Box(np.array([-1.0, 0.0]), np.array([1.0, np.inf]), dtype=np.float64),
     r"unbounded in dimension\(s\) \[1\]"),
    (gym.spaces.Box(np.array([-1.0, 0.5]), np.array([1.0, 0.5]), dtype=np.float64),
     r"low >= high in dimension\(s\) \[1\]"),
])
def test_action_spaces_the_planner_cannot_use_are_refused(space, match):
    with pytest.raises(ValueError, match=match):
        action_bounds(space)
    with pytest.raises(ValueError, match=match):
        PCCAgent(WideDotEnv(space), seed=0)


def test_plans_over_the_whole_box_of_a_wide_action_space():
    env = WideDotEnv()
    # Three extreme initial plans (constant at each bound, bang-bang) and one uniform, kept
    # as they are by a line search too short for iLQR to move them.
    # No action cost, so a small uniform plan is not favoured.
    agent = agent_for(env, num_candidates=4, num_extreme=3, iterations=1,
                      line_search_steps=(1e-9,), r_weight=0.0)
    np.testing.assert_allclose(agent.scale_action(np.array([-2.0, 1.0])), [-1.0, 0.5])
    np.testing.assert_allclose(agent.unscale_action(np.array([1.0, -0.5])), [2.0, -1.0])
    goal = np.stack([env.frame(np.array([8.0, 8.0]))] * 2)
    agent.set_goal(goal)
    actions = []
    for seed in range(8):
        obs, _ = env.reset(seed=seed)
        action, _ = agent.predict(obs)
        assert env.action_space.contains(action)
        actions.append(action)
    actions = np.array(actions)
    assert np.all(np.abs(actions) <= 2.0)
    at_bound = np.all(np.abs(np.abs(actions) - 2.0) < 1e-3, axis=1)
    assert at_bound.any(), actions  # an extreme plan won: at the env's bounds, not at +-1


def test_learn_trains_on_actions_scaled_to_the_box(monkeypatch):
    env = WideDotEnv()
    agent = agent_for(env)
    seen = {}

    def capture(model, data, *args, **kwargs):
        seen["action"], seen["future_action"] = data.action, data.future_action
        raise KeyboardInterrupt  # stop before training

    monkeypatch.setattr(agent_module, "train_embedding", capture)
    obs = np.zeros((3, 2, 16, 16), np.uint8)
    actions = np.array([[-2.0, 2.0], [1.0, 0.0], [0.5, -1.0]], np.float32)
    with pytest.raises(KeyboardInterrupt):
        agent.learn(dataset=(obs, actions, obs))
    np.testing.assert_allclose(seen["action"], actions / 2)
    # The further steps of multi-step data are scaled the same way.
    with pytest.raises(KeyboardInterrupt):
        agent.learn(dataset={"obs": obs, "action": actions, "next_obs": obs,
                             "future_action": actions[:, None], "future_obs": obs[:, None]})
    np.testing.assert_allclose(seen["future_action"], actions[:, None] / 2)
    assert agent.config_dict()["action_scaling"] == "box"


def test_goal_from_a_user_image_is_checked():
    env = WideDotEnv()
    agent = agent_for(env)
    with pytest.raises(ValueError, match=r"set_goal\(\): .* shape \(2, 16, 16\)"):
        agent.set_goal(np.zeros((16, 16, 3), np.uint8))  # an RGB picture is not an observation
    agent.set_goal(np.stack([env.frame(np.array([3.0, 3.0]))] * 2))
    assert agent.goal_observation.shape == (2, 16, 16)
