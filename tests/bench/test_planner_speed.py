"""pcc_bench.planner_speed times each domain's own planner settings."""

from __future__ import annotations

import json

from pcc_agent.presets import get_preset
from pcc_bench import planner_speed


def test_speed_rows_use_the_domain_presets_and_report_the_warm_up(tmp_path):
    out = tmp_path / "speed.json"
    planner_speed.main(["--envs", "planar", "three_link_arm", "--sweep", "4", "--steps", "3",
                        "--output", str(out)])
    payload = json.loads(out.read_text())
    assert payload["warmup_ms"] > 0 and payload["command"].startswith("python -m")
    planar, arm, sweep = payload["rows"]
    assert planar["plan_length"] == get_preset("pcc/Planar-v0").planner.plan_length
    assert arm["plan_length"] == get_preset("pcc/ThreeLink-v0").planner.plan_length
    assert arm["target_ms"] == planner_speed.TARGET_MS and planar["target_ms"] is None
    assert sweep["env"] == "cartpole" and sweep["plan_length"] == 4 and sweep["sweep"]
    assert all(r["steps"] == 3 and r["mean_ms_per_step"] > 0 for r in payload["rows"])
