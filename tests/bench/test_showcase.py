"""pcc_bench.showcase: the per-task table and the controlled-episode picture of the main job."""

from __future__ import annotations

from pcc_bench.showcase import per_task_table


def _rec(percentages):
    return {"task_seeds": [11, 12], "percentages": percentages}


def test_per_task_table_puts_models_then_oracle_and_floor():
    cell = {"pcc": {0: _rec([50.0, 0.0]), 1: _rec([75.0, 25.0])},
            "oracle": {0: _rec([75.0, 75.0])}, "no-action": {0: _rec([0.0, 0.0])}}
    lines = per_task_table(cell).splitlines()
    assert lines[0].split() == ["task", "pcc", "#0", "pcc", "#1", "oracle", "no-action"]
    assert lines[1].split() == ["0", "50.0", "75.0", "75.0", "0.0"]
    assert lines[2].split() == ["1", "0.0", "25.0", "75.0", "0.0"]
    assert lines[3].split() == ["mean", "25.0", "50.0", "75.0", "0.0"]
    assert max(len(line) for line in lines) <= 100


def test_an_empty_cell_gives_no_table():
    assert per_task_table({}) == ""
