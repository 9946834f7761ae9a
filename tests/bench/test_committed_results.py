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


#: The repository's budget for committed weights (issue #38): every model of the small-CNN
#: rows (Planar, CartPole, lane keeping), the best model of the other rows.
WEIGHTS_BUDGET_BYTES = 40 * 1024**2


def test_committed_weights_fit_the_budget_and_match_their_records():
    from pcc_agent.io import sha256_of

    weights = sorted((REPRODUCE / "weights").rglob("*.safetensors"))
    assert weights, "no committed weights"
    total = sum(path.stat().st_size for path in weights)
    assert total <= WEIGHTS_BUDGET_BYTES, f"{total / 1024**2:.1f} MB of weights, budget 40 MB"
    named = {}
    for record_path in (REPRODUCE / "runs").rglob("*.json"):
        entry = json.loads(record_path.read_text()).get("weights")
        if entry:
            named[REPRODUCE / entry["file"]] = entry["sha256"]
    for path in weights:
        assert path in named, f"{path} is named by no record"
        assert sha256_of(path) == named[path], path
