"""Run records of the reproduction grid: what a run is, where its files live, if it counts.

A run (:class:`RunSpec`) is one cell of the grid: one model, or one reference controller
(oracle, no action), and its control tasks. Its record is one JSON file below the results
directory; :func:`load_finished_run` refuses a partial record or one that is stale (written
for other settings, another planner revision or another training recipe than the preset's).
"""

from __future__ import annotations

import json
import os
import platform
from dataclasses import asdict, dataclass, replace
from pathlib import Path
from typing import Any

from pcc_bench.paths import DEFAULT_RESULTS_ROOT

#: Where ``pcc reproduce`` writes by default.
DEFAULT_RESULTS_DIR = DEFAULT_RESULTS_ROOT / "reproduce"
#: The format number of a run record.
RESULT_FORMAT = 1
#: The true-dynamics controller with the agents' planner settings (the horizon may be the
#: oracle's own, pcc_agent.oracle.OracleConfig.plan_length): the ceiling.
ORACLE = "oracle"
#: The controller that applies zero actions: the floor beside the oracle's ceiling. Where a
#: start lies near the goal (CartPole) doing nothing already scores, and a learned controller
#: is only useful above it.
NO_ACTION = "no-action"
#: Controllers that train nothing: one run per (env, noise level), no data set, no checkpoint.
REFERENCE_METHODS = (ORACLE, NO_ACTION)


@dataclass(frozen=True)
class RunSpec:
    """One cell of the grid: one model (or a reference controller) and its control tasks.

    ``validation_tasks``: when set, the trained model also runs that many validation tasks
    (``pcc_agent.evaluation.VALIDATION_TASK_SEED``), recorded as ``validation``; the presets
    with spare trainings keep their models by that score. ``keep_best_control_every``: the
    training scores control on those tasks every so many epochs and keeps the best weights
    (``ReproducePreset.keep_best_control_every``). The other optional fields are
    command-line overrides of the preset (None: the preset's value).
    """

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
    learning_rate: float | None = None
    prediction_horizon: int | None = None
    plan_length: int | None = None
    validation_tasks: int | None = None
    keep_best_control_every: int | None = None

    @property
    def env_kwargs(self) -> dict[str, Any]:
        """The ``gym.make`` arguments of the run's env: its process noise, where there is any."""
        return {"noise_std": self.noise_std} if self.noise_std else {}

    @property
    def relative_path(self) -> Path:
        """Where the run's JSON lives below the results directory."""
        env = self.env_id.replace("/", "_")
        noise = f"noise{self.noise_std!r}"
        return Path("runs") / self.preset / env / noise / self.method / f"seed{self.seed}.json"


def cpu_name() -> str:
    """The CPU model from /proc/cpuinfo (Linux), else platform.processor()."""
    try:
        for line in Path("/proc/cpuinfo").read_text().splitlines():
            if line.startswith("model name"):
                return line.split(":", 1)[1].strip()
    except OSError:
        pass
    return platform.processor()


def machine_info() -> dict[str, Any]:
    """The host, its CPU model, the SIMD kernels torch picked on it and the CPU's SIMD features.

    Kernels for different instruction sets round differently (oneDNN's convolutions limited
    to AVX2 train other SAC weights than its AVX-512 ones), so bit-identical reruns are only
    expected on hosts with the same features.
    """
    import torch

    from pcc_agent.training import simd_flags

    return {
        "platform": platform.platform(),
        "cpu": cpu_name(),
        "cpu_count": os.cpu_count(),
        "torch_cpu_capability": torch.backends.cpu.get_cpu_capability(),
        "simd_flags": list(simd_flags()),
    }


def checkpoint_path(results_dir: str | Path, spec: RunSpec) -> Path:
    """Where a run's trained agent is saved (``PCCAgent.load`` reads it back)."""
    return Path(results_dir) / "checkpoints" / spec.relative_path.with_suffix(".pt")


def weights_path(results_dir: str | Path, spec: RunSpec) -> Path:
    """Where a run's float16 weights are kept: the agent its record was evaluated with.

    Small enough to commit beside the record (``results/<dir>/weights/...``), so that an
    evaluation change re-runs without retraining and reproduces the record exactly.
    """
    return Path(results_dir) / "weights" / spec.relative_path.with_suffix(".safetensors")


def training_checkpoint_path(results_dir: str | Path, spec: RunSpec) -> Path:
    """Where a run's training in progress is checkpointed (removed once the run is done)."""
    return checkpoint_path(results_dir, spec).with_suffix(".training.pt")


def control_selection_path(results_dir: str | Path, spec: RunSpec) -> Path:
    """Where a run's control scores and best weights so far are kept while it trains.

    Used with ``keep_best_control_every``; removed with the training checkpoint.
    """
    return checkpoint_path(results_dir, spec).with_suffix(".control.pt")


@dataclass(frozen=True)
class ResumePoint:
    """Where an interrupted training of a run continues: its epoch and the seconds spent."""

    epoch: int
    seconds: float


