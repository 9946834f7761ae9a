"""The Ray backend runs a tiny grid on a local Ray instance (skipped without Ray)."""

from __future__ import annotations

import json

import pytest
from test_local_executor import _computed

ray = pytest.importorskip("ray")


def test_tiny_grid_on_local_ray(tmp_path, single_torch_thread):
    from pcc_bench.executors import RayExecutor, SerialExecutor
    from pcc_bench.grid import expand_grid, run_grid
    from pcc_bench.presets import REPRODUCE_PRESETS
    from pcc_bench.records import NO_ACTION, ORACLE, load_finished_run

    preset = REPRODUCE_PRESETS["quick"].override(num_tasks=1)
    runs = [r for r in expand_grid(preset) if r.method in (ORACLE, NO_ACTION)]
    assert {r.method for r in runs} == {ORACLE, NO_ACTION}
    ray.init(num_cpus=1, include_dashboard=False, log_to_driver=False)
    try:
        records = run_grid(runs, tmp_path, executor=RayExecutor())
    finally:
        ray.shutdown()
    assert sorted(r["spec"]["method"] for r in records) == sorted(r.method for r in runs)
    for spec in runs:  # written by the driver, and valid for the grid
        assert load_finished_run(tmp_path / spec.relative_path, spec) is not None
    # A finished grid has nothing left to run (the records count as finished).
    assert run_grid(runs, tmp_path, executor=RayExecutor()) == []
    # The records are the serial executor's (the backend changes where runs execute only).
    serial = run_grid(runs, tmp_path / "serial", executor=SerialExecutor())
    for spec in runs:
        written = [json.loads((root / spec.relative_path).read_text())
                   for root in (tmp_path, tmp_path / "serial")]
        assert _computed(written[0]) == _computed(written[1]), spec
    assert len(serial) == len(runs)
