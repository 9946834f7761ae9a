"""Execute one run of the grid.

Train (or resume) a model, run its control tasks and write its record; or re-evaluate a saved
model when only the planner settings changed.
"""

from __future__ import annotations

import sys
import time
from dataclasses import asdict, replace
from pathlib import Path
from typing import Any

from pcc_agent.io import atomic_write_json, versions
from pcc_bench.presets import LATENT_MAP_ENVS, LATENT_MAP_MODELS
from pcc_bench.records import (
    NO_ACTION,
    ORACLE,
    REFERENCE_METHODS,
    RESULT_FORMAT,
    RunSpec,
    checkpoint_path,
    control_selection_path,
    load_finished_run,
    machine_info,
    preset_for,
    remove_training_checkpoint,
    resume_point,
    stop_reason_of,
    training_checkpoint_path,
)
from pcc_bench.weights import record_to_reevaluate, save_half_weights, saved_agent_path

#: Epochs between a run's training checkpoints: a run cut short (Ctrl-C, a crash, the end of
#: a working session) resumes from its last one; at most this many epochs are redone.
TRAIN_CHECKPOINT_EVERY = 5


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

    env_kwargs = spec.env_kwargs
    seeds = task_seeds(spec.task_seed, spec.num_tasks)
    trained = record_to_reevaluate(Path(results_dir), spec)
    if trained is not None:
        return _reevaluate(trained, spec, Path(results_dir), seeds, env_kwargs)
    record: dict[str, Any] = {
        "format": RESULT_FORMAT,
        "spec": asdict(spec),
        "versions": versions(),
        "machine": machine_info(),
        "command": " ".join(sys.argv),
    }
    start = time.perf_counter()
    if spec.method == ORACLE:
        from pcc_agent.oracle import OracleController, oracle_config_for, oracle_planner_for

        config = oracle_config_for(spec.env_id)
        planner = oracle_planner_for(spec.env_id, config)
        record["config"] = {"oracle": asdict(config), "planner": asdict(planner),
                            "planner_revision": PLANNER_REVISION}
        record["train_seconds"] = 0.0
        evaluation_start = time.perf_counter()
        evaluation = evaluate_control(
            lambda env: OracleController(env, config, planner), spec.env_id, seeds, env_kwargs
        )
    elif spec.method == NO_ACTION:
        from pcc_bench.zero_action import ZeroActionPolicy

        record["config"] = {"no_action": True}
        record["train_seconds"] = 0.0
        evaluation_start = time.perf_counter()
        evaluation = evaluate_control(
            lambda env: ZeroActionPolicy(env.action_space), spec.env_id, seeds, env_kwargs
        )
    else:
        from pcc_agent.agent import PCCAgent

        preset = preset_for(spec)
        agent = PCCAgent(
            spec.env_id,
            method=spec.method,
            preset=preset,
            seed=spec.seed,
            env_kwargs=env_kwargs,
            data_cache_dir=data_dir,
        )
        in_progress = training_checkpoint_path(results_dir, spec)
        resumed = resume_point(in_progress, replace(preset.train, seed=spec.seed),
                                agent.model.architecture())
        selection = _control_selection(spec, results_dir, env_kwargs)
        agent.learn(progress_bar=False, checkpoint_path=in_progress, callback=selection,
                    resume=resumed is not None, checkpoint_every=TRAIN_CHECKPOINT_EVERY)
        record["train_seconds"] = time.perf_counter() - start
        if resumed is not None:  # add the epochs trained before the interruption
            record["train_seconds"] += resumed.seconds
            record["training_resumed_at_epoch"] = resumed.epoch
        # The trained agent in float32 (not committed), and in float16 (small enough to
        # commit): the record evaluates the float16 one, so loading its file reproduces it.
        agent.save(checkpoint_path(results_dir, spec))
        record["config"] = agent.config_dict()
        record["training"] = agent.train_summary()
        if selection is not None:
            record["training"]["control_selection"] = {
                "every": spec.keep_best_control_every, "tasks": spec.validation_tasks,
                "history": [list(item) for item in selection.history],
                "kept_epoch": selection.best_epoch, "kept_score": selection.best_score}
        agent, record["weights"] = save_half_weights(agent, results_dir, spec)
        evaluation_start = time.perf_counter()
        evaluation = evaluate_control(agent, spec.env_id, seeds, env_kwargs)
        if spec.validation_tasks:
            record["validation"] = validation_control(agent, spec, env_kwargs)
        _maybe_plot_latent_map(agent, spec, Path(results_dir))
    record["eval_seconds"] = time.perf_counter() - evaluation_start
    record["task_seeds"] = seeds
    record["percentages"] = [t.percent_in_goal for t in evaluation.tasks]
    record["tasks"] = [t.to_dict() for t in evaluation.tasks]
    record["mean"] = evaluation.mean
    record["status"] = "done"
    atomic_write_json(path, record)
    if spec.method not in REFERENCE_METHODS:  # the training is complete, its record written
        remove_training_checkpoint(training_checkpoint_path(results_dir, spec))
        control_selection_path(results_dir, spec).unlink(missing_ok=True)
    return record


