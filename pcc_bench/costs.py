"""What a grid will cost: CPU-core seconds from measured training speeds and finished runs."""

from __future__ import annotations

import json
from collections.abc import Iterable, Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np

from pcc_bench.paths import COMMITTED_RESULTS_DIR
from pcc_bench.records import ORACLE, REFERENCE_METHODS, RunSpec


@dataclass(frozen=True)
class CostEstimate:
    """Compute time of a grid, in CPU-core seconds (divide by the workers for wall time)."""

    expected_seconds: float
    upper_seconds: float
    runs_from_records: int  # how many runs took their figure from finished runs of their kind


def _cost_key(spec: RunSpec, with_method: bool = True) -> tuple[Any, ...]:
    """Runs with the same key train the same kind of model for the same epoch budget."""
    budget = (spec.env_id, spec.model_variant, spec.num_samples, spec.max_epochs, spec.patience,
              spec.flush_denormals, spec.learning_rate)
    return (*budget, spec.method) if with_method else budget


def _cap_seconds(spec: RunSpec, measured: dict[tuple[str, str, str], float]) -> float:
    """Seconds for one run that trains to its epoch cap (early stopping makes it shorter)."""
    from pcc_agent.presets import get_preset

    if spec.method in REFERENCE_METHODS:
        return 300.0 if spec.method == ORACLE else 30.0
    preset = get_preset(spec.env_id, spec.model_variant)
    samples = spec.num_samples or preset.data.num_samples
    epochs = spec.max_epochs or preset.train.epochs
    cnn = preset.model.encoder_kind == "cnn"
    guess = 0.1 if cnn and spec.model_variant == "paper" else (2e-3 if cnn else 7e-4)
    per_sample = measured.get((spec.env_id, spec.method, spec.model_variant), guess)
    return per_sample * samples * epochs


def estimate_cost(
    runs: Sequence[RunSpec], finished: Iterable[dict[str, Any]] = ()
) -> CostEstimate:
    """Cost of ``runs`` (one CPU core per run).

    The upper bound trains every model to its epoch cap at the seconds per epoch measured in
    ``train_speed.json`` of the committed results (1 thread), or a conservative per-sample guess.
    The expected figure uses, where there are any, the median time (training plus control)
    of ``finished`` run records of the same kind (env, method, variant, data size, epoch cap,
    patience), else of the other methods' models of that kind: early stopping usually ends a
    run long before the cap. The upper bound of a run is never below the slowest finished
    run of its kind.
    """
    measured: dict[tuple[str, str, str], float] = {}
    speed_file = COMMITTED_RESULTS_DIR / "train_speed.json"
    if speed_file.exists():
        for row in json.loads(speed_file.read_text()):
            per_sample = row["seconds_per_epoch"] / row["num_samples"]
            measured[(row["env"], row["method"], row["variant"])] = per_sample
    observed: dict[tuple[Any, ...], list[float]] = {}
    for rec in finished:
        try:
            spec = RunSpec(**rec["spec"])
            seconds = float(rec["train_seconds"]) + float(rec.get("eval_seconds", 0.0))
        except (KeyError, TypeError, ValueError):  # an older or hand-made record
            continue
        observed.setdefault(_cost_key(spec), []).append(seconds)
        if spec.method not in REFERENCE_METHODS:
            observed.setdefault(_cost_key(spec, with_method=False), []).append(seconds)
    expected = upper = 0.0
    from_records = 0
    for spec in runs:
        cap = _cap_seconds(spec, measured)
        seen = observed.get(_cost_key(spec))
        if not seen and spec.method not in REFERENCE_METHODS:
            seen = observed.get(_cost_key(spec, with_method=False))
        if seen:
            expected += float(np.median(seen))
            # A finished run that took longer than the cap's estimate (a slower or busier
            # machine, control time) raises the bound: it must not read below the estimate.
            upper += max(cap, max(seen))
            from_records += 1
        else:
            expected += cap
            upper += cap
    return CostEstimate(expected, upper, from_records)
