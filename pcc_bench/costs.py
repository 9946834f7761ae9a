"""What a grid will cost: run times measured by finished runs of the same kind, and wall time.

Every run of the grid gets an expected and an upper duration, in seconds of one core, from the
best source there is:

1. ``same kind``: finished runs of the same kind (env, method, variant, data size, epoch cap,
   patience, subnormal flushing, learning rate): the mean of their times (training, which
   includes the data set, plus control, scaled to the run's number of tasks). Early stopping
   is in those times as often as it happened.
2. ``same model``: finished runs of the same model and training (env, method, variant, data
   size, flushing, learning rate) with another epoch cap or patience: their seconds per epoch
   times the epochs the run is expected to train, which is the epochs those runs stopped at
   where that holds for the run's cap and patience, else the cap.
3. ``one-step model``: for a run with the multi-step prediction term, finished runs of the
   same model trained without it, as in 2, their seconds per epoch times
   :func:`multistep_cost_factor`.
4. ``other methods``: finished runs of other methods of the same kind (their mean time).
5. ``epoch cap``: the seconds per epoch of ``train_speed.json`` (committed results, one
   thread) or a conservative guess per sample, times the epoch cap (and the multi-step
   factor).

A run that resumes a training checkpoint (``pcc reproduce`` keeps one every few epochs) is
charged only for the epochs it has left to its cap, at the checkpoint's own seconds per epoch
(``checkpoint``; the estimate's other sources where the checkpoint has no epoch times, scaled
by the share of the cap left).

Among the records of a source, those measured on this machine (the same CPU) are used when
there are at least :data:`MIN_THIS_MACHINE`; else those not known to come from another
machine (older records name only the core count), else all. The upper duration trains to the
epoch cap at the slowest measured seconds per epoch, and is never below the slowest finished
run of the kind. The wall time then places the runs in grid order on the workers, each run on
the first free one, as the grid's pool does.
"""

from __future__ import annotations

import heapq
import json
import os
from collections import Counter
from collections.abc import Iterable, Sequence
from dataclasses import dataclass, field, replace
from pathlib import Path
from typing import Any

import numpy as np

from pcc_bench.paths import COMMITTED_RESULTS_DIR
from pcc_bench.records import NO_ACTION, ORACLE, REFERENCE_METHODS, RESULT_FORMAT, RunSpec

#: The committed grids whose run records time the runs of the same kind elsewhere.
COMMITTED_GRIDS = ("quick", "reproduce")

#: What each source of an estimate means, for the ``--status`` line.
BASIS_TEXT = {
    "same kind": "the mean time of finished runs of the same kind",
    "same model": "finished runs of the same model with another epoch cap or patience (their "
                  "seconds per epoch times the epochs they trained)",
    "one-step model": "finished runs of the same model without the multi-step term (their "
                      "seconds per epoch times the term's cost factor and the epochs they "
                      "trained)",
    "other methods": "the mean time of finished runs of other methods of the same kind",
    "epoch cap": "the epoch cap at train_speed.json's seconds per epoch or a guess (no "
                 "finished run of their kind)",
    "reference guess": "a guess (no finished run of that reference controller)",
    "checkpoint": "their training checkpoint's seconds per epoch, for the epochs left to the "
                  "cap",
    "re-evaluation": "their control seconds (trained models whose control tasks run again "
                     "with new planner settings)",
}


