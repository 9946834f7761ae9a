"""Smoke test of the SAC comparison: tiny budget, both observation kinds, outputs written."""

from __future__ import annotations

import json

from benchmarks import vs_sac


def test_vs_sac_tiny_budget(tmp_path):
    out = tmp_path / "vs_sac"
    code = vs_sac.main([
        "--env", "pcc/Planar-v0", "--steps", "120", "--checkpoints", "60", "--seeds", "0",
        "--num-tasks", "1", "--buffer-size", "500", "--threads", "1",
        "--results-dir", str(out), "--reproduce-dir", str(tmp_path / "none"),
    ])
    assert code == 0
    summary = json.loads((out / "Planar-v0.json").read_text())
    for policy in ("sac_image_sparse (120 steps)", "sac_state_sparse (120 steps)"):
        curve = summary["sac"][policy]
        assert [p["env_steps"] for p in curve] == [60, 120]
        assert all(0.0 <= p["mean"] <= 100.0 for p in curve)
    assert (out / "Planar-v0.png").exists() and (out / "Planar-v0.md").exists()
    # No reproduction results: the oracle ceiling is run here, on the same task.
    oracle = summary["model_based"]["oracle (vs_sac)"]
    assert oracle["n_tasks"] == 1 and 0.0 <= oracle["mean"] <= 100.0
    # Finished runs are reused, not retrained.
    record = vs_sac.sac_run_path(out, "pcc/Planar-v0", "image", 120, 0, "sparse")
    assert record.exists()
    mtime = record.stat().st_mtime
    vs_sac.main(["--env", "pcc/Planar-v0", "--steps", "120", "--checkpoints", "60",
                 "--seeds", "0", "--num-tasks", "1", "--observations", "image",
                 "--results-dir", str(out), "--reproduce-dir", str(tmp_path / "none")])
    assert record.stat().st_mtime == mtime
    # Another budget is another agent with its own curve; the first one is kept.
    vs_sac.main(["--env", "pcc/Planar-v0", "--steps", "90", "--checkpoints", "60",
                 "--seeds", "0", "--num-tasks", "1", "--observations", "image",
                 "--results-dir", str(out), "--reproduce-dir", str(tmp_path / "none")])
    assert record.stat().st_mtime == mtime
    summary = json.loads((out / "Planar-v0.json").read_text())
    assert [p["env_steps"] for p in summary["sac"]["sac_image_sparse (90 steps)"]] == [60, 90]
    assert list(summary["sac"])[:2] == ["sac_image_sparse (90 steps)",
                                        "sac_image_sparse (120 steps)"]


def test_finished_sac_run_with_other_tasks_is_not_reused(tmp_path):
    path = tmp_path / "seed0.json"
    record = {"status": "done", "steps": 120, "curve": [{"env_steps": 60}, {"env_steps": 120}],
              "task_seeds": [1, 2]}
    path.write_text(json.dumps(record))
    assert vs_sac.load_finished_sac_run(path, 120, [60, 120], [1, 2], "dense") is not None
    assert vs_sac.load_finished_sac_run(path, 120, [60, 120], [1, 2, 3], "dense") is None
    assert vs_sac.load_finished_sac_run(path, 120, [30, 60, 120], [1, 2], "dense") is None
    assert vs_sac.load_finished_sac_run(path, 200, [60, 200], [1, 2], "dense") is None
    # A record without a reward key was trained on the dense reward.
    assert vs_sac.load_finished_sac_run(path, 120, [60, 120], [1, 2], "sparse") is None


def test_dense_reward_is_its_own_agent_and_curve(tmp_path):
    out = tmp_path / "vs_sac"
    args = ["--env", "pcc/Planar-v0", "--steps", "60", "--checkpoints", "60", "--seeds", "0",
            "--num-tasks", "1", "--observations", "state", "--threads", "1",
            "--results-dir", str(out), "--reproduce-dir", str(tmp_path / "none")]
    vs_sac.main([*args, "--reward", "dense"])
    path = vs_sac.sac_run_path(out, "pcc/Planar-v0", "state", 60, 0, "dense")
    assert json.loads(path.read_text())["reward"] == "dense"
    assert not vs_sac.sac_run_path(out, "pcc/Planar-v0", "state", 60, 0, "sparse").exists()
    summary = json.loads((out / "Planar-v0.json").read_text())
    assert list(summary["sac"]) == ["sac_state (60 steps)"]
    for reward_type, reward_ok in (("dense", lambda r: r < 0), ("sparse", lambda r: r in (0, 1))):
        env = vs_sac.make_env("pcc/Planar-v0", "state", reward_type)
        env.reset(seed=0)
        _, reward, *_ = env.step(env.action_space.sample())
        assert reward_ok(reward), (reward_type, reward)


def test_model_based_points_are_per_preset(tmp_path):
    from benchmarks.reproduce import _write_json_atomic

    for preset, values, n in (("paper", [10.0, 20.0], 5000), ("paper-fast", [80.0], 3000)):
        _write_json_atomic(
            tmp_path / "runs" / preset / "pcc.json",
            {
                "format": 1,
                "status": "done",
                "spec": {"env_id": "pcc/Planar-v0", "method": "pcc", "noise_std": 0.0,
                         "preset": preset},
                "percentages": values,
                "config": {"data": {"num_samples": n}},
            },
        )
    points = vs_sac.summarize("pcc/Planar-v0", tmp_path / "none", tmp_path)["model_based"]
    assert points["pcc (paper)"]["mean"] == 15.0 and points["pcc (paper)"]["num_samples"] == 5000
    assert points["pcc (paper-fast)"]["mean"] == 80.0


def test_model_based_points_on_other_tasks_are_left_out(tmp_path):
    from benchmarks.reproduce import _write_json_atomic

    for name, tasks, values in (("same", [1, 2], [10.0, 30.0]), ("other", [3, 4], [90.0, 90.0])):
        _write_json_atomic(
            tmp_path / "runs" / name / "pcc.json",
            {"format": 1, "status": "done", "task_seeds": tasks, "percentages": values,
             "spec": {"env_id": "pcc/Planar-v0", "method": "pcc", "noise_std": 0.0,
                      "preset": "paper"}, "config": {"data": {"num_samples": 5000}}},
        )
    points = vs_sac.summarize("pcc/Planar-v0", tmp_path / "sac", tmp_path, [1, 2])["model_based"]
    assert points["pcc (paper)"]["mean"] == 20.0 and points["pcc (paper)"]["n_tasks"] == 2
