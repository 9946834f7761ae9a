"""Argument types and the parser set-up shared by the benchmark commands.

Every command builds its parser with :func:`command_parser`: the description is the first
paragraph of the command module's docstring, the epilog its ``Examples:`` (or ``Usage:``)
section, and the program name is ``python -m pcc_bench.<command>``, or ``pcc <command>``
when the ``pcc`` command runs it (:func:`invoked_as`).
"""

from __future__ import annotations

import argparse
import contextlib
import re
import textwrap
from collections.abc import Iterator
from contextvars import ContextVar

_PROG: ContextVar[str | None] = ContextVar("pcc_bench_prog", default=None)


def positive_int(text: str) -> int:
    """An integer of at least 1 (argparse type)."""
    value = int(text)
    if value < 1:
        raise argparse.ArgumentTypeError(f"must be at least 1, got {value}")
    return value


def positive_float(text: str) -> float:
    """A float greater than 0 (argparse type; NaN is refused)."""
    try:
        value = float(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"expected a number, got {text!r}") from None
    if not value > 0:
        raise argparse.ArgumentTypeError(f"must be > 0, got {text}")
    return value


def non_negative_float(text: str) -> float:
    """A float of at least 0 (argparse type; NaN is refused)."""
    value = float(text)
    if not value >= 0:
        raise argparse.ArgumentTypeError(f"must be >= 0, got {text}")
    return value


def known_envs() -> list[str]:
    """The env ids with a preset."""
    from pcc_agent.presets import PRESETS

    return sorted(PRESETS)


@contextlib.contextmanager
def invoked_as(prog: str) -> Iterator[None]:
    """Within this block, commands name themselves ``prog`` in their usage and examples."""
    token = _PROG.set(prog)
    try:
        yield
    finally:
        _PROG.reset(token)


def examples_of(doc: str | None) -> str:
    """The ``Examples:`` or ``Usage:`` section of a module docstring (empty if none)."""
    lines = (doc or "").splitlines()
    for start, line in enumerate(lines):
        if re.fullmatch(r"(Examples?|Usage)\b.*:", line.strip()):
            section = []
            for body in lines[start + 1:]:
                if body and not body.startswith(" "):
                    break
                section.append(body)
            # A backslash-newline in a docstring joins lines: squeeze the indentation it leaves.
            text = textwrap.dedent("\n".join(section)).strip()
            text = "\n".join(re.sub(r"(?<=\S) {2,}", " ", row) for row in text.splitlines())
            qualifier = line.strip().rstrip(":").split(" ", 1)[1:]  # "Usage (C=...)"
            heading = " ".join(["examples", *qualifier]).replace("``", "")
            return f"{heading}:\n" + textwrap.indent(text, "  ")
    return ""


def command_parser(doc: str | None, module: str, **kwargs: object) -> argparse.ArgumentParser:
    """The parser of the command in ``module`` (``"pcc_bench.reproduce"``), see module doc."""
    default_prog = f"python -m {module}"
    prog = _PROG.get() or default_prog
    description = (doc or "").split("\n\n")[0].strip()
    epilog = examples_of(doc).replace(default_prog, prog)
    return argparse.ArgumentParser(
        prog=prog, description=description, epilog=epilog or None,
        formatter_class=argparse.RawDescriptionHelpFormatter, **kwargs,  # type: ignore[arg-type]
    )
