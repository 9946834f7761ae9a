"""Reproduce the paper's tables with its reproducible protocol (N models x M control tasks).

For every (env, method, noise, model seed) of a preset this script generates or loads the
cached data set of that seed, trains the model, runs the control tasks and writes ONE JSON
file per run (config, versions, training time, per-task percentages and true-state
trajectories). Finished runs are skipped, so an interrupted grid resumes where it stopped;
files are written atomically, so a killed run never leaves a partial result that counts.
Then it aggregates every run file into ``summary.json`` and ``summary.md`` (mean and standard
error over all tasks and for the top-1 model, IQM with a bootstrap interval across models,
the paper's numbers beside ours, the oracle controller as the ceiling and zero actions as the
floor) and a bar chart.

Examples:
    python -m benchmarks.reproduce --preset quick
    python -m benchmarks.reproduce --preset paper --envs pcc/Planar-v0 --workers 2
    python -m benchmarks.reproduce --preset paper --backend ray --ray-address auto \
        --ray-gpus-per-task 0.5
    python -m benchmarks.reproduce --preset paper --envs pcc/Planar-v0 --status
    python -m benchmarks.reproduce --aggregate-only
"""

from __future__ import annotations

import argparse
import contextlib
import json
import math
import multiprocessing
import os
import platform
import signal
import sys
import threading
import time
from collections.abc import Iterable, Iterator, Sequence
from concurrent.futures import InvalidStateError, ProcessPoolExecutor, as_completed
from dataclasses import asdict, dataclass, replace
from pathlib import Path
from typing import Any

import numpy as np

from benchmarks.presets import (
    ABLATIONS,
    ALL_METHODS,
    LATENT_MAP_ENVS,
    LATENT_MAP_MODELS,
    PAPER_RESULTS,
    REPRODUCE_PRESETS,
    RESTART_SEED_STRIDE,
    ReproducePreset,
)
from benchmarks.worker_lifetime import end_with_driver

DEFAULT_RESULTS_DIR = Path("pcc_results") / "reproduce"
RESULT_FORMAT = 1
ORACLE = "oracle"
#: The controller that applies zero actions: the floor beside the oracle's ceiling. Where a
#: start lies near the goal (CartPole) doing nothing already scores, and a learned controller
#: is only useful above it.
NO_ACTION = "no-action"
#: Controllers that train nothing: one run per (env, noise level), no data set, no checkpoint.
REFERENCE_METHODS = (ORACLE, NO_ACTION)
#: Epochs between a run's training checkpoints: a run cut short (Ctrl-C, a crash, the end of
#: a working session) resumes from its last one; at most this many epochs are redone.
TRAIN_CHECKPOINT_EVERY = 5


@dataclass(frozen=True)
class RunSpec:
    """One cell of the grid: one model (or a reference controller) and its control tasks."""

    env_id: str
    method: str
    seed: int
    noise_std: float
    num_tasks: int
    task_seed: int
    model_variant: str
    preset: str
    num_samples: int | None = None
    max_epochs: int | None = None
    patience: int | None = None
    flush_denormals: bool | None = None

    @property
    def relative_path(self) -> Path:
        """Where the run's JSON lives below the results directory."""
        env = self.env_id.replace("/", "_")
        noise = f"noise{self.noise_std!r}"
        return Path("runs") / self.preset / env / noise / self.method / f"seed{self.seed}.json"


def _versions() -> dict[str, str]:
    import gymnasium
    import stable_baselines3
    import torch

    import pcc_agent

    return {
        "pcc_control": pcc_agent.__version__,
        "torch": torch.__version__,
        "gymnasium": gymnasium.__version__,
        "stable_baselines3": stable_baselines3.__version__,
        "numpy": np.__version__,
        "python": platform.python_version(),
    }


def machine_info() -> dict[str, Any]:
    """The host, the SIMD kernels torch picked on it and the CPU's SIMD features.

    Kernels for different instruction sets round differently (oneDNN's convolutions limited
    to AVX2 train other SAC weights than its AVX-512 ones), so bit-identical reruns are only
    expected on hosts with the same features.
    """
    import torch

    try:
        cpuinfo = Path("/proc/cpuinfo").read_text().split()
    except OSError:  # not Linux
        cpuinfo = []
    simd = sorted({flag for flag in cpuinfo if flag.startswith(("avx", "amx", "fma"))})
    return {
        "platform": platform.platform(),
        "cpu_count": os.cpu_count(),
        "torch_cpu_capability": torch.backends.cpu.get_cpu_capability(),
        "simd_flags": simd,
    }


def _write_json_atomic(path: Path, payload: Any) -> None:
    path.parent.mkdir(parents=True, exist_ok=True)
    tmp = path.with_suffix(path.suffix + f".{os.getpid()}.tmp")
    with open(tmp, "w") as handle:
        json.dump(payload, handle, indent=1)
        handle.flush()
        os.fsync(handle.fileno())
    os.replace(tmp, path)


def _write_text_atomic(path: Path, text: str) -> None:
    from pcc_agent.checkpoint import atomic_write_text

    atomic_write_text(text, path)


def _save_figure_atomic(fig: Any, path: Path) -> None:
    """``fig.savefig`` through a temporary file, so a reader never sees half a PNG."""
    tmp = path.with_suffix(path.suffix + f".{os.getpid()}.tmp")
    fig.savefig(tmp, dpi=120, format=path.suffix.lstrip(".") or "png", bbox_inches="tight")
    os.replace(tmp, path)


def checkpoint_path(results_dir: str | Path, spec: RunSpec) -> Path:
    """Where a run's trained agent is saved (``PCCAgent.load`` reads it back)."""
    return Path(results_dir) / "checkpoints" / spec.relative_path.with_suffix(".pt")


def training_checkpoint_path(results_dir: str | Path, spec: RunSpec) -> Path:
    """Where a run's training in progress is checkpointed (removed once the run is done)."""
    return checkpoint_path(results_dir, spec).with_suffix(".training.pt")


@dataclass(frozen=True)
class ResumePoint:
    """Where an interrupted training of a run continues: its epoch and the seconds spent."""

    epoch: int
    seconds: float


def _resume_point(
    path: Path, train_config: Any, architecture: dict[str, Any]
) -> ResumePoint | None:
    """Where an interrupted training of this run continues (None: start afresh).

    A checkpoint of other training settings or another architecture, a finished training
    (the run was killed during its control tasks) or an unreadable file is deleted: the run
    trains from scratch. Both sides are compared after filling in the configs' defaults, so
    a config field added to the library later (with a default that keeps the old behaviour)
    does not throw away a checkpoint written before it existed.
    """
    from pcc_agent.checkpoint import CheckpointError, load_checkpoint
    from pcc_agent.presets import ModelConfig, TrainConfig

    if not path.exists():
        return None
    try:
        saved = load_checkpoint(path)
        usable = (not saved.extra.get("finished")
                  and TrainConfig.from_dict(saved.config.get("train_config") or {})
                  == train_config
                  and saved.model_config == ModelConfig.from_dict(architecture["model_config"])
                  and list(saved.architecture["obs_shape"]) == list(architecture["obs_shape"])
                  and saved.architecture["action_dim"] == architecture["action_dim"])
    except (CheckpointError, KeyError, TypeError, ValueError):
        usable = False
    if usable:
        history = saved.extra.get("history", [])
        seconds = sum(float(row.get("time/epoch_seconds", 0.0)) for row in history)
        return ResumePoint(int(saved.extra.get("epochs", 0)), seconds)
    _remove_training_checkpoint(path)
    return None


