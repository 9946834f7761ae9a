"""Evaluate a saved agent on its env's evaluation tasks: % of steps in goal, task by task.

The tasks are the reproduction protocol's (``--num-tasks`` start states drawn with
``--task-seed``; by default the 10 evaluation tasks of the ``paper`` preset), the metric the
paper's (percentage of an episode's steps whose true state is in the goal region). Beside
each task: the oracle (the planner on the true dynamics: the ceiling of the env's planner
settings) and the no-action floor (zero actions), read from the reproduction records in
``--references-dir`` where they exist for the same tasks and the current planner.

``MODEL`` is a saved agent's file or the name of a pretrained agent shipped with the package
(``pcc_agent.zoo``), which then runs in seconds and prints the score it was shipped with.
``--hold`` also starts the agent inside the goal region and counts how long it stays there
(:func:`pcc_agent.evaluation.evaluate_goal_hold`), beside the oracle.

Examples:
    pcc evaluate planar-pcc --picture planar.png
    python -m pcc_bench.evaluate pcc_results/models/Planar-v0_pcc_seed0.pt
    python -m pcc_bench.evaluate planar_e2c.pt --num-tasks 3 --json planar_e2c_eval.json
    pcc evaluate pendulum-swingup-pcc --hold
"""

from __future__ import annotations

import argparse
import sys
import textwrap
from collections.abc import Sequence
from pathlib import Path
from typing import Any

from pcc_agent.zoo import PRETRAINED, pretrained_path
from pcc_bench.arguments import command_parser, non_negative_float, positive_int
from pcc_bench.paths import COMMITTED_RESULTS_DIR
from pcc_bench.presets import REPRODUCE_PRESETS
from pcc_bench.records import NO_ACTION, ORACLE, RunSpec, load_finished_run
from pcc_bench.tables import terminal_table

DEFAULT_REFERENCES_DIR = COMMITTED_RESULTS_DIR / "reproduce"
_PAPER = REPRODUCE_PRESETS["paper"]


def reference_percentages(
    references_dir: Path, env_id: str, method: str, seeds: Sequence[int], noise_std: float = 0.0
) -> dict[int, float] | None:
    """A reference controller's % in goal per task seed, from a reproduction record.

    Looks for the ``paper`` preset's record of ``method`` (``"oracle"`` or ``"no-action"``)
    on ``env_id`` with the same tasks; None when there is none, or it is stale (another
    planner revision or other planner settings than the env's preset).
    """
    spec = RunSpec(env_id=env_id, method=method, seed=0, noise_std=float(noise_std),
                   num_tasks=len(seeds), task_seed=_PAPER.task_seed, model_variant="paper",
                   preset="paper")
    record = load_finished_run(references_dir / spec.relative_path, spec)
    if record is None:
        return None
    by_seed = {int(s): float(p) for s, p in zip(record["task_seeds"], record["percentages"])}
    return by_seed if all(int(s) in by_seed for s in seeds) else None


def build_parser() -> argparse.ArgumentParser:
    """The command-line interface."""
    parser = command_parser(__doc__, "pcc_bench.evaluate")
    parser.add_argument("model", type=Path,
                        help="An agent saved by PCCAgent.save / pcc train, or a pretrained "
                        f"agent's name ({', '.join(sorted(PRETRAINED))}).")
    parser.add_argument("--env", default=None, metavar="ENV_ID",
                        help="The env to control (default: the one the agent was trained on).")
    parser.add_argument("--num-tasks", type=positive_int, default=_PAPER.num_tasks,
                        help="Control tasks (default: %(default)s).")
    parser.add_argument("--task-seed", type=int, default=_PAPER.task_seed,
                        help="Base seed of the tasks (default: %(default)s, the evaluation "
                        "tasks; the references are only shown for these).")
    parser.add_argument("--noise", type=non_negative_float, default=0.0, metavar="STD",
                        help="Process noise standard deviation of the env (default: 0).")
    parser.add_argument("--references-dir", type=Path, default=DEFAULT_REFERENCES_DIR,
                        help="Reproduction results with the oracle and no-action records "
                        "(default: the repository's committed results).")
    parser.add_argument("--picture", type=Path, default=None, metavar="PNG",
                        help="Also draw the first task's controlled episode to this PNG.")
    parser.add_argument("--hold", action="store_true",
                        help="Also start 5 times inside the goal region, near the goal state, "
                        "and count the steps of 100 the agent stays there, beside the "
                        "oracle's where the env has cheap true dynamics: tells a controller "
                        "that cannot reach the goal from one that cannot stay.")
    parser.add_argument("--json", type=Path, default=None,
                        help="Also write the per-task results to this JSON file.")
    return parser


