"""The float16 weights behind a run record: written, loaded, and back-filled for old runs.

Every trained run saves its agent twice: a float32 ``.pt`` checkpoint (not committed) and
float16 control-only safetensors weights (``<results-dir>/weights/...``: the encoder and the
latent dynamics, all that control uses; 1.2 MB for a Planar model, small enough to commit).
The record's percentages are those of the agent loaded from the float16 file, so loading
that file reproduces them exactly; the record names the file and its SHA-256 under
``"weights"``.

Records made before this existed were evaluated with float32 weights. This command exports
their float16 weights from the float32 checkpoints, re-evaluates the rounded agents on the
same tasks and updates the records (the float32 results are kept as
``percentages_float32``). Rounding the weights can change a task's outcome: the Planar
``quick`` model 1 went from 0 % to 65 % on one task.

Examples:
    python -m pcc_bench.weights --results-dir results/quick
    pcc export-weights --results-dir results/reproduce --preset paper+max_epochs=150
"""

from __future__ import annotations

import argparse
import sys
from collections.abc import Sequence
from pathlib import Path
from typing import Any

from pcc_agent.io import sha256_of
from pcc_bench.arguments import command_parser
from pcc_bench.records import (
    REFERENCE_METHODS,
    RunSpec,
    checkpoint_path,
    load_finished_run,
    same_planner,
    same_recipe,
    same_spec,
    weights_path,
)

#: Floating-point type of the committed weights.
WEIGHTS_DTYPE = "float16"


def save_half_weights(agent: Any, results_dir: str | Path, spec: RunSpec) -> tuple[Any, dict]:
    """Save ``agent``'s float16 control-only weights for ``spec`` and load them back.

    Returns:
        ``(rounded_agent, weights_entry)``: the agent loaded from the float16 file (the one
        to evaluate) and the record's ``"weights"`` entry (file relative to the results
        directory, dtype, SHA-256).
    """
    from pcc_agent.agent import PCCAgent

    path = weights_path(results_dir, spec)
    agent.save(path, half=True, control_only=True)
    entry = {"file": path.relative_to(results_dir).as_posix(), "dtype": WEIGHTS_DTYPE,
             "parts": "control", "sha256": sha256_of(path)}
    return PCCAgent.load(path), entry


def saved_agent_path(record: dict[str, Any], results_dir: Path, spec: RunSpec) -> Path | None:
    """The file to re-evaluate a record's agent from, or None when none is kept.

    The float16 weights when the record was evaluated with them (they reproduce it), else the
    float32 checkpoint.
    """
    weights = record.get("weights")
    if weights is not None:
        path = results_dir / weights["file"]
        return path if path.exists() else None
    path = checkpoint_path(results_dir, spec)
    return path if path.exists() else None


def record_to_reevaluate(results_dir: Path, spec: RunSpec) -> dict[str, Any] | None:
    """The finished record of a run whose model needs only its control tasks run again.

    That is a record of the run's spec and training recipe, with its weights kept, that was
    evaluated with other planner settings. None where the run is current, untrained, or must
    train again. Reads the record once.
    """
    if spec.method in REFERENCE_METHODS:
        return None
    trained = load_finished_run(Path(results_dir) / spec.relative_path)
    if (trained is None or not same_spec(trained.get("spec"), spec)
            or not same_recipe(trained, spec)
            or same_planner(trained, spec)  # current: nothing to run again
            or saved_agent_path(trained, Path(results_dir), spec) is None):
        return None
    return trained


def export_run(path: Path, results_dir: Path) -> str:
    """Give one finished record float16 weights (see the module docstring); a status word."""
    from pcc_agent.evaluation import evaluate_control
    from pcc_agent.io import atomic_write_json

    record = load_finished_run(path)
    if record is None:
        return "unfinished"
    spec = RunSpec(**record["spec"])
    if spec.method in REFERENCE_METHODS:
        return "reference"
    if record.get("weights") is not None:
        return "has weights"
    source = checkpoint_path(results_dir, spec)
    if not source.exists():
        return "no checkpoint"
    from pcc_agent.agent import PCCAgent

    agent, entry = save_half_weights(PCCAgent.load(source), results_dir, spec)
    env_kwargs = spec.env_kwargs
    evaluation = evaluate_control(agent, spec.env_id, record["task_seeds"], env_kwargs)
    record = dict(record)
    record["percentages_float32"] = record["percentages"]
    record["mean_float32"] = record["mean"]
    record["percentages"] = [t.percent_in_goal for t in evaluation.tasks]
    record["tasks"] = [t.to_dict() for t in evaluation.tasks]
    record["mean"] = evaluation.mean
    record["weights"] = entry
    record["weights_command"] = " ".join(sys.argv)
    atomic_write_json(path, record)
    return f"exported: {record['mean_float32']:.1f} % (float32) -> {record['mean']:.1f} %"


def build_parser() -> argparse.ArgumentParser:
    """The command-line interface."""
    parser = command_parser(__doc__, "pcc_bench.weights")
    parser.add_argument("--results-dir", type=Path, required=True,
                        help="Results directory of a grid (its runs/ and checkpoints/).")
    parser.add_argument("--preset", default=None,
                        help="Only the runs of this preset label (default: all).")
    return parser


def main(argv: Sequence[str] | None = None) -> int:
    """Entry point of ``python -m pcc_bench.weights`` and ``pcc export-weights``."""
    import torch

    args = build_parser().parse_args(argv)
    torch.set_num_threads(1)  # the evaluations of the grid ran on one thread
    runs = args.results_dir / "runs"
    if not runs.is_dir():
        raise SystemExit(f"No runs/ directory in {args.results_dir}.")
    pattern = f"{args.preset}/**/*.json" if args.preset else "**/*.json"
    paths = sorted(runs.glob(pattern))
    if not paths:
        raise SystemExit(f"No run records match {runs / pattern}.")
    for path in paths:
        print(f"{path.relative_to(args.results_dir)}: {export_run(path, args.results_dir)}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
