"""The oracle controller: true-state iLQR-MPC through the shared evaluation function."""

from __future__ import annotations

import dataclasses

import gymnasium as gym
import numpy as np
import pytest
import torch

import pcc_envs  # noqa: F401
from pcc_agent.evaluation import evaluate_control
from pcc_agent.oracle import (
    ORACLE_CONFIGS,
    OracleConfig,
    OracleController,
    TrueDynamics,
    agent_planner_for,
    oracle_config_for,
    oracle_planner_for,
)
from pcc_agent.presets import PRESETS, get_preset


def test_finite_difference_jacobians_match_linearization_of_pendulum():
    env = gym.make("pcc/PendulumSwingUp-v0").unwrapped
    dynamics = TrueDynamics(env, fd_step=1e-6)
    s = torch.tensor([[0.3, -0.5], [np.pi - 1e-7, 0.0]], dtype=torch.float64)
    u = torch.tensor([[0.2], [0.0]], dtype=torch.float64)
    A, B = dynamics.jacobians(s, u)
    # Across the angle wrap the difference goes through state_error: no spurious jump.
    assert torch.all(A.abs() < 10) and torch.all(torch.isfinite(B))
    h = 1e-4
    for j in range(2):
        e = torch.zeros(2, dtype=torch.float64)
        e[j] = h
        diff = env.state_error(
            dynamics.step(s[:1] + e, u[:1]).numpy(), dynamics.step(s[:1] - e, u[:1]).numpy()
        )
        np.testing.assert_allclose(A[0, :, j].numpy(), diff[0] / (2 * h), rtol=1e-4, atol=1e-6)


def test_oracle_balances_the_pendulum_with_the_agents_planner():
    env_id = "pcc/PendulumBalance-v0"
    planner = agent_planner_for(env_id)
    assert planner == get_preset(env_id).planner  # the ceiling runs the agents' settings
    result = evaluate_control(lambda env: OracleController(env), env_id, [3])
    # The 400 steps are in goal when balancing from a start inside the goal region.
    assert result.tasks[0].percent_in_goal > 90.0


def test_oracle_runs_its_own_horizon_where_it_has_one_and_the_agents_settings_otherwise():
    for env_id, config in ORACLE_CONFIGS.items():
        agents, oracle = agent_planner_for(env_id), oracle_planner_for(env_id)
        horizon = agents.plan_length if config.plan_length is None else config.plan_length
        assert oracle == dataclasses.replace(agents, plan_length=horizon), env_id
    # CartPole-v1's agents plan 20 steps; its oracle keeps 50 (docs/planner.md).
    assert agent_planner_for("pcc/CartPole-v1").plan_length == 20
    controller = OracleController(gym.make("pcc/CartPole-v1"))
    assert controller.mpc.config.plan_length == 50


def test_oracle_horizon_must_be_positive():
    with pytest.raises(ValueError, match="plan_length"):
        OracleConfig(state_weights=(1.0,), plan_length=0)


def test_oracle_cost_is_kappa_times_state_weights_and_the_agents_action_weight():
    env = gym.make("pcc/CartPole-v0")
    planner = dataclasses.replace(agent_planner_for("pcc/CartPole-v0"), kappa=7.0, r_weight=0.5)
    oracle = OracleController(env, planner=planner)
    weights = torch.tensor(oracle_config_for("pcc/CartPole-v0").state_weights,
                           dtype=torch.float64)
    torch.testing.assert_close(oracle.mpc.cost.Q, 7.0 * torch.diag(weights))
    torch.testing.assert_close(oracle.mpc.cost.R, 0.5 * torch.eye(1, dtype=torch.float64))
    assert oracle.mpc.config is planner


def test_every_registered_env_has_oracle_weights_of_its_state_size():
    for env_id in PRESETS:
        env = gym.make(env_id)
        assert len(oracle_config_for(env_id).state_weights) == env.unwrapped.state_dim, env_id
        env.close()


def test_lane_keeping_oracle_steers_back_towards_the_lane_centre():
    pytest.importorskip("pybullet")
    env = gym.make("pcc/LaneKeeping-v0")
    obs, info = env.reset(seed=5)
    start_heading = abs(info["state"][1])  # the forced drift leaves the car turned away
    oracle = OracleController(env, planner=dataclasses.replace(
        agent_planner_for("pcc/LaneKeeping-v0"), plan_length=5, num_candidates=2))
    for _ in range(10):
        action, _ = oracle.predict(obs)
        obs, _, _, _, info = env.step(action)
    env.close()
    assert start_heading > 0.2 and abs(info["state"][1]) < start_heading - 0.1


def test_oracle_refuses_envs_without_true_dynamics():
    class NoDynamics:
        pass

    with pytest.raises(ValueError, match="true transition"):
        TrueDynamics(NoDynamics())