def _control_selection(spec: RunSpec, results_dir: str | Path,
                       env_kwargs: dict[str, Any]) -> Any:
    """The run's :class:`~pcc_agent.callbacks.KeepBestControl`, or None.

    None when the run keeps the lowest-validation-loss weights. It scores on the validation
    tasks, its state checkpointed beside the training's.
    """
    if not spec.keep_best_control_every:
        return None
    from pcc_agent.callbacks import KeepBestControl, validation_task_score

    assert spec.validation_tasks
    every = spec.keep_best_control_every
    return KeepBestControl(validation_task_score(spec.env_id, spec.validation_tasks, env_kwargs),
                           every=every, start=every,
                           state_path=control_selection_path(results_dir, spec))


def validation_control(agent: Any, spec: RunSpec, env_kwargs: dict[str, Any]) -> dict[str, Any]:
    """% in goal on the run's validation tasks (task seed 2021): the score trainings are kept by.

    Run after the evaluation tasks, so those are planned exactly as without validation.
    """
    from pcc_agent.evaluation import evaluate_on_validation_tasks

    assert spec.validation_tasks
    evaluation = evaluate_on_validation_tasks(agent, spec.env_id, spec.validation_tasks,
                                              env_kwargs)
    return {"task_seeds": [t.seed for t in evaluation.tasks],
            "percentages": [t.percent_in_goal for t in evaluation.tasks],
            "mean": evaluation.mean}


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

    saved = saved_agent_path(record, results_dir, spec)
    assert saved is not None  # checked by the caller
    agent = PCCAgent.load(saved)
    planner = preset_for(spec).planner
    agent.set_planner(planner)
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
    if spec.validation_tasks:
        record["validation"] = validation_control(agent, spec, env_kwargs)
    record["reevaluated"] = True
    record["command"] = " ".join(sys.argv)
    atomic_write_json(results_dir / spec.relative_path, record)
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


def training_outcome(record: dict[str, Any]) -> str:
    """Where a run's training stopped, briefly; empty for a run that trained nothing.

    E.g. ``"250 epochs, the cap"`` or ``"early stop at epoch 209, best 109"``.

    The runs train without a progress bar (it would garble the grid's), so this is where the
    grid says why each training stopped; the record's ``training`` has the full line.
    """
    training = record.get("training") or {}
    epochs, best = training.get("epochs"), training.get("best_epoch")
    reason = stop_reason_of(record)
    if reason is None or epochs is None:
        return ""
    return {
        "epoch_cap": f"{epochs} epochs, the cap",
        "early_stopping": f"early stop at epoch {epochs}, best {best}",
        "diverged": f"diverged after epoch {epochs}",
        "callback": f"stopped by a callback at epoch {epochs}",
    }.get(reason, f"{epochs} epochs, {reason}")


def report_line(i: int, n: int, record: dict[str, Any]) -> str:
    spec = record["spec"]
    outcome = training_outcome(record)
    done = "already finished" if record.get("skipped") else (
        f"train {record['train_seconds']:.0f}s{f': {outcome};' if outcome else ','} "
        f"control {record['eval_seconds']:.0f}s")
    return (
        f"[{i}/{n}] {spec['env_id']} {spec['method']} noise={spec['noise_std']} "
        f"seed={spec['seed']}: {record['mean']:.1f}% of steps in goal ({done})"
    )
