"""Two one-thread trainings at once against one two-thread training: which uses 2 cores better.

Trains the quick preset's Planar recipe for ``--epochs`` epochs three ways, each in fresh
processes: one training on one thread alone, one on two threads alone, and two one-thread
trainings at the same time. Prints and writes seconds per epoch of each training and the
epochs per second of all of them together (the throughput of a grid).

Example:
    python -m pcc_bench.train_threads --epochs 30 --output results/train_threads.json
"""

from __future__ import annotations

import argparse
import json
import subprocess
import sys
import time
from collections.abc import Sequence
from pathlib import Path

from pcc_bench.arguments import command_parser, positive_int

#: The ways to use two cores: (threads, model seed) per training started together.
LAYOUTS = {
    "1 thread alone": [(1, 0)],
    "2 threads alone": [(2, 0)],
    "2 x 1 thread at once": [(1, 0), (1, 1)],
}


def seconds_per_epoch(threads: int, seed: int, epochs: int) -> float:
    """Train the quick Planar recipe on ``threads`` threads; its mean seconds per epoch."""
    import torch

    torch.set_num_threads(threads)
    from pcc_agent.agent import PCCAgent
    from pcc_agent.presets import get_preset

    preset = get_preset("pcc/Planar-v0", "fast").with_training(
        lr=1.5e-3, epochs=epochs, patience=100, min_epochs=0)
    agent = PCCAgent("pcc/Planar-v0", preset=preset, seed=seed)
    agent.learn()
    assert agent.train_result is not None
    value = agent.train_result.seconds_per_epoch()
    assert value is not None
    return value


def _start(threads: int, seed: int, epochs: int) -> subprocess.Popen:
    return subprocess.Popen([sys.executable, "-m", "pcc_bench.train_threads", "--one",
                             str(threads), str(seed), "--epochs", str(epochs)],
                            stdout=subprocess.PIPE, text=True)


def build_parser() -> argparse.ArgumentParser:
    """The command-line interface."""
    parser = command_parser(__doc__, "pcc_bench.train_threads")
    parser.add_argument("--epochs", type=positive_int, default=30)
    parser.add_argument("--output", type=Path, default=None, help="JSON file to write")
    parser.add_argument("--one", nargs=2, type=int, metavar=("THREADS", "SEED"),
                        help=argparse.SUPPRESS)  # one training, in a worker process
    return parser


def main(argv: Sequence[str] | None = None) -> int:
    """Entry point of ``python -m pcc_bench.train_threads`` and ``pcc speed threads``."""
    args = build_parser().parse_args(argv)
    if args.one:
        print(json.dumps(seconds_per_epoch(*args.one, args.epochs)))
        return 0
    from pcc_agent.io import atomic_write_json, versions
    from pcc_bench.records import machine_info

    _start(1, 9, 1).wait()  # collect the data set into the cache before timing anything
    rows = {}
    for name, jobs in LAYOUTS.items():
        start = time.perf_counter()
        processes = [_start(threads, seed, args.epochs) for threads, seed in jobs]
        per_epoch = [json.loads(p.communicate()[0].strip().splitlines()[-1]) for p in processes]
        rows[name] = {"seconds_per_epoch": per_epoch, "wall_s": time.perf_counter() - start,
                      "epochs_per_second_total": sum(1.0 / s for s in per_epoch)}
        print(f"{name:22s} {', '.join(f'{s:.2f}' for s in per_epoch)} s/epoch; "
              f"{rows[name]['epochs_per_second_total']:.2f} epochs/s in all", flush=True)
    if args.output:
        atomic_write_json(args.output, {"command": " ".join(sys.argv), "epochs": args.epochs,
                                        "machine": machine_info(), "versions": versions(),
                                        "rows": rows})
        print(f"wrote {args.output}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
