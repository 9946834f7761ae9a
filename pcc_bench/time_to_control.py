r"""Time to control: percentage of steps in goal against minutes of training on this CPU.

The headline figure of training speed (issue #38). Each model trains once, on one CPU thread,
with the preset's data, networks and recipe; whenever its wall-clock training time (data
collection included) passes one of ``--minutes``, the weights a user would keep if they
stopped there (those of the best validation loss so far, as the trainer keeps) are set aside.
Afterwards every kept model runs the control tasks with its domain's planner. A row is
``(env, method, train_minutes)`` with the all-model mean over ``n_models`` models x the tasks.

With ``--keep-best-control N`` a model is also scored every ``N`` epochs on 10 validation
tasks (task seed 2021, never the evaluation tasks), as the rows' trainings are, and a mark
keeps the best-scoring weights so far instead (the lowest-loss ones before the first score).
The scoring's time is training time: it counts toward the minutes.

Training stops at the last mark, or earlier by the preset's early stopping: a model that
stopped before a mark counts at that mark with its final weights (``stopped_early`` in its
record). Models train in parallel, one per worker process and one torch thread each
(``--workers 2`` uses both cores of a 2-core machine: measured faster than one two-thread
training of these small models). Minutes are this machine's: the JSON keeps the CPU model.

Every model's record is written to ``--results-dir`` as soon as it is evaluated, and a run
that is started again skips the models already done (resumable across sessions).

Usage:
    python -m pcc_bench.time_to_control --envs pcc/Planar-v0 --methods pcc e2c \
        --seeds 0 1 2 --minutes 2 5 10 15 --workers 2
    python -m pcc_bench.time_to_control --envs pcc/CartPole-v1 --methods pcc --variant motion \
        --seeds 0 1 2 --minutes 5 10 20 30 --keep-best-control 5 --workers 2
"""

from __future__ import annotations

import argparse
import copy
import json
import math
import sys
import time
from collections.abc import Sequence
from dataclasses import replace
from pathlib import Path
from typing import Any

import numpy as np

from pcc_agent.io import atomic_save_figure, atomic_write_json
from pcc_bench.arguments import command_parser
from pcc_bench.executors import make_executor
from pcc_bench.paths import DEFAULT_RESULTS_ROOT
from pcc_bench.presets import CONTROL_SELECTION_TASKS
from pcc_bench.records import cpu_name

#: Task seed of the evaluation tasks (the paper's protocol; never used to choose a recipe).
EVALUATION_TASK_SEED = 2020
DEFAULT_MINUTES = (2.0, 5.0, 10.0, 15.0)
DEFAULT_RESULTS_DIR = DEFAULT_RESULTS_ROOT / "time_to_control"


def recipe_label(variant: str, lr: float | None, keep_best_control: int | None = None,
                 prediction_horizon: int | None = None, plan_length: int | None = None) -> str:
    """The preset variant with its overrides (``+lr=``, ``+prediction_horizon=``, ...)."""
    label = variant if lr is None else f"{variant}+lr={lr:g}"
    if prediction_horizon:
        label += f"+prediction_horizon={prediction_horizon}"
    if plan_length:
        label += f"+plan_length={plan_length}"
    return label if not keep_best_control else f"{label}+keep_best_control={keep_best_control}"


def record_path(results_dir: Path, env_id: str, method: str, recipe: str, seed: int,
                task_seed: int) -> Path:
    """Where one model's record lives."""
    name = env_id.split("/")[-1]
    return results_dir / name / f"{method}_{recipe}_tasks{task_seed}_seed{seed}.json"


