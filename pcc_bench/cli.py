"""The ``pcc`` command: train, evaluate, reproduce the paper, compare with SAC, measure.

``pcc <command> [options]`` runs the command module ``pcc_bench.<module>`` (the same as
``python -m pcc_bench.<module> [options]``); ``pcc <command> --help`` lists its options and
examples; ``pcc --version`` prints the version.
"""

from __future__ import annotations

import importlib
import sys
from collections.abc import Sequence

from pcc_bench.arguments import invoked_as

#: ``pcc <command>``: (module run, one-line description).
COMMANDS: dict[str, tuple[str, str]] = {
    "train": ("pcc_bench.train", "train one agent (PCC, E2C, RCE, ...) on an env and save it"),
    "evaluate": ("pcc_bench.evaluate",
                 "% of steps in goal of a saved or pretrained agent on 10 evaluation tasks"),
    "reproduce": ("pcc_bench.reproduce",
                  "reproduce the paper's tables: N models x M tasks, resumable"),
    "vs-sac": ("pcc_bench.vs_sac", "SAC (Stable-Baselines3) on the same images, tasks, metric"),
    "diagnostics": ("pcc_bench.latent_diagnostics",
                    "latent diagnostics of the grid's models beside their control"),
    "speed": ("", "timings: 'pcc speed train', 'pcc speed planner', 'pcc speed env'"),
    "floor": ("pcc_bench.no_action_floor", "the no-action floor (zero actions) of every env"),
    "planner-sweep": ("pcc_bench.planner_sweep",
                      "control quality over a grid of planner settings"),
    "latent-maps": ("pcc_bench.latent_maps", "latent maps (paper Figure 2) of saved agents"),
    "export-weights": ("pcc_bench.weights",
                       "float16 weights for a grid's older records, re-evaluated with them"),
}
#: ``pcc speed <what>``: (module run, one-line description).
SPEED_COMMANDS: dict[str, tuple[str, str]] = {
    "train": ("pcc_bench.train_speed", "seconds per training epoch (and to converge)"),
    "planner": ("pcc_bench.planner_speed", "milliseconds per MPC step of each domain's planner"),
    "env": ("pcc_bench.env_speed", "env steps and data-set samples per second"),
    "control": ("pcc_bench.time_to_control",
                "time to control: % in goal against minutes of training"),
    "threads": ("pcc_bench.train_threads",
                "two one-thread trainings at once against one two-thread training"),
}

EXAMPLES = """examples:
  pcc evaluate planar-pcc                       # a shipped pretrained agent, in seconds
  pcc train --env pcc/Planar-v0                 # a PCC agent, saved under pcc_results/models
  pcc evaluate pcc_results/models/Planar-v0_pcc_seed0.pt
  pcc reproduce --preset quick                  # Planar, PCC, a few minutes on 2 CPU cores
  pcc vs-sac --env pcc/Planar-v0 --steps 20000
  pcc speed planner --envs pcc/Planar-v0"""


def _version() -> str:
    import pcc_agent

    return f"pcc-control {pcc_agent.__version__}"


def _listing(prog: str, commands: dict[str, tuple[str, str]], examples: str = "") -> str:
    width = max(len(name) for name in commands) + 2
    lines = [f"usage: {prog} <command> [options]", "", "commands:"]
    lines += [f"  {name.ljust(width)}{text}" for name, (_, text) in commands.items()]
    lines += ["", f"Run '{prog} <command> --help' for the options and examples of a command."]
    if examples:
        lines += ["", examples]
    return "\n".join(lines)


def _run(module: str, prog: str, argv: list[str]) -> int:
    with invoked_as(prog):
        result = importlib.import_module(module).main(argv)
    return result if isinstance(result, int) else 0


def _dispatch(prog: str, commands: dict[str, tuple[str, str]], argv: list[str],
              examples: str = "") -> int:
    if not argv or argv[0] in ("-h", "--help"):
        print(_listing(prog, commands, examples))
        return 0
    name, rest = argv[0], argv[1:]
    if name not in commands:
        print(f"{prog}: unknown command {name!r}\n\n{_listing(prog, commands)}",
              file=sys.stderr)
        return 2
    module = commands[name][0]
    if not module:  # a group: pcc speed <what>
        return _dispatch(f"{prog} {name}", SPEED_COMMANDS, rest)
    return _run(module, f"{prog} {name}", rest)


def main(argv: Sequence[str] | None = None) -> int:
    """Entry point of ``pcc``: ``pcc --version``, ``pcc <command> [options]``."""
    args = list(sys.argv[1:] if argv is None else argv)
    if args and args[0] in ("-V", "--version"):
        print(_version())
        return 0
    return _dispatch("pcc", COMMANDS, args, EXAMPLES)


if __name__ == "__main__":
    sys.exit(main())