def main(argv: Sequence[str] | None = None) -> int:
    """Entry point of ``python -m pcc_bench.evaluate`` and ``pcc evaluate``."""
    args = build_parser().parse_args(argv)
    shipped = None
    if not args.model.exists() and not args.model.with_suffix(".pt").exists():
        if str(args.model) not in PRETRAINED:
            raise SystemExit(f"No saved agent at {args.model}, and no pretrained agent of that "
                             f"name (shipped: {', '.join(sorted(PRETRAINED))}).")
        shipped = PRETRAINED[str(args.model)]
        args.model = pretrained_path(shipped.name)
    import numpy as np
    import torch

    from pcc_agent.agent import PCCAgent

    # One thread, as the grid evaluates: the same numbers as its records, and faster for the
    # planner's small matrices than several threads.
    torch.set_num_threads(1)
    from pcc_agent.evaluation import evaluate_control, format_mean_se, task_seeds
    from pcc_agent.io import atomic_write_json

    env_kwargs = {"noise_std": args.noise} if args.noise else {}
    agent = PCCAgent.load(args.model, env=args.env)
    env_id = args.env or agent.env_id
    seeds = task_seeds(args.task_seed, args.num_tasks)
    evaluation = evaluate_control(agent, env_id, seeds, env_kwargs, record_states=False)
    ours = evaluation.percentages
    references: dict[str, dict[int, float] | None] = {
        method: (reference_percentages(args.references_dir, env_id, method, seeds, args.noise)
                 if args.task_seed == _PAPER.task_seed else None)
        for method in (ORACLE, NO_ACTION)
    }

    def cell(method: str, seed: int) -> str:
        values = references[method]
        return "-" if values is None else f"{values[seed]:.1f}"

    rows: list[list[Any]] = [[k + 1, seed, f"{value:.1f}", cell(ORACLE, seed),
                              cell(NO_ACTION, seed)] for k, (seed, value) in
                             enumerate(zip(seeds, ours))]
    means = {m: (None if v is None else float(np.mean([v[s] for s in seeds])))
             for m, v in references.items()}
    rows.append(["mean", "", format_mean_se(evaluation.mean, evaluation.standard_error),
                 *("-" if means[m] is None else f"{means[m]:.1f}" for m in (ORACLE, NO_ACTION))])
    print(f"{agent.method} on {env_id}: % of steps in goal per task\n(model: {args.model})")
    print(terminal_table(["task", "seed", agent.method, "oracle", "no action"], rows))
    if shipped is not None and args.env is None and not args.noise and seeds == task_seeds(
            shipped.task_seed, len(shipped.percentages)):
        same_cpu = ("" if shipped.measured_on_this_cpu() else
                    " This CPU's vector instructions differ from that one's, so it rounds "
                    "differently and its scores may differ.")
        print(textwrap.fill(f"Shipped with {shipped.mean:.1f} % on these tasks, measured on a "
                            f"{shipped.machine}.{same_cpu} It is the model of "
                            f"{shipped.source}.", 100))
    if all(v is None for v in references.values()):
        print("No oracle or no-action records of these tasks (the references are kept for the "
              f"{_PAPER.num_tasks}\nevaluation tasks) in --references-dir {args.references_dir}")
    hold = _print_goal_hold(agent, env_id, env_kwargs) if args.hold else None
    if args.picture is not None:
        from pcc_bench.episode_figure import plot_controlled_episode

        plot_controlled_episode(agent, env_id, seeds[0], args.picture, env_kwargs=env_kwargs)
        print(f"Wrote {args.picture} (task 1, frame by frame, green while in goal)")
    if args.json is not None:
        atomic_write_json(args.json, {
            "model": str(args.model), "env_id": env_id, "method": agent.method,
            "noise_std": args.noise, "task_seeds": seeds, "percentages": ours.tolist(),
            "mean": evaluation.mean, "oracle": means[ORACLE], "no_action": means[NO_ACTION],
            **({} if hold is None else {"goal_hold": hold}),
        })
        print(f"Wrote {args.json}")
    return 0


def _print_goal_hold(agent: Any, env_id: str, env_kwargs: dict[str, Any]) -> dict[str, Any]:
    """Print the agent's goal hold beside the oracle's; return both as JSON-friendly dicts."""
    import gymnasium as gym

    from pcc_agent.evaluation import evaluate_goal_hold
    from pcc_agent.oracle import OracleController

    held = {agent.method: evaluate_goal_hold(agent, env_id, env_kwargs=env_kwargs)}
    probe = gym.make(env_id)
    has_oracle = getattr(probe.unwrapped, "supports_oracle", False)
    probe.close()
    if has_oracle:
        held[ORACLE] = evaluate_goal_hold(lambda env: OracleController(env), env_id,
                                          env_kwargs=env_kwargs)
    first = next(iter(held.values()))
    rows: list[list[Any]] = [
        [k + 1, " ".join(f"{x:.2f}" for x in start), *(h.steps_held[k] for h in held.values())]
        for k, start in enumerate(first.starts)]
    rows.append(["mean", "", *(f"{h.mean_steps:.1f}" for h in held.values())])
    print(f"\nGoal hold: steps of {first.horizon} in the goal region from starts inside it, "
          "near the goal state")
    print(terminal_table(["start", "true state", *held], rows))
    return {name: h.to_dict() for name, h in held.items()}


if __name__ == "__main__":
    sys.exit(main())