@dataclass(frozen=True)
class CostEstimate:
    """What the runs of a grid cost.

    Attributes:
        expected_seconds: Sum of the runs' expected durations (seconds of one core each).
        upper_seconds: The same if every model trains to its epoch cap.
        runs_from_records: How many runs took their figure from finished runs (sources
            ``same kind``, ``same model``, ``one-step model``, ``other methods``).
        run_seconds: Expected duration of each run, in the order of the runs given.
        run_upper_seconds: Upper duration of each run.
        bases: Source of each run's figure (a key of :data:`BASIS_TEXT`), with
            ``", this machine"`` appended when its records were measured on this machine.
        sources: The directories the records used came from.
    """

    expected_seconds: float
    upper_seconds: float
    runs_from_records: int
    run_seconds: tuple[float, ...] = ()
    run_upper_seconds: tuple[float, ...] = ()
    bases: tuple[str, ...] = ()
    sources: tuple[str, ...] = field(default=())

    def wall_seconds(self, workers: int) -> float:
        """Wall time of the expected durations on ``workers`` parallel workers."""
        return makespan(self.run_seconds, workers)

    def upper_wall_seconds(self, workers: int) -> float:
        """Wall time if every model trains to its epoch cap."""
        return makespan(self.run_upper_seconds, workers)

    def basis_text(self) -> str:
        """What the figures rest on.

        E.g. ``"5 runs from the mean time of finished runs of the same kind; records in
        results/quick, measured on this machine"``.
        """
        kinds = Counter(b.partition(", ")[0] for b in self.bases)
        machines = Counter(b.partition(", ")[2] for b in self.bases if ", " in b)
        text = "; ".join(f"{n} run{'s' if n > 1 else ''} from {BASIS_TEXT[kind]}"
                         for kind, n in kinds.most_common())
        if machines:
            text += "; records" + (f" in {', '.join(self.sources)}," if self.sources else "")
            if len(machines) == 1:
                text += f" measured on {next(iter(machines))}"
            else:
                text += " measured on " + ", on ".join(
                    f"{where} for {n} run{'s' if n > 1 else ''}"
                    for where, n in machines.most_common())
        return text


def makespan(durations: Sequence[float], workers: int) -> float:
    """When the last of ``durations`` ends, each started in order on the first free worker."""
    free = [0.0] * max(1, min(int(workers), len(durations) or 1))
    for seconds in durations:
        heapq.heapreplace(free, free[0] + float(seconds))
    return max(free) if durations else 0.0


def format_duration(seconds: float) -> str:
    """``"9.6 min"`` below an hour, ``"4.9 h"`` from there on."""
    if seconds < 3600:
        return f"{seconds / 60:.1f} min"
    return f"{seconds / 3600:,.1f} h"


def _machine_match(machine: Any, here: dict[str, Any] | None) -> str:
    """Whether a record's machine is ``here``: ``"this"``, ``"other"`` or ``"unknown"``.

    The same machine: the same CPU model, or the same core count and SIMD features where an
    older record does not name its CPU. ``"unknown"``: the record does not say enough (older
    records name only the core count).
    """
    if not isinstance(machine, dict) or not here:
        return "unknown"
    keys = [k for k in ("cpu", "cpu_count", "torch_cpu_capability", "simd_flags")
            if k in machine and k in here]
    if not ({"cpu", "simd_flags"} & set(keys)):
        return "unknown"  # a core count alone says too little
    return "this" if all(machine[k] == here[k] for k in keys) else "other"


@dataclass(frozen=True)
class _Timed:
    """One finished run's measured times."""

    spec: RunSpec
    train_seconds: float
    eval_seconds: float
    epochs: int | None
    stopped_early: bool
    machine: str  # "this", "other" or "unknown" (see _machine_match)
    source: str

    def seconds(self, num_tasks: int) -> float:
        """Training plus control, the control scaled to ``num_tasks`` tasks."""
        return self.train_seconds + self.eval_seconds * num_tasks / max(self.spec.num_tasks, 1)

    def seconds_per_epoch(self) -> float | None:
        return self.train_seconds / self.epochs if self.epochs else None


def _timed(records: Iterable[dict[str, Any]], here: dict[str, Any] | None) -> list[_Timed]:
    timed = []
    for rec in records:
        try:
            spec = RunSpec(**rec["spec"])
            train = float(rec["train_seconds"])
            evaluation = float(rec.get("eval_seconds", 0.0))
        except (KeyError, TypeError, ValueError):  # an older or hand-made record
            continue
        training = rec.get("training") if isinstance(rec.get("training"), dict) else {}
        epochs = training.get("epochs")
        cap = _epoch_cap(spec) if spec.method not in REFERENCE_METHODS else None
        timed.append(_Timed(
            spec, train, evaluation, int(epochs) if epochs else None,
            bool(epochs and cap and int(epochs) < cap),
            _machine_match(rec.get("machine"), here), str(rec.get("_source", "")),
        ))
    return timed


