"""Does longer training help control? Train one model far past early stopping, evaluating it.

The reproduction grid stops a model 30 epochs after its best validation loss (150-450 epochs
on Planar); the paper's reference code trains 5,000. This trains one model of a preset with
early stopping disabled and, at chosen epochs, saves the agent as it is, loads it back and
runs the grid's control tasks (same task seeds, same planner, same metric), so the
percentage of steps in goal can be read as a function of training length. Data, model and
seed are those of the grid's run for the same (env, preset variant, method, seed): up to that
run's stopping epoch the two trainings are the same computation.

Every evaluation is appended to ``--output`` as it finishes (atomically), so a run cut short
keeps what it measured; the training itself is not resumable.

Usage:
    python -m pcc_bench.long_training --seed 1 --epochs 1000 --eval-at 150 250 500 750 1000 \
        --output results/long_training/planar_pcc_fast_seed1.json
"""

from __future__ import annotations

import argparse
import dataclasses
import sys
import tempfile
import time
from collections.abc import Sequence
from pathlib import Path
from typing import Any

import torch

from pcc_agent.io import atomic_write_json, versions
from pcc_agent.presets import VARIANTS
from pcc_bench.arguments import command_parser
from pcc_bench.presets import REPRODUCE_PRESETS


def build_parser() -> argparse.ArgumentParser:
    """The command-line interface."""
    parser = command_parser(__doc__, "pcc_bench.long_training")
    parser.add_argument("--env", default="pcc/Planar-v0")
    parser.add_argument("--method", default="pcc")
    parser.add_argument("--variant", default="fast", choices=VARIANTS,
                        help="Preset variant (the grid's 'paper', 'paper-fast' or 'paper-motion' "
                        "recipe).")
    parser.add_argument("--seed", type=int, default=0, help="Data, model and training seed.")
    parser.add_argument("--epochs", type=int, default=1000)
    parser.add_argument("--eval-at", type=int, nargs="+", default=[150, 250, 500, 750, 1000],
                        help="Epochs after which the control tasks run.")
    parser.add_argument("--num-samples", type=int, default=None,
                        help="Training transitions (default: the preset's data size).")
    parser.add_argument("--num-tasks", type=int, default=REPRODUCE_PRESETS["paper"].num_tasks)
    parser.add_argument("--data-dir", default=None, help="Data-set cache (PCC_DATA_DIR).")
    parser.add_argument("--output", type=Path, required=True)
    return parser


def main(argv: Sequence[str] | None = None) -> int:
    """Entry point of ``python -m pcc_bench.long_training``."""
    args = build_parser().parse_args(argv)
    if args.epochs < 1 or any(e < 1 or e > args.epochs for e in args.eval_at):
        raise SystemExit(f"--eval-at epochs must be in [1, {args.epochs}], got {args.eval_at}.")
    torch.set_num_threads(1)

    from pcc_agent.agent import PCCAgent
    from pcc_agent.evaluation import evaluate_control, task_seeds
    from pcc_agent.planning import PLANNER_REVISION
    from pcc_agent.presets import get_preset

    preset = get_preset(args.env, args.variant)
    preset = dataclasses.replace(
        preset, train=dataclasses.replace(preset.train, epochs=args.epochs, patience=0)
    )
    seeds = task_seeds(REPRODUCE_PRESETS["paper"].task_seed, args.num_tasks)
    agent = PCCAgent(args.env, method=args.method, preset=preset, seed=args.seed,
                     data_cache_dir=args.data_dir)
    record: dict[str, Any] = {
        "command": "python -m pcc_bench.long_training "
        + " ".join(argv if argv is not None else sys.argv[1:]),
        "env_id": args.env,
        "method": args.method,
        "variant": args.variant,
        "seed": args.seed,
        "task_seeds": seeds,
        "planner_revision": PLANNER_REVISION,
        "versions": versions(),
        "config": agent.config_dict(),
        "evaluations": [],
        "status": "running",
    }
    wanted = sorted(set(args.eval_at))
    start = time.perf_counter()

    def evaluate_now(locals_: dict[str, Any], globals_: dict[str, Any]) -> bool:
        epoch, metrics = locals_["epoch"], locals_["metrics"]
        if epoch not in wanted:
            return True
        with tempfile.TemporaryDirectory() as tmp:
            agent.save(Path(tmp) / "agent.pt")  # the weights as they are now, not the best
            snapshot = PCCAgent.load(Path(tmp) / "agent.pt")
        evaluation = evaluate_control(snapshot, args.env, seeds, record_states=False)
        row = {
            "epoch": epoch,
            "train_seconds": round(time.perf_counter() - start, 1),
            "val_loss": metrics.get("val_loss"),
            "percentages": [t.percent_in_goal for t in evaluation.tasks],
            "mean": evaluation.mean,
            "se": evaluation.standard_error,
        }
        record["evaluations"].append(row)
        atomic_write_json(args.output, record)
        print(f"epoch {epoch}: val loss {row['val_loss']:.1f}, {row['mean']:.1f}% in goal "
              f"{row['percentages']}", flush=True)
        return True

    agent.learn(total_timesteps=args.num_samples, callback=evaluate_now, progress_bar=False)
    record["status"] = "done"
    record["training"] = agent.train_summary()
    atomic_write_json(args.output, record)
    return 0


if __name__ == "__main__":
    sys.exit(main())
