"""PCCAgent.predict's actions pinned across the #40 refactor (agent -> planning.mpc).

The expected actions below were recorded with the code BEFORE the refactor (commit 4c84a50,
``PCCAgent.predict`` calling ``ilqr.plan`` itself), on this test's tiny Planar agent; the
refactored agent, which plans through :class:`pcc_agent.planning.LatentMPC`, must reproduce
them. Closed loop over a few steps, with replanning at every step and every 2 steps, and a
batch with an episode start in the middle.
"""

from __future__ import annotations

import dataclasses
import os

import gymnasium as gym
import numpy as np
import pytest
import torch

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


@pytest.fixture(scope="module", autouse=True)
def one_thread():
    """Training and planning on one thread: another module's setting cannot change the bits."""
    threads = torch.get_num_threads()
    torch.set_num_threads(1)
    yield
    torch.set_num_threads(threads)


@pytest.fixture(scope="module")
def weights(one_thread, tmp_path_factory):
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


# Recorded with the code before the refactor (see the module docstring), one torch thread,
# by test_print_actions. The refactored agent encodes the goal alone (cached) rather than in
# one batch with the observations, which moves latents by float32 rounding (~1e-8), and a
# CPU with other vector instructions rounds differently (up to 2.3e-5 on an AMD EPYC with
# AVX-512 against these values): hence the tolerance, far below what a planning change moves.
EVERY_STEP = [[-0.09385429, 0.10689044], [-0.17626631, 0.17392623],
              [-0.1760803, 0.17375527], [-0.1749684, 0.17284745]]
EVERY_TWO = [[-0.09385429, 0.10689044], [-0.17235288, 0.17033793],
             [-0.17966229, 0.17775095], [-0.17301294, 0.17138681],
             [-0.09588542, 0.10976428]]
BATCH = [[[-0.092655584, 0.105315864], [-0.0928255, 0.106141135]],
         [[-0.17318334, 0.17088898], [-0.177044, 0.17524119]],
         [[-0.17482035, 0.17266247], [-0.09537174, 0.10808598]]]


ATOL = 1e-4


def test_print_actions(weights):  # PCC_PIN_PRINT=1 pytest -s: how the values were recorded
    if os.environ.get("PCC_PIN_PRINT"):
        for name, actions in (("every step", closed_loop(agent_with(weights, 1))),
                              ("every 2", closed_loop(agent_with(weights, 2), steps=5)),
                              ("batch", batch_run(agent_with(weights, 1)))):
            print(name, np.array2string(actions, precision=9, separator=", "))


def test_predict_pinned_replanning_every_step(weights):
    np.testing.assert_allclose(closed_loop(agent_with(weights, 1)), EVERY_STEP, atol=ATOL)


def test_predict_pinned_replanning_every_two_steps(weights):
    np.testing.assert_allclose(closed_loop(agent_with(weights, 2), steps=5), EVERY_TWO,
                               atol=ATOL)


def test_predict_pinned_batch_with_episode_start(weights):
    np.testing.assert_allclose(batch_run(agent_with(weights, 1)), BATCH, atol=ATOL)