def _epoch_cap(spec: RunSpec) -> int:
    from pcc_agent.presets import get_preset

    return spec.max_epochs or get_preset(spec.env_id, spec.model_variant).train.epochs


def _patience(spec: RunSpec) -> int:
    from pcc_agent.presets import get_preset

    if spec.patience is not None:
        return spec.patience
    return get_preset(spec.env_id, spec.model_variant).train.patience


def _model_key(spec: RunSpec) -> tuple[Any, ...]:
    """Runs with the same key train the same model at the same speed per epoch."""
    return (spec.env_id, spec.method, spec.model_variant, spec.num_samples,
            bool(spec.flush_denormals), spec.learning_rate, spec.prediction_horizon)


def _cost_key(spec: RunSpec, with_method: bool = True) -> tuple[Any, ...]:
    """Runs with the same key train the same kind of model for the same epoch budget."""
    if spec.method in REFERENCE_METHODS:  # no training: the controller and env decide
        return (spec.env_id, spec.method)
    budget = (spec.env_id, spec.model_variant, spec.num_samples, spec.max_epochs, spec.patience,
              bool(spec.flush_denormals), spec.learning_rate, spec.prediction_horizon)
    return (*budget, spec.method) if with_method else budget


#: Extra cost of each further step of the multi-step prediction term, as a share of a one-step
#: epoch (one more latent step and one more decoder pass with its likelihood per transition).
#: Measured: CartPole-v1 ``motion`` 5.59 s against 10.32 s per 3,000 transitions with K = 5
#: (x 1.85, ``train_speed.json``); 2-link rows 50.7 against 89.4 s per epoch with K = 3
#: (x 1.76). 0.3 gives x 2.2 and x 1.6.
MULTISTEP_COST_PER_STEP = 0.3


def multistep_cost_factor(prediction_horizon: int | None) -> float:
    """How many one-step epochs an epoch with the ``K``-step prediction term costs."""
    steps = max(int(prediction_horizon or 1), 1)
    return 1.0 + MULTISTEP_COST_PER_STEP * (steps - 1)


def _cap_seconds(spec: RunSpec, measured: dict[tuple[str, str, str], float]) -> float:
    """Seconds for one run that trains to its epoch cap, without finished runs to go by."""
    from pcc_agent.presets import get_preset

    if spec.method in REFERENCE_METHODS:
        return 300.0 if spec.method == ORACLE else 30.0
    preset = get_preset(spec.env_id, spec.model_variant)
    samples = spec.num_samples or preset.data.num_samples
    cnn = preset.model.encoder_kind != "mlp"
    guess = 0.1 if cnn and spec.model_variant == "paper" else (2e-3 if cnn else 7e-4)
    per_sample = measured.get((spec.env_id, spec.method, spec.model_variant), guess)
    return per_sample * samples * _epoch_cap(spec) * multistep_cost_factor(
        spec.prediction_horizon)


#: Records of this machine that suffice on their own (early stopping varies from run to run).
MIN_THIS_MACHINE = 3


def _prefer_this_machine(timed: list[_Timed], enough: int = MIN_THIS_MACHINE
                         ) -> tuple[list[_Timed], str]:
    """The records to go by, and where they were measured.

    This machine's when there are ``enough``, else those not known to come from another
    machine, else all.
    """
    here = [t for t in timed if t.machine == "this"]
    if here and (len(here) >= enough or len(here) == len(timed)):
        return here, "this machine"
    maybe = [t for t in timed if t.machine != "other"]
    if maybe:
        return maybe, "this machine" if len(here) == len(maybe) else (
            "machines older records do not name")
    return timed, "other machines"


def _train_speeds() -> dict[tuple[str, str, str], float]:
    measured: dict[tuple[str, str, str], float] = {}
    speed_file = COMMITTED_RESULTS_DIR / "train_speed.json"
    if speed_file.exists():
        for row in json.loads(speed_file.read_text()):
            if row.get("prediction_horizon", 1) > 1:  # the estimate scales one-step epochs
                continue
            per_sample = row["seconds_per_epoch"] / row["num_samples"]
            measured[(row["env"], row["method"], row["variant"])] = per_sample
    return measured


