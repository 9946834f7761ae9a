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
    python -m pcc_bench.reproduce --preset quick
    python -m pcc_bench.reproduce --preset paper --envs pcc/Planar-v0 --workers 2
    python -m pcc_bench.reproduce --preset paper --backend ray --ray-address auto \
        --ray-gpus-per-task 0.5
    python -m pcc_bench.reproduce --preset paper --envs pcc/Planar-v0 --status
    python -m pcc_bench.reproduce --aggregate-only
"""

from __future__ import annotations

import argparse
import os
import signal
import sys
from collections.abc import Sequence
from pathlib import Path
from typing import Any

from pcc_agent.io import atomic_write_json, atomic_write_text
from pcc_bench.aggregation import aggregate, choose_models
from pcc_bench.arguments import (
    command_parser,
    known_envs,
    non_negative_float,
    positive_float,
    positive_int,
)
from pcc_bench.costs import status_lines
from pcc_bench.executors import interrupt
from pcc_bench.grid import expand_grid, run_grid
from pcc_bench.plots import summary_bar_chart
from pcc_bench.presets import ALL_METHODS, REPRODUCE_PRESETS, RESTART_SEED_STRIDE
from pcc_bench.records import (
    DEFAULT_RESULTS_DIR,
    REFERENCE_METHODS,
    load_finished_run,
    load_records,
    training_progress,
)
from pcc_bench.showcase import show_control
from pcc_bench.tables import (
    markdown_table,
    paper_table,
    settings_table,
    summary_terminal_table,
)


def write_summary(results_dir: Path) -> list[dict[str, Any]]:
    """Aggregate the run files into summary.json, summary.md and a bar chart."""
    records = load_records(results_dir)
    rows = aggregate(choose_models(records))
    if not rows:
        print("No finished runs to aggregate.")
        return rows
    atomic_write_json(results_dir / "summary.json", rows)
    sections = []
    for table in sorted({paper_table(r) for r in rows}):
        sections.append(f"## {table}\n\n" + markdown_table(
            [r for r in rows if paper_table(r) == table]))
    from pcc_agent.oracle import ORACLE_CONFIGS

    own_horizons = ", ".join(f"{env} T = {c.plan_length}" for env, c in ORACLE_CONFIGS.items()
                             if c.plan_length is not None)
    text = (
        "# Percentage of steps in goal (true state), ours beside the paper's\n\n"
        "Mean ± standard error over all tasks of all models (`all`) and over the best model's "
        "tasks (`top-1`). The paper's LaneKeeping numbers are its TORCS domain. "
        "`k of N x M (reduced grid)`: only k of the preset's N models have been run. A preset "
        "name `base+field=value` marks runs with command-line overrides of the preset. "
        "`oracle`: the agents' iLQR-MPC settings (Evaluation settings below) on the true "
        f"state and dynamics, with the oracle's own horizon where it has one ({own_horizons}: "
        "docs/planner.md), the ceiling; `no action`: zero actions on the "
        "same tasks (the floor; above 0 where starts lie in the goal region). "
        "`[planner rN]`: rows evaluated by an older planner revision, with that revision's "
        "oracle; they are history, not comparable with the current rows.\n\n"
        + "\n".join(sections)
        + "\n## Evaluation settings\n\n"
        + settings_table(rows)
    )
    atomic_write_text(text, results_dir / "summary.md")
    summary_bar_chart(rows, results_dir / "summary.png")
    print("Percentage of steps in goal (true state), mean ± standard error over all tasks of all\n"
          "models (all) and over the best model's tasks (top-1); the paper's 'all' beside ours;\n"
          "oracle: the planner on the true dynamics (ceiling); floor: zero actions.")
    for table in sorted({paper_table(r) for r in rows}):
        print(f"\n{table}\n" + summary_terminal_table(
            [r for r in rows if paper_table(r) == table]))
    print(f"Wrote {results_dir / 'summary.json'}, summary.md and summary.png\n(summary.md: the "
          "full tables, with the IQM and the evaluation settings)")
    return rows


def build_parser() -> argparse.ArgumentParser:
    """The command-line interface."""
    parser = command_parser(__doc__, "pcc_bench.reproduce")
    parser.add_argument("--preset", default="quick", choices=sorted(REPRODUCE_PRESETS),
                        metavar="NAME", help="The grid (default: %(default)s; any of: "
                        "%(choices)s).")
    parser.add_argument("--envs", nargs="+", choices=known_envs(), metavar="ENV",
                        help="Subset of the preset's env ids (any of: %(choices)s).")
    parser.add_argument("--methods", nargs="+", choices=ALL_METHODS, metavar="METHOD",
                        help="Subset / override of the methods (any of: %(choices)s).")
    parser.add_argument("--num-models", type=positive_int,
                        help="Override the number of models.")
    parser.add_argument(
        "--seeds", type=int, nargs="+",
        help="Run only these model seeds (e.g. to split a grid over machines, or to fill in "
        "missing models); overrides --num-models.",
    )
    parser.add_argument("--num-tasks", type=positive_int,
                        help="Override the number of tasks per model.")
    parser.add_argument("--max-epochs", type=positive_int,
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
    parser.add_argument("--learning-rate", type=positive_float, metavar="LR",
                        help="Override Adam's learning rate (runs and rows are labelled).")
    parser.add_argument(
        "--prediction-horizon", type=positive_int, metavar="K",
        help="Train with the multi-step prediction term over K steps (K >= 2; a named variant "
        "of the objective, not the paper's: TrainConfig.prediction_horizon; runs and rows are "
        "labelled).")
    parser.add_argument(
        "--plan-length", type=positive_int, metavar="T",
        help="The learned agents plan T steps ahead instead of the env's setting (the oracle "
        "keeps its own; runs and rows are labelled). Choose it on validation tasks.")
    parser.add_argument(
        "--keep-best-control", type=positive_int, metavar="EPOCHS",
        help="Every EPOCHS epochs, score each training on 10 validation tasks (task seed "
        "2021, never the evaluation tasks) and keep its best-controlling weights instead of "
        "those of the lowest validation loss (runs and rows are labelled).")
    noise = parser.add_mutually_exclusive_group()
    noise.add_argument(
        "--noise", type=non_negative_float, nargs="+", metavar="STD",
        help="Override the process-noise levels, as standard deviations (0: deterministic).",
    )
    noise.add_argument(
        "--noise-variance", type=non_negative_float, nargs="+", metavar="VAR",
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
        type=positive_int,
        default=os.cpu_count() or 1,
        help="Parallel runs on this machine for the process backend (loky worker processes, "
        "one core each; 1: one after another in this process).",
    )
    parser.add_argument("--backend", choices=("process", "ray"), default="process",
                        help="process: this machine (see --workers); ray: Ray tasks on a Ray "
                        "cluster (pip install 'pcc-control[ray]').")
    parser.add_argument("--ray-address", default=None, help="Ray cluster address (e.g. 'auto').")
    parser.add_argument(
        "--ray-gpus-per-task", type=non_negative_float, default=0.0,
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
        "its best validation loss, or not started), e.g. while the grid runs elsewhere, and "
        "the estimated wall time of the rest (from finished runs of the same kind).",
    )
    return parser


def main(argv: Sequence[str] | None = None) -> int:
    """Entry point of ``python -m pcc_bench.reproduce`` and ``pcc reproduce``."""
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
        if args.learning_rate is not None:
            changes["learning_rate"] = args.learning_rate
        if args.prediction_horizon is not None:
            if args.prediction_horizon < 2:
                raise SystemExit("--prediction-horizon must be at least 2 (1 is the paper's "
                                 "one-step objective: leave the option out).")
            changes["prediction_horizon"] = args.prediction_horizon
        if args.plan_length is not None:
            changes["plan_length"] = args.plan_length
        if args.keep_best_control is not None:
            changes["keep_best_control_every"] = args.keep_best_control
        noise_stds = args.noise or [variance**0.5 for variance in args.noise_variance or ()]
        if noise_stds:
            changes["noise_levels"] = tuple(noise_stds)
            changes["env_noise_levels"] = {}
        try:
            preset = preset.override(**changes)
        except ValueError as error:
            raise SystemExit(str(error)) from None
        runs = expand_grid(preset, include_oracle=not args.no_oracle, include_floor=args.floor)
        if args.references_only:
            runs = [run for run in runs if run.method in REFERENCE_METHODS]
            if not runs:
                raise SystemExit("--references-only with --no-oracle --no-floor leaves no run.")
        if args.status:
            print("\n".join(training_progress(results_dir, run) for run in runs))
        pending = [r for r in runs if load_finished_run(results_dir / r.relative_path, r) is None]
        print("\n".join(status_lines(preset.name, runs, pending, results_dir,
                                     max(1, args.workers), args.backend)))
        if args.status:
            return 0
        if preset.runs_preset != preset.name:
            print(f"Its trainings are filed under {preset.runs_preset!r}, as that preset's "
                  f"runs; its rows are labelled {preset.name!r}.")
        elif preset.name != args.preset:
            print(f"The overrides change what the runs compute: their files and rows are "
                  f"labelled {preset.name!r}.")
        # SIGTERM (kill, a batch scheduler's stop) ends the grid like Ctrl-C does.
        signal.signal(signal.SIGTERM, interrupt)
        try:
            run_grid(runs, results_dir, args.workers, args.backend, args.ray_address,
                     args.data_dir, args.ray_gpus_per_task)
        except KeyboardInterrupt:
            print("Interrupted: finished runs and training checkpoints are kept; run the same "
                  "command again to continue.", file=sys.stderr)
            return 130
    write_summary(results_dir)
    if not args.aggregate_only:
        show_control(runs, results_dir, preset.name)
    return 0


if __name__ == "__main__":
    sys.exit(main())
