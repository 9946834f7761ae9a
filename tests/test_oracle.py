"""The oracle controller: true-state iLQR-MPC through the shared evaluation function."""

from __future__ import annotations

import dataclasses

import gymnasium as gym
import numpy as np
import pytest
import torch

import pcc_envs  # noqa: F401
from pcc_agent.evaluation import evaluate_control
from pcc_agent.oracle import OracleController, TrueDynamics, oracle_config_for


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


def test_oracle_balances_the_pendulum():
    config = oracle_config_for("pcc/PendulumBalance-v0")
    short = dataclasses.replace(config, planner=dataclasses.replace(config.planner, plan_length=15))
    env_id = "pcc/PendulumBalance-v0"
    result = evaluate_control(lambda env: OracleController(env, short), env_id, [3])
    # The first 400 steps are in goal when balancing from a start inside the goal region.
    assert result.tasks[0].percent_in_goal > 90.0


def test_oracle_refuses_envs_without_batched_true_dynamics():
    pytest.importorskip("pybullet")
    env = gym.make("pcc/LaneKeeping-v0")
    with pytest.raises(ValueError, match="oracle"):
        OracleController(env)
    env.close()