def _remove_training_checkpoint(path: Path) -> None:
    """Delete a training checkpoint and the JSON copy of its configuration beside it."""
    path.unlink(missing_ok=True)
    path.with_suffix(".json").unlink(missing_ok=True)


def training_progress(results_dir: str | Path, spec: RunSpec) -> str:
    """One line on where a run stands: done, training or not started.

    For a training in progress: its epoch, epoch cap and best validation loss so far. Reads
    the run's record and its training checkpoint; changes nothing.
    """
    from pcc_agent.checkpoint import CheckpointError, load_checkpoint
    from pcc_agent.presets import get_preset

    label = f"{spec.env_id} {spec.method} noise={spec.noise_std} seed={spec.seed}"
    record = load_finished_run(Path(results_dir) / spec.relative_path, spec)
    if record is not None:
        return f"{label}: done, {record['mean']:.1f}% of steps in goal"
    path = training_checkpoint_path(results_dir, spec)
    if not path.exists():
        return f"{label}: not started"
    try:
        extra = load_checkpoint(path).extra
    except CheckpointError as error:
        return f"{label}: unreadable training checkpoint ({error}); it will train afresh"
    history = extra.get("history") or [{}]
    epoch_seconds = float(history[-1].get("time/epoch_seconds", float("nan")))
    best = extra.get("best_validation_loss")
    best_text = f"{best:.2f} at epoch {extra.get('best_epoch')}" if best is not None else "-"
    cap = spec.max_epochs or get_preset(spec.env_id, spec.model_variant).train.epochs
    return (f"{label}: training, epoch {extra.get('epochs', 0)} of at most {cap}, best "
            f"validation loss {best_text} ({epoch_seconds:.1f} s/epoch)")


def load_finished_run(path: Path, spec: RunSpec | None = None) -> dict[str, Any] | None:
    """Return a finished run's record, or None if the file is missing, partial or stale.

    With ``spec``, a record written for other settings of the same cell (e.g. another
    ``--num-tasks`` or ``--max-epochs``) is stale too.
    """
    try:
        with open(path) as handle:
            record = json.load(handle)
    except (OSError, json.JSONDecodeError):
        return None
    if not isinstance(record, dict):
        return None
    if record.get("format") != RESULT_FORMAT or record.get("status") != "done":
        return None
    if spec is not None and not _same_spec(record.get("spec"), spec):
        return None
    if spec is not None and not _same_planner(record, spec):
        return None
    if spec is not None and not _same_recipe(record, spec):
        return None
    return record


def _same_spec(stored: Any, spec: RunSpec) -> bool:
    """Whether a record's spec is ``spec``; overrides added later (absent) count as unset."""
    if not isinstance(stored, dict):
        return False
    expected = asdict(spec)
    unset = {key: None for key, value in expected.items() if value is None}
    return {**unset, **stored} == expected


def _preset_for(spec: RunSpec) -> Any:
    """The env preset of a run, with the run's overrides applied."""
    from pcc_agent.presets import get_preset

    preset = get_preset(spec.env_id, spec.model_variant)
    if spec.max_epochs is not None:
        preset = replace(preset, train=replace(preset.train, epochs=spec.max_epochs))
    if spec.patience is not None:
        preset = replace(preset, train=replace(preset.train, patience=spec.patience))
    if spec.flush_denormals:
        preset = replace(preset, train=replace(preset.train, flush_denormals=True))
    if spec.num_samples is not None:
        preset = replace(preset, data=replace(preset.data, num_samples=spec.num_samples))
    return replace(preset, data=replace(preset.data, noise_std=spec.noise_std))


def _same_planner(record: dict[str, Any], spec: RunSpec) -> bool:
    """Whether a record was evaluated by this planner revision with the preset's settings.

    Records without a revision were evaluated by revision 1. Oracle records are compared
    with the env's current ``ORACLE_CONFIGS`` entry and the preset's planner (the oracle runs
    the agents' settings); no-action records plan nothing and always match.
    """
    from pcc_agent.planning import PLANNER_REVISION

    if spec.method == NO_ACTION:  # plans nothing
        return True
    config = record.get("config", {})
    if config.get("planner_revision", 1) != PLANNER_REVISION:
        return False
    if spec.method == ORACLE:
        from pcc_agent.oracle import oracle_config_for

        wanted = json.loads(json.dumps(asdict(oracle_config_for(spec.env_id))))
        if config.get("oracle") != wanted:
            return False
    wanted = json.loads(json.dumps(asdict(_preset_for(spec).planner)))
    return config.get("planner") == wanted


def _same_recipe(record: dict[str, Any], spec: RunSpec) -> bool:
    """Whether a record's model was trained with the preset's data, network and training.

    Compared as dataclasses, so a config field added to the library later (with a default
    that keeps the old behaviour) leaves older records valid. The training seed is the run's
    own (``spec.seed``, checked with the spec), not the preset's. Reference records (oracle,
    no action) train nothing and always match.
    """
    if spec.method in REFERENCE_METHODS:
        return True
    from pcc_agent.losses import model_config_for_method
    from pcc_agent.presets import DataConfig, ModelConfig, TrainConfig

    config = record.get("config", {})
    preset = _preset_for(spec)
    try:
        train = TrainConfig.from_dict(config["train"])
        model = ModelConfig.from_dict(config["model"])
        data = DataConfig(**config["data"])
    except (KeyError, TypeError, ValueError):
        return False
    # The data's noise is the spec's (checked by _same_spec). Records written before the
    # agent reported it carry the unused preset value 0.0 there, so it is not compared.
    return (replace(train, seed=preset.train.seed) == preset.train
            and model == model_config_for_method(preset.model, spec.method)
            and replace(data, noise_std=preset.data.noise_std) == preset.data)


