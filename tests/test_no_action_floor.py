"""The no-action floor benchmark: zero actions, the reproduction's tasks, outputs written."""

from __future__ import annotations

import json

import gymnasium as gym
import numpy as np
import pytest

from benchmarks import no_action_floor


def test_zero_action_policy_is_batched_and_refuses_spaces_without_zero():
    policy = no_action_floor.ZeroActionPolicy(gym.spaces.Box(-1.0, 1.0, (3,)))
    action, state = policy.predict(np.zeros((2, 4)))
    assert action.shape == (2, 3) and not action.any() and state is None
    with pytest.raises(ValueError, match="zero action is outside"):
        no_action_floor.ZeroActionPolicy(gym.spaces.Box(0.5, 1.0, (1,)))


def test_floor_of_planar_is_zero_and_written(tmp_path):
    # Planar starts in a corner, far from the goal: standing still never reaches it.
    out = tmp_path / "floor"
    assert no_action_floor.main(["--envs", "pcc/Planar-v0", "--preset", "quick",
                                 "--output", str(out)]) == 0
    payload = json.loads(out.with_suffix(".json").read_text())
    (row,) = payload["rows"]
    assert row["mean"] == 0.0 and row["num_tasks"] == 5 and len(row["percentages"]) == 5
    assert "--preset quick" in payload["command"]
    assert "| pcc/Planar-v0 | 0 | 5 (2020) | 0.0 ± 0.0 |" in out.with_suffix(".md").read_text()


def test_floor_counts_steps_a_falling_cartpole_spends_in_the_goal():
    # CartPole starts near upright: with no force the pole spends its first steps in the goal.
    row = no_action_floor.measure_floor("pcc/CartPole-v0", num_tasks=2, task_seed=2020)
    assert row["mean"] > 0.0 and len(row["task_seeds"]) == 2


def test_bad_noise_is_refused(capsys):
    with pytest.raises(SystemExit):
        no_action_floor.main(["--noise", "-1"])
    assert "--noise must be" in capsys.readouterr().err
