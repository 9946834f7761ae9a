"""How soon does a Planar latent space form? R^2 of position on the latent means, per epoch.

Trains a PCC model on Planar (the paper's networks by default) with optional recipe overrides
and, every ``--every`` epochs, fits a quadratic regression of the true agent position on the
encoder means of ``--probe`` training images: R^2 near 1 means the latent space is a smooth
chart of the plane, near 0 that it is still collapsed. Also logs the validation loss, the
spread of the latent means and the mean encoder standard deviation.

Usage:
    python -m pcc_bench.latent_formation --epochs 60
    python -m pcc_bench.latent_formation --epochs 60 --variant fast
    python -m pcc_bench.latent_formation --epochs 60 --model input_standardization=true
"""

from __future__ import annotations

import dataclasses
import json
import sys
import time
from pathlib import Path
from typing import Any

import numpy as np
import torch

from pcc_agent.io import atomic_write_text
from pcc_agent.model import EmbeddingModel
from pcc_agent.presets import VARIANTS, get_preset
from pcc_agent.training import train_embedding
from pcc_bench.arguments import command_parser

ENV_ID = "pcc/Planar-v0"


def _parse_overrides(items: list[str]) -> dict[str, Any]:
    """``key=value`` pairs, values parsed as JSON (``true``, ``20``, ``1e-3``)."""
    out: dict[str, Any] = {}
    for item in items:
        key, sep, value = item.partition("=")
        if not sep:
            raise SystemExit(f"Override {item!r} is not of the form key=value.")
        out[key] = json.loads(value)
    return out


def position_r2(model: EmbeddingModel, obs: torch.Tensor, states: np.ndarray) -> dict[str, float]:
    """R^2 of a quadratic regression of ``states`` on the latent means, and latent statistics."""
    with torch.no_grad():
        mean, logvar = model.encode(obs)
    z = mean.double().numpy()
    features = [np.ones((len(z), 1)), z, z**2]
    features += [z[:, i : i + 1] * z[:, j : j + 1]
                 for i in range(z.shape[1]) for j in range(i + 1, z.shape[1])]
    design = np.concatenate(features, axis=1)
    coef, *_ = np.linalg.lstsq(design, states, rcond=None)
    residual = states - design @ coef
    return {
        "r2": float(1.0 - residual.var(0).sum() / states.var(0).sum()),
        "latent_spread": float(z.std(0).mean()),
        "encoder_std": float(torch.exp(0.5 * logvar).mean()),
    }


def main(argv: list[str] | None = None) -> None:
    parser = command_parser(__doc__, "pcc_bench.latent_formation")
    parser.add_argument("--epochs", type=int, default=60)
    parser.add_argument("--every", type=int, default=5)
    parser.add_argument("--variant", default="paper", choices=VARIANTS)
    parser.add_argument("--model", nargs="*", default=[], help="ModelConfig overrides key=value")
    parser.add_argument("--train", nargs="*", default=[], help="TrainConfig overrides key=value")
    parser.add_argument("--seed", type=int, default=0, help="data and model seed")
    parser.add_argument("--probe", type=int, default=1000, help="images for the regression")
    parser.add_argument("--data-dir", default=None)
    parser.add_argument("--output", type=Path, default=None)
    args = parser.parse_args(argv)

    torch.set_num_threads(1)
    from pcc_envs.data import load_or_collect

    preset = get_preset(ENV_ID, args.variant)
    model_config = dataclasses.replace(preset.model, **_parse_overrides(args.model))
    train_config = dataclasses.replace(preset.train, epochs=args.epochs, patience=0,
                                       **_parse_overrides(args.train))
    data = load_or_collect(ENV_ID, preset.data.num_samples, seed=args.seed,
                           cache_dir=args.data_dir)
    model = EmbeddingModel(data.obs.shape[1:], data.action.shape[1], model_config,
                           seed=args.seed)
    probe_obs = torch.as_tensor(data.obs[: args.probe])
    probe_states = data.state[: args.probe]
    rows: list[dict[str, float]] = []
    start = time.perf_counter()

    def log(epoch: int, metrics: dict[str, float]) -> None:
        if epoch % args.every and epoch != args.epochs:
            return
        row = {"epoch": epoch, "seconds": round(time.perf_counter() - start, 1),
               "val_loss": metrics["val_loss"], **position_r2(model, probe_obs, probe_states)}
        rows.append(row)
        print(json.dumps(row), flush=True)

    train_embedding(model, data, train_config, method="pcc", device="cpu", seed=args.seed,
                    progress_bar=False, epoch_callback=log)
    if args.output is not None:
        args.output.parent.mkdir(parents=True, exist_ok=True)
        payload = {"command": "python -m pcc_bench.latent_formation "
                   + " ".join(argv if argv is not None else sys.argv[1:]),
                   "model_config": model_config.to_dict(), "train_config": train_config.to_dict(),
                   "rows": rows}
        atomic_write_text(json.dumps(payload, indent=1) + "\n", args.output)


if __name__ == "__main__":
    main()