def execute_run(spec: RunSpec, results_dir: str | Path, data_dir: str | None = None) -> dict:
    """Train one model and run its control tasks; write and return the run record.

    Skips the work when a finished record for ``spec`` already exists.
    """
    import torch

    path = Path(results_dir) / spec.relative_path
    done = load_finished_run(path, spec)
    if done is not None:
        done["skipped"] = True
        return done
    torch.set_num_threads(1)

    from pcc_agent.evaluation import evaluate_control, task_seeds
    from pcc_agent.planning import PLANNER_REVISION

    env_kwargs = {"noise_std": spec.noise_std} if spec.noise_std else {}
    seeds = task_seeds(spec.task_seed, spec.num_tasks)
    trained = load_finished_run(path)
    if (
        trained is not None
        and spec.method not in REFERENCE_METHODS
        and _same_spec(trained.get("spec"), spec)
        and _same_recipe(trained, spec)
        and checkpoint_path(results_dir, spec).exists()
    ):
        return _reevaluate(trained, spec, Path(results_dir), seeds, env_kwargs)
    record: dict[str, Any] = {
        "format": RESULT_FORMAT,
        "spec": asdict(spec),
        "versions": _versions(),
        "machine": machine_info(),
        "command": " ".join(sys.argv),
    }
    start = time.perf_counter()
    if spec.method == ORACLE:
        from pcc_agent.oracle import OracleController, oracle_config_for

        config = oracle_config_for(spec.env_id)
        planner = _preset_for(spec).planner  # the agents' own settings: a true ceiling
        record["config"] = {"oracle": asdict(config), "planner": asdict(planner),
                            "planner_revision": PLANNER_REVISION}
        record["train_seconds"] = 0.0
        evaluation_start = time.perf_counter()
        evaluation = evaluate_control(
            lambda env: OracleController(env, config, planner), spec.env_id, seeds, env_kwargs
        )
    elif spec.method == NO_ACTION:
        from benchmarks.no_action_floor import ZeroActionPolicy

        record["config"] = {"no_action": True}
        record["train_seconds"] = 0.0
        evaluation_start = time.perf_counter()
        evaluation = evaluate_control(
            lambda env: ZeroActionPolicy(env.action_space), spec.env_id, seeds, env_kwargs
        )
    else:
        from pcc_agent.agent import PCCAgent

        preset = _preset_for(spec)
        agent = PCCAgent(
            spec.env_id,
            method=spec.method,
            preset=preset,
            seed=spec.seed,
            env_kwargs=env_kwargs,
            data_cache_dir=data_dir,
        )
        in_progress = training_checkpoint_path(results_dir, spec)
        resumed = _resume_point(in_progress, replace(preset.train, seed=spec.seed),
                                agent.model.architecture())
        agent.learn(progress_bar=False, checkpoint_path=in_progress,
                    resume=resumed is not None, checkpoint_every=TRAIN_CHECKPOINT_EVERY)
        record["train_seconds"] = time.perf_counter() - start
        if resumed is not None:  # add the epochs trained before the interruption
            record["train_seconds"] += resumed.seconds
            record["training_resumed_at_epoch"] = resumed.epoch
        # The trained agent, for re-evaluation with other planner settings (not committed).
        agent.save(checkpoint_path(results_dir, spec))
        record["config"] = agent.config_dict()
        record["training"] = agent.train_summary()
        evaluation_start = time.perf_counter()
        evaluation = evaluate_control(agent, spec.env_id, seeds, env_kwargs)
        _maybe_plot_latent_map(agent, spec, Path(results_dir))
    record["eval_seconds"] = time.perf_counter() - evaluation_start
    record["task_seeds"] = seeds
    record["percentages"] = [t.percent_in_goal for t in evaluation.tasks]
    record["tasks"] = [t.to_dict() for t in evaluation.tasks]
    record["mean"] = evaluation.mean
    record["status"] = "done"
    _write_json_atomic(path, record)
    if spec.method not in REFERENCE_METHODS:  # the training is complete, its record written
        _remove_training_checkpoint(training_checkpoint_path(results_dir, spec))
    return record


def _reevaluate(
    record: dict[str, Any], spec: RunSpec, results_dir: Path, seeds: list[int],
    env_kwargs: dict[str, Any],
) -> dict[str, Any]:
    """Run the control tasks again with the preset's current planner, from the saved agent.

    Used when the planner settings of a preset changed after a model was trained: the model
    is not retrained; its record keeps the training information and gets the new control
    results, the new planner settings and ``reevaluated: true``.
    """
    from pcc_agent.agent import PCCAgent
    from pcc_agent.evaluation import evaluate_control
    from pcc_agent.planning import PLANNER_REVISION

    agent = PCCAgent.load(checkpoint_path(results_dir, spec))
    planner = _preset_for(spec).planner
    agent.preset = replace(agent.preset, planner=planner)
    start = time.perf_counter()
    evaluation = evaluate_control(agent, spec.env_id, seeds, env_kwargs)
    record = dict(record)
    record["config"] = {**record.get("config", {}), "planner": asdict(planner),
                        "planner_revision": PLANNER_REVISION}
    record["previous_planner_results"] = record.get("percentages")
    record["eval_seconds"] = time.perf_counter() - start
    record["percentages"] = [t.percent_in_goal for t in evaluation.tasks]
    record["tasks"] = [t.to_dict() for t in evaluation.tasks]
    record["mean"] = evaluation.mean
    record["reevaluated"] = True
    record["command"] = " ".join(sys.argv)
    _write_json_atomic(results_dir / spec.relative_path, record)
    return record


def _maybe_plot_latent_map(agent: Any, spec: RunSpec, results_dir: Path) -> None:
    """Latent maps (paper Figure 2) for the first models of the envs in ``LATENT_MAP_ENVS``."""
    if spec.seed >= LATENT_MAP_MODELS or spec.env_id not in LATENT_MAP_ENVS:
        return
    from pcc_agent.plots import plot_env_latent_map

    out = results_dir / "latent_maps" / spec.preset
    out.mkdir(parents=True, exist_ok=True)
    name = f"{spec.env_id.split('/')[1]}_{spec.method}_noise{spec.noise_std!r}_seed{spec.seed}.png"
    plot_env_latent_map(agent, out / name, title=f"{spec.method} seed {spec.seed}")


def _has_oracle(env_id: str) -> bool:
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
            if include_oracle and _has_oracle(env_id):
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
                            **common,
                        )
                    )
    return runs


def _worker_init() -> None:
    os.environ.setdefault("OMP_NUM_THREADS", "1")
    import torch

    torch.set_num_threads(1)


def _pool_worker_init(parent_ignores_sigint: bool = False, driver_pid: int | None = None,
                      forked_by_main_thread: bool = False) -> None:
    """A pool worker ends at Ctrl-C (the terminal signals the whole process group).

    Python's default would raise KeyboardInterrupt inside the run, which the pool reports as
    that run's result before the worker takes the next queued run. The run's training
    checkpoint is kept, so re-running the grid continues it. A grid started in the background
    by a non-interactive shell ignores SIGINT; its workers then ignore it too, so a stray
    SIGINT cannot kill them under a main process that keeps going. A worker also ends when
    the driver ``driver_pid`` ends without stopping it (``kill -9``): see
    :func:`benchmarks.worker_lifetime.end_with_driver`.
    """
    signal.signal(signal.SIGINT, signal.SIG_IGN if parent_ignores_sigint else signal.SIG_DFL)
    signal.signal(signal.SIGTERM, signal.SIG_DFL)  # not the main process's graceful handler
    if driver_pid is not None:
        end_with_driver(driver_pid, forked_by_main_thread)
    _worker_init()


def _interrupt(signum: int, frame: Any) -> None:
    """Signal handler: stop the grid the way Ctrl-C does (raise KeyboardInterrupt)."""
    raise KeyboardInterrupt(signal.Signals(signum).name)


