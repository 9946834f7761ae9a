"""The ``pcc`` command: the project's main jobs from the shell.

``pcc reproduce [options]`` runs the reproduction pipeline (see ``benchmarks/reproduce.py``;
``pcc reproduce --help`` lists the options). With no options it runs the ``quick`` preset:
Planar, PCC, a few minutes on 2 CPU cores, and prints the percentage of steps in goal and
where it wrote its table and plots.
"""

from __future__ import annotations

import sys
from collections.abc import Sequence

USAGE = """usage: pcc <command> [options]

commands:
  reproduce   reproduce the paper's tables (default preset: quick, Planar + PCC)

Run 'pcc <command> --help' for the options of a command."""


def main(argv: Sequence[str] | None = None) -> int:
    """Dispatch ``pcc <command>``."""
    args = list(sys.argv[1:] if argv is None else argv)
    if not args or args[0] in ("-h", "--help"):
        print(USAGE)
        return 0
    command, rest = args[0], args[1:]
    if command == "reproduce":
        from benchmarks.reproduce import main as reproduce_main

        return reproduce_main(rest)
    print(f"pcc: unknown command {command!r}\n\n{USAGE}", file=sys.stderr)
    return 2


if __name__ == "__main__":
    sys.exit(main())
