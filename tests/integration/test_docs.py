"""The README stays a front door, and its commands cannot drift from what CI runs."""

from __future__ import annotations

import re
from pathlib import Path

ROOT = Path(__file__).resolve().parents[2]
README = ROOT / "README.md"
CI = ROOT / ".ci" / "run"
README_LIMIT_BYTES = 12 * 1024


def _quickstart_commands() -> list[str]:
    """The command lines of the README's first ``bash`` block, comments stripped."""
    text = README.read_text(encoding="utf-8")
    block = re.search(r"```bash\n(.*?)```", text, re.S)
    assert block is not None, "README.md has no ```bash quickstart block"
    lines = [line.split("#", 1)[0].strip() for line in block.group(1).splitlines()]
    return [line for line in lines if line]


def test_readme_is_at_most_12_kb() -> None:
    size = len(README.read_bytes())
    assert size <= README_LIMIT_BYTES, (
        f"README.md is {size} bytes, over {README_LIMIT_BYTES}: move history to RESULTS_LOG.md "
        "and details to docs/"
    )


def test_readme_quickstart_is_two_commands() -> None:
    commands = _quickstart_commands()
    assert len(commands) == 2, commands
    assert commands[0] == "pip install . && pcc reproduce"


def test_readme_test_command_is_what_ci_runs() -> None:
    """Both halves of the README's test command appear, in order, as lines of .ci/run."""
    install, run_tests = (part.strip() for part in _quickstart_commands()[1].split("&&"))
    ci_lines = [line.strip() for line in CI.read_text(encoding="utf-8").splitlines()]
    ci_commands = [line for line in ci_lines if line and not line.startswith("#")]
    # CI adds --quiet to pip; the install target must be the README's.
    install_at = [i for i, line in enumerate(ci_commands)
                  if line.replace(" --quiet", "") == install]
    assert install_at, f".ci/run does not run {install!r}"
    assert run_tests in ci_commands[install_at[0]:], f".ci/run does not run {run_tests!r}"


def test_readme_main_command_is_started_by_ci() -> None:
    ci = CI.read_text(encoding="utf-8")
    assert "pip wheel" in ci and "pcc reproduce" in ci


def test_readme_and_results_log_links_exist() -> None:
    for doc in (README, ROOT / "RESULTS_LOG.md"):
        text = doc.read_text(encoding="utf-8")
        for target in re.findall(r"\]\(([^)#\s]+)(?:#[^)]*)?\)", text):
            if "://" in target:
                continue
            assert (doc.parent / target).exists(), f"{doc.name} links to missing {target}"


def test_docs_nav_pages_exist() -> None:
    nav = re.findall(r":\s*([\w/.-]+\.md)\s*$", (ROOT / "mkdocs.yml").read_text(), re.M)
    assert nav, "mkdocs.yml has no nav"
    missing = [page for page in nav if not (ROOT / "docs" / page).exists()]
    assert not missing, f"mkdocs.yml lists missing pages: {missing}"
