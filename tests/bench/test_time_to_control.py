"""pcc_bench.time_to_control: minute marks, the kept weights, resumable records, the rows."""

from __future__ import annotations

import json
import math

import pytest

from pcc_bench import time_to_control as ttc


def _record(method: str, recipe: str, seed: int, marks: dict[float, list[float]]) -> dict:
    return {"env": "pcc/Planar-v0", "method": method, "recipe": recipe, "seed": seed,
            "marks": [{"minutes": m, "percentages": p} for m, p in marks.items()]}


def test_rows_average_all_tasks_of_all_models_per_mark():
    records = [_record("pcc", "fast", 0, {1.0: [0.0, 10.0], 2.0: [50.0, 70.0]}),
               _record("pcc", "fast", 1, {1.0: [20.0, 30.0], 2.0: [50.0, 30.0]}),
               _record("e2c", "fast", 0, {1.0: [5.0, 5.0], 2.0: [5.0, 5.0]})]
    rows = ttc.aggregate(records)
    pcc = [r for r in rows if r["method"] == "pcc"]
    assert [r["train_minutes"] for r in pcc] == [1.0, 2.0]
    assert pcc[0]["mean_all"] == 15.0 and pcc[1]["mean_all"] == 50.0
    assert all(r["n_models"] == 2 and r["n_tasks"] == 4 for r in pcc)
    e2c = [r for r in rows if r["method"] == "e2c"]
    assert e2c[0]["n_models"] == 1 and e2c[0]["se"] == 0.0


def test_recipe_label_names_an_overridden_learning_rate():
    assert ttc.recipe_label("fast", None) == "fast"
    assert ttc.recipe_label("fast", 1.5e-3) == "fast+lr=0.0015"


def test_nonpositive_minutes_are_refused(tmp_path):
    with pytest.raises(SystemExit, match="--minutes must be positive"):
        ttc.main(["--minutes", "0", "--results-dir", str(tmp_path)])


def _tiny_run(tmp_path, *extra: str) -> list[str]:
    """Arguments of a one-model Planar run of at most 2 epochs and 1 task, plus ``extra``."""
    return ["--envs", "pcc/Planar-v0", "--seeds", "0", "--max-epochs", "2", "--patience", "0",
            "--num-tasks", "1", "--workers", "1", "--results-dir", str(tmp_path), *extra]


def test_a_tiny_run_keeps_a_model_per_mark_and_resumes(tmp_path, capsys):
    args = _tiny_run(tmp_path, "--minutes", "1e-6", "2e-6")
    assert ttc.main(args) == 0
    (path,) = tmp_path.glob("Planar-v0/*.json")
    record = json.loads(path.read_text())
    # Both marks pass during the first epoch: training stops there, both keep its weights.
    assert record["epochs_trained"] == 1
    assert [m["minutes"] for m in record["marks"]] == [1e-6, 2e-6]
    assert all(m["epoch"] == 1 and m["best_epoch"] == 1 for m in record["marks"])
    assert all(len(m["percentages"]) == 1 for m in record["marks"])
    summary = json.loads((tmp_path / "time_to_control.json").read_text())
    assert [r["train_minutes"] for r in summary["rows"]] == [1e-6, 2e-6]
    assert (tmp_path / "time_to_control.png").stat().st_size > 0
    assert ttc.main(args) == 0  # the model is done: nothing is trained again
    assert "1 of 1 models already done; 0 to train" in capsys.readouterr().out


def test_recipe_label_names_control_selection():
    assert ttc.recipe_label("motion", None, 10) == "motion+keep_best_control=10"
    assert ttc.recipe_label("fast", 1.5e-3, None) == "fast+lr=0.0015"
    assert (ttc.recipe_label("motion", None, 5, prediction_horizon=3)
            == "motion+prediction_horizon=3+keep_best_control=5")
    assert (ttc.recipe_label("motion", None, None, 3, plan_length=50)
            == "motion+prediction_horizon=3+plan_length=50")


def test_a_prediction_horizon_trains_the_multistep_term_under_its_own_label(tmp_path):
    assert ttc.main(_tiny_run(tmp_path, "--minutes", "1e-6", "--prediction-horizon", "2",
                              "--plan-length", "7")) == 0
    (path,) = tmp_path.glob("Planar-v0/*.json")
    assert path.name == "pcc_fast+prediction_horizon=2+plan_length=7_tasks2020_seed0.json"
    record = json.loads(path.read_text())
    assert (record["prediction_horizon"], record["plan_length"]) == (2, 7)
    with pytest.raises(SystemExit, match="--prediction-horizon must be >= 2"):
        ttc.main(_tiny_run(tmp_path, "--prediction-horizon", "1"))


def test_nonpositive_control_interval_is_refused(tmp_path):
    with pytest.raises(SystemExit, match="--keep-best-control must be >= 1"):
        ttc.main(["--keep-best-control", "0", "--results-dir", str(tmp_path)])


def test_a_mark_keeps_the_best_controlling_weights_when_asked(tmp_path):
    args = _tiny_run(tmp_path, "--minutes", "1e-6", "--keep-best-control", "1")
    assert ttc.main(args) == 0
    (path,) = tmp_path.glob("Planar-v0/*keep_best_control=1*.json")
    record = json.loads(path.read_text())
    assert record["keep_best_control_every"] == 1
    (mark,) = record["marks"]
    # Epoch 1 is scored before its mark is taken, so the mark holds the scored weights.
    assert mark["selected_by"] == "control" and mark["best_epoch"] == 1
    assert 0.0 <= mark["control_score"] <= 100.0
    assert math.isfinite(mark["val_loss"]) and mark["val_loss"] > 0  # the kept epoch's loss