def train_and_evaluate(env_id: str, method: str, variant: str, seed: int,
                       minutes: Sequence[float], max_epochs: int, patience: int,
                       num_tasks: int, task_seed: int, flush_denormals: bool,
                       lr: float | None = None,
                       keep_best_control: int | None = None,
                       prediction_horizon: int | None = None,
                       plan_length: int | None = None) -> dict[str, Any]:
    """Train one model, keep its best weights at each minute mark, evaluate each of them.

    Best: of the lowest validation loss, or with ``keep_best_control`` (epochs between
    scores) of the best validation-task control score so far. ``prediction_horizon``: train
    with the multi-step prediction term (``TrainConfig.prediction_horizon``; None: the
    preset's); ``plan_length``: the agent's planning horizon (None: the env's).
    """
    import torch

    from pcc_agent.agent import PCCAgent
    from pcc_agent.callbacks import KeepBestControl, validation_task_score
    from pcc_agent.evaluation import evaluate_control, task_seeds
    from pcc_agent.presets import get_preset

    torch.set_num_threads(1)
    preset = get_preset(env_id, variant)
    train = replace(preset.train, epochs=max_epochs, patience=patience,
                    flush_denormals=flush_denormals, lr=preset.train.lr if lr is None else lr,
                    prediction_horizon=prediction_horizon or preset.train.prediction_horizon)
    planner = preset.planner if plan_length is None else replace(preset.planner,
                                                                 plan_length=plan_length)
    preset = replace(preset, train=train, planner=planner)
    marks = sorted(float(m) for m in minutes)
    start = time.perf_counter()
    agent = PCCAgent(env_id, method=method, preset=preset, seed=seed, device="cpu")
    best = {"loss": math.inf, "epoch": 0, "state": copy.deepcopy(agent.model.state_dict())}
    kept: list[dict[str, Any]] = []
    val_losses: dict[int, float] = {}  # per epoch: the validation loss of control-kept weights
    keep = None if not keep_best_control else KeepBestControl(
        validation_task_score(env_id, CONTROL_SELECTION_TASKS), every=keep_best_control,
        start=keep_best_control)

    def mark_of(epoch: int, state: Any, stopped_early: bool,
                control_epoch: int | None) -> dict[str, Any]:
        """The next mark: the lowest-loss weights' facts, or those of ``control_epoch``."""
        mark = {"minutes": marks[len(kept)], "epoch": epoch, "best_epoch": best["epoch"],
                "val_loss": best["loss"], "state": state, "stopped_early": stopped_early}
        if keep is None:
            return mark
        mark["selected_by"] = "loss"
        if keep.best_score is not None:
            mark["control_score"] = keep.best_score
        if control_epoch is not None:
            mark.update(selected_by="control", best_epoch=control_epoch,
                        val_loss=val_losses[control_epoch])
        return mark

    def on_epoch(locals_: dict[str, Any], _globals: dict[str, Any]) -> bool:
        epoch, val_loss = int(locals_["epoch"]), float(locals_["metrics"]["val_loss"])
        val_losses[epoch] = val_loss
        if val_loss < best["loss"] - train.min_delta:
            best.update(loss=val_loss, epoch=epoch, state=copy.deepcopy(agent.model.state_dict()))
        elapsed = (time.perf_counter() - start) / 60.0
        while len(kept) < len(marks) and elapsed >= marks[len(kept)]:
            if keep is not None and keep.best_state is not None:  # scored: its best weights
                kept.append(mark_of(epoch, keep.best_state, False, keep.best_epoch))
            else:
                kept.append(mark_of(epoch, best["state"], False, None))
        return len(kept) < len(marks)

    # The control score runs first, so a mark passed in an epoch sees that epoch's score.
    agent.learn(callback=on_epoch if keep is None else [keep, on_epoch])
    epochs = agent.train_result.epochs if agent.train_result is not None else 0
    # The trainer restored its best-loss weights (and KeepBestControl its best-scoring ones).
    final_state = copy.deepcopy(agent.model.state_dict())
    # -1: the trainer's final weights scored at least as well as every scored epoch.
    control_epoch = None if keep is None or keep.best_epoch == -1 else keep.best_epoch
    while len(kept) < len(marks):
        kept.append(mark_of(epochs, final_state, True, control_epoch))
    seeds = task_seeds(task_seed, num_tasks)
    goal = agent.goal_observation
    marks_out = []
    for mark in kept:
        agent.model.load_state_dict(mark.pop("state"))
        agent.set_goal(goal)  # re-encode the goal with these weights
        agent.set_planner()  # every mark plans with the same draws, as a freshly loaded agent
        evaluation = evaluate_control(agent, env_id, seeds, record_states=False)
        mark["percentages"] = [t.percent_in_goal for t in evaluation.tasks]
        mark["mean"] = float(np.mean(mark["percentages"]))
        marks_out.append(mark)
    return {"env": env_id, "method": method, "variant": variant, "seed": seed,
            "task_seed": task_seed, "max_epochs": max_epochs, "patience": patience,
            "flush_denormals": flush_denormals, "lr": train.lr,
            "keep_best_control_every": keep_best_control or None,
            "prediction_horizon": train.prediction_horizon,
            "plan_length": planner.plan_length,
            "recipe": recipe_label(variant, lr, keep_best_control, prediction_horizon,
                                   plan_length),
            "epochs_trained": epochs,
            "train_message": agent.train_result.message if agent.train_result else "",
            "marks": marks_out}


