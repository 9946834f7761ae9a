"""Control quality of one trained agent under several planner settings.

The reproduction pipeline saves every trained agent (``<results>/checkpoints/...pt``); this
script re-runs its control tasks with other plan lengths, cost weights or iteration counts,
so that planner settings can be chosen with numbers before they go into a preset. Training
is not repeated.

Example:
    python -m benchmarks.planner_sweep CHECKPOINT --plan-lengths 10 20 40 --kappas 1 10

    where CHECKPOINT is e.g. benchmarks/results/reproduce/checkpoints/runs/paper/
    pcc_Planar-v0/noise0.0/pcc/seed1.pt
"""

from __future__ import annotations

import argparse
import dataclasses
import itertools
import json
import sys
import time
from collections.abc import Sequence
from pathlib import Path

from benchmarks.presets import REPRODUCE_PRESETS


def main(argv: Sequence[str] | None = None) -> int:
    """Entry point of ``python -m benchmarks.planner_sweep``."""
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("checkpoint", type=Path, help="A PCCAgent file (PCCAgent.save).")
    parser.add_argument("--plan-lengths", type=int, nargs="+", default=[10])
    parser.add_argument("--kappas", type=float, nargs="+", default=[1.0])
    parser.add_argument("--r-weights", type=float, nargs="+", default=[0.1])
    parser.add_argument("--mpc-iterations", type=int, nargs="+", default=[2])
    parser.add_argument("--num-tasks", type=int, default=REPRODUCE_PRESETS["paper"].num_tasks)
    parser.add_argument("--task-seed", type=int, default=REPRODUCE_PRESETS["paper"].task_seed)
    parser.add_argument("--out", type=Path, default=None, help="JSON file for the rows.")
    args = parser.parse_args(argv)

    import torch

    from pcc_agent import PCCAgent
    from pcc_agent.evaluation import evaluate_control, format_mean_se, task_seeds

    torch.set_num_threads(1)
    agent = PCCAgent.load(args.checkpoint)
    seeds = task_seeds(args.task_seed, args.num_tasks)
    base = agent.preset.planner
    rows = []
    grid = itertools.product(args.plan_lengths, args.kappas, args.r_weights, args.mpc_iterations)
    for plan_length, kappa, r_weight, mpc_iterations in grid:
        agent.preset = dataclasses.replace(
            agent.preset,
            planner=dataclasses.replace(base, plan_length=plan_length, kappa=kappa,
                                        r_weight=r_weight, mpc_iterations=mpc_iterations),
        )
        agent._plan_generator.manual_seed(agent.seed)
        start = time.perf_counter()
        result = evaluate_control(agent, agent.env_id, seeds, agent.env_kwargs,
                                  record_states=False)
        row = {
            "checkpoint": str(args.checkpoint), "env": agent.env_id, "method": agent.method,
            "plan_length": plan_length, "kappa": kappa, "r_weight": r_weight,
            "mpc_iterations": mpc_iterations, "num_tasks": len(seeds), "task_seed": args.task_seed,
            "mean": result.mean, "se": result.standard_error,
            "percentages": result.percentages.tolist(),
            "seconds": time.perf_counter() - start,
        }
        rows.append(row)
        print(f"plan {plan_length:4d} kappa {kappa:6g} R {r_weight:6g} mpc iters "
              f"{mpc_iterations}: {format_mean_se(row['mean'], row['se'])} % in goal", flush=True)
    if args.out is not None:
        args.out.parent.mkdir(parents=True, exist_ok=True)
        args.out.write_text(json.dumps(rows, indent=1))
    return 0


if __name__ == "__main__":
    sys.exit(main())