def _expected_epochs(spec: RunSpec, timed: list[_Timed]) -> float:
    """Epochs the run will train, the mean over the runs of ``timed`` with its patience.

    A run that stopped early, or trained to a cap at least the run's, trained as far as the
    run will (up to its cap); one that reached a lower cap would have gone on: the run's cap.
    Without runs of that patience, the cap.
    """
    cap, patience = _epoch_cap(spec), _patience(spec)
    epochs = []
    for t in timed:
        if t.epochs is None or _patience(t.spec) != patience:
            continue
        if t.stopped_early or _epoch_cap(t.spec) >= cap:
            epochs.append(min(t.epochs, cap))
        else:
            epochs.append(cap)
    return float(np.mean(epochs)) if epochs else float(cap)


def estimate_cost(
    runs: Sequence[RunSpec], finished: Iterable[dict[str, Any]] = (),
    machine: dict[str, Any] | None = None,
    resumed: dict[RunSpec, CheckpointedTraining] | None = None,
    reevaluated: dict[RunSpec, float] | None = None,
) -> CostEstimate:
    """Expected and upper durations of ``runs`` (one core each), see the module docstring.

    Args:
        runs: The runs to estimate, in the order the grid starts them.
        finished: Finished run records to go by (any grid's; a ``_source`` key names where
            a record came from).
        machine: This machine (:func:`pcc_bench.records.machine_info`); records measured on
            it are preferred. None: no preference.
        resumed: The runs that resume a training checkpoint (:func:`checkpointed_trainings`).
        reevaluated: The runs that only run their control tasks again, and the seconds their
            records' control took (:func:`reevaluations`).
    """
    resumed = resumed or {}
    reevaluated = reevaluated or {}
    measured = _train_speeds()
    timed = _timed(finished, machine)
    by_kind: dict[tuple[Any, ...], list[_Timed]] = {}
    by_model: dict[tuple[Any, ...], list[_Timed]] = {}
    for t in timed:
        by_kind.setdefault(_cost_key(t.spec), []).append(t)
        if t.spec.method not in REFERENCE_METHODS:
            by_kind.setdefault(_cost_key(t.spec, with_method=False), []).append(t)
            by_model.setdefault(_model_key(t.spec), []).append(t)
    expected: list[float] = []
    upper: list[float] = []
    bases: list[str] = []
    sources: set[str] = set()
    for spec in runs:
        reference = spec.method in REFERENCE_METHODS
        cap = _epoch_cap(spec) if not reference else 0
        guess = _cap_seconds(spec, measured)
        same_kind = by_kind.get(_cost_key(spec))
        same_model = None if reference else by_model.get(_model_key(spec))
        other_methods = None if reference else by_kind.get(_cost_key(spec, with_method=False))
        multistep = not reference and (spec.prediction_horizon or 1) > 1
        one_step = (by_model.get(_model_key(replace(spec, prediction_horizon=None)))
                    if multistep else None)
        if same_kind:
            # A reference run varies little: one run of it on this machine is enough.
            used, where = _prefer_this_machine(same_kind, 1 if reference else MIN_THIS_MACHINE)
            basis = "same kind"
            seconds = [t.seconds(spec.num_tasks) for t in used]
            run_expected = float(np.mean(seconds))
            speeds = [s for t in used if (s := t.seconds_per_epoch()) is not None]
            evals = [t.eval_seconds * spec.num_tasks / max(t.spec.num_tasks, 1) for t in used]
            if reference:  # no epochs to run longer: the slowest of its runs
                run_upper = max(seconds)
            else:
                run_upper = max(max(speeds) * cap + max(evals) if speeds else guess,
                                max(seconds))
        elif (same_model and any(t.epochs for t in same_model)) or (
                one_step and any(t.epochs for t in one_step)):
            # The same model's epochs; a multi-step run's from its one-step model, scaled.
            exact = bool(same_model and any(t.epochs for t in same_model))
            timed_model = same_model if exact else one_step
            used, where = _prefer_this_machine([t for t in timed_model or () if t.epochs])
            basis = "same model" if exact else "one-step model"
            factor = 1.0 if exact else multistep_cost_factor(spec.prediction_horizon)
            speed = factor * float(np.mean([t.seconds_per_epoch() for t in used]))
            control = float(np.mean([t.eval_seconds * spec.num_tasks / max(t.spec.num_tasks, 1)
                                     for t in used]))
            run_expected = speed * _expected_epochs(spec, used) + control
            run_upper = factor * max(t.seconds_per_epoch() or 0.0 for t in used) * cap + control
        elif other_methods:
            used, where = _prefer_this_machine(other_methods)
            basis = "other methods"
            seconds = [t.seconds(spec.num_tasks) for t in used]
            run_expected = float(np.mean(seconds))
            run_upper = max(guess, max(seconds))
        else:
            used, where = [], ""
            basis = "reference guess" if reference else "epoch cap"
            run_expected = run_upper = guess
        checkpoint = resumed.get(spec)
        if checkpoint is not None and cap:  # only the epochs left to the cap
            left = max(cap - checkpoint.epochs, 0)
            if checkpoint.seconds_per_epoch is not None:
                used, basis = [], "checkpoint"
                run_expected = run_upper = left * checkpoint.seconds_per_epoch
            else:
                run_expected, run_upper = run_expected * left / cap, run_upper * left / cap
        if spec in reevaluated:  # no training: the control tasks again
            used, basis = [], "re-evaluation"
            run_expected = run_upper = reevaluated[spec]
        expected.append(run_expected)
        upper.append(max(run_upper, run_expected))
        bases.append(f"{basis}, {where}" if used and machine is not None else basis)
        sources.update(t.source for t in used if t.source)
    return CostEstimate(
        float(sum(expected)), float(sum(upper)),
        sum(b.split(", ")[0] in ("same kind", "same model", "one-step model", "other methods")
            for b in bases),
        tuple(expected), tuple(upper), tuple(bases), tuple(sorted(sources)),
    )


