"""Latent iLQR-MPC planner speed: milliseconds per MPC step in closed loop.

For each environment preset, a random (fixed-seed) ReLU MLP transition of the paper's size
for that environment plays both the planner's model and the system, and ``LatentMPC`` drives
it from a random latent state towards a random goal for ``--steps`` steps. The first step
plans from scratch (``num_candidates`` plans, ``iterations`` iterations); the others refine
the shifted previous plan (``mpc_iterations`` iterations). Reported: median milliseconds per
step over the episode (and the first step separately).

Threads: ``torch.set_num_threads(--threads)`` (default 1). The planner's tensors are tiny, so
more intra-op threads only add synchronization overhead; one thread per planner is also what
several environments or engineers sharing a machine should use.

The first step's time includes loading the compiled planner loops (numba, cached on disk
after the first run in an environment; compiling them takes seconds the very first time).

Usage:
    python -m benchmarks.planner_speed                 # all presets + plan-length sweep
    python -m benchmarks.planner_speed --envs planar --steps 40
"""

from __future__ import annotations

import argparse
import json
import platform
import statistics
import time
from pathlib import Path

import torch

from pcc_agent.planning import LatentMPC, MLPDynamics, PlannerConfig, QuadraticCost
from pcc_agent.presets import get_preset

# env: (latent_dim, action_dim, transition hidden sizes) from the paper's architectures.
PRESETS: dict[str, tuple[int, int, tuple[int, ...]]] = {
    "planar": (2, 2, (20, 20)),
    "pendulum": (3, 1, (30, 30)),
    "cartpole": (8, 1, (40, 40)),
    "three_link_arm": (8, 3, (40, 40)),
    "lane_keeping": (8, 1, (40, 40)),
}
SWEEP_ENV = "cartpole"
SWEEP_PLAN_LENGTHS = (10, 50, 200)
#: The paper's Planar setup plans over the whole 40-step episode (the Planar preset's window).
PLANAR_PAPER_PLAN_LENGTH = get_preset("pcc/Planar-v0").planner.plan_length
TARGETS_MS = {("planar", PLANAR_PAPER_PLAN_LENGTH): 5.0, ("cartpole", 200): 20.0}


def measure(env: str, plan_length: int, steps: int, config_kwargs: dict, seed: int) -> dict:
    """Closed-loop MPC episode on a random MLP latent system; timing statistics."""
    latent_dim, action_dim, hidden = PRESETS[env]
    generator = torch.Generator().manual_seed(seed)
    dynamics = MLPDynamics.random(latent_dim, action_dim, hidden, generator)
    goal = torch.randn(latent_dim, generator=generator)
    z = torch.randn(latent_dim, generator=generator)
    config = PlannerConfig(plan_length=plan_length, **config_kwargs)
    mpc = LatentMPC(dynamics, QuadraticCost.from_config(config, goal, action_dim), config,
                    seed=seed)
    times = []
    with torch.inference_mode(False), torch.no_grad():
        for _ in range(steps):
            start = time.perf_counter()
            action = mpc.act(z)
            times.append(1e3 * (time.perf_counter() - start))
            z = dynamics.step(z[None], action[None])[0]
    return {
        "env": env,
        "plan_length": plan_length,
        "latent_dim": latent_dim,
        "action_dim": action_dim,
        "hidden": list(hidden),
        "iterations": config.iterations,
        "mpc_iterations": config.mpc_iterations,
        "num_candidates": config.num_candidates,
        "line_search_steps": len(config.line_search_steps),
        "steps": steps,
        "ms_per_step": round(statistics.median(times), 3),
        "first_step_ms": round(times[0], 3),
        "max_ms": round(max(times), 3),
        "final_distance": round(float(torch.linalg.norm(z - goal)), 4),
        "threads": torch.get_num_threads(),
        "target_ms": TARGETS_MS.get((env, plan_length)),
    }


def main(argv: list[str] | None = None) -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--envs", nargs="+", default=list(PRESETS), choices=list(PRESETS))
    parser.add_argument("--plan-length", type=int, default=10)
    parser.add_argument("--sweep", nargs="*", type=int, default=list(SWEEP_PLAN_LENGTHS),
                        help=f"plan lengths for the {SWEEP_ENV} (8-d latent) sweep; empty: none")
    parser.add_argument("--steps", type=int, default=50, help="MPC steps per episode")
    parser.add_argument("--iterations", type=int, default=PlannerConfig.iterations)
    parser.add_argument("--mpc-iterations", type=int, default=PlannerConfig.mpc_iterations)
    parser.add_argument("--num-candidates", type=int, default=PlannerConfig.num_candidates)
    parser.add_argument("--threads", type=int, default=1)
    parser.add_argument("--seed", type=int, default=0)
    parser.add_argument("--output", type=Path,
                        default=Path(__file__).parent / "results" / "planner_speed.json")
    args = parser.parse_args(argv)

    torch.set_num_threads(args.threads)
    config_kwargs = {
        "iterations": args.iterations,
        "mpc_iterations": args.mpc_iterations,
        "num_candidates": args.num_candidates,
    }
    runs = [(env, args.plan_length) for env in args.envs]
    if "planar" in args.envs and ("planar", PLANAR_PAPER_PLAN_LENGTH) not in runs:
        runs.append(("planar", PLANAR_PAPER_PLAN_LENGTH))
    runs += [(SWEEP_ENV, length) for length in args.sweep if (SWEEP_ENV, length) not in runs]
    rows = []
    for env, length in runs:
        row = measure(env, length, args.steps, config_kwargs, args.seed)
        rows.append(row)
        target = f" (target <= {row['target_ms']})" if row["target_ms"] else ""
        print(f"{env:15s} T={length:4d} nz={row['latent_dim']} nu={row['action_dim']}: "
              f"{row['ms_per_step']:8.2f} ms/step{target}, first step {row['first_step_ms']:.1f} "
              f"ms", flush=True)
    args.output.parent.mkdir(parents=True, exist_ok=True)
    payload = {
        "benchmark": "planner_speed",
        "torch": torch.__version__,
        "python": platform.python_version(),
        "machine": platform.machine(),
        "rows": rows,
    }
    args.output.write_text(json.dumps(payload, indent=2) + "\n")
    print(f"wrote {args.output}")


if __name__ == "__main__":
    main()