def resume_point(
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
    remove_training_checkpoint(path)
    return None


def remove_training_checkpoint(path: Path) -> None:
    """Delete a training checkpoint and the JSON copy of its configuration beside it."""
    path.unlink(missing_ok=True)
    path.with_suffix(".json").unlink(missing_ok=True)


def training_progress(results_dir: str | Path, spec: RunSpec) -> str:
    """One line on where a run stands: done, to re-evaluate, training or not started.

    For a training in progress: its epoch, epoch cap and best validation loss so far. Reads
    the run's record and its training checkpoint; changes nothing.
    """
    from pcc_agent.checkpoint import CheckpointError, load_checkpoint
    from pcc_agent.presets import get_preset
    from pcc_bench.weights import record_to_reevaluate

    label = f"{spec.env_id} {spec.method} noise={spec.noise_std} seed={spec.seed}"
    record = load_finished_run(Path(results_dir) / spec.relative_path, spec)
    if record is not None:
        return f"{label}: done, {record['mean']:.1f}% of steps in goal"
    if record_to_reevaluate(Path(results_dir), spec) is not None:
        return (f"{label}: trained, its control tasks to run again from the saved weights "
                "(evaluated with other planner settings)")
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


def stop_reason_of(record: dict[str, Any]) -> str | None:
    """Why a run's training ended (``pcc_agent.training.STOP_REASONS``), or None.

    None: the run trained nothing (oracle, no action) or its record does not say.

    Records written before ``stop_reason`` was stored (the committed ones among them) have it
    inferred from their ``converged`` and ``diverged`` flags and their message.
    """
    training = record.get("training")
    if not isinstance(training, dict) or not training:
        return None
    if training.get("stop_reason"):
        return str(training["stop_reason"])
    message = str(training.get("message", ""))
    if training.get("diverged"):
        return "diverged"
    if training.get("converged"):
        return "early_stopping"
    if message.startswith("Reached the maximum"):
        return "epoch_cap"
    if "callback" in message:
        return "callback"
    return None


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
    if spec is not None and not same_spec(record.get("spec"), spec):
        return None
    if spec is not None and not same_planner(record, spec):
        return None
    if spec is not None and not same_recipe(record, spec):
        return None
    return record


def same_spec(stored: Any, spec: RunSpec) -> bool:
    """Whether a record's spec is ``spec``; overrides added later (absent) count as unset."""
    if not isinstance(stored, dict):
        return False
    expected = asdict(spec)
    unset = {key: None for key, value in expected.items() if value is None}
    return {**unset, **stored} == expected


def preset_for(spec: RunSpec) -> Any:
    """The env preset of a run, with the run's overrides applied."""
    from pcc_agent.presets import get_preset

    preset = get_preset(spec.env_id, spec.model_variant)
    overrides = {"epochs": spec.max_epochs, "patience": spec.patience, "lr": spec.learning_rate,
                 "prediction_horizon": spec.prediction_horizon}
    # Flushing is off unless the run asks for it: the library's default turned on after most
    # committed runs were made without it, and a grid's recipe must not change under them.
    preset = preset.with_training(flush_denormals=bool(spec.flush_denormals),
                                  **{k: v for k, v in overrides.items() if v is not None})
    if spec.num_samples is not None:
        preset = replace(preset, data=replace(preset.data, num_samples=spec.num_samples))
    if spec.plan_length is not None:
        preset = replace(preset, planner=replace(preset.planner, plan_length=spec.plan_length))
    return replace(preset, data=replace(preset.data, noise_std=spec.noise_std))


def same_planner(record: dict[str, Any], spec: RunSpec) -> bool:
    """Whether a record was evaluated by this planner revision with the preset's settings.

    Records without a revision were evaluated by revision 1. Oracle records are compared
    with the env's current ``ORACLE_CONFIGS`` entry and the oracle's planner (the agents'
    settings, with the oracle's own horizon where it has one); the horizon is judged by the
    planner the record ran, so records written before ``OracleConfig`` had ``plan_length``
    stay valid where they ran that horizon. No-action records plan nothing and always match.
    """
    from pcc_agent.planning import PLANNER_REVISION

    if spec.method == NO_ACTION:  # plans nothing
        return True
    config = record.get("config", {})
    if config.get("planner_revision", 1) != PLANNER_REVISION:
        return False
    planner = preset_for(spec).planner
    if spec.method == ORACLE:
        from pcc_agent.oracle import OracleConfig, oracle_config_for, oracle_planner_for

        wanted_oracle = oracle_config_for(spec.env_id)
        try:
            recorded = OracleConfig(**config.get("oracle", {}))
        except (TypeError, ValueError):
            return False
        # The horizon is compared below, in the planner the oracle ran.
        if (_as_json(asdict(replace(recorded, plan_length=None)))
                != _as_json(asdict(replace(wanted_oracle, plan_length=None)))):
            return False
        planner = oracle_planner_for(spec.env_id, wanted_oracle)
    return config.get("planner") == _as_json(asdict(planner))


def _as_json(value: Any) -> Any:
    """``value`` as it reads back from a JSON record (tuples become lists)."""
    return json.loads(json.dumps(value))


def same_recipe(record: dict[str, Any], spec: RunSpec) -> bool:
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
    preset = preset_for(spec)
    try:
        train = TrainConfig.from_dict(config["train"])
        model = ModelConfig.from_dict(config["model"])
        data = DataConfig(**config["data"])
    except (KeyError, TypeError, ValueError):
        return False
    # The data's noise is the spec's (checked by same_spec). Records written before the
    # agent reported it carry the unused preset value 0.0 there, so it is not compared.
    return (replace(train, seed=preset.train.seed) == preset.train
            and model == model_config_for_method(preset.model, spec.method)
            and replace(data, noise_std=preset.data.noise_std) == preset.data)


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
        if not same_recipe(rec, spec):
            print(f"Not aggregated (trained with other data, network or training settings than "
                  f"the preset's; re-run the grid to retrain it): {path}")
            continue
        revision = planner_revision_of(rec)
        if revision is not None and revision != PLANNER_REVISION:
            # Kept as history, in rows of their own: the preset label says which planner.
            records.append({**rec, "spec": {**rec["spec"], "preset": rec["spec"]["preset"]
                                            + planner_tag(revision)}})
            continue
        if not same_planner(rec, spec):
            print(f"Not aggregated (evaluated with other planner settings than the preset's; "
                  f"re-run the grid to re-evaluate it): {path}")
            continue
        records.append(rec)
    return records
