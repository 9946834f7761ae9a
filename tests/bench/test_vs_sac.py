"""Smoke test of the SAC comparison: tiny budget, both observation kinds, outputs written."""

from __future__ import annotations

import json
import tempfile

import numpy as np
import pytest
import torch

from pcc_agent.agent import sb3_logger
from pcc_bench import sac_state, vs_sac, vs_sac_summary
from pcc_bench.records import NO_ACTION


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
    # The floor too: a Planar start is far from the goal, so zero actions never reach it.
    floor = summary["model_based"]["no-action (vs_sac)"]
    assert floor["method"] == NO_ACTION and floor["n_tasks"] == 1 and floor["mean"] == 0.0
    assert "| no-action (vs_sac) | - (zero actions) | 0.0 ± n/a |" in (
        out / "Planar-v0.md").read_text()
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
              "task_seeds": [1, 2], "buffer_size": 120}
    path.write_text(json.dumps(record))
    load = vs_sac.load_finished_sac_run
    assert load(path, 120, [60, 120], [1, 2], "dense", 120) is not None
    assert load(path, 120, [60, 120], [1, 2, 3], "dense", 120) is None
    assert load(path, 120, [30, 60, 120], [1, 2], "dense", 120) is None
    assert load(path, 200, [60, 200], [1, 2], "dense", 120) is None
    # A record without a reward key was trained on the dense reward.
    assert load(path, 120, [60, 120], [1, 2], "sparse", 120) is None
    # Another replay-buffer size is another agent.
    assert load(path, 120, [60, 120], [1, 2], "dense", 100) is None


