"""Latent iLQR-MPC planner speed: milliseconds per MPC step in closed loop.

For each domain, a random (fixed-seed) ReLU MLP transition of the paper's size for that
domain plays both the planner's model and the system, and ``LatentMPC`` drives it from a
random latent state towards a random goal for ``--steps`` steps with the domain's own planner
settings (``pcc_agent.presets``: horizon, replanning interval, iterations, candidates). The
first step plans from scratch (``num_candidates`` plans, ``iterations`` iterations); the
others refine the shifted previous plan (``mpc_iterations`` iterations) or, between replans,
execute it. Reported per domain: the median and mean milliseconds per step (the mean is what
an episode costs), the first step, and, once per process, the one-off cost of loading the
compiled planner loops (``warmup_ms``: numba, cached on disk after the very first run in an
environment; compiling them takes seconds that first time). The warm-up is paid by a tiny plan
before any timing, so it never hides in a domain's first step.

Threads: ``torch.set_num_threads(--threads)`` (default 1). The planner's tensors are tiny, so
more intra-op threads only add synchronization overhead; one thread per planner is also what
several environments or engineers sharing a machine should use.

Usage:
    python -m pcc_bench.planner_speed                 # every domain + plan-length sweep
    python -m pcc_bench.planner_speed --envs planar --steps 40
"""

from __future__ import annotations

import dataclasses
import json
import platform
import statistics
import time
from pathlib import Path

import torch

from pcc_agent.io import atomic_write_text
from pcc_agent.planning import LatentMPC, MLPDynamics, PlannerConfig, QuadraticCost
from pcc_agent.presets import get_preset
from pcc_bench.arguments import command_parser
from pcc_bench.paths import COMMITTED_RESULTS_DIR
from pcc_bench.records import cpu_name

# domain: (env id, latent_dim, action_dim, transition hidden sizes) from the paper's
# architectures.
PRESETS: dict[str, tuple[str, int, int, tuple[int, ...]]] = {
    "planar": ("pcc/Planar-v0", 2, 2, (20, 20)),
    "pendulum": ("pcc/PendulumSwingUp-v0", 3, 1, (30, 30)),
    "cartpole": ("pcc/CartPole-v0", 8, 1, (40, 40)),
    "two_link_arm": ("pcc/TwoLink-v0", 8, 2, (40, 40)),
    "three_link_arm": ("pcc/ThreeLink-v0", 8, 3, (40, 40)),
    "lane_keeping": ("pcc/LaneKeeping-v0", 8, 1, (40, 40)),
}
SWEEP_ENV = "cartpole"
SWEEP_PLAN_LENGTHS = (10, 50, 200)
#: Target: at most 20 ms per step (mean) for an 8-d latent space at every domain's horizon.
TARGET_MS = 20.0


def warm_up() -> float:
    """Milliseconds of the first-ever plan in this process (loading the compiled loops)."""
    config = PlannerConfig(plan_length=2, iterations=1, num_candidates=1)
    dynamics = MLPDynamics.random(2, 1, (4,), torch.Generator().manual_seed(0))
    mpc = LatentMPC(dynamics, QuadraticCost.from_config(config, torch.zeros(2), 1), config)
    start = time.perf_counter()
    mpc.act(torch.ones(2))
    return 1e3 * (time.perf_counter() - start)


def measure(env: str, steps: int, seed: int, plan_length: int | None = None,
            overrides: dict | None = None) -> dict:
    """Closed-loop MPC episode on a random MLP latent system; timing statistics.

    The planner settings are the domain's preset, with ``plan_length`` (and the
    ``overrides``) replacing the preset's where given.
    """
    env_id, latent_dim, action_dim, hidden = PRESETS[env]
    config = get_preset(env_id).planner
    if plan_length is not None:
        config = dataclasses.replace(config, plan_length=plan_length,
                                     replan_every=min(config.replan_every, plan_length))
    config = dataclasses.replace(config, **(overrides or {}))
    generator = torch.Generator().manual_seed(seed)
    dynamics = MLPDynamics.random(latent_dim, action_dim, hidden, generator)
    goal = torch.randn(latent_dim, generator=generator)
    z = torch.randn(latent_dim, generator=generator)
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
        "env_id": env_id,
        "plan_length": config.plan_length,
        "replan_every": config.replan_every,
        "latent_dim": latent_dim,
        "action_dim": action_dim,
        "hidden": list(hidden),
        "iterations": config.iterations,
        "mpc_iterations": config.mpc_iterations,
        "num_candidates": config.num_candidates,
        "num_extreme": config.num_extreme,
        "line_search_steps": len(config.line_search_steps),
        "steps": steps,
        "ms_per_step": round(statistics.median(times), 3),
        "mean_ms_per_step": round(statistics.fmean(times), 3),
        "first_step_ms": round(times[0], 3),
        "max_ms": round(max(times), 3),
        "final_distance": round(float(torch.linalg.norm(z - goal)), 4),
        "threads": torch.get_num_threads(),
        "target_ms": TARGET_MS if latent_dim == 8 else None,
    }


def main(argv: list[str] | None = None) -> None:
    """Entry point of ``python -m pcc_bench.planner_speed``."""
    parser = command_parser(__doc__, "pcc_bench.planner_speed")
    parser.add_argument("--envs", nargs="+", default=list(PRESETS), choices=list(PRESETS))
    parser.add_argument("--sweep", nargs="*", type=int, default=list(SWEEP_PLAN_LENGTHS),
                        help=f"plan lengths for the {SWEEP_ENV} (8-d latent) sweep; empty: none")
    parser.add_argument("--steps", type=int, default=50, help="MPC steps per episode")
    parser.add_argument("--threads", type=int, default=1)
    parser.add_argument("--seed", type=int, default=0)
    parser.add_argument("--output", type=Path,
                        default=COMMITTED_RESULTS_DIR / "planner_speed.json")
    args = parser.parse_args(argv)

    torch.set_num_threads(args.threads)
    warmup_ms = warm_up()
    print(f"loading the compiled planner loops (once per process): {warmup_ms:.0f} ms")
    runs: list[tuple[str, int | None]] = [(env, None) for env in args.envs]
    runs += [(SWEEP_ENV, length) for length in args.sweep]
    rows = []
    for env, length in runs:
        row = measure(env, args.steps, args.seed, length)
        row["sweep"] = length is not None
        rows.append(row)
        target = f" (target <= {row['target_ms']:g})" if row["target_ms"] else ""
        print(f"{env:15s} T={row['plan_length']:4d} replan {row['replan_every']:2d} "
              f"nz={row['latent_dim']} nu={row['action_dim']}: {row['mean_ms_per_step']:8.2f} "
              f"ms/step mean{target}, median {row['ms_per_step']:.2f}, first step "
              f"{row['first_step_ms']:.1f} ms", flush=True)
    args.output.parent.mkdir(parents=True, exist_ok=True)
    payload = {
        "benchmark": "planner_speed",
        "command": "python -m pcc_bench.planner_speed" + (
            " " + " ".join(argv) if argv else ""),
        "torch": torch.__version__,
        "python": platform.python_version(),
        "machine": platform.machine(),
        "processor": cpu_name(),
        "warmup_ms": round(warmup_ms, 1),
        "rows": rows,
    }
    atomic_write_text(json.dumps(payload, indent=2) + "\n", args.output)
    print(f"wrote {args.output}")


if __name__ == "__main__":
    main()