def _ignore_cancelled_future_race(args: threading.ExceptHookArgs) -> None:
    """Thread excepthook: drop the executor manager's error on futures we cancelled.

    At Ctrl-C the workers die with the whole process group while the main process cancels the
    queued futures; Python 3.11's pool manager then tries to mark those cancelled futures as
    failed and prints an ``InvalidStateError`` traceback after the clean exit message (Python
    3.12 ignores that case itself). Every other thread error goes to the default hook.
    """
    manager = type(args.thread).__name__ == "_ExecutorManagerThread"
    if not (manager and isinstance(args.exc_value, InvalidStateError)):
        threading.__excepthook__(args)


#: What a backend reports per run, in completion order: the record, or the run's error.
Outcome = tuple[RunSpec, dict[str, Any] | Exception]


def run_grid(
    runs: Sequence[RunSpec],
    results_dir: Path,
    workers: int,
    backend: str = "process",
    ray_address: str | None = None,
    data_dir: str | None = None,
    ray_gpus_per_task: float = 0.0,
) -> list[dict[str, Any]]:
    """Execute the runs that are not finished yet, in a process pool or on Ray.

    A failed run does not stop the others; the failures are raised together at the end.
    Ctrl-C cancels the queued runs (finished ones are kept: re-running continues the grid).
    """
    todo = [r for r in runs if load_finished_run(results_dir / r.relative_path, r) is None]
    print(f"{len(runs) - len(todo)} of {len(runs)} runs already finished; {len(todo)} to run.")
    if not todo:
        return []
    if backend == "ray":
        outcomes = _ray_outcomes(todo, results_dir.resolve(), data_dir, ray_address,
                                 ray_gpus_per_task)
        # Ray workers may run on other machines: the driver writes what they return.
        return collect_outcomes(outcomes, len(todo), write_to=results_dir)
    if workers <= 1:
        _worker_init()
        return collect_outcomes(_serial_outcomes(todo, results_dir, data_dir), len(todo))
    outcomes = pool_outcomes(execute_run, todo, workers, results_dir, data_dir)
    return collect_outcomes(outcomes, len(todo))


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
                _write_json_atomic(write_to / spec.relative_path, outcome)
            records.append(outcome)
            bar.write(_report_line(i + 1, total, outcome))
    if failures:
        raise RuntimeError(f"{len(failures)} run(s) failed:\n" + "\n".join(failures))
    return records


def _serial_outcomes(
    todo: Sequence[RunSpec], results_dir: Path, data_dir: str | None
) -> Iterator[Outcome]:
    for spec in todo:
        try:
            yield spec, execute_run(spec, results_dir, data_dir)
        except Exception as error:  # one failed run must not stop the grid
            yield spec, error


def pool_outcomes(
    run: Any, todo: Sequence[RunSpec], workers: int, *args: Any
) -> Iterator[Outcome]:
    """``run(spec, *args)`` for every spec in a pool of ``workers`` processes.

    If the consumer stops early (Ctrl-C, an error, ``close()``), the queued runs are
    cancelled instead of being trained silently before the program exits. If this process is
    killed outright (``kill -9``), the workers end with it.
    """
    parent_ignores_sigint = signal.getsignal(signal.SIGINT) is signal.SIG_IGN
    # The workers are created by the submits below, in this same thread.
    main_thread = threading.current_thread() is threading.main_thread()
    pool = ProcessPoolExecutor(
        max_workers=workers, initializer=_pool_worker_init,
        initargs=(parent_ignores_sigint, os.getpid(), main_thread),
    )
    futures: dict[Any, RunSpec] = {}
    try:
        futures = {pool.submit(run, spec, *args): spec for spec in todo}
        for future in as_completed(futures):
            try:
                outcome: dict[str, Any] | Exception = future.result()
            except Exception as error:  # one failed run must not stop or hang the grid
                outcome = error
            yield futures[future], outcome
    except BaseException:
        # Cancel each queued future here: the pool's own cancel_futures can miss them when
        # the executor object is collected before its manager thread acts on the flag.
        threading.excepthook = _ignore_cancelled_future_race
        for future in futures:
            future.cancel()
        pool.shutdown(wait=False, cancel_futures=True)
        # Runs in progress stop too (their last epoch checkpoint is kept), also when the signal
        # reached only this process (SIGTERM, or SIGINT sent to one pid). The grid's pool
        # workers are the only child processes the driver starts.
        for worker in multiprocessing.active_children():
            worker.terminate()
        print("Stopped: queued runs cancelled.", file=sys.stderr, flush=True)
        raise
    pool.shutdown()


def _ray_outcomes(
    todo: Sequence[RunSpec], results_dir: Path, data_dir: str | None, address: str | None,
    gpus_per_task: float,
) -> Iterator[Outcome]:
    """The runs as Ray tasks (one CPU and ``gpus_per_task`` GPUs each), in completion order."""
    try:
        import ray
    except ImportError as exc:  # pragma: no cover - depends on the optional extra
        raise SystemExit("--backend ray needs Ray: pip install 'pcc-control[ray]'") from exc
    ray.init(address=address, ignore_reinit_error=True)
    task = ray.remote(num_cpus=1, num_gpus=gpus_per_task)(_ray_task)
    pending = {task.remote(spec, str(results_dir), data_dir): spec for spec in todo}
    try:
        while pending:
            (ref,), _ = ray.wait(list(pending), num_returns=1)
            spec = pending.pop(ref)
            try:
                outcome: dict[str, Any] | Exception = ray.get(ref)
            except Exception as error:  # a failed task must not lose the others' results
                outcome = error
            yield spec, outcome
    except BaseException:
        for ref in pending:
            ray.cancel(ref)
        raise


def _ray_task(spec: RunSpec, results_dir: str, data_dir: str | None) -> dict[str, Any]:
    _worker_init()
    return execute_run(spec, results_dir, data_dir)


def _report_line(i: int, n: int, record: dict[str, Any]) -> str:
    spec = record["spec"]
    done = "already finished" if record.get("skipped") else (
        f"train {record['train_seconds']:.0f}s, control {record['eval_seconds']:.0f}s")
    return (
        f"[{i}/{n}] {spec['env_id']} {spec['method']} noise={spec['noise_std']} "
        f"seed={spec['seed']}: {record['mean']:.1f}% of steps in goal ({done})"
    )


# ---------------------------------------------------------------------------- aggregation
def interquartile_mean(values: np.ndarray) -> float:
    """Mean of the middle 50% of the values (rliable's IQM)."""
    values = np.sort(np.asarray(values, dtype=np.float64).ravel())
    n = values.size
    lo, hi = int(math.floor(0.25 * n)), int(math.ceil(0.75 * n))
    return float(values[lo:hi].mean()) if hi > lo else float(values.mean())


def bootstrap_iqm_ci(
    per_model: list[np.ndarray], reps: int = 2000, seed: int = 0
) -> tuple[float, float]:
    """95% bootstrap interval of the IQM, resampling models (then tasks within each model)."""
    rng = np.random.default_rng(seed)
    stats = np.empty(reps)
    n = len(per_model)
    for r in range(reps):
        picks = rng.integers(0, n, n)
        sample = [
            per_model[i][rng.integers(0, len(per_model[i]), len(per_model[i]))] for i in picks
        ]
        stats[r] = interquartile_mean(np.concatenate(sample))
    return float(np.percentile(stats, 2.5)), float(np.percentile(stats, 97.5))


