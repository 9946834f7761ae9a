"""The no-action floor: the metric when the controller always applies a zero action.

The reproduction tables put each method beside the oracle's ceiling; this is the matching
floor. On some domains the start states begin inside or near the goal region (CartPole starts
near upright), so a controller that does nothing already scores above 0%, and a learned
controller is only useful where it beats this number. Same tasks, task seeds, episode
lengths and evaluation function (:func:`pcc_agent.evaluation.evaluate_control`) as
``benchmarks.reproduce``.

Usage:
    python -m benchmarks.no_action_floor                       # every env, preset 'paper'
    python -m benchmarks.no_action_floor --envs pcc/CartPole-v0 --noise 1.0
"""

from __future__ import annotations

import argparse
import sys
from collections.abc import Sequence
from pathlib import Path
from typing import Any

import gymnasium as gym
import numpy as np

from benchmarks.presets import ALL_ENVS, REPRODUCE_PRESETS
from benchmarks.reproduce import _write_json_atomic, _write_text_atomic

DEFAULT_OUTPUT = Path("benchmarks") / "results" / "no_action_floor"


def contains_zero_action(action_space: gym.spaces.Box) -> bool:
    """Whether the zero action lies inside the bounds of ``action_space``."""
    return bool(np.all((action_space.low <= 0.0) & (action_space.high >= 0.0)))


class ZeroActionPolicy:
    """An SB3-style policy that always returns the zero action (batched, like a VecEnv's)."""

    def __init__(self, action_space: gym.spaces.Box) -> None:
        if not contains_zero_action(action_space):
            raise ValueError(f"the zero action is outside the action space {action_space}")
        self.action_shape = action_space.shape

    def predict(self, observation: Any, state: Any = None, episode_start: Any = None,
                deterministic: bool = True) -> tuple[np.ndarray, None]:
        """Zeros for each observation of the batch (SB3's ``predict`` signature)."""
        batch = len(observation) if isinstance(observation, np.ndarray) else 1
        return np.zeros((batch, *self.action_shape), dtype=np.float32), None


def zero_action_percentages(env_id: str, task_seed_list: Sequence[int],
                            noise_std: float = 0.0) -> list[float]:
    """Per-task percentage of steps in goal with zero actions, one per task seed.

    Raises ``ValueError`` if the env's action space does not contain the zero action.
    """
    from pcc_agent.evaluation import evaluate_control

    env_kwargs = {"noise_std": noise_std} if noise_std else None
    ev = evaluate_control(lambda env: ZeroActionPolicy(env.action_space), env_id,
                          list(task_seed_list), env_kwargs=env_kwargs, record_states=False)
    return ev.percentages.tolist()


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

    parser = argparse.ArgumentParser(prog="python -m benchmarks.no_action_floor",
                                     description=__doc__.split("\n\n")[0])
    parser.add_argument("--envs", nargs="+", default=list(ALL_ENVS), choices=ALL_ENVS)
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
    _write_json_atomic(json_path,
                       {"preset": args.preset, "rows": rows,
                        "command": " ".join(["python -m benchmarks.no_action_floor", *argv])})
    _write_text_atomic(md_path, format_table(rows))
    print(f"Wrote {json_path} and {md_path}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
