"""The reproduction pipeline: a smoke run in a subprocess, resumability of the per-run files."""

from __future__ import annotations

import dataclasses
import json
import subprocess
import sys
from pathlib import Path

import numpy as np

from benchmarks.reproduce import (
    RunSpec,
    aggregate,
    estimate_cost,
    execute_run,
    interquartile_mean,
    load_finished_run,
)
from pcc_agent.planning import PLANNER_REVISION

ROOT = Path(__file__).resolve().parents[1]


def tiny_spec(seed: int = 0) -> RunSpec:
    return RunSpec(
        env_id="pcc/Planar-v0",
        method="pcc",
        seed=seed,
        noise_std=0.0,
        num_tasks=1,
        task_seed=7,
        model_variant="paper",
        preset="test",
        num_samples=256,
        max_epochs=1,
    )


def test_smoke_quick_preset_in_subprocess(tmp_path):
    cmd = [
        sys.executable,
        "-m",
        "benchmarks.reproduce",
        "--preset",
        "quick",
        "--num-models",
        "1",
        "--num-tasks",
        "1",
        "--max-epochs",
        "1",
        "--workers",
        "1",
        "--no-oracle",
        "--results-dir",
        str(tmp_path / "res"),
        "--data-dir",
        str(tmp_path / "data"),
    ]
    out = subprocess.run(cmd, cwd=ROOT, capture_output=True, text=True, timeout=600)
    assert out.returncode == 0, out.stdout + out.stderr
    rows = json.loads((tmp_path / "res" / "summary.json").read_text())
    assert rows[0]["env"] == "pcc/Planar-v0" and rows[0]["n_models"] == 1
    assert 0.0 <= rows[0]["mean_all"] <= 100.0
    assert "% of steps in goal" in out.stdout
    assert (tmp_path / "res" / "summary.md").exists()


def test_finished_run_is_skipped_and_partial_run_redone(tmp_path):
    spec = tiny_spec()
    record = execute_run(spec, tmp_path, str(tmp_path / "data"))
    path = tmp_path / spec.relative_path
    assert record["status"] == "done" and path.exists()
    assert len(record["percentages"]) == 1 and len(record["tasks"][0]["states"]) > 0
    again = execute_run(spec, tmp_path, str(tmp_path / "data"))
    assert again.get("skipped") is True
    # A run killed mid-way leaves at most a truncated or unfinished file: it is redone.
    path.write_text(path.read_text()[:100])
    assert load_finished_run(path) is None
    redone = execute_run(spec, tmp_path, str(tmp_path / "data"))
    assert not redone.get("skipped") and load_finished_run(path) is not None
    assert redone["percentages"] == record["percentages"]


def test_aggregate_all_and_top1():
    def rec(seed, values):
        return {
            "spec": {
                "env_id": "e",
                "method": "pcc",
                "noise_std": 0.0,
                "preset": "p",
                "seed": seed,
                "model_variant": "paper",
            },
            "percentages": values,
            "train_seconds": 1.0,
        }

    rows = aggregate([rec(0, [0.0, 10.0]), rec(1, [50.0, 70.0])])
    (row,) = rows
    assert row["mean_all"] == 32.5 and row["mean_top1"] == 60.0 and row["top1_seed"] == 1
    assert row["oracle_mean"] is None
    # an oracle run of another preset on the same tasks is the ceiling of this row too
    oracle = rec(0, [40.0, 60.0])
    oracle["spec"] = {**oracle["spec"], "method": "oracle", "preset": "other"}
    with_oracle = aggregate([rec(0, [0.0, 10.0]), oracle])
    assert next(r for r in with_oracle if r["method"] == "pcc")["oracle_mean"] == 50.0
    assert np.isclose(row["se_all"], np.std([0, 10, 50, 70], ddof=1) / 2)
    assert row["n_models"] == 2 and row["n_tasks"] == 2
    assert row["iqm_ci"][0] <= row["iqm"] <= row["iqm_ci"][1]


def test_interquartile_mean():
    assert interquartile_mean(np.array([0, 1, 2, 3, 4, 5, 6, 100])) == 3.5


