"""Train one agent (PCC, E2C, RCE or an ablation) on an environment and save it.

The agent collects its data set with the env's sampler (cached on disk, see ``--data-dir``),
trains its embedding with the preset of the env (``--variant``), shows a progress bar over
epochs and saves itself to ``--output``; ``pcc evaluate`` then runs its control tasks.

Examples:
    python -m pcc_bench.train --env pcc/Planar-v0
    python -m pcc_bench.train --env pcc/Planar-v0 --method e2c --samples 2000 --epochs 20 \
        --output planar_e2c.pt
    python -m pcc_bench.train --env pcc/Planar-v0 --keep-best-control 25
    python -m pcc_bench.train --env pcc/CartPole-v1 --variant motion --prediction-horizon 3
"""

from __future__ import annotations

import argparse
import sys
import time
from collections.abc import Sequence
from pathlib import Path

from pcc_bench.arguments import command_parser, known_envs, positive_int
from pcc_bench.paths import DEFAULT_RESULTS_ROOT

DEFAULT_MODELS_DIR = DEFAULT_RESULTS_ROOT / "models"


def default_output(env_id: str, method: str, seed: int) -> Path:
    """Where ``pcc train`` saves an agent by default."""
    return DEFAULT_MODELS_DIR / f"{env_id.split('/')[-1]}_{method}_seed{seed}.pt"


def build_parser() -> argparse.ArgumentParser:
    """The command-line interface."""
    from pcc_agent.losses import METHODS
    from pcc_agent.presets import VARIANTS

    parser = command_parser(__doc__, "pcc_bench.train")
    parser.add_argument("--env", default="pcc/Planar-v0", metavar="ENV_ID",
                        help="A registered env id (default: %(default)s; with a preset: "
                        f"{', '.join(known_envs())}).")
    parser.add_argument("--method", default="pcc", choices=sorted(METHODS),
                        help="The embedding objective (default: %(default)s).")
    parser.add_argument("--variant", default="fast", choices=VARIANTS,
                        help="Preset variant: 'paper' (the paper's networks), 'fast' "
                        "(CPU-friendly; default) or 'motion' (the CNN domains' CPU CNN "
                        "seeing each frame's motion).")
    parser.add_argument("--seed", type=int, default=0, help="Seed of data, weights, batches.")
    parser.add_argument("--samples", type=positive_int, default=None,
                        help="Transitions in the data set (default: the preset's).")
    parser.add_argument("--epochs", type=positive_int, default=None,
                        help="Epoch cap (default: the preset's; early stopping may end sooner).")
    parser.add_argument("--device", default="auto", help="'auto', 'cpu', 'cuda', ...")
    parser.add_argument("--data-dir", default=None,
                        help="Dataset cache (default: PCC_DATA_DIR or "
                        "~/.cache/pcc_control/datasets).")
    parser.add_argument("--output", type=Path, default=None,
                        help=f"The saved agent (default: {DEFAULT_MODELS_DIR}/"
                        "<env>_<method>_seed<seed>.pt).")
    parser.add_argument("--keep-best-control", type=positive_int, default=None, metavar="EVERY",
                        help="Score control on 5 validation tasks (task seed 2021) every EVERY "
                        "epochs and save the weights that score best, instead of those of the "
                        "lowest validation loss (pcc_agent.callbacks.KeepBestControl).")
    parser.add_argument("--prediction-horizon", type=positive_int, default=None, metavar="K",
                        help="Also train the multi-step prediction term over K >= 2 steps "
                        "(TrainConfig.prediction_horizon; not the paper's objective).")
    parser.add_argument("--no-progress", action="store_true", help="No progress bar.")
    return parser


def main(argv: Sequence[str] | None = None) -> int:
    """Entry point of ``python -m pcc_bench.train`` and ``pcc train``."""
    args = build_parser().parse_args(argv)
    from pcc_agent.agent import PCCAgent
    from pcc_agent.presets import get_preset

    preset = get_preset(args.env, args.variant) if args.env in known_envs() else args.variant
    changes = {name: value for name, value in (("epochs", args.epochs),
                                               ("prediction_horizon", args.prediction_horizon))
               if value is not None}
    if changes:
        if isinstance(preset, str):
            raise SystemExit(f"--{next(iter(changes)).replace('_', '-')} needs a preset; "
                             f"{args.env!r} has none.")
        if changes.get("prediction_horizon") == 1:
            raise SystemExit("--prediction-horizon must be at least 2 (1 is the paper's "
                             "one-step objective: leave the option out).")
        preset = preset.with_training(**changes)
    keep = None
    if args.keep_best_control is not None:
        if isinstance(preset, str):
            raise SystemExit(f"--keep-best-control needs an env with control tasks; "
                             f"{args.env!r} has none.")
        from pcc_agent.callbacks import KeepBestControl, validation_task_score

        keep = KeepBestControl(validation_task_score(args.env), every=args.keep_best_control)
    agent = PCCAgent(args.env, method=args.method, preset=preset, seed=args.seed,
                     device=args.device, data_cache_dir=args.data_dir)
    start = time.perf_counter()
    agent.learn(total_timesteps=args.samples, progress_bar=not args.no_progress, callback=keep)
    seconds = time.perf_counter() - start
    if keep is not None:
        scores = ", ".join(f"{'final' if epoch < 0 else epoch} {score:.1f}"
                           for epoch, score in keep.history)
        kept = "the lowest validation loss's" if keep.best_epoch == -1 else (
            f"epoch {keep.best_epoch}'s")
        print(f"Validation control (% in goal, 5 tasks) by epoch: {scores}; kept {kept} "
              "weights.")
    output = args.output or default_output(agent.env_id, args.method, args.seed)
    agent.save(output)
    # The progress bar already printed why training stopped; without it, say it here.
    message = agent.train_summary().get("message", "")
    print(f"Trained {args.method} on {agent.env_id} in {seconds:.0f} s"
          + (f": {message}." if args.no_progress and message else "."))
    print(f"Saved {output}\nEvaluate it: pcc evaluate {output}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