@dataclass(frozen=True)
class CheckpointedTraining:
    """How far a run's training checkpoint got: epochs trained and their mean seconds."""

    epochs: int
    seconds_per_epoch: float | None


def reevaluations(results_dir: Path, runs: Iterable[RunSpec]) -> dict[RunSpec, float]:
    """The runs of ``runs`` that only run their control tasks again, and those tasks' seconds.

    See :func:`pcc_bench.weights.record_to_reevaluate`; the seconds are the record's own
    control time per task (``eval_seconds``) times the run's tasks, its validation tasks
    included (a re-evaluation runs both).
    """
    from pcc_bench.weights import record_to_reevaluate

    found = {}
    for spec in runs:
        record = record_to_reevaluate(results_dir, spec)
        if record is not None:
            tasks = max(len(record.get("percentages") or ()), 1)
            per_task = float(record.get("eval_seconds", 0.0)) / tasks
            found[spec] = per_task * (spec.num_tasks + (spec.validation_tasks or 0))
    return found


def checkpointed_trainings(results_dir: Path, runs: Iterable[RunSpec]
                           ) -> dict[RunSpec, CheckpointedTraining]:
    """The runs of ``runs`` that resume a training checkpoint, and how far each got.

    An unreadable checkpoint counts as none (the run trains afresh).
    """
    from pcc_agent.checkpoint import CheckpointError, load_checkpoint
    from pcc_bench.records import training_checkpoint_path

    found = {}
    for spec in runs:
        path = training_checkpoint_path(results_dir, spec)
        if not path.exists():
            continue
        try:
            extra = load_checkpoint(path).extra
            epochs = int(extra.get("epochs", 0))
            seconds = [float(row["time/epoch_seconds"]) for row in extra.get("history") or []
                       if "time/epoch_seconds" in row]
        except (CheckpointError, TypeError, ValueError, KeyError):
            continue
        if epochs > 0:
            found[spec] = CheckpointedTraining(
                epochs, float(np.mean(seconds)) if seconds else None)
    return found


