"""Every command and the code snippet of the README run, so the README cannot drift.

The quickstart's two commands are run by CI (``.ci/run``: the install, ``pcc reproduce``'s
wheel, the test command) and by ``test_smoke_quick_preset_in_subprocess``; the inline
commands and the Python snippet run here, made small where they would train for minutes.
"""

from __future__ import annotations

import os
import re
import subprocess
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[2]
README = ROOT / "README.md"

#: How each inline command of the README is checked: the arguments run here (None: covered
#: elsewhere, the reason given).
INLINE_COMMANDS: dict[str, list[str] | str] = {
    "pcc reproduce": "the quickstart's main job: CI and test_smoke_quick_preset_in_subprocess",
    "pcc reproduce --status": ["reproduce", "--status", "--results-dir", "res"],
    "pcc evaluate planar-pcc --picture planar.png":
        ["evaluate", "planar-pcc", "--picture", "planar.png"],
    "pcc speed control": ["speed", "control", "--help"],  # trains for minutes: options only
    "pcc speed threads": ["speed", "threads", "--help"],  # trains for minutes: options only
    'pip install -e ".[docs]" && mkdocs serve': "CI installs the docs extra and builds the site",
}


def _readme() -> str:
    return README.read_text(encoding="utf-8")


def _inline_commands() -> set[str]:
    return set(re.findall(r"`((?:pcc|pip|python|mkdocs) [^`]*)`", _readme()))


def test_every_inline_readme_command_is_checked():
    assert _inline_commands() == set(INLINE_COMMANDS), (
        "README commands changed: say in INLINE_COMMANDS how each one is checked")


@pytest.mark.parametrize("command", sorted(k for k, v in INLINE_COMMANDS.items()
                                           if isinstance(v, list)))
def test_inline_readme_command_runs(command, tmp_path):
    args = INLINE_COMMANDS[command]
    assert isinstance(args, list)
    result = subprocess.run([sys.executable, "-m", "pcc_bench.cli", *args], cwd=tmp_path,
                            capture_output=True, text=True, timeout=300,
                            env={**os.environ, "PYTHONPATH": str(ROOT)})
    assert result.returncode == 0, result.stderr[-2000:]
    if "--picture" in args:
        assert (tmp_path / "planar.png").stat().st_size > 0
        assert "Shipped with" in result.stdout


def test_readme_python_snippet_runs(tmp_path):
    """The snippet as written, with its 250 epochs cut to 2 (the result is not checked)."""
    blocks = re.findall(r"```python\n(.*?)```", _readme(), re.S)
    assert len(blocks) == 1, "the README has one Python snippet"
    long_training = "epochs=250, patience=100)"
    assert long_training in blocks[0], "update this test: the snippet's training changed"
    code = blocks[0].replace(long_training, "epochs=2, patience=100, min_epochs=0)")
    result = subprocess.run([sys.executable, "-c", code], cwd=tmp_path, capture_output=True,
                            text=True, timeout=600,
                            env={**os.environ, "PYTHONPATH": str(ROOT),
                                 "PCC_DATA_DIR": str(tmp_path / "data")})
    assert result.returncode == 0, result.stderr[-2000:]
    assert "% of steps in goal" in result.stdout
    assert (tmp_path / "planar_pcc.pt").exists()
