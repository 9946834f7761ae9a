"""The reproduction grid: the runs of a preset, and running the unfinished ones.

The runs execute on an :class:`~pcc_bench.executors.Executor`; each outcome is reported as
it comes, and the failures are raised together at the end.
"""

from __future__ import annotations

import contextlib
from collections.abc import Iterator, Sequence
from pathlib import Path
from typing import Any

from pcc_agent.io import atomic_write_json
from pcc_bench.executors import Executor, Outcome, make_executor
from pcc_bench.presets import RESTART_SEED_STRIDE, ReproducePreset
from pcc_bench.records import NO_ACTION, ORACLE, RunSpec, load_finished_run
from pcc_bench.runs import execute_run, report_line


def has_oracle(env_id: str) -> bool:
    from pcc_agent.oracle import ORACLE_CONFIGS

    return env_id in ORACLE_CONFIGS


def expand_grid(preset: ReproducePreset, include_oracle: bool = True,
                include_floor: bool | None = None) -> list[RunSpec]:
    """All runs of a preset, the reference runs first (one each per env and noise level).

    The references are the oracle (where the env has one) and the no-action floor;
    ``include_floor`` defaults to ``include_oracle``.

    A ``restarts`` preset's runs are its trainings, filed under ``preset.runs_preset``: the
    first training of every model, then the second, and so on.
    """
    runs: list[RunSpec] = []
    for env_id in preset.envs:
        for noise in preset.noise_levels_for(env_id):
            common = {
                "env_id": env_id,
                "noise_std": float(noise),
                "num_tasks": preset.num_tasks,
                "task_seed": preset.task_seed,
                "model_variant": preset.model_variant,
                "preset": preset.runs_preset,
            }
            if include_oracle and has_oracle(env_id):
                runs.append(RunSpec(method=ORACLE, seed=0, **common))
            if include_oracle if include_floor is None else include_floor:
                runs.append(RunSpec(method=NO_ACTION, seed=0, **common))
            trainings = [m + k * RESTART_SEED_STRIDE for k in range(preset.restarts)
                         for m in preset.seeds()]
            for seed in trainings:
                for method in preset.methods:
                    runs.append(
                        RunSpec(
                            method=method,
                            seed=seed,
                            num_samples=preset.num_samples.get(env_id),
                            max_epochs=preset.max_epochs,
                            patience=preset.patience,
                            flush_denormals=preset.flush_denormals,
                            learning_rate=preset.learning_rate,
                            prediction_horizon=preset.prediction_horizon,
                            plan_length=preset.plan_length,
                            validation_tasks=preset.validation_tasks,
                            keep_best_control_every=preset.keep_best_control_every or None,
                            **common,
                        )
                    )
    return runs


def run_grid(
    runs: Sequence[RunSpec],
    results_dir: Path,
    workers: int = 1,
    backend: str = "process",
    ray_address: str | None = None,
    data_dir: str | None = None,
    ray_gpus_per_task: float = 0.0,
    executor: Executor | None = None,
) -> list[dict[str, Any]]:
    """Execute the runs that are not finished yet, on ``executor``.

    Without ``executor``, :func:`~pcc_bench.executors.make_executor` picks one from
    ``backend`` (``"process"``: ``workers`` loky worker processes on this machine, serial for
    one worker; ``"ray"``: Ray tasks at ``ray_address`` with ``ray_gpus_per_task`` GPUs each,
    for a cluster). A failed run does not stop the others; the failures are raised together
    at the end. Ctrl-C cancels the queued runs (finished ones are kept: re-running continues
    the grid).
    """
    todo = [r for r in runs if load_finished_run(results_dir / r.relative_path, r) is None]
    print(f"{len(runs) - len(todo)} of {len(runs)} runs already finished; {len(todo)} to run.")
    if not todo:
        return []
    if executor is None:
        executor = make_executor(backend, workers, ray_address, ray_gpus_per_task)
    # Remote workers see absolute paths; their records are written by this driver.
    outcomes = executor.outcomes(execute_run, todo, results_dir.resolve(), data_dir)
    return collect_outcomes(outcomes, len(todo),
                            write_to=results_dir if executor.driver_writes else None)


def collect_outcomes(
    outcomes: Iterator[Outcome], total: int, write_to: Path | None = None
) -> list[dict[str, Any]]:
    """Report every outcome as it comes (with a progress bar); raise the failures at the end.

    With ``write_to``, the driver also writes each new record there (atomically).
    """
    from tqdm.auto import tqdm

    records: list[dict[str, Any]] = []
    failures: list[str] = []
    with contextlib.ExitStack() as stack:
        if hasattr(outcomes, "close"):  # a stop here (Ctrl-C) stops the backend's queue too
            stack.callback(outcomes.close)
        bar = stack.enter_context(tqdm(total=total, unit="run", desc="grid"))
        for i, (spec, outcome) in enumerate(outcomes):
            bar.update()
            if isinstance(outcome, Exception):
                failures.append(f"{spec.env_id} {spec.method} seed={spec.seed}: {outcome!r}")
                bar.write(f"[{i + 1}/{total}] FAILED {failures[-1]}")
                continue
            if write_to is not None and not outcome.get("skipped"):
                atomic_write_json(write_to / spec.relative_path, outcome)
            records.append(outcome)
            bar.write(report_line(i + 1, total, outcome))
    if failures:
        raise RuntimeError(f"{len(failures)} run(s) failed:\n" + "\n".join(failures))
    return records