def is_restart_training(spec: dict[str, Any]) -> bool:
    """Whether a run is a second or later training of a ``restarts`` preset's model.

    Such runs count only through :func:`select_restarts`, so that a preset's own rows keep
    its models ``0 .. N-1``.
    """
    return int(spec.get("seed", 0)) >= RESTART_SEED_STRIDE


def aggregate(records: Iterable[dict[str, Any]]) -> list[dict[str, Any]]:
    """Summary rows per (env, method, noise, preset) from run records.

    Restart trainings (:func:`is_restart_training`) are left out: pass the records of
    :func:`select_restarts` to get the rows of the ``restarts`` presets.
    """
    from pcc_agent.evaluation import standard_error

    groups: dict[tuple[str, str, float, str], list[dict[str, Any]]] = {}
    for rec in records:
        s = rec["spec"]
        if is_restart_training(s):
            continue
        groups.setdefault((s["env_id"], s["method"], s["noise_std"], s["preset"]), []).append(rec)
    def reference_means(method: str) -> tuple[dict[Any, float], dict[Any, float]]:
        """A reference controller's mean per (env, noise, preset), and per task set.

        The references do not depend on the model variant: a preset without its own run uses
        another preset's on the same tasks (same env, noise, task seed and task count).
        """
        own = {(k[0], k[2], k[3]): float(np.mean(v[0]["percentages"]))
               for k, v in groups.items() if k[1] == method}
        by_tasks = {(k[0], k[2], v[0]["spec"].get("task_seed"), len(v[0]["percentages"]),
                     planner_revision_of(v[0])): float(np.mean(v[0]["percentages"]))
                    for k, v in groups.items() if k[1] == method}
        return own, by_tasks

    references = {method: reference_means(method) for method in REFERENCE_METHODS}

    def reference_mean(method: str, env_id: str, noise: float, preset: str,
                       recs: list[dict[str, Any]]) -> float | None:
        own, by_tasks = references[method]
        # An oracle only serves rows of its own planner revision; the floor plans nothing.
        revision = None if method == NO_ACTION else planner_revision_of(recs[0])
        tasks = (env_id, noise, recs[0]["spec"].get("task_seed"), len(recs[0]["percentages"]),
                 revision)
        return own.get((env_id, noise, preset), by_tasks.get(tasks))

    rows = []
    for (env_id, method, noise, preset), recs in sorted(groups.items()):
        recs = sorted(recs, key=lambda r: r["spec"]["seed"])
        per_model = [np.asarray(r["percentages"], dtype=np.float64) for r in recs]
        all_tasks = np.concatenate(per_model)
        means = np.array([m.mean() for m in per_model])
        best = int(np.argmax(means))
        top = per_model[best]

        planned = _registered_preset(preset)
        row: dict[str, Any] = {
            "env": env_id,
            "method": method,
            "noise_std": noise,
            "preset": preset,
            "model_variant": recs[0]["spec"]["model_variant"],
            "n_models": len(recs),
            # The preset's grid size: a row with fewer models is a reduced grid.
            "n_models_planned": (
                1 if method in REFERENCE_METHODS else planned.num_models if planned else None),
            "n_tasks": int(np.median([m.size for m in per_model])),
            "seeds": [r["spec"]["seed"] for r in recs],
            "task_seed": recs[0]["spec"].get("task_seed"),
            "mean_all": float(all_tasks.mean()),
            "se_all": standard_error(all_tasks),
            "mean_top1": float(top.mean()),
            "se_top1": standard_error(top),
            "top1_seed": recs[best]["spec"]["seed"],
            "iqm": interquartile_mean(all_tasks),
            "iqm_ci": list(bootstrap_iqm_ci(per_model)) if len(per_model) > 1 else None,
            "oracle_mean": reference_mean(ORACLE, env_id, noise, preset, recs),
            "floor_mean": reference_mean(NO_ACTION, env_id, noise, preset, recs),
            "train_seconds_mean": float(np.mean([r["train_seconds"] for r in recs])),
            "settings": recs[0].get("config", {}),
        }
        paper = PAPER_RESULTS.get((env_id, method, noise))
        row["paper_all"] = list(paper["all"]) if paper else None
        row["paper_top1"] = list(paper["top1"]) if paper and "top1" in paper else None
        rows.append(row)
    return rows


def _registered_preset(label: str) -> ReproducePreset | None:
    """The registered preset behind a row label such as ``"paper+max_epochs=5"``."""
    return REPRODUCE_PRESETS.get(label.split(" [", 1)[0].split("+", 1)[0])


def _fmt(pair: Sequence[float | None] | None) -> str:
    from pcc_agent.evaluation import format_mean_se

    return "-" if pair is None else format_mean_se(pair[0], pair[1])


def paper_table(row: dict[str, Any]) -> str:
    """Which of the paper's tables a summary row belongs to."""
    if row["noise_std"]:
        return "Table 3: noisy dynamics"
    if row["method"] in ABLATIONS:
        return "Table 2: ablations"
    return "Table 1: E2C, RCE and PCC"


def _models_cell(row: dict[str, Any]) -> str:
    """The models-x-tasks cell: ``"10 x 10"``, or the difference from the preset's grid.

    ``"3 of 10 x 10 (reduced grid)"`` when models are missing; ``"12 x 10 (2 beyond the
    preset's 10)"`` when extra seeds were run (top-1 is then the best of more models than the
    protocol's).
    """
    planned = row.get("n_models_planned")
    if planned is not None and row["n_models"] < planned:
        return f"{row['n_models']} of {planned} x {row['n_tasks']} (reduced grid)"
    if planned is not None and row["n_models"] > planned:
        return (f"{row['n_models']} x {row['n_tasks']} ({row['n_models'] - planned} beyond "
                f"the preset's {planned})")
    return f"{row['n_models']} x {row['n_tasks']}"


def _noise_variance(row: dict[str, Any]) -> str:
    """A row's process-noise variance as Table 3 writes it (rows keep the std, ``noise_std``)."""
    return f"{row['noise_std'] ** 2:g}"


def markdown_table(rows: list[dict[str, Any]]) -> str:
    """The summary as a Markdown table, our numbers beside the paper's.

    The noise column gives the process-noise variance, as the paper's Table 3 subscripts do
    (``summary.json`` keeps the standard deviation, ``noise_std``).
    """
    lines = [
        "| env | method | noise variance | preset (variant) | models x tasks | ours: all "
        "| paper: all "
        "| ours: top-1 | paper: top-1 | IQM [95% CI] | oracle | no action |",
        "|---|---|---|---|---|---|---|---|---|---|---|---|",
    ]
    for r in rows:
        ci = r["iqm_ci"]
        iqm = f"{r['iqm']:.1f}" + (f" [{ci[0]:.1f}, {ci[1]:.1f}]" if ci else "")
        oracle, floor = ("-" if r.get(key) is None else f"{r[key]:.1f}"
                         for key in ("oracle_mean", "floor_mean"))
        lines.append(
            f"| {r['env']} | {r['method']} | {_noise_variance(r)} | {r['preset']} "
            f"({r['model_variant']}) | {_models_cell(r)} "
            f"| {_fmt((r['mean_all'], r['se_all']))} | {_fmt(r['paper_all'])} "
            f"| {_fmt((r['mean_top1'], r['se_top1']))} | {_fmt(r['paper_top1'])} | {iqm} "
            f"| {oracle} | {floor} |"
        )
    return "\n".join(lines) + "\n"


