"""Latent maps (paper Figure 2) of saved agents, e.g. the reproduction grid's checkpoints.

The grid draws the maps of its first two models per method as it trains; this draws them for
any saved agent afterwards (the best model, a failed one), one PNG per checkpoint, named
after the checkpoint file.

Usage (``C=results/reproduce/checkpoints/runs/paper-fast/pcc_Planar-v0/noise0.0``):
    python -m pcc_bench.latent_maps $C/pcc/seed3.pt $C/pcc/seed6.pt \
        --out results/reproduce/latent_maps/paper-fast --prefix Planar-v0_pcc_noise0.0_
"""

from __future__ import annotations

import argparse
import sys
from collections.abc import Sequence
from pathlib import Path

from pcc_bench.arguments import command_parser


def build_parser() -> argparse.ArgumentParser:
    """The command-line interface."""
    parser = command_parser(__doc__, "pcc_bench.latent_maps")
    parser.add_argument("checkpoints", type=Path, nargs="+", help="Agents saved by PCCAgent.save.")
    parser.add_argument("--out", type=Path, required=True, help="Folder for the PNG files.")
    parser.add_argument("--prefix", default="", help="Prepended to each PNG's name.")
    parser.add_argument("--num-states", type=int, default=800)
    return parser


def main(argv: Sequence[str] | None = None) -> int:
    """Entry point of ``python -m pcc_bench.latent_maps``."""
    args = build_parser().parse_args(argv)
    from pcc_agent.agent import PCCAgent
    from pcc_agent.plots import plot_env_latent_map

    missing = [str(p) for p in args.checkpoints if not p.is_file()]
    if missing:
        raise SystemExit(f"No such checkpoint file: {', '.join(missing)}")
    args.out.mkdir(parents=True, exist_ok=True)
    for path in args.checkpoints:
        agent = PCCAgent.load(path)
        png = args.out / f"{args.prefix}{path.stem}.png"
        plot_env_latent_map(agent, png, title=f"{agent.method} {path.stem}",
                            num_states=args.num_states)
        print(png)
    return 0


if __name__ == "__main__":
    sys.exit(main())