def run_model(job: tuple[str, str, int], settings: dict[str, Any]) -> dict[str, Any]:
    """One model of the grid (an executor's run): train, keep, evaluate; the CPU it ran on."""
    env, method, seed = job
    record = train_and_evaluate(env, method, settings["variant"], seed, settings["minutes"],
                                settings["max_epochs"], settings["patience"],
                                settings["num_tasks"], settings["task_seed"],
                                settings["flush_denormals"], settings["lr"],
                                settings["keep_best_control"],
                                settings.get("prediction_horizon"), settings.get("plan_length"))
    record["cpu"] = cpu_name()
    return record


def aggregate(records: Sequence[dict[str, Any]]) -> list[dict[str, Any]]:
    """One row per (env, method, minute mark): the all-model mean and standard error."""
    groups: dict[tuple[str, str, str, float], list[float]] = {}
    models: dict[tuple[str, str, str, float], int] = {}
    for record in records:
        for mark in record["marks"]:
            key = (record["env"], record["method"], record["recipe"], mark["minutes"])
            groups.setdefault(key, []).extend(mark["percentages"])
            models[key] = models.get(key, 0) + 1
    rows = []
    for key, values in sorted(groups.items()):
        env, method, recipe, minutes = key
        array = np.asarray(values, dtype=float)
        rows.append({"env": env, "method": method, "recipe": recipe, "train_minutes": minutes,
                     "n_models": models[key], "n_tasks": int(array.size),
                     "mean_all": round(float(array.mean()), 2),
                     "se": round(float(array.std(ddof=1) / math.sqrt(array.size))
                                 if array.size > 1 else 0.0, 2)})
    return rows


