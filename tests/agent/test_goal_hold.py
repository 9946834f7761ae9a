"""The goal hold: starts inside the goal region, and the steps a controller stays there."""

from __future__ import annotations

import gymnasium as gym
import numpy as np
import pytest

import pcc_envs  # noqa: F401  (registers the pcc/ ids)
from pcc_agent.evaluation import evaluate_goal_hold, goal_hold_starts
from pcc_agent.oracle import OracleController

ENV_ID = "pcc/PendulumBalance-v0"


class ZeroAction:
    """A policy that never acts: an upright pendulum falls out of the goal region."""

    def predict(self, observation, state=None, episode_start=None, deterministic=True):
        return np.zeros((len(observation), 1), dtype=np.float32), state


def test_starts_lie_in_the_goal_region_near_the_goal_and_follow_the_seed():
    env = gym.make(ENV_ID)
    core = env.unwrapped
    starts = goal_hold_starts(env, 6, spread=0.05, seed=3)
    assert starts.shape == (6, core.state_dim)
    assert all(core.in_goal(s) for s in starts)
    half_width = (core.state_high - core.state_low) / 2
    assert np.all(np.abs(starts - core.goal_state) <= 0.05 * half_width + 1e-12)
    assert np.array_equal(starts, goal_hold_starts(env, 6, spread=0.05, seed=3))
    assert not np.array_equal(starts, goal_hold_starts(env, 6, spread=0.05, seed=4))
    env.close()


def test_the_oracle_holds_the_upright_pendulum_and_doing_nothing_does_not():
    oracle = evaluate_goal_hold(lambda env: OracleController(env), ENV_ID, num_starts=3,
                                horizon=40)
    assert oracle.steps_held == [40, 40, 40] and oracle.held_fraction == 1.0
    idle = evaluate_goal_hold(ZeroAction(), ENV_ID, num_starts=3, horizon=40)
    assert idle.starts == oracle.starts  # the same starts for every controller
    assert min(idle.steps_held) < 40 and idle.mean_steps < 40 and idle.held_fraction < 1
    assert idle.to_dict()["mean_steps"] == pytest.approx(idle.mean_steps)


def test_bad_arguments_are_refused_with_what_is_wrong():
    env = gym.make(ENV_ID)
    with pytest.raises(ValueError, match="num_starts must be >= 1 and spread > 0"):
        goal_hold_starts(env, 0)
    with pytest.raises(ValueError, match="num_starts must be >= 1 and spread > 0"):
        goal_hold_starts(env, 2, spread=0.0)
    env.close()
    with pytest.raises(ValueError, match="horizon must be >= 1"):
        evaluate_goal_hold(ZeroAction(), ENV_ID, horizon=0)
    classic = gym.make("CartPole-v1")
    with pytest.raises(ValueError, match="lacks goal_state, state_low, state_high, in_goal"):
        goal_hold_starts(classic, 2)
    classic.close()
