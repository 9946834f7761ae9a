"""Embedding-model training speed: seconds per epoch and samples per second.

For each environment preset, variant and method, a model is built from the preset and trained
for ``--epochs`` timed epochs (after one warm-up epoch) on ``num_samples`` transitions with the
preset's batch size, without validation, checkpoints or logging. Data are real (from
``pcc_envs.data.load_or_collect``, when ``--real-data`` is given and pcc_envs is importable) or
synthetic (a square moved by the action, rendered at the preset's observation shape: speed
does not depend on image content).

``--prediction-horizon K`` times training with the multi-step prediction term over ``K`` steps
(data hold ``K`` consecutive transitions; rows carry ``prediction_horizon``).

``--mixed-precision bf16`` (or ``auto``: only where the CPU has AMX or AVX512-BF16) times the
bfloat16-autocast variant (rows carry ``mixed_precision`` and ``bf16_autocast``; and
``flush_denormals``, the preset's, on by default).

``--converge`` instead trains PCC on Planar with the paper's settings (validation split, early
stopping) and reports the epochs and wall time until early stopping.

Results go to ``results/train_speed.json`` (a list of rows: env, method, variant,
seconds_per_epoch, samples_per_second, device, threads, num_samples, batch_size, ...; and the
1-minute load average before / after the measurement: on a shared machine, more torch threads
than idle cores make timings collapse, so ``--threads 1`` is the robust setting there).

Usage:
    python -m pcc_bench.train_speed                                  # Planar PCC, paper size
    python -m pcc_bench.train_speed --envs all --variants fast --max-samples 2000
    python -m pcc_bench.train_speed --envs pcc/CartPole-v1 --variants motion --prediction-horizon 5
    python -m pcc_bench.train_speed --converge --real-data --max-epochs 300
"""

from __future__ import annotations

import argparse
import dataclasses
import json
import os
import platform
import statistics
import time
from pathlib import Path
from typing import Any

import numpy as np
import torch

from pcc_agent.config import MIXED_PRECISION_MODES
from pcc_agent.io import atomic_write_text
from pcc_agent.losses import METHODS, model_config_for_method
from pcc_agent.model import EmbeddingModel
from pcc_agent.presets import ACTION_DIMS, OBS_SHAPES, PRESETS, VARIANTS, get_preset
from pcc_agent.training import (
    TransitionArrays,
    resolve_device,
    train_embedding,
    uses_bf16_autocast,
)
from pcc_bench.arguments import command_parser
from pcc_bench.paths import COMMITTED_RESULTS_DIR
from pcc_bench.records import cpu_name

DEFAULT_OUTPUT = COMMITTED_RESULTS_DIR / "train_speed.json"
PLANAR = "pcc/Planar-v0"