def load_timing_records(directories: Iterable[Path]) -> list[dict[str, Any]]:
    """Finished run records below ``<directory>/runs`` for timing, each once.

    Unlike :func:`pcc_bench.records.load_records` this keeps records evaluated with other
    planner settings (their training times still hold) and prints nothing; a trained run's
    record made with other data, network or training settings than its preset's today is
    left out (it timed another model). Each record gets a ``_source`` key: its directory.
    """
    from pcc_bench.records import same_recipe

    records = []
    seen: set[Path] = set()
    for directory in directories:
        for path in sorted((Path(directory) / "runs").rglob("*.json")):
            resolved = path.resolve()
            if resolved in seen:
                continue
            seen.add(resolved)
            try:
                rec = json.loads(path.read_text())
                spec = RunSpec(**rec["spec"])
            except (OSError, ValueError, TypeError, KeyError):
                continue
            if not isinstance(rec, dict) or rec.get("format") != RESULT_FORMAT or rec.get(
                    "status") != "done":
                continue
            if spec.method not in (ORACLE, NO_ACTION) and not same_recipe(rec, spec):
                continue
            rec["_source"] = _display(Path(directory))
            records.append(rec)
    return records


def _display(directory: Path) -> str:
    """A directory as the user knows it: relative to the working or the checkout directory."""
    resolved = directory.resolve()
    for root in (Path.cwd(), COMMITTED_RESULTS_DIR.parent):
        try:
            return str(resolved.relative_to(root.resolve()))
        except ValueError:
            continue
    return str(directory)


def timing_directories(results_dir: Path) -> list[Path]:
    """Where ``--status`` looks for finished runs.

    The results directory, then the committed grids (:data:`COMMITTED_GRIDS`) of a source
    checkout.
    """
    committed = [COMMITTED_RESULTS_DIR / name for name in COMMITTED_GRIDS]
    return [Path(results_dir)] + [d for d in committed if (d / "runs").is_dir()]


def _paper_cnn(spec: RunSpec) -> bool:
    from pcc_agent.presets import get_preset

    return (spec.method not in REFERENCE_METHODS and spec.model_variant == "paper"
            and get_preset(spec.env_id, "paper").model.encoder_kind == "cnn")


def status_lines(
    preset_name: str, runs: Sequence[RunSpec], pending: Sequence[RunSpec], results_dir: Path,
    workers: int, backend: str = "process",
) -> list[str]:
    """The cost lines of ``pcc reproduce`` (also with ``--status``).

    The wall time expected and at most, and what the figures rest on.
    """
    from pcc_bench.records import machine_info

    head = f"Preset {preset_name!r}: {len(runs)} runs, {len(pending)} to run"
    if not pending:
        return [head + "."]
    finished = load_timing_records(timing_directories(results_dir))
    resumed = checkpointed_trainings(results_dir, pending)
    reevaluated = reevaluations(results_dir, pending)
    cost = estimate_cost(pending, finished, machine_info(), resumed, reevaluated)
    if resumed:
        head += (f" ({len(resumed)} resume{'s' if len(resumed) == 1 else ''} a training "
                 f"checkpoint, {sum(c.epochs for c in resumed.values())} epochs done)")
    if reevaluated:
        head += (f" ({len(reevaluated)} only re-evaluate{'s' if len(reevaluated) == 1 else ''}"
                 " a trained model with new planner settings)")
    if backend == "ray":
        return [
            f"{head}: about {cost.expected_seconds / 3600:,.1f} core-hours, at most "
            f"{cost.upper_seconds / 3600:,.1f} if every model trains to its epoch cap (Ray: "
            "the wall time is that over the cluster's CPUs).",
            f"  Based on: {cost.basis_text()}.",
        ]
    cores = os.cpu_count() or 1
    slots = min(workers, cores)
    sharing = f" ({workers} workers share {cores} cores)" if workers > cores else ""
    gpu = "; its CNN 'paper' models want a GPU" if any(_paper_cnn(r) for r in pending) else ""
    return [
        f"{head}: estimated {format_duration(cost.wall_seconds(slots))} wall time on "
        f"{workers} worker(s){sharing}, at most {format_duration(cost.upper_wall_seconds(slots))}"
        f" if every model trains to its epoch cap{gpu}.",
        f"  Based on: {cost.basis_text()}; each run on one core, started in grid order on the "
        "first free worker.",
    ]