def test_record_of_other_settings_is_stale(tmp_path):
    spec = tiny_spec()
    path = tmp_path / spec.relative_path
    from pcc_agent.presets import get_preset

    planner = json.loads(json.dumps(dataclasses.asdict(get_preset(spec.env_id).planner)))
    record = {"format": 1, "status": "done", "spec": dataclasses.asdict(spec), "percentages": [],
              "config": {"planner": planner, "planner_revision": PLANNER_REVISION}}
    path.parent.mkdir(parents=True)
    path.write_text(json.dumps(record))
    assert load_finished_run(path, spec) is not None
    # Evaluated by an older planner (a record without a revision is revision 1): stale.
    for old in ({**record["config"], "planner_revision": PLANNER_REVISION - 1},
                {"planner": planner}):
        path.write_text(json.dumps({**record, "config": old}))
        assert load_finished_run(path, spec) is None
    path.write_text(json.dumps(record))
    # Same file path, but --num-tasks / --max-epochs changed: the old record must not count.
    assert load_finished_run(path, dataclasses.replace(spec, num_tasks=5)) is None
    assert load_finished_run(path, dataclasses.replace(spec, max_epochs=3)) is None
    assert load_finished_run(path, dataclasses.replace(spec, patience=100)) is None
    # A record written before an override existed (key absent) matches a spec leaving it unset.
    older = {key: value for key, value in record["spec"].items() if key != "patience"}
    path.write_text(json.dumps({**record, "spec": older}))
    assert load_finished_run(path, spec) is not None
    assert load_finished_run(path, dataclasses.replace(spec, patience=100)) is None


def test_run_with_old_planner_settings_is_reevaluated_not_retrained(tmp_path):
    spec = tiny_spec(seed=1)
    first = execute_run(spec, tmp_path, str(tmp_path / "data"))
    path = tmp_path / spec.relative_path
    record = json.loads(path.read_text())
    record["config"]["planner"]["plan_length"] = 3  # as if the preset's planner had changed
    path.write_text(json.dumps(record))
    assert load_finished_run(path, spec) is None
    again = execute_run(spec, tmp_path, str(tmp_path / "data"))
    assert again["reevaluated"] is True and first["config"]["planner_revision"] == PLANNER_REVISION
    assert again["train_seconds"] == first["train_seconds"]
    assert again["config"]["planner"]["plan_length"] == first["config"]["planner"]["plan_length"]
    assert load_finished_run(path, spec) is not None


def test_explicit_model_seeds_select_the_grid_cells():
    from benchmarks.presets import REPRODUCE_PRESETS
    from benchmarks.reproduce import expand_grid

    preset = REPRODUCE_PRESETS["paper"].replace(envs=("pcc/Planar-v0",), methods=("pcc", "e2c"),
                                                model_seeds=(3, 7))
    runs = expand_grid(preset, include_oracle=False)
    assert sorted((r.method, r.seed) for r in runs) == [("e2c", 3), ("e2c", 7), ("pcc", 3),
                                                         ("pcc", 7)]
    assert {r.seed for r in expand_grid(preset.replace(model_seeds=None), False)} == set(range(10))


def test_training_overrides_reach_the_trained_model(tmp_path):
    from benchmarks.presets import REPRODUCE_PRESETS
    from benchmarks.reproduce import expand_grid

    long = REPRODUCE_PRESETS["paper-fast-long"].replace(envs=("pcc/Planar-v0",), methods=("pcc",))
    assert {(r.max_epochs, r.patience) for r in expand_grid(long, False)} == {(1000, 100)}
    spec = dataclasses.replace(tiny_spec(), patience=7, max_epochs=2)
    record = execute_run(spec, tmp_path, str(tmp_path / "data"))
    train = record["config"]["train"]
    assert (train["patience"], train["epochs"]) == (7, 2)
    assert record["spec"]["patience"] == 7


def test_cost_estimate_uses_finished_runs_of_the_same_kind():
    pcc, rce, e2c = (dataclasses.replace(tiny_spec(9), method=m) for m in ("pcc", "rce", "e2c"))
    finished = [
        {"spec": dataclasses.asdict(dataclasses.replace(pcc, seed=s)), "train_seconds": t,
         "eval_seconds": 1.0}
        for s, t in [(0, 10.0), (1, 30.0), (2, 1000.0)]
    ] + [{"spec": dataclasses.asdict(rce), "train_seconds": 4.0, "eval_seconds": 0.0}]
    nothing_known = estimate_cost([pcc])
    assert nothing_known.runs_from_records == 0
    assert nothing_known.expected_seconds == nothing_known.upper_seconds > 0
    # pcc: median of its own kind (31 s); rce: its own record; e2c: median over all methods.
    cost = estimate_cost([pcc, rce, e2c], finished)
    assert cost.runs_from_records == 3
    assert np.isclose(cost.expected_seconds, 31.0 + 4.0 + np.median([11, 31, 1001, 4]))
    caps = [estimate_cost([spec]).upper_seconds for spec in (pcc, rce, e2c)]
    assert np.isclose(cost.upper_seconds, sum(caps))
    # Another epoch budget is another kind: no record applies.
    longer = dataclasses.replace(pcc, max_epochs=2)
    assert estimate_cost([longer], finished).runs_from_records == 0