def synthetic_data(env_id: str, num_samples: int, seed: int,
                   prediction_horizon: int = 1) -> TransitionArrays:
    """Planar-like transitions: a bright square moved by the action (2-D, extra dims ignored).

    Every frame of an observation shows the square at successive positions (oldest first), so
    multi-frame presets see a velocity too. With ``prediction_horizon`` K above 1, each sample
    holds K consecutive transitions (each further action moves the square on). Good enough
    for timing and for a convergence run when the real environments are not importable.
    """
    rng = np.random.default_rng(seed)
    frames, height, width = OBS_SHAPES[env_id]
    half = max(1, height // 20)
    action = rng.uniform(-1, 1, (num_samples, ACTION_DIMS[env_id]))
    low, high = half, np.array([height, width]) - half - 1
    pos = rng.uniform(low, high, (num_samples, 2))
    further = rng.uniform(-1, 1, (num_samples, prediction_horizon - 1, ACTION_DIMS[env_id]))
    actions = np.concatenate([action[:, None], further], axis=1).astype(np.float32)
    steps = np.zeros((num_samples, prediction_horizon, 2))
    steps[:, :, : min(2, actions.shape[2])] = 2 * half * actions[:, :, :2]
    # positions of the frames of x_t (oldest first), then one frame per action
    track = [np.clip(pos - steps[:, 0] * (frames - 1 - k), low, high) for k in range(frames)]
    for k in range(prediction_horizon):
        track.append(np.clip(track[-1] + steps[:, k], low, high))
    rows = np.arange(height)[None, :, None]
    cols = np.arange(width)[None, None, :]

    def render(centers: np.ndarray) -> np.ndarray:
        r, c = np.round(centers).astype(int).T
        inside = (np.abs(rows - r[:, None, None]) <= half) & (np.abs(cols - c[:, None, None])
                                                               <= half)
        return (255 * inside).astype(np.uint8)

    images = [render(t) for t in track]

    def observation(first: int) -> np.ndarray:
        return np.stack(images[first:first + frames], axis=1)

    if prediction_horizon == 1:
        return TransitionArrays(observation(0), actions[:, 0], observation(1))
    future_obs = np.stack([observation(k) for k in range(2, prediction_horizon + 1)], axis=1)
    return TransitionArrays(observation(0), actions[:, 0], observation(1),
                            np.ascontiguousarray(actions[:, 1:]), future_obs)


def load_data(env_id: str, num_samples: int, seed: int, real: bool,
              prediction_horizon: int = 1) -> tuple[Any, str]:
    """Real data through pcc_envs when requested and available, else synthetic."""
    if real:
        try:
            from pcc_envs.data import load_or_collect
        except ImportError as error:
            print(f"pcc_envs.data unavailable ({error}); using synthetic data")
        else:
            return load_or_collect(env_id, num_samples, seed,
                                   prediction_horizon=prediction_horizon), "real"
    return synthetic_data(env_id, num_samples, seed, prediction_horizon), "synthetic"


def measure(env_id: str, variant: str, method: str, args: argparse.Namespace) -> dict[str, Any]:
    """Time ``args.epochs`` epochs after one warm-up epoch."""
    preset = get_preset(env_id, variant)
    num_samples = min(preset.data.num_samples, args.max_samples or preset.data.num_samples)
    horizon = args.prediction_horizon
    data, source = load_data(env_id, num_samples, args.seed, args.real_data, horizon)
    config = model_config_for_method(preset.model, method)
    model = EmbeddingModel(OBS_SHAPES[env_id], ACTION_DIMS[env_id], config, seed=args.seed)
    train = dataclasses.replace(preset.train, epochs=args.epochs + 1, validation_fraction=0.0,
                                patience=0, seed=args.seed, prediction_horizon=horizon,
                                mixed_precision=args.mixed_precision)
    result = train_embedding(model, data, train, method=method, device=args.device,
                             progress_bar=False)
    if result.diverged:
        raise RuntimeError(f"{env_id} {method}: {result.message}")
    times = [row["time/epoch_seconds"] for row in result.history[1:]]
    seconds = statistics.median(times)
    return {
        "env": env_id, "method": method, "variant": variant,
        "seconds_per_epoch": round(seconds, 4),
        "samples_per_second": round(num_samples / seconds, 1),
        "device": str(resolve_device(args.device)), "threads": torch.get_num_threads(),
        "num_samples": num_samples, "batch_size": train.batch_size,
        "timed_epochs": len(times), "data": source, "prediction_horizon": horizon,
        "mixed_precision": args.mixed_precision,
        "bf16_autocast": uses_bf16_autocast(args.mixed_precision, resolve_device(args.device)),
        "flush_denormals": train.flush_denormals, "cpu": cpu_name(),
        "parameters": sum(p.numel() for p in model.parameters()),
    }


def converge(args: argparse.Namespace) -> dict[str, Any]:
    """Planar PCC, paper settings, trained until early stopping (or ``--max-epochs``)."""
    preset = get_preset(PLANAR, "paper")
    data, source = load_data(PLANAR, preset.data.num_samples, args.seed, args.real_data)
    model = EmbeddingModel(OBS_SHAPES[PLANAR], ACTION_DIMS[PLANAR], preset.model, seed=args.seed)
    train = dataclasses.replace(preset.train, epochs=args.max_epochs, seed=args.seed,
                                patience=args.patience)
    start = time.perf_counter()
    result = train_embedding(model, data, train, method="pcc", device=args.device,
                             progress_bar=not args.no_progress)
    return {
        "env": PLANAR, "method": "pcc", "variant": "paper", "mode": "converge",
        "epochs": result.epochs, "best_epoch": result.best_epoch,
        "converged": result.converged, "wall_time_seconds": round(time.perf_counter() - start, 1),
        "best_validation_loss": round(result.best_validation_loss, 3),
        "seconds_per_epoch": round(result.wall_time / max(result.epochs, 1), 4),
        "samples_per_second": round(
            preset.data.num_samples * result.epochs / max(result.wall_time, 1e-9), 1),
        "device": str(resolve_device(args.device)), "threads": torch.get_num_threads(),
        "num_samples": preset.data.num_samples, "batch_size": train.batch_size, "data": source,
        "message": result.message,
    }


def main(argv: list[str] | None = None) -> list[dict[str, Any]]:
    """Command-line entry point; returns the rows written."""
    parser = command_parser(__doc__, "pcc_bench.train_speed")
    parser.add_argument("--envs", nargs="+", default=[PLANAR],
                        help=f"env ids or 'all' (known: {', '.join(PRESETS)})")
    parser.add_argument("--variants", nargs="+", default=["paper"], choices=VARIANTS)
    parser.add_argument("--methods", nargs="+", default=["pcc"], choices=sorted(METHODS))
    parser.add_argument("--epochs", type=int, default=3, help="timed epochs (plus one warm-up)")
    parser.add_argument("--max-samples", type=int, default=0,
                        help="cap on the preset's data size (0 = the paper's size)")
    parser.add_argument("--threads", type=int, default=0, help="torch threads (0 = default)")
    parser.add_argument("--device", default="cpu", help="cpu, cuda or auto")
    parser.add_argument("--seed", type=int, default=0)
    parser.add_argument("--prediction-horizon", type=int, default=1, metavar="K",
                        help="train with the multi-step prediction term over K steps (1: the "
                             "paper's one-step objective)")
    parser.add_argument("--mixed-precision", default="off", choices=MIXED_PRECISION_MODES,
                        help="bfloat16 autocast: off (float32, the default), bf16, or auto "
                             "(only where the hardware multiplies bfloat16)")
    parser.add_argument("--real-data", action="store_true", help="use pcc_envs.data")
    parser.add_argument("--converge", action="store_true",
                        help="train Planar PCC to early stopping instead")
    parser.add_argument("--max-epochs", type=int, default=500)
    parser.add_argument("--patience", type=int, default=30)
    parser.add_argument("--no-progress", action="store_true")
    parser.add_argument("--output", type=Path, default=DEFAULT_OUTPUT)
    parser.add_argument("--append", action="store_true",
                        help="merge into the output file (rows with the same env, method, "
                             "variant, mode, threads, prediction horizon, mixed precision and "
                             "CPU are replaced)")
    args = parser.parse_args(argv)
    if args.prediction_horizon < 1:
        parser.error(f"--prediction-horizon must be at least 1, got {args.prediction_horizon}")
    if args.threads > 0:
        torch.set_num_threads(args.threads)
    envs = list(PRESETS) if args.envs == ["all"] else args.envs
    rows: list[dict[str, Any]] = []
    if args.converge:
        rows.append(converge(args))
        print(json.dumps(rows[-1]))
    else:
        for env_id in envs:
            for variant in args.variants:
                for method in args.methods:
                    load_before = os.getloadavg()[0]
                    rows.append(measure(env_id, variant, method, args))
                    # other processes on the machine distort timings (threads oversubscribed)
                    rows[-1]["load_average_1min"] = [round(load_before, 2),
                                                     round(os.getloadavg()[0], 2)]
                    print(json.dumps(rows[-1]))
    for row in rows:
        row.update(torch=torch.__version__, machine=platform.machine())
    args.output.parent.mkdir(parents=True, exist_ok=True)
    if args.append and args.output.exists():
        def key(row: dict[str, Any]) -> tuple:
            return (row["env"], row["method"], row["variant"], row.get("mode", "epoch"),
                    row["threads"], row.get("prediction_horizon", 1),
                    row.get("mixed_precision", "off"), row.get("cpu"))

        new_keys = {key(row) for row in rows}
        old = [row for row in json.loads(args.output.read_text()) if key(row) not in new_keys]
        rows = old + rows
    atomic_write_text(json.dumps(rows, indent=2) + "\n", args.output)
    print(f"wrote {args.output}")
    return rows


if __name__ == "__main__":
    main()