def _training_recipe(settings: dict[str, Any]) -> str:
    """A short description of how the models of a row were trained (from the run config)."""
    model, train = settings.get("model", {}), settings.get("train", {})
    changes = []
    if model.get("input_standardization"):
        changes.append("input standardization")
    if train.get("warmup_epochs"):
        changes.append(f"{train['warmup_epochs']}-epoch KL warm-up")
    if train.get("flush_denormals"):
        changes.append("subnormals flushed to zero")
    recipe = "paper recipe" if not changes else "paper recipe + " + " + ".join(changes)
    if not train:
        return recipe
    return (f"{recipe}; early stop after {train.get('patience')} epochs without improvement, "
            f"not before epoch {train.get('min_epochs', 0)}, at most {train.get('epochs')}")


def settings_table(rows: list[dict[str, Any]]) -> str:
    """The evaluation and training settings of every (env, preset, method) row."""
    from benchmarks.presets import TASK_STARTS

    seen: dict[tuple[str, str, str], dict[str, Any]] = {}
    for r in rows:
        if (r["method"] not in REFERENCE_METHODS
                and (r["env"], r["preset"], r["method"]) not in seen):
            seen[(r["env"], r["preset"], r["method"])] = r
    lines = [
        "| env | preset | method | episode length | plan length (replan every) "
        "| iLQR iters (first / MPC) | candidates (extreme) | kappa (Q = kappa I) | R "
        "| action bounds | data size "
        "| tasks per model (task seed) | model seeds | task starts | training |",
        "|---|---|---|---|---|---|---|---|---|---|---|---|---|---|---|",
    ]
    for (env, preset, method), row in seen.items():
        s = row["settings"]
        p = s.get("planner", {})
        registered = _registered_preset(preset)
        recipe = _training_recipe(s)
        if registered is not None and registered.restarts > 1:
            recipe += (f"; each model the best of {registered.restarts} trainings by "
                       "validation loss")
        lines.append(
            f"| {env} | {preset} | {method} | {s.get('episode_length', '-')} "
            f"| {p.get('plan_length')} ({p.get('replan_every', 1)}) "
            f"| {p.get('iterations')} / {p.get('mpc_iterations')} "
            f"| {p.get('num_candidates')} ({p.get('num_extreme', 2)}) "
            f"| {p.get('kappa')} | {p.get('r_weight')} I "
            f"| [{p.get('action_low')}, {p.get('action_high')}] "
            f"| {s.get('data', {}).get('num_samples')} "
            f"| {row['n_tasks']} ({row.get('task_seed', '-')}) | {row['seeds']} "
            f"| {TASK_STARTS.get(env, '-')} | {recipe} |"
        )
    return "\n".join(lines) + "\n"


def planner_revision_of(record: dict[str, Any]) -> int | None:
    """The planner revision a record was evaluated with (None: it planned nothing)."""
    if record.get("spec", {}).get("method") == NO_ACTION:
        return None
    return int(record.get("config", {}).get("planner_revision", 1))


def planner_tag(revision: int | None) -> str:
    """The suffix of a row label made by an older planner revision, e.g. ``" [planner r2]"``."""
    from pcc_agent.planning import PLANNER_REVISION

    if revision is None or revision == PLANNER_REVISION:
        return ""
    return f" [planner r{revision}]"


def load_records(results_dir: Path) -> list[dict[str, Any]]:
    """Every finished run record below ``results_dir``.

    Records evaluated by an older planner revision are kept, with their preset label
    suffixed by :func:`planner_tag` (``"paper-fast-long [planner r2]"``), so that no summary
    row or reference column mixes two planners; records of the current revision with other
    planner settings than the preset's are left out (the grid re-evaluates them).
    """
    from pcc_agent.planning import PLANNER_REVISION

    records = []
    for path in sorted((results_dir / "runs").rglob("*.json")):
        rec = load_finished_run(path)
        if rec is None:
            continue
        try:
            spec = RunSpec(**rec["spec"])
        except TypeError:  # a hand-made or older record without a full spec: no check
            records.append(rec)
            continue
        if not _same_recipe(rec, spec):
            print(f"Not aggregated (trained with other data, network or training settings than "
                  f"the preset's; re-run the grid to retrain it): {path}")
            continue
        revision = planner_revision_of(rec)
        if revision is not None and revision != PLANNER_REVISION:
            # Kept as history, in rows of their own: the preset label says which planner.
            records.append({**rec, "spec": {**rec["spec"], "preset": rec["spec"]["preset"]
                                            + planner_tag(revision)}})
            continue
        if not _same_planner(rec, spec):
            print(f"Not aggregated (evaluated with other planner settings than the preset's; "
                  f"re-run the grid to re-evaluate it): {path}")
            continue
        records.append(rec)
    return records


def select_restarts(
    records: Sequence[dict[str, Any]],
    presets: Iterable[ReproducePreset] = REPRODUCE_PRESETS.values(),
) -> list[dict[str, Any]]:
    """The models of every ``restarts`` preset, chosen from its trainings' records.

    Model ``m`` of (env, method, noise) exists once all of its trainings (seeds ``m + k *
    RESTART_SEED_STRIDE``) are finished; it is the training with the lowest best validation
    loss. Its record is that training's, filed under the restarts preset with seed ``m``,
    the summed training time, and every training's validation loss and control score
    (``restarts``) for the record. Trainings run with command-line overrides (filed under
    ``runs_preset + "+..."``) make the models of the overridden preset (``name + "+..."``).
    Only trainings of the preset's recipe (variant, epoch cap, patience, tasks) count.
    """
    selected = []
    for preset in presets:
        if preset.restarts <= 1:
            continue
        by_cell: dict[tuple[Any, ...], dict[int, dict[str, Any]]] = {}
        for rec in records:
            s = rec["spec"]
            filed = str(s.get("preset", ""))
            if s["method"] in REFERENCE_METHODS or not (
                    filed == preset.runs_preset or filed.startswith(preset.runs_preset + "+")):
                continue
            overrides = filed[len(preset.runs_preset):]
            if not overrides and not _is_training_of(s, preset):
                continue
            training = s["seed"] // RESTART_SEED_STRIDE
            if training >= preset.restarts:  # a training of a preset with more restarts
                continue
            cell = (preset.name + overrides, s["env_id"], s["method"], s["noise_std"],
                    s["seed"] % RESTART_SEED_STRIDE)
            by_cell.setdefault(cell, {})[training] = rec
        for (label, _, _, _, model_seed), trainings in sorted(by_cell.items()):
            if model_seed >= preset.num_models or sorted(trainings) != list(
                    range(preset.restarts)):
                continue
            losses = {k: rec.get("training", {}).get("best_validation_loss")
                      for k, rec in trainings.items()}
            if any(loss is None for loss in losses.values()):
                continue
            best = trainings[min(losses, key=lambda k: (losses[k], k))]
            selected.append({
                **best,
                "spec": {**best["spec"], "preset": label, "seed": model_seed},
                "selected_training_seed": best["spec"]["seed"],
                "train_seconds": sum(float(r["train_seconds"]) for r in trainings.values()),
                "restarts": [{"seed": r["spec"]["seed"], "best_validation_loss": losses[k],
                              "mean": r["mean"]} for k, r in sorted(trainings.items())],
            })
    return selected


