"""benchmarks.planner_sweep re-evaluates a saved agent under several planner settings."""

from __future__ import annotations

import dataclasses
import json

from benchmarks import planner_sweep
from pcc_agent import PCCAgent
from pcc_agent.planning.config import PlannerConfig
from pcc_agent.presets import get_preset


def test_planner_sweep_runs_every_setting(tmp_path):
    preset = get_preset("pcc/Planar-v0")
    preset = dataclasses.replace(
        preset,
        train=dataclasses.replace(preset.train, epochs=1),
        planner=PlannerConfig(plan_length=5, iterations=1, mpc_iterations=1, num_candidates=2),
    )
    agent = PCCAgent("pcc/Planar-v0", preset=preset, seed=0, data_cache_dir=tmp_path / "d")
    agent.learn(total_timesteps=200)
    agent.save(tmp_path / "a.pt")
    out = tmp_path / "sweep.json"
    assert planner_sweep.main([str(tmp_path / "a.pt"), "--plan-lengths", "3", "6",
                               "--mpc-iterations", "1", "--num-tasks", "1",
                               "--out", str(out)]) == 0
    rows = json.loads(out.read_text())
    assert [r["plan_length"] for r in rows] == [3, 6]
    assert all(0.0 <= r["mean"] <= 100.0 for r in rows)
