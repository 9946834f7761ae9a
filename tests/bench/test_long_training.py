"""Smoke test of the long-training benchmark: evaluations at the asked epochs, written as JSON."""

from __future__ import annotations

import json

import pytest

from pcc_bench import long_training


def test_long_training_evaluates_at_the_asked_epochs(tmp_path):
    out = tmp_path / "long.json"
    code = long_training.main([
        "--seed", "0", "--epochs", "3", "--eval-at", "1", "3", "--num-samples", "300",
        "--num-tasks", "2", "--data-dir", str(tmp_path / "data"), "--output", str(out),
    ])
    assert code == 0
    record = json.loads(out.read_text())
    assert record["status"] == "done"
    assert [row["epoch"] for row in record["evaluations"]] == [1, 3]
    for row in record["evaluations"]:
        assert len(row["percentages"]) == 2
        assert all(0.0 <= p <= 100.0 for p in row["percentages"])
        assert row["val_loss"] > 0
    assert record["training"]["epochs"] == 3


def test_long_training_rejects_eval_epochs_past_the_end(tmp_path):
    with pytest.raises(SystemExit, match="--eval-at"):
        long_training.main(["--epochs", "5", "--eval-at", "6", "--output", str(tmp_path / "x")])
