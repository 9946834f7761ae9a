"""The no-action floor: the metric when the controller always applies a zero action.

The reproduction tables put each method beside the oracle's ceiling; this is the matching
floor. On some domains the start states begin inside or near the goal region (CartPole starts
near upright), so a controller that does nothing already scores above 0%, and a learned
controller is only useful where it beats this number. Same tasks, task seeds, episode
lengths and evaluation function (:func:`pcc_agent.evaluation.evaluate_control`) as
``pcc_bench.reproduce``.

Usage:
    python -m pcc_bench.no_action_floor                       # every env, preset 'paper'
    python -m pcc_bench.no_action_floor --envs pcc/CartPole-v0 --noise 1.0
"""

from __future__ import annotations

import sys
from collections.abc import Sequence
from pathlib import Path
from typing import Any

import numpy as np

from pcc_agent.io import atomic_write_json, atomic_write_text
from pcc_bench.arguments import command_parser, known_envs
from pcc_bench.paths import COMMITTED_RESULTS_DIR
from pcc_bench.presets import ALL_ENVS, REPRODUCE_PRESETS
from pcc_bench.zero_action import (  # noqa: F401 - re-exported: the floor's policy
    ZeroActionPolicy,
    contains_zero_action,
    zero_action_percentages,
)

DEFAULT_OUTPUT = COMMITTED_RESULTS_DIR / "no_action_floor"


def measure_floor(env_id: str, num_tasks: int, task_seed: int,
                  noise_std: float = 0.0) -> dict[str, Any]:
    """Percentage of steps in goal with zero actions on ``num_tasks`` tasks of ``env_id``."""
    from pcc_agent.evaluation import standard_error, task_seeds

    seeds = task_seeds(task_seed, num_tasks)
    percentages = zero_action_percentages(env_id, seeds, noise_std)
    return {"env_id": env_id, "noise_std": noise_std, "num_tasks": num_tasks,
            "task_seed": task_seed, "task_seeds": seeds, "percentages": percentages,
            "mean": float(np.mean(percentages)), "se": standard_error(percentages)}


def format_table(rows: Sequence[dict[str, Any]]) -> str:
    """A Markdown table of the floors."""
    from pcc_agent.evaluation import format_mean_se

    lines = ["| env | noise std | tasks (task seed) | % steps in goal, zero action (mean ± SE) |",
             "|---|---|---|---|"]
    for row in rows:
        lines.append(f"| {row['env_id']} | {row['noise_std']:g} | {row['num_tasks']} "
                     f"({row['task_seed']}) | {format_mean_se(row['mean'], row['se'])} |")
    return "\n".join(lines) + "\n"


def main(argv: Sequence[str] | None = None) -> int:
    from pcc_agent.evaluation import format_mean_se

    parser = command_parser(__doc__, "pcc_bench.no_action_floor")
    parser.add_argument("--envs", nargs="+", default=list(ALL_ENVS), choices=known_envs(),
                        metavar="ENV")
    parser.add_argument("--preset", default="paper", choices=sorted(REPRODUCE_PRESETS),
                        help="Reproduction preset whose tasks (number, seed) are used.")
    parser.add_argument("--noise", type=float, default=0.0, help="Process noise std.")
    parser.add_argument("--output", type=Path, default=DEFAULT_OUTPUT,
                        help="Writes <output>.json and <output>.md.")
    argv = list(sys.argv[1:] if argv is None else argv)
    args = parser.parse_args(argv)
    if not np.isfinite(args.noise) or args.noise < 0:
        parser.error(f"--noise must be a finite number >= 0, got {args.noise}")
    preset = REPRODUCE_PRESETS[args.preset]
    rows = []
    for env_id in args.envs:
        row = measure_floor(env_id, preset.num_tasks, preset.task_seed, args.noise)
        print(f"{env_id}: {format_mean_se(row['mean'], row['se'])}% of steps in goal with no "
              "action")
        rows.append(row)
    # Suffixes are appended, not swapped: "--output floor_v1.0" writes floor_v1.0.json.
    json_path, md_path = (args.output.with_name(args.output.name + ext) for ext in (".json", ".md"))
    atomic_write_json(json_path,
                       {"preset": args.preset, "rows": rows,
                        "command": " ".join(["python -m pcc_bench.no_action_floor", *argv])})
    atomic_write_text(format_table(rows), md_path)
    print(f"Wrote {json_path} and {md_path}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