@pytest.mark.parametrize("args, message", [
    (["--steps", "100", "--checkpoints", "50", "200"], "beyond --steps 100"),
    (["--checkpoints", "0"], "--checkpoints"),
    (["--num-tasks", "0"], "--num-tasks"),
    (["--buffer-size", "-5"], "--buffer-size"),
])
def test_bad_command_line_is_refused(tmp_path, capsys, args, message):
    with pytest.raises(SystemExit) as exit_info:
        vs_sac.main([*args, "--results-dir", str(tmp_path)])
    assert exit_info.value.code == 2 and message in capsys.readouterr().err


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
    from pcc_agent.io import atomic_write_json

    for preset, values, n in (("paper", [10.0, 20.0], 5000), ("paper-fast", [80.0], 3000)):
        atomic_write_json(
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
    points = vs_sac_summary.summarize("pcc/Planar-v0", tmp_path / "none", tmp_path)[
        "model_based"]
    assert points["pcc (paper)"]["mean"] == 15.0 and points["pcc (paper)"]["num_samples"] == 5000
    assert points["pcc (paper-fast)"]["mean"] == 80.0


def test_restarts_model_counts_the_data_of_every_training(tmp_path):
    """A best-of-2 model consumed two data sets: its point sits at 2 x 5000 samples."""
    from pcc_agent.agent import PCCAgent
    from pcc_agent.io import atomic_write_json
    from pcc_bench.records import RunSpec, preset_for

    for seed, loss, score in ((0, 140.0, 20.0), (1000, 130.0, 70.0)):
        spec = {"env_id": "pcc/Planar-v0", "method": "pcc", "noise_std": 0.0, "seed": seed,
                "preset": "paper-fast-long", "model_variant": "fast", "num_tasks": 10,
                "task_seed": 2020, "max_epochs": 1000, "patience": 100}
        agent = PCCAgent(spec["env_id"], method="pcc", preset=preset_for(RunSpec(**spec)),
                         seed=seed)
        atomic_write_json(
            tmp_path / "runs" / f"seed{seed}.json",
            {"format": 1, "status": "done", "percentages": [score], "mean": score,
             "train_seconds": 1.0, "training": {"best_validation_loss": loss}, "spec": spec,
             "config": json.loads(json.dumps(agent.config_dict()))},
        )
    summary = vs_sac_summary.summarize("pcc/Planar-v0", tmp_path / "none", tmp_path)
    points = summary["model_based"]
    assert points["pcc (paper-fast-long)"]["num_samples"] == 5000
    assert points["pcc (paper-fast-long-best2)"]["num_samples"] == 10000
    assert points["pcc (paper-fast-long-best2)"]["mean"] == 70.0
    assert "pcc (paper-fast-long-best3)" not in points
    # One task each: the standard error is undefined, and the table says so.
    assert points["pcc (paper-fast-long)"]["se"] is None
    vs_sac_summary.write_outputs(summary, tmp_path)
    assert "| 20.0 ± n/a |" in (tmp_path / "Planar-v0.md").read_text()


def test_model_based_points_on_other_tasks_are_left_out(tmp_path):
    from pcc_agent.io import atomic_write_json

    for name, tasks, values in (("same", [1, 2], [10.0, 30.0]), ("other", [3, 4], [90.0, 90.0])):
        atomic_write_json(
            tmp_path / "runs" / name / "pcc.json",
            {"format": 1, "status": "done", "task_seeds": tasks, "percentages": values,
             "spec": {"env_id": "pcc/Planar-v0", "method": "pcc", "noise_std": 0.0,
                      "preset": "paper"}, "config": {"data": {"num_samples": 5000}}},
        )
    points = vs_sac_summary.summarize("pcc/Planar-v0", tmp_path / "sac", tmp_path, [1, 2])[
        "model_based"]
    assert points["pcc (paper)"]["mean"] == 20.0 and points["pcc (paper)"]["n_tasks"] == 2


def test_no_floor_where_the_zero_action_is_not_allowed(tmp_path, monkeypatch):
    monkeypatch.setattr(vs_sac_summary, "contains_zero_action", lambda space: False)
    monkeypatch.setattr(vs_sac_summary, "oracle_point", lambda *args: None)
    points = vs_sac_summary.summarize("pcc/Planar-v0", tmp_path / "sac", tmp_path, [1])[
        "model_based"]
    assert not any(entry["method"] == NO_ACTION for entry in points.values())


def _tiny_state_run(tmp_path, **kwargs):
    return vs_sac.run_sac("pcc/Planar-v0", "state", 0, 120, [40, 80], [7], 500,
                          tmp_path, "sparse", save_every=30, **kwargs)


def test_sac_run_cut_short_continues_from_its_state(tmp_path, monkeypatch):
    import pcc_agent.evaluation

    real_evaluate = pcc_agent.evaluation.evaluate_control
    calls = []

    def evaluate_then_interrupt(*args, **kwargs):
        calls.append(1)
        if len(calls) == 2:
            raise KeyboardInterrupt  # the second evaluation (80 steps) is cut short
        return real_evaluate(*args, **kwargs)

    monkeypatch.setattr(pcc_agent.evaluation, "evaluate_control", evaluate_then_interrupt)
    record_path = vs_sac.sac_run_path(tmp_path, "pcc/Planar-v0", "state", 120, 0, "sparse")
    state_file = sac_state.state_path(record_path)
    with pytest.raises(KeyboardInterrupt):
        _tiny_state_run(tmp_path)
    # The record file holds the curve so far as a partial run, which never counts as done.
    partial = json.loads(record_path.read_text())
    assert partial["status"] == "partial" and partial["steps_done"] == 40
    assert [p["env_steps"] for p in partial["curve"]] == [40]
    assert vs_sac.load_finished_sac_run(record_path, 120, [40, 80, 120], [7], "sparse",
                                        120) is None
    saved = torch.load(state_file, weights_only=True)
    # Saved after the evaluation at 40 steps (39 processed) and 30 steps later; not at the cut.
    assert saved["steps_done"] == 69
    assert [p["env_steps"] for p in saved["curve"]] == [40]

    monkeypatch.setattr(pcc_agent.evaluation, "evaluate_control", real_evaluate)
    record = _tiny_state_run(tmp_path)
    assert record["resumed_at_steps"] == [69]
    # The evaluation at 40 steps is kept, not repeated; 80 and 120 are made by the resumed run.
    assert [p["env_steps"] for p in record["curve"]] == [40, 80, 120]
    assert record["curve"][0] == saved["curve"][0]
    assert record["train_seconds"] >= saved["train_seconds"]
    assert record_path.exists() and not state_file.exists()
    # The last evaluation keeps each task's true-state trajectory, as the reproduction does.
    (task,) = record["tasks"]
    assert task["seed"] == 7 and task["percent_in_goal"] == record["curve"][-1]["mean"]
    assert len(task["states"]) == task["steps"] == 40  # Planar's episode: 40 steps
    assert all(len(state) == 2 for state in task["states"])  # Planar's state: (x, y)
    # A state left by a crash between writing the record and removing the state goes too.
    state_file.write_bytes(b"left over")
    assert _tiny_state_run(tmp_path) == record and not state_file.exists()


def test_partial_run_without_its_state_is_retrained_and_checked(tmp_path, monkeypatch, capsys):
    """A session ends: the partial record stays (committed), the state file is lost."""
    import pcc_agent.evaluation

    real_evaluate = pcc_agent.evaluation.evaluate_control
    calls = []

    def evaluate_then_interrupt(*args, **kwargs):
        calls.append(1)
        if len(calls) == 2:
            raise KeyboardInterrupt
        return real_evaluate(*args, **kwargs)

    monkeypatch.setattr(pcc_agent.evaluation, "evaluate_control", evaluate_then_interrupt)
    record_path = vs_sac.sac_run_path(tmp_path, "pcc/Planar-v0", "state", 120, 0, "sparse")
    with pytest.raises(KeyboardInterrupt):
        _tiny_state_run(tmp_path)
    sac_state.state_path(record_path).unlink()
    partial = json.loads(record_path.read_text())
    summary = vs_sac_summary.summarize("pcc/Planar-v0", tmp_path, tmp_path / "none")
    assert summary["sac"] == {}  # a partial run is in no mean
    assert summary["partial"] == [{"curve": "sac_state_sparse (120 steps)", "seed": 0,
                                   "steps_done": 40, "points": [
                                       {"env_steps": 40, "mean": partial["curve"][0]["mean"]}]}]
    vs_sac_summary.write_outputs(summary, tmp_path)
    assert "seed 0, at 40 steps" in (tmp_path / "Planar-v0.md").read_text()

    monkeypatch.setattr(pcc_agent.evaluation, "evaluate_control", real_evaluate)
    record = _tiny_state_run(tmp_path)
    assert record["status"] == "done" and record["resumed_at_steps"] == []
    assert "starts afresh" in capsys.readouterr().out
    # Trained again from scratch, the run reaches the earlier sitting's weights at 40 steps.
    assert record["curve"][0]["policy_sha256"] == partial["curve"][0]["policy_sha256"]
    assert record["curve"][0]["earlier_sitting_sha256_match"] is True
    assert all("earlier_sitting_sha256_match" not in p for p in record["curve"][1:])

    # Weights that differ from the earlier sitting's are flagged, not hidden.
    tampered = {**partial, "curve": [{**partial["curve"][0], "policy_sha256": "0" * 64}]}
    record_path.write_text(json.dumps(tampered))
    rerun = _tiny_state_run(tmp_path)
    assert rerun["curve"][0]["earlier_sitting_sha256_match"] is False
    assert "OTHER weights" in capsys.readouterr().out


def test_evaluations_do_not_change_the_training(tmp_path):
    """The same seed trains the same weights whatever steps it is evaluated at."""
    def run(checkpoints, seed=0, where="a"):
        return vs_sac.run_sac("pcc/Planar-v0", "state", seed, 120, checkpoints, [7], 500,
                              tmp_path / where, "sparse")

    reference = run([])["policy_sha256"]
    evaluated_twice = run([30, 90], where="b")
    evaluated_once = run([90], where="c")
    assert evaluated_twice["policy_sha256"] == evaluated_once["policy_sha256"] == reference
    assert run([], seed=1, where="d")["policy_sha256"] != reference
    assert evaluated_once["machine"]["torch_cpu_capability"]
    assert evaluated_once["versions"]["torch"]
    # Each evaluation records the weights it evaluated: the same at the same step.
    at_90 = [[p["policy_sha256"] for p in r["curve"] if p["env_steps"] == 90]
             for r in (evaluated_twice, evaluated_once)]
    assert at_90[0] == at_90[1] and len(at_90[0]) == 1
    assert len({p["policy_sha256"] for p in evaluated_twice["curve"]}) == 3  # 30, 90, 120


def test_sac_state_restores_weights_buffer_and_counters(tmp_path):
    from stable_baselines3 import SAC

    env = vs_sac.make_env("pcc/Planar-v0", "state", "sparse")
    model = SAC("MlpPolicy", env, buffer_size=200, learning_starts=10, seed=0, device="cpu")
    model.set_logger(sb3_logger(None, []))  # SB3's default leaves an empty temp dir per call
    model.learn(total_timesteps=50)
    settings = {"seed": 0, "steps": 100}
    path = tmp_path / "run.state.pt"
    sac_state.save_state(path, model, 50, settings, [{"env_steps": 25, "mean": 1.0}], 2.5, [])

    fresh = SAC("MlpPolicy", vs_sac.make_env("pcc/Planar-v0", "state", "sparse"),
                buffer_size=200, learning_starts=10, seed=1, device="cpu")
    state = sac_state.load_state(path, settings)
    sac_state.restore_state(fresh, state)
    for name, params in model.get_parameters()["policy"].items():
        assert torch.equal(params, fresh.get_parameters()["policy"][name]), name
    assert torch.equal(model.log_ent_coef, fresh.log_ent_coef)
    critic_opt = model.critic.optimizer.state_dict()["state"]
    fresh_opt = fresh.critic.optimizer.state_dict()["state"]
    assert all(torch.equal(critic_opt[k]["exp_avg"], fresh_opt[k]["exp_avg"]) for k in critic_opt)
    buffer, restored = model.replay_buffer, fresh.replay_buffer
    assert restored.pos == buffer.pos == 50 and not restored.full
    for name in ("observations", "next_observations", "actions", "rewards", "dones"):
        assert np.array_equal(getattr(buffer, name), getattr(restored, name)), name
    assert (fresh.num_timesteps, fresh._n_updates) == (50, model._n_updates)


def test_sac_state_of_other_settings_or_unreadable_is_discarded(tmp_path):
    from stable_baselines3 import SAC

    model = SAC("MlpPolicy", vs_sac.make_env("pcc/Planar-v0", "state", "sparse"),
                buffer_size=50, seed=0, device="cpu")
    path = tmp_path / "run.state.pt"
    sac_state.save_state(path, model, 0, {"seed": 0}, [], 0.0, [])
    assert sac_state.load_state(path, {"seed": 1}) is None
    assert not path.exists()
    path.write_bytes(b"not a torch file")
    assert sac_state.load_state(path, {"seed": 0}) is None
    assert not path.exists()
    assert sac_state.load_state(path, {"seed": 0}) is None  # missing
    with pytest.raises(ValueError, match="save_every"):
        vs_sac.run_sac("pcc/Planar-v0", "state", 0, 10, [], [7], 50, tmp_path, "sparse",
                       save_every=0)


def test_interrupted_comparison_exits_130_with_how_to_continue(tmp_path, monkeypatch, capsys):
    def interrupted(*args, **kwargs):
        raise KeyboardInterrupt

    monkeypatch.setattr(vs_sac, "run_sac", interrupted)
    code = vs_sac.main(["--env", "pcc/Planar-v0", "--steps", "100", "--seeds", "0",
                        "--results-dir", str(tmp_path / "out")])
    assert code == 130
    assert "run the same command again to continue" in capsys.readouterr().err
    assert not (tmp_path / "out" / "Planar-v0.json").exists()


def test_sac_run_makes_no_temp_directory(tmp_path, monkeypatch):
    # SB3's default logger makes an empty tempdir/SB3-<date> per learn(); one per run adds up.
    temp = tmp_path / "temp"
    temp.mkdir()
    monkeypatch.setattr(tempfile, "tempdir", str(temp))
    monkeypatch.delenv("SB3_LOGDIR", raising=False)  # SB3 would write there instead
    vs_sac.run_sac("pcc/Planar-v0", "state", 0, 20, [20], [7], 50, tmp_path / "sac", "sparse")
    assert list(temp.glob("SB3-*")) == []


def test_floor_of_the_reproduction_runs_is_used_not_measured_again(tmp_path, monkeypatch):
    from pcc_agent.io import atomic_write_json
    from pcc_bench.records import NO_ACTION

    atomic_write_json(
        tmp_path / "runs" / "floor.json",
        {"format": 1, "status": "done", "task_seeds": [1, 2], "percentages": [0.0, 40.0],
         "spec": {"env_id": "pcc/Planar-v0", "method": NO_ACTION, "noise_std": 0.0,
                  "preset": "paper"}, "config": {"no_action": True}},
    )
    monkeypatch.setattr(vs_sac_summary, "oracle_point", lambda *args: None)
    monkeypatch.setattr(vs_sac_summary, "zero_action_percentages",
                        lambda *args: pytest.fail("re-run"))
    points = vs_sac_summary.summarize("pcc/Planar-v0", tmp_path / "sac", tmp_path, [1, 2])[
        "model_based"]
    assert points["no-action (paper)"]["mean"] == 20.0
    assert "no-action (vs_sac)" not in points
