"""PCCAgent.predict's actions pinned across the #40 refactor (agent -> planning.mpc).

The expected actions below were recorded with the code BEFORE the refactor (commit 4c84a50,
``PCCAgent.predict`` calling ``ilqr.plan`` itself), on this test's tiny Planar agent; the
refactored agent, which plans through :class:`pcc_agent.planning.LatentMPC`, must reproduce
them. Closed loop over a few steps, with replanning at every step and every 2 steps, and a
batch with an episode start in the middle.
"""

from __future__ import annotations

import dataclasses

import gymnasium as gym
import numpy as np
import pytest

import pcc_envs  # noqa: F401
from pcc_agent import PCCAgent
from pcc_agent.planning import PlannerConfig
from pcc_agent.presets import get_preset

ENV_ID = "pcc/Planar-v0"
PLANNER = PlannerConfig(plan_length=5, iterations=2, mpc_iterations=1, num_candidates=3)


def tiny_preset():
    preset = get_preset(ENV_ID)
    return dataclasses.replace(
        preset, train=dataclasses.replace(preset.train, epochs=2, batch_size=64), planner=PLANNER)


@pytest.fixture(scope="module")
def weights(tmp_path_factory):
    agent = PCCAgent(ENV_ID, preset=tiny_preset(), seed=5,
                     data_cache_dir=tmp_path_factory.mktemp("data"))
    agent.learn(total_timesteps=300)
    return agent.model.state_dict(), agent.goal_observation


def agent_with(weights, replan_every):
    state_dict, goal = weights
    planner = dataclasses.replace(PLANNER, replan_every=replan_every)
    agent = PCCAgent(ENV_ID, preset=tiny_preset(), seed=5, planner=planner)
    agent.model.load_state_dict(state_dict)
    agent.set_goal(goal)
    return agent


def closed_loop(agent, steps=4):
    env = gym.make(ENV_ID)
    obs, _ = env.reset(seed=11)
    state, actions = None, []
    for _ in range(steps):
        action, state = agent.predict(obs, state=state)
        actions.append(action)
        obs, *_ = env.step(action)
    return np.array(actions)


def batch_run(agent):
    env_a, env_b = gym.make(ENV_ID), gym.make(ENV_ID)
    obs = np.stack([env_a.reset(seed=1)[0], env_b.reset(seed=2)[0]])
    state, actions = None, []
    for step in range(3):
        starts = np.array([step == 0, step in (0, 2)])
        action, state = agent.predict(obs, state=state, episode_start=starts)
        actions.append(action)
        obs = np.stack([env_a.step(action[0])[0], env_b.step(action[1])[0]])
    return np.array(actions)


# Recorded with the code before the refactor (see the module docstring).
EVERY_STEP = [[-0.09385287, 0.10688899], [-0.17626679, 0.17392679],
              [-0.17608084, 0.17375591], [-0.1749457, 0.17284028]]
EVERY_TWO = [[-0.09385287, 0.10688899], [-0.17235103, 0.17033596],
             [-0.17966107, 0.1777499], [-0.17301118, 0.17138503],
             [-0.09586865, 0.10976548]]
BATCH = [[[-0.0926629, 0.10532482], [-0.09282064, 0.10613586]],
         [[-0.17318194, 0.17088825], [-0.17703809, 0.1752354]],
         [[-0.17480825, 0.17264996], [-0.09536728, 0.1080812]]]


def test_predict_pinned_replanning_every_step(weights):
    np.testing.assert_allclose(closed_loop(agent_with(weights, 1)), EVERY_STEP, atol=1e-5)


def test_predict_pinned_replanning_every_two_steps(weights):
    np.testing.assert_allclose(closed_loop(agent_with(weights, 2), steps=5), EVERY_TWO,
                               atol=1e-5)


def test_predict_pinned_batch_with_episode_start(weights):
    np.testing.assert_allclose(batch_run(agent_with(weights, 1)), BATCH, atol=1e-5)