def _is_training_of(spec: dict[str, Any], preset: ReproducePreset) -> bool:
    """Whether a run record's spec follows ``preset``'s recipe (no override)."""
    return (
        spec.get("model_variant") == preset.model_variant
        and spec.get("num_tasks", preset.num_tasks) == preset.num_tasks
        and spec.get("task_seed", preset.task_seed) == preset.task_seed
        and spec.get("max_epochs") == preset.max_epochs
        and spec.get("patience") == preset.patience
        and spec.get("flush_denormals") == preset.flush_denormals
        and spec.get("num_samples") == preset.num_samples.get(spec.get("env_id", ""))
    )


def write_summary(results_dir: Path) -> list[dict[str, Any]]:
    """Aggregate the run files into summary.json, summary.md and a bar chart."""
    records = load_records(results_dir)
    rows = aggregate(records + select_restarts(records))
    if not rows:
        print("No finished runs to aggregate.")
        return rows
    _write_json_atomic(results_dir / "summary.json", rows)
    sections = []
    for table in sorted({paper_table(r) for r in rows}):
        sections.append(f"## {table}\n\n" + markdown_table(
            [r for r in rows if paper_table(r) == table]))
    text = (
        "# Percentage of steps in goal (true state), ours beside the paper's\n\n"
        "Mean ± standard error over all tasks of all models (`all`) and over the best model's "
        "tasks (`top-1`). The paper's LaneKeeping numbers are its TORCS domain. "
        "`k of N x M (reduced grid)`: only k of the preset's N models have been run. A preset "
        "name `base+field=value` marks runs with command-line overrides of the preset. "
        "`oracle`: the agents' iLQR-MPC settings (Evaluation settings below) on the true "
        "state and dynamics (the ceiling of those settings); `no action`: zero actions on the "
        "same tasks (the floor; above 0 where starts lie in the goal region). "
        "`[planner rN]`: rows evaluated by an older planner revision, with that revision's "
        "oracle; they are history, not comparable with the current rows.\n\n"
        + "\n".join(sections)
        + "\n## Evaluation settings\n\n"
        + settings_table(rows)
    )
    _write_text_atomic(results_dir / "summary.md", text)
    _bar_chart(rows, results_dir / "summary.png")
    print(text)
    print(f"Wrote {results_dir / 'summary.json'}, summary.md and summary.png")
    return rows


def _bar_chart(rows: list[dict[str, Any]], path: Path) -> None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    rows = [r for r in rows if r["method"] not in REFERENCE_METHODS]
    if not rows:
        return
    labels = [f"{r['env'].split('/')[1]}\n{r['method']}\n{r['preset']}"
              + (f"\nnoise variance {_noise_variance(r)}" if r["noise_std"] else "")
              for r in rows]
    x = np.arange(len(rows))
    fig, ax = plt.subplots(figsize=(max(6, 1.1 * len(rows)), 4))
    ax.bar(
        x - 0.2,
        [r["mean_all"] for r in rows],
        0.4,
        yerr=[np.nan if r["se_all"] is None else r["se_all"] for r in rows],
        label="ours (all models)",
        capsize=3,
    )
    paper = [r["paper_all"][0] if r["paper_all"] else np.nan for r in rows]
    paper_se = [r["paper_all"][1] if r["paper_all"] else 0 for r in rows]
    ax.bar(x + 0.2, paper, 0.4, yerr=paper_se, label="paper (all models)", capsize=3)
    for xi, r in zip(x, rows):
        if r["oracle_mean"] is not None:
            ax.hlines(r["oracle_mean"], xi - 0.45, xi + 0.45, colors="k", linestyles="--")
        if r.get("floor_mean"):  # a floor of 0 would only hide the axis
            ax.hlines(r["floor_mean"], xi - 0.45, xi + 0.45, colors="0.4", linestyles=":")
    ax.set_xticks(x, labels, fontsize=7)
    ax.set_ylabel("% of steps in goal")
    ax.set_title("Control from pixels (dashed: oracle on the true state; dotted: zero actions)")
    ax.legend()
    fig.tight_layout()
    _save_figure_atomic(fig, path)
    plt.close(fig)


@dataclass(frozen=True)
class CostEstimate:
    """Compute time of a grid, in CPU-core seconds (divide by the workers for wall time)."""

    expected_seconds: float
    upper_seconds: float
    runs_from_records: int  # how many runs took their figure from finished runs of their kind


