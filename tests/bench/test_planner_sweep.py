"""pcc_bench.planner_sweep re-evaluates a saved agent under several planner settings."""

from __future__ import annotations

import dataclasses
import json

import pytest

from pcc_agent import PCCAgent
from pcc_agent.planning.config import PlannerConfig
from pcc_agent.presets import get_preset
from pcc_bench import planner_sweep


def _tiny_planar_agent(tmp_path, seed=0):
    preset = get_preset("pcc/Planar-v0")
    preset = dataclasses.replace(
        preset,
        train=dataclasses.replace(preset.train, epochs=1),
        planner=PlannerConfig(plan_length=5, iterations=1, mpc_iterations=1, num_candidates=2),
    )
    agent = PCCAgent("pcc/Planar-v0", preset=preset, seed=seed, data_cache_dir=tmp_path / "d")
    agent.learn(total_timesteps=200)
    return agent


def test_planner_sweep_runs_every_setting(tmp_path):
    _tiny_planar_agent(tmp_path).save(tmp_path / "a.pt")
    out = tmp_path / "sweep.json"
    assert planner_sweep.main([str(tmp_path / "a.pt"), "--plan-lengths", "3", "6",
                               "--mpc-iterations", "1", "--num-tasks", "1",
                               "--out", str(out)]) == 0
    payload = json.loads(out.read_text())
    rows = payload["rows"]
    assert payload["status"] == "done" and payload["command"].endswith(str(out))
    assert [r["plan_length"] for r in rows] == [3, 6]
    assert all(0.0 <= r["mean"] <= 100.0 for r in rows)
    assert {r["task_seed"] for r in rows} == {planner_sweep.VALIDATION_TASK_SEED}
    assert "summary" not in payload  # one agent: its rows are the summary


def test_sweep_over_several_agents_summarizes_each_setting(tmp_path):
    for seed, name in enumerate(("a.pt", "b.pt")):
        _tiny_planar_agent(tmp_path, seed).save(tmp_path / name)
    out = tmp_path / "sweep.json"
    assert planner_sweep.main([str(tmp_path / "a.pt"), str(tmp_path / "b.pt"),
                               "--plan-lengths", "3", "6", "--mpc-iterations", "1",
                               "--num-tasks", "1", "--task-seed", "2022",
                               "--out", str(out)]) == 0
    payload = json.loads(out.read_text())
    rows, summary = payload["rows"], payload["summary"]
    assert payload["status"] == "done"
    assert [(r["plan_length"], r["checkpoint"][-4:]) for r in rows] == [
        (3, "a.pt"), (3, "b.pt"), (6, "a.pt"), (6, "b.pt")]
    assert [s["plan_length"] for s in summary] == [3, 6]
    for setting in summary:
        means = [r["mean"] for r in rows if r["plan_length"] == setting["plan_length"]]
        assert setting["agent_means"] == means and setting["num_agents"] == 2
        assert setting["mean_over_agents"] == pytest.approx(sum(means) / 2)


@pytest.mark.parametrize("argv", [[], ["a.pt", "--oracle", "pcc/Planar-v0"]])
def test_sweep_wants_either_agents_or_the_oracle(argv, capsys):
    with pytest.raises(SystemExit):
        planner_sweep.main(argv)
    assert "either saved agents" in capsys.readouterr().err


def test_oracle_sweep_leaves_out_invalid_settings_and_records_state_weights(tmp_path, capsys):
    out = tmp_path / "oracle.json"
    assert planner_sweep.main(["--oracle", "pcc/PendulumBalance-v0", "--plan-lengths", "3",
                               "--replan-every", "1", "5", "--num-candidates", "2",
                               "--state-weights", "1,0.1", "1,0", "--num-tasks", "1",
                               "--out", str(out)]) == 0
    assert "Left out" in capsys.readouterr().out  # replan_every 5 > plan_length 3
    rows = json.loads(out.read_text())["rows"]
    assert [r["state_weights"] for r in rows] == [[1.0, 0.1], [1.0, 0.0]]
    assert all(r["method"] == "oracle" and r["replan_every"] == 1 for r in rows)


def test_sweep_starts_from_validation_starts_except_on_evaluation_tasks(tmp_path, monkeypatch):
    """A fixed-start domain's tasks of another seed would replay the evaluation task."""
    import pcc_agent.evaluation as evaluation

    calls = []
    real = evaluation.evaluate_control

    def spy(*args, **kwargs):
        calls.append(kwargs.get("reset_options"))
        return real(*args, **kwargs)

    monkeypatch.setattr(evaluation, "evaluate_control", spy)
    argv = ["--oracle", "pcc/PendulumBalance-v0", "--plan-lengths", "3", "--num-candidates", "2",
            "--num-tasks", "1", "--out", str(tmp_path / "o.json")]
    assert planner_sweep.main(argv) == 0
    assert json.loads((tmp_path / "o.json").read_text())["rows"][0]["starts"] == "validation"
    assert planner_sweep.main([*argv, "--task-seed", "2020", "--allow-evaluation-tasks"]) == 0
    assert json.loads((tmp_path / "o.json").read_text())["rows"][0]["starts"] == "task"
    assert calls == [{"start": "validation"}, {"start": "task"}]


def test_sweep_refuses_the_evaluation_tasks_unless_asked(capsys):
    with pytest.raises(SystemExit):
        planner_sweep.main(["--oracle", "pcc/Planar-v0", "--task-seed", "2020"])
    assert "evaluation tasks" in capsys.readouterr().err