def plot(rows: Sequence[dict[str, Any]], path: Path) -> None:
    """% in goal against training minutes, one panel per env, one line per method."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    envs = sorted({row["env"] for row in rows})
    fig, axes = plt.subplots(1, len(envs), figsize=(4.5 * len(envs), 3.6), squeeze=False)
    for ax, env in zip(axes[0], envs):
        for method, recipe in sorted({(row["method"], row["recipe"]) for row in rows
                                      if row["env"] == env}):
            sel = [row for row in rows if row["env"] == env and row["method"] == method
                   and row["recipe"] == recipe]
            ax.errorbar([r["train_minutes"] for r in sel], [r["mean_all"] for r in sel],
                        yerr=[r["se"] for r in sel], marker="o", capsize=3,
                        label=f"{method}, {recipe} ({sel[0]['n_models']} models)")
        ax.set_title(env)
        ax.set_xlabel("training minutes per model (1 CPU thread)")
        ax.set_ylabel("% of steps in goal")
        ax.set_ylim(0, 100)
        ax.grid(alpha=0.3)
        # Below the panel: recipe labels are long and would cover the curves or the next panel.
        ax.legend(fontsize=7, loc="upper center", bbox_to_anchor=(0.5, -0.2), frameon=False)
    fig.tight_layout()
    atomic_save_figure(fig, path, dpi=110)
    plt.close(fig)


def build_parser() -> argparse.ArgumentParser:
    """The command-line interface."""
    parser = command_parser(__doc__, "pcc_bench.time_to_control")
    parser.add_argument("--envs", nargs="+", default=["pcc/Planar-v0"])
    parser.add_argument("--methods", nargs="+", default=["pcc"])
    parser.add_argument("--variant", default="fast", help="preset variant (default: fast)")
    parser.add_argument("--seeds", nargs="+", type=int, default=[0, 1, 2])
    parser.add_argument("--minutes", nargs="+", type=float, default=list(DEFAULT_MINUTES),
                        help="training minutes at which the model is kept and evaluated")
    parser.add_argument("--lr", type=float, default=None,
                        help="learning rate override (default: the preset's)")
    parser.add_argument("--keep-best-control", type=int, default=None, metavar="EPOCHS",
                        help=f"every EPOCHS epochs score the model on {CONTROL_SELECTION_TASKS} "
                        "validation tasks (task seed 2021) and keep its best-controlling "
                        "weights at each mark (the scoring counts as training time; the "
                        "recipe label says so)")
    parser.add_argument("--prediction-horizon", type=int, default=None, metavar="K",
                        help="train with the multi-step prediction term over K >= 2 steps "
                        "(TrainConfig.prediction_horizon; not the paper's objective; the "
                        "recipe label says so)")
    parser.add_argument("--plan-length", type=int, default=None, metavar="T",
                        help="the agent plans T steps ahead instead of the env's setting "
                        "(the recipe label says so)")
    parser.add_argument("--max-epochs", type=int, default=1000)
    parser.add_argument("--patience", type=int, default=100)
    parser.add_argument("--num-tasks", type=int, default=10)
    parser.add_argument("--task-seed", type=int, default=EVALUATION_TASK_SEED,
                        help="2020: the evaluation tasks; another seed for choosing a recipe")
    parser.add_argument("--no-flush-denormals", action="store_true",
                        help="train without flush-to-zero (slow on Intel CPUs)")
    parser.add_argument("--workers", type=int, default=2,
                        help="models trained at once, one CPU thread each")
    parser.add_argument("--backend", choices=("process", "ray"), default="process",
                        help="local loky worker processes, or Ray tasks on a Ray cluster")
    parser.add_argument("--results-dir", type=Path, default=DEFAULT_RESULTS_DIR)
    parser.add_argument("--out", type=Path, default=None,
                        help="summary JSON (default: RESULTS_DIR/time_to_control.json)")
    return parser


def main(argv: Sequence[str] | None = None) -> int:
    """Train what is missing, then write the summary JSON and plot."""
    args = build_parser().parse_args(argv)
    if any(m <= 0 for m in args.minutes):
        raise SystemExit(f"--minutes must be positive, got {args.minutes}.")
    if args.keep_best_control is not None and args.keep_best_control < 1:
        raise SystemExit(f"--keep-best-control must be >= 1 epoch, got {args.keep_best_control}.")
    if args.prediction_horizon is not None and args.prediction_horizon < 2:
        raise SystemExit(f"--prediction-horizon must be >= 2 (1 is the paper's one-step "
                         f"objective: leave it out), got {args.prediction_horizon}.")
    if args.plan_length is not None and args.plan_length < 1:
        raise SystemExit(f"--plan-length must be >= 1, got {args.plan_length}.")
    flush = not args.no_flush_denormals
    recipe = recipe_label(args.variant, args.lr, args.keep_best_control, args.prediction_horizon,
                          args.plan_length)
    command = " ".join(["python -m pcc_bench.time_to_control",
                        *(argv if argv is not None else sys.argv[1:])])
    jobs = [(env, method, seed) for env in args.envs for method in args.methods
            for seed in args.seeds]
    todo = [job for job in jobs if not record_path(args.results_dir, job[0], job[1],
                                                   recipe, job[2], args.task_seed).exists()]
    print(f"{len(jobs) - len(todo)} of {len(jobs)} models already done; {len(todo)} to train "
          f"for up to {max(args.minutes):g} min each on {args.workers} worker(s).", flush=True)

    if todo:
        executor = make_executor(args.backend, args.workers)
        settings = {"variant": args.variant, "minutes": args.minutes,
                    "max_epochs": args.max_epochs, "patience": args.patience,
                    "num_tasks": args.num_tasks, "task_seed": args.task_seed,
                    "flush_denormals": flush, "lr": args.lr,
                    "keep_best_control": args.keep_best_control,
                    "prediction_horizon": args.prediction_horizon,
                    "plan_length": args.plan_length}
        failed = 0
        for (env, method, seed), outcome in executor.outcomes(run_model, todo, settings):
            if isinstance(outcome, Exception):
                failed += 1
                print(f"{env} {method} seed {seed} failed: {outcome!r}", file=sys.stderr)
                continue
            outcome["command"] = command
            atomic_write_json(record_path(args.results_dir, env, method, recipe, seed,
                                          args.task_seed), outcome)
            print(f"{env} {method} {recipe} seed {seed}: "
                  + ", ".join(f"{m['minutes']:g} min {m['mean']:.1f}%"
                              for m in outcome["marks"]), flush=True)
        if failed:
            raise SystemExit(f"{failed} model(s) failed; run the command again to retry them.")
    records = [json.loads(path.read_text())
               for path in sorted(args.results_dir.glob(f"*/*_tasks{args.task_seed}_seed*.json"))]
    rows = aggregate(records)
    out = args.out or args.results_dir / "time_to_control.json"
    atomic_write_json(out, {"command": command, "cpu": cpu_name(),
                            "task_seed": args.task_seed, "rows": rows})
    plot(rows, out.with_suffix(".png"))
    for row in rows:
        print(f"{row['env']:<24} {row['method']:<6} {row['recipe']:<16} "
              f"{row['train_minutes']:>5g} min  "
              f"{row['mean_all']:5.1f} ± {row['se']:.1f}%  ({row['n_models']} models)")
    print(f"wrote {out} and {out.with_suffix('.png')}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