def _cost_key(spec: RunSpec, with_method: bool = True) -> tuple[Any, ...]:
    """Runs with the same key train the same kind of model for the same epoch budget."""
    budget = (spec.env_id, spec.model_variant, spec.num_samples, spec.max_epochs, spec.patience,
              spec.flush_denormals)
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
    ``benchmarks/results/train_speed.json`` (1 thread), or a conservative per-sample guess.
    The expected figure uses, where there are any, the median time (training plus control)
    of ``finished`` run records of the same kind (env, method, variant, data size, epoch cap,
    patience), else of the other methods' models of that kind: early stopping usually ends a
    run long before the cap. The upper bound of a run is never below the slowest finished
    run of its kind.
    """
    measured: dict[tuple[str, str, str], float] = {}
    speed_file = Path(__file__).resolve().parent / "results" / "train_speed.json"
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


# ---------------------------------------------------------------------------- command line
def _positive_int(text: str) -> int:
    value = int(text)
    if value < 1:
        raise argparse.ArgumentTypeError(f"must be at least 1, got {value}")
    return value


def _non_negative_float(text: str) -> float:
    value = float(text)
    if not value >= 0:
        raise argparse.ArgumentTypeError(f"must be >= 0, got {text}")
    return value


def _known_envs() -> list[str]:
    from pcc_agent.presets import PRESETS

    return sorted(PRESETS)


def build_parser() -> argparse.ArgumentParser:
    """The command-line interface."""
    parser = argparse.ArgumentParser(
        prog="pcc reproduce",
        description="Reproduce the PCC paper's tables: N models x M control tasks per "
        "(env, method), resumable, aggregated into summary.json / summary.md.",
    )
    parser.add_argument("--preset", default="quick", choices=sorted(REPRODUCE_PRESETS))
    parser.add_argument("--envs", nargs="+", choices=_known_envs(), metavar="ENV",
                        help="Subset of the preset's env ids (any of: %(choices)s).")
    parser.add_argument("--methods", nargs="+", choices=ALL_METHODS, metavar="METHOD",
                        help="Subset / override of the methods (any of: %(choices)s).")
    parser.add_argument("--num-models", type=_positive_int,
                        help="Override the number of models.")
    parser.add_argument(
        "--seeds", type=int, nargs="+",
        help="Run only these model seeds (e.g. to split a grid over machines, or to fill in "
        "missing models); overrides --num-models.",
    )
    parser.add_argument("--num-tasks", type=_positive_int,
                        help="Override the number of tasks per model.")
    parser.add_argument("--max-epochs", type=_positive_int,
                        help="Override the training epoch cap.")
    parser.add_argument(
        "--patience", type=int,
        help="Override the early-stopping patience (epochs without validation improvement).",
    )
    parser.add_argument(
        "--flush-denormals", action="store_true",
        help="Train with subnormal floats flushed to zero: many times faster on Intel CPUs "
        "for image models whose weight decay drives unlit pixels' weights subnormal "
        "(Pendulum); other weights than without it, so its runs and rows are labelled.",
    )
    noise = parser.add_mutually_exclusive_group()
    noise.add_argument(
        "--noise", type=_non_negative_float, nargs="+", metavar="STD",
        help="Override the process-noise levels, as standard deviations (0: deterministic).",
    )
    noise.add_argument(
        "--noise-variance", type=_non_negative_float, nargs="+", metavar="VAR",
        help="Override the process-noise levels, as variances, the way the paper's Table 3 "
        "labels them: '--noise-variance 2' is Planar_2 (standard deviation sqrt(2)).",
    )
    parser.add_argument("--no-oracle", action="store_true",
                        help="Skip the oracle ceiling (and the floor, unless --floor).")
    parser.add_argument("--no-floor", dest="floor", action="store_false", default=None,
                        help="Skip the no-action floor (zero actions on the same tasks).")
    parser.add_argument("--floor", dest="floor", action="store_true",
                        help="Run the no-action floor even with --no-oracle.")
    parser.add_argument("--references-only", action="store_true",
                        help="Run only the oracle (ceiling) and no-action (floor) rows: no "
                             "training, minutes on a CPU.")
    parser.add_argument("--results-dir", type=Path, default=DEFAULT_RESULTS_DIR)
    parser.add_argument(
        "--data-dir",
        default=None,
        help="Dataset cache (default: PCC_DATA_DIR or ~/.cache/pcc_control/datasets).",
    )
    parser.add_argument(
        "--workers",
        type=_positive_int,
        default=os.cpu_count() or 1,
        help="Parallel runs (one core each) for the process backend.",
    )
    parser.add_argument("--backend", choices=("process", "ray"), default="process")
    parser.add_argument("--ray-address", default=None, help="Ray cluster address (e.g. 'auto').")
    parser.add_argument(
        "--ray-gpus-per-task", type=_non_negative_float, default=0.0,
        help="GPUs Ray reserves for each run (e.g. 1, or 0.25 to share a GPU among four "
        "runs); with 0 (default) Ray hides the GPUs from the runs, which then train on CPU.",
    )
    parser.add_argument(
        "--aggregate-only",
        action="store_true",
        help="Only rebuild the summary from existing run files.",
    )
    parser.add_argument(
        "--status",
        action="store_true",
        help="Only print where each run of the grid stands (done, training at epoch E with "
        "its best validation loss, or not started), e.g. while the grid runs elsewhere.",
    )
    return parser


def main(argv: Sequence[str] | None = None) -> int:
    """Entry point of ``python -m benchmarks.reproduce`` and ``pcc reproduce``."""
    args = build_parser().parse_args(argv)
    results_dir: Path = args.results_dir
    if not args.aggregate_only:
        preset = REPRODUCE_PRESETS[args.preset]
        changes: dict[str, Any] = {}
        if args.envs:
            changes["envs"] = tuple(args.envs)
        if args.methods:
            changes["methods"] = tuple(args.methods)
        if args.num_models is not None:
            if args.num_models > RESTART_SEED_STRIDE:
                raise SystemExit(f"--num-models must be at most {RESTART_SEED_STRIDE}, got "
                                 f"{args.num_models}.")
            changes["num_models"] = args.num_models
        if args.seeds:
            if min(args.seeds) < 0:
                raise SystemExit(f"--seeds must be non-negative, got {args.seeds}.")
            if max(args.seeds) >= RESTART_SEED_STRIDE:
                raise SystemExit(f"--seeds must be below {RESTART_SEED_STRIDE} (larger seeds "
                                 f"are the restart trainings of a restarts preset), got "
                                 f"{args.seeds}.")
            changes["model_seeds"] = tuple(sorted(set(args.seeds)))
        if args.num_tasks is not None:
            changes["num_tasks"] = args.num_tasks
        if args.max_epochs is not None:
            changes["max_epochs"] = args.max_epochs
        if args.patience is not None:
            if args.patience < 0:
                raise SystemExit(f"--patience must be >= 0, got {args.patience}.")
            changes["patience"] = args.patience
        if args.flush_denormals:
            changes["flush_denormals"] = True
        noise_stds = args.noise or [variance**0.5 for variance in args.noise_variance or ()]
        if noise_stds:
            changes["noise_levels"] = tuple(noise_stds)
            changes["env_noise_levels"] = {}
        preset = preset.override(**changes)
        runs = expand_grid(preset, include_oracle=not args.no_oracle, include_floor=args.floor)
        if args.references_only:
            runs = [run for run in runs if run.method in REFERENCE_METHODS]
            if not runs:
                raise SystemExit("--references-only with --no-oracle --no-floor leaves no run.")
        if args.status:
            print("\n".join(training_progress(results_dir, run) for run in runs))
        pending = [r for r in runs if load_finished_run(results_dir / r.relative_path, r) is None]
        cost = estimate_cost(pending, load_records(results_dir) if pending else ())
        workers = max(1, args.workers)
        print(
            f"Preset {preset.name!r}: {len(runs)} runs, {len(pending)} to run, estimated "
            f"{cost.expected_seconds / 3600 / workers:.1f} h on {args.workers} CPU worker(s) "
            f"({cost.runs_from_records} of {len(pending)} from finished runs of the same kind; "
            f"at most {cost.upper_seconds / 3600 / workers:.1f} h if every model trains to its "
            "epoch cap; CNN 'paper' models want a GPU)."
        )
        if args.status:
            return 0
        if preset.name != args.preset:
            print(f"The overrides change what the runs compute: their files and rows are "
                  f"labelled {preset.name!r}.")
        # SIGTERM (kill, a batch scheduler's stop) ends the grid like Ctrl-C does.
        signal.signal(signal.SIGTERM, _interrupt)
        try:
            run_grid(runs, results_dir, args.workers, args.backend, args.ray_address,
                     args.data_dir, args.ray_gpus_per_task)
        except KeyboardInterrupt:
            print("Interrupted: finished runs and training checkpoints are kept; run the same "
                  "command again to continue.", file=sys.stderr)
            return 130
    write_summary(results_dir)
    return 0


if __name__ == "__main__":
    sys.exit(main())
