"""The no-action floor benchmark: zero actions, the reproduction's tasks, outputs written."""

from __future__ import annotations

import json

import gymnasium as gym
import numpy as np
import pytest

from pcc_bench import no_action_floor
from pcc_bench.presets import REPRODUCE_PRESETS


def test_zero_action_policy_is_batched_and_refuses_spaces_without_zero():
    policy = no_action_floor.ZeroActionPolicy(gym.spaces.Box(-1.0, 1.0, (3,)))
    action, state = policy.predict(np.zeros((2, 4)))
    assert action.shape == (2, 3) and not action.any() and state is None
    with pytest.raises(ValueError, match="zero action is outside"):
        no_action_floor.ZeroActionPolicy(gym.spaces.Box(0.5, 1.0, (1,)))


def test_floor_of_planar_is_zero_and_written(tmp_path):
    # Planar starts in a corner, far from the goal: standing still never reaches it.
    out = tmp_path / "floor_v1.0"  # a dotted name keeps its last part
    assert no_action_floor.main(["--envs", "pcc/Planar-v0", "--preset", "quick",
                                 "--output", str(out)]) == 0
    payload = json.loads((tmp_path / "floor_v1.0.json").read_text())
    (row,) = payload["rows"]
    tasks = REPRODUCE_PRESETS["quick"].num_tasks
    assert row["mean"] == 0.0 and row["num_tasks"] == tasks and len(row["percentages"]) == tasks
    assert "--preset quick" in payload["command"]
    table = (tmp_path / "floor_v1.0.md").read_text()
    assert f"| pcc/Planar-v0 | 0 | {tasks} (2020) | 0.0 ± 0.0 |" in table


def test_floor_counts_steps_a_falling_cartpole_spends_in_the_goal():
    # CartPole starts within pi/6 of upright, the goal is pi/10: a start inside the goal stays
    # there for some steps with no force (the 2nd task of seed 2020), one outside scores 0.
    row = no_action_floor.measure_floor("pcc/CartPole-v0", num_tasks=2, task_seed=2020)
    assert row["percentages"][0] == 0.0 and row["percentages"][1] > 0.0


def test_bad_noise_is_refused(capsys):
    with pytest.raises(SystemExit):
        no_action_floor.main(["--noise", "-1"])
    assert "--noise must be" in capsys.readouterr().err


def test_evaluation_closes_the_env_when_the_controller_cannot_be_built():
    from pcc_agent.evaluation import evaluate_control

    closed = []

    def factory(env):
        original_close = env.close
        env.close = lambda: (closed.append(True), original_close())
        return no_action_floor.ZeroActionPolicy(gym.spaces.Box(0.5, 1.0, (2,)))

    with pytest.raises(ValueError, match="zero action is outside"):
        evaluate_control(factory, "pcc/Planar-v0", [1], record_states=False)
    assert closed == [True]
