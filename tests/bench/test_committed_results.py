"""The committed results (results/ at the repository root) load and aggregate as committed."""

from __future__ import annotations

import json

import pytest

from pcc_bench.paths import COMMITTED_RESULTS_DIR

REPRODUCE = COMMITTED_RESULTS_DIR / "reproduce"
pytestmark = pytest.mark.skipif(not (REPRODUCE / "summary.json").exists(),
                                reason="no committed results (not a source checkout)")


def test_committed_records_aggregate_into_the_committed_summary(capsys):
    from pcc_bench.aggregation import aggregate, choose_models
    from pcc_bench.records import load_records

    records = load_records(REPRODUCE)
    rows = aggregate(choose_models(records))
    assert json.loads(json.dumps(rows)) == json.loads((REPRODUCE / "summary.json").read_text())


def test_committed_summary_markdown_is_rendered_by_the_code(tmp_path):
    import shutil

    from pcc_bench.reproduce import write_summary

    shutil.copytree(REPRODUCE / "runs", tmp_path / "runs")
    write_summary(tmp_path)
    assert (tmp_path / "summary.md").read_text() == (REPRODUCE / "summary.md").read_text()
