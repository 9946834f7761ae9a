"""examples/pendulum_from_pixels.py: its wrapped env, the agent's plans on it, a tiny run."""

from __future__ import annotations

import importlib.util
from pathlib import Path

import gymnasium as gym
import numpy as np
import pytest

pytest.importorskip("pygame", reason="classic-control rendering needs the examples extra")

EXAMPLE = Path(__file__).resolve().parents[2] / "examples" / "pendulum_from_pixels.py"


@pytest.fixture(scope="module")
def example():
    spec = importlib.util.spec_from_file_location("pendulum_from_pixels", EXAMPLE)
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


def test_wrapped_pendulum_is_an_image_env_with_its_own_torque_range(example):
    env = example.make_pixel_env(max_episode_steps=5)
    assert env.observation_space == gym.spaces.Box(0, 255, (2, 48, 48), np.uint8)
    assert env.action_space == gym.spaces.Box(-2.0, 2.0, (1,), np.float32)
    obs, _ = env.reset(seed=0)
    assert obs.shape == (2, 48, 48) and obs.dtype == np.uint8 and obs.max() > 0
    down = example.start_at(env, np.pi, seed=1)
    assert abs(abs(example.angle_of(env)) - np.pi) < 1e-6
    up = example.goal_observation(env)
    assert example.angle_of(env) == 0.0
    assert np.array_equal(up[0], up[1]) and not np.array_equal(up, down)  # at rest, elsewhere


def test_agent_plans_within_the_pendulums_torque_range(example):
    env = example.make_pixel_env(max_episode_steps=5)
    agent = example.make_agent(env, seed=0, epochs=1, device="cpu")
    assert agent.planner.plan_length == 10  # the swing-up planner of pcc/PendulumSwingUp-v0
    agent.set_planner(num_candidates=4, num_extreme=3, iterations=1, line_search_steps=(1e-9,),
                      r_weight=0.0)  # plans stay near their starts, 3 of 4 at the bounds
    agent.set_goal(example.goal_observation(env))
    actions = []
    for seed in range(6):
        obs = example.start_at(env, np.pi / 2 * seed, seed=seed)
        action, _ = agent.predict(obs)
        assert env.action_space.contains(action)
        actions.append(float(action[0]))
    assert max(abs(a) for a in actions) > 1.0, actions  # [-2, 2], not the pcc envs' [-1, 1]


def test_two_trainings_side_by_side_report_the_one_chosen_on_validation_starts(example, tmp_path):
    out = tmp_path / "result.json"
    result = example.main(["--samples", "200", "--epochs", "2", "--episodes", "1", "--steps",
                           "5", "--select-every", "1", "--select-from", "1",
                           "--select-episodes", "1", "--choose-episodes", "2",
                           "--out", str(out)])
    assert [t["seed"] for t in result["trainings"]] == [0, 1]
    assert all(t["epochs"] == 2 and t["choice_score"] is not None
               for t in result["trainings"])
    scores = [t["choice_score"] for t in result["trainings"]]
    assert result["chosen_seed"] == int(np.argmax(scores))  # ties: the first
    assert len(result["percent_upright"]) == 1 and out.exists()
    with pytest.raises(SystemExit):
        example.main(["--trainings", "0"])
