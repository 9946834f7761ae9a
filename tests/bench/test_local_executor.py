"""The local executor: loky worker processes that give the serial executor's records."""

from __future__ import annotations

import dataclasses
import json
import multiprocessing
import os
from pathlib import Path
from typing import Any

from test_reproduce import tiny_spec

from pcc_bench.executors import LokyExecutor, SerialExecutor, make_executor
from pcc_bench.records import NO_ACTION
from pcc_bench.runs import execute_run


def _run_and_say_where(spec: Any, results_dir: Path, data_dir: str) -> dict[str, Any]:
    """``execute_run``, plus the process that ran it."""
    import torch

    record = execute_run(spec, results_dir, data_dir)
    where = {"pid": os.getpid(), "parent": os.getppid(),
             "process": multiprocessing.current_process().name,
             "torch_threads": torch.get_num_threads()}
    return {**record, "where": where}


def _computed(record: dict[str, Any]) -> str:
    """What a run computed: its record as JSON without the wall-clock fields (seconds, times),
    the test's ``where`` (JSON: a tuple and the list it is written as compare equal) and the
    weights file's digest (the file's metadata holds the training's wall time; the weights
    are compared by the evaluation they give)."""

    def drop_timings(value: Any) -> Any:
        if isinstance(value, dict):
            return {key: drop_timings(item) for key, item in value.items()
                    if "seconds" not in key and "time" not in key
                    and key not in ("where", "sha256")}
        if isinstance(value, (list, tuple)):
            return [drop_timings(item) for item in value]
        return value

    return json.dumps(drop_timings(record), sort_keys=True)


def test_make_executor_runs_several_workers_on_loky():
    assert isinstance(make_executor("process", workers=2), LokyExecutor)
    assert isinstance(make_executor("process", workers=1), SerialExecutor)


def test_two_loky_workers_give_the_serial_records(tmp_path, single_torch_thread):
    """A grid with a trained model of two methods and a reference run, on two loky workers:
    each run in a worker process of this one (one torch thread), and every record as the
    serial executor's in this process, field for field except the timings."""
    specs = [
        dataclasses.replace(tiny_spec(0), method=NO_ACTION, num_samples=None, max_epochs=None),
        tiny_spec(0),
        dataclasses.replace(tiny_spec(1), method="e2c"),
    ]
    results: dict[str, dict[Any, Any]] = {}
    for name, executor in (("serial", SerialExecutor()), ("loky", LokyExecutor(2))):
        # Each backend generates its own data sets too (no cache shared between them).
        outcomes = executor.outcomes(_run_and_say_where, specs, tmp_path / name,
                                     str(tmp_path / f"{name}-data"))
        results[name] = dict(outcomes)
        for spec, outcome in results[name].items():
            assert not isinstance(outcome, Exception), f"{name} {spec}: {outcome!r}"
    serial, pooled = results["serial"], results["loky"]
    assert set(serial) == set(pooled) == set(specs)

    assert {record["where"]["pid"] for record in serial.values()} == {os.getpid()}
    workers = {record["where"]["pid"] for record in pooled.values()}
    assert os.getpid() not in workers and 1 <= len(workers) <= 2
    for record in pooled.values():
        assert record["where"]["parent"] == os.getpid()
        assert record["where"]["process"].startswith("LokyProcess")
        assert record["where"]["torch_threads"] == 1

    for spec in specs:
        assert _computed(pooled[spec]) == _computed(serial[spec]), spec
        # The records the workers wrote are the ones they returned.
        written = json.loads((tmp_path / "loky" / spec.relative_path).read_text())
        assert _computed(written) == _computed(pooled[spec]), spec
