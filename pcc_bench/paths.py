"""Default locations of the benchmark outputs."""

from __future__ import annotations

from pathlib import Path

#: Where the commands write by default (relative to the working directory).
DEFAULT_RESULTS_ROOT = Path("pcc_results")
#: The results committed to the repository (present in a source checkout, not in the wheel).
COMMITTED_RESULTS_DIR = Path(__file__).resolve().parents[1] / "results"
