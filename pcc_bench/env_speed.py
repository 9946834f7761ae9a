"""Environment and dataset-sampler speed for every registered environment.

For each id: ``steps_per_second`` is ``env.step`` (dynamics + rendering + info) through
``gym.make`` (so including Gymnasium's wrappers and episode resets) with uniform random
actions drawn beforehand; ``samples_per_second`` is :func:`pcc_envs.data.collect_transitions`
(the paper's uniform protocol, three rendered frames per two-frame sample). Each number is
the best of ``--repeats`` timed runs after a warm-up (render tables are built in the warm-up).

Targets (one core): >= 10,000 steps/s Planar, >= 3,000 pendulum, cart-pole and arms; the
sampler at >= 10x the public reference sampler (Planar 14,700 samples/s, Pendulum 15,000,
CartPole 12,400, 3-link 2,120).

Results go to ``results/env_speed.json`` (a list of rows: env, steps_per_second,
samples_per_second, threads, machine, steps, samples).

Usage:
    python -m pcc_bench.env_speed                      # all ids, one thread
    python -m pcc_bench.env_speed --envs pcc/Planar-v0 --samples 50000
"""

from __future__ import annotations

import argparse
import json
import os
import platform
import time
from pathlib import Path
from typing import Any

from pcc_agent.io import atomic_write_text
from pcc_bench.arguments import command_parser
from pcc_bench.paths import COMMITTED_RESULTS_DIR

_THREAD_VARS = ("OMP_NUM_THREADS", "OPENBLAS_NUM_THREADS", "MKL_NUM_THREADS")


def parse_args(argv: list[str] | None = None) -> argparse.Namespace:
    parser = command_parser(__doc__, "pcc_bench.env_speed")
    parser.add_argument("--envs", nargs="*", default=None, help="ids (default: all registered)")
    parser.add_argument("--steps", type=int, default=4000, help="env steps per timed run")
    parser.add_argument("--samples", type=int, default=20000, help="samples per timed run")
    parser.add_argument(
        "--lane-steps", type=int, default=300, help="steps/samples for the slow Bullet env"
    )
    parser.add_argument("--repeats", type=int, default=3, help="timed runs; the best is kept")
    parser.add_argument("--threads", type=int, default=1, help="numpy/OpenCV threads")
    parser.add_argument(
        "--output", type=Path, default=COMMITTED_RESULTS_DIR / "env_speed.json"
    )
    return parser.parse_args(argv)


def _best(fn: Any, repeats: int) -> float:
    fn()
    best = float("inf")
    for _ in range(repeats):
        start = time.perf_counter()
        fn()
        best = min(best, time.perf_counter() - start)
    return best


def main(argv: list[str] | None = None) -> list[dict[str, Any]]:
    args = parse_args(argv)
    for var in _THREAD_VARS:  # before numpy is imported
        os.environ[var] = str(args.threads)
    import cv2
    import gymnasium as gym
    import numpy as np

    import pcc_envs
    from pcc_envs.data import collect_transitions

    cv2.setNumThreads(args.threads)
    machine = (
        f"{platform.machine()} {platform.processor() or platform.node()}, {os.cpu_count()} cpus"
    )
    rows = []
    for env_id in args.envs or list(pcc_envs.ENV_IDS):
        slow = not gym.make(env_id).unwrapped.supports_oracle
        steps = args.lane_steps if slow else args.steps
        samples = args.lane_steps if slow else args.samples
        env = gym.make(env_id)
        env.reset(seed=0)
        env.action_space.seed(0)
        actions = [env.action_space.sample() for _ in range(steps)]

        def run_steps(env: Any = env, actions: list[Any] = actions) -> None:
            env.reset(seed=0)
            for action in actions:
                _, _, terminated, truncated, _ = env.step(action)
                if terminated or truncated:
                    env.reset()

        step_time = _best(run_steps, args.repeats)
        env.close()
        sample_time = _best(
            lambda env_id=env_id, samples=samples: collect_transitions(env_id, samples, seed=0),
            args.repeats,
        )
        row = {
            "env": env_id,
            "steps_per_second": round(steps / step_time, 1),
            "samples_per_second": round(samples / sample_time, 1),
            "threads": args.threads,
            "machine": machine,
            "steps": steps,
            "samples": samples,
            "numpy": np.__version__,
        }
        print(json.dumps(row))
        rows.append(row)
    args.output.parent.mkdir(parents=True, exist_ok=True)
    atomic_write_text(json.dumps(rows, indent=2) + "\n", args.output)
    print(f"wrote {args.output}")
    return rows


if __name__ == "__main__":
    main()
