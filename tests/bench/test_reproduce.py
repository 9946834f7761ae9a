"""The reproduction pipeline: a smoke run in a subprocess, resumability of the per-run files."""

from __future__ import annotations

import dataclasses
import json
import os
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from pcc_agent.planning import PLANNER_REVISION
from pcc_bench.aggregation import aggregate, interquartile_mean
from pcc_bench.costs import (
    MULTISTEP_COST_PER_STEP,
    CheckpointedTraining,
    checkpointed_trainings,
    estimate_cost,
    multistep_cost_factor,
    reevaluations,
)
from pcc_bench.records import RunSpec, load_finished_run, training_progress
from pcc_bench.runs import execute_run, report_line

ROOT = Path(__file__).resolve().parents[2]


def tiny_spec(seed: int = 0) -> RunSpec:
    return RunSpec(
        env_id="pcc/Planar-v0",
        method="pcc",
        seed=seed,
        noise_std=0.0,
        num_tasks=1,
        task_seed=7,
        model_variant="paper",
        preset="test",
        num_samples=256,
        max_epochs=1,
    )


def test_smoke_quick_preset_in_subprocess(tmp_path):
    cmd = [
        sys.executable,
        "-m",
        "pcc_bench.reproduce",
        "--preset",
        "quick",
        "--num-models",
        "1",
        "--num-tasks",
        "1",
        "--max-epochs",
        "1",
        "--workers",
        "1",
        "--no-oracle",
        "--results-dir",
        str(tmp_path / "res"),
        "--data-dir",
        str(tmp_path / "data"),
    ]
    out = subprocess.run(cmd, cwd=ROOT, capture_output=True, text=True, timeout=600)
    assert out.returncode == 0, out.stdout + out.stderr
    rows = json.loads((tmp_path / "res" / "summary.json").read_text())
    assert rows[0]["env"] == "pcc/Planar-v0" and rows[0]["n_models"] == 1
    assert 0.0 <= rows[0]["mean_all"] <= 100.0
    assert "% of steps in goal" in out.stdout
    assert (tmp_path / "res" / "summary.md").exists()


def test_finished_run_is_skipped_and_partial_run_redone(tmp_path):
    spec = tiny_spec()
    record = execute_run(spec, tmp_path, str(tmp_path / "data"))
    path = tmp_path / spec.relative_path
    assert record["status"] == "done" and path.exists()
    assert len(record["percentages"]) == 1 and len(record["tasks"][0]["states"]) > 0
    assert record["machine"]["torch_cpu_capability"]  # which kernels made the numbers
    assert record["training"]["stop_reason"] == "epoch_cap"  # max_epochs=1
    assert "(train " in report_line(1, 1, record) and ": 1 epochs, the cap; control " in (
        report_line(1, 1, record))
    again = execute_run(spec, tmp_path, str(tmp_path / "data"))
    assert again.get("skipped") is True
    # A run killed mid-way leaves at most a truncated or unfinished file: it is redone.
    path.write_text(path.read_text()[:100])
    assert load_finished_run(path) is None
    redone = execute_run(spec, tmp_path, str(tmp_path / "data"))
    assert not redone.get("skipped") and load_finished_run(path) is not None
    assert redone["percentages"] == record["percentages"]


def test_run_killed_mid_training_resumes_to_the_uninterrupted_result(tmp_path):
    """SIGKILL while the model trains: nothing counts as finished; the next call continues
    from the last training checkpoint and ends where an uninterrupted run ends."""
    import signal
    import time

    from pcc_bench.records import training_checkpoint_path, training_progress

    spec = dataclasses.replace(tiny_spec(3), max_epochs=40, patience=40)
    assert training_progress(tmp_path, spec).endswith("seed=3: not started")
    data_dir = tmp_path / "data"
    code = (
        "from pcc_bench.records import RunSpec; from pcc_bench.runs import execute_run; "
        f"execute_run(RunSpec(**{dataclasses.asdict(spec)!r}), {str(tmp_path)!r}, "
        f"{str(data_dir)!r})"
    )
    child = subprocess.Popen([sys.executable, "-c", code], cwd=ROOT)
    in_progress = training_checkpoint_path(tmp_path, spec)
    deadline = time.monotonic() + 300
    while not in_progress.exists():  # the first checkpoint, a few epochs into training
        assert child.poll() is None and time.monotonic() < deadline, "run ended too soon"
        time.sleep(0.01)
    child.send_signal(signal.SIGKILL)
    child.wait()
    path = tmp_path / spec.relative_path
    assert load_finished_run(path, spec) is None
    assert "seed=3: training, epoch " in training_progress(tmp_path, spec)
    assert "of at most 40, best validation loss" in training_progress(tmp_path, spec)
    checkpointed = checkpointed_trainings(tmp_path, [spec, dataclasses.replace(spec, seed=4)])
    assert list(checkpointed) == [spec] and 0 < checkpointed[spec].epochs < 40
    assert checkpointed[spec].seconds_per_epoch > 0
    resumed = execute_run(spec, tmp_path, str(data_dir))
    assert not resumed.get("skipped") and load_finished_run(path, spec) is not None
    assert "seed=3: done, " in training_progress(tmp_path, spec)
    assert 0 < resumed["training_resumed_at_epoch"] < 40
    assert not in_progress.exists()  # removed once the run is done
    straight = execute_run(spec, tmp_path / "straight", str(data_dir))
    assert "training_resumed_at_epoch" not in straight
    for key in ("epochs", "best_epoch", "best_validation_loss"):
        assert resumed["training"][key] == straight["training"][key], key
    assert resumed["percentages"] == straight["percentages"]


def test_a_run_that_keeps_its_best_controlling_weights_records_the_choice(tmp_path):
    from pcc_bench.records import control_selection_path

    spec = dataclasses.replace(tiny_spec(1), max_epochs=4, patience=10, validation_tasks=1,
                               keep_best_control_every=2)
    record = execute_run(spec, tmp_path, str(tmp_path / "data"))
    chosen = record["training"]["control_selection"]
    assert chosen["every"] == 2 and chosen["tasks"] == 1
    assert [epoch for epoch, _ in chosen["history"]] == [2, 4, -1]
    assert chosen["kept_score"] == max(score for _, score in chosen["history"])
    assert chosen["kept_epoch"] in (2, 4, -1)
    assert len(record["validation"]["percentages"]) == 1
    assert not control_selection_path(tmp_path, spec).exists()  # removed once done


def test_the_settings_table_says_how_the_weights_were_chosen():
    from pcc_bench.tables import settings_table

    row = {"env": "pcc/CartPole-v1", "method": "pcc", "n_tasks": 10, "seeds": [0],
           "preset": "paper-motion+max_epochs=60,keep_best_control_every=10",
           "settings": {"planner": {}, "train": {"epochs": 60}}}
    assert ("control best on 10 validation tasks (task seed 2021), scored every 10 epochs"
            in settings_table([row]))
    row["preset"] = "paper-motion+keep_best_control_every=10 [planner r3]"  # an older row
    assert "scored every 10 epochs;" in settings_table([row]).replace(" |", ";")
    row["preset"] = "paper-motion+max_epochs=60"
    assert "validation tasks" not in settings_table([row])


def test_training_checkpoint_of_a_finished_or_other_training_is_discarded(tmp_path):
    from pcc_agent.checkpoint import load_checkpoint, save_checkpoint
    from pcc_agent.model import EmbeddingModel
    from pcc_agent.presets import get_preset
    from pcc_agent.training import train_embedding
    from pcc_bench.records import resume_point

    preset = get_preset("pcc/Planar-v0")
    config = dataclasses.replace(preset.train, epochs=1, seed=0)
    model = EmbeddingModel((1, 40, 40), 2, preset.model, seed=0)
    arch = model.architecture()
    obs = np.zeros((64, 1, 40, 40), np.uint8)
    path = tmp_path / "seed0.training.pt"
    train_embedding(model, (obs, np.zeros((64, 2), np.float32), obs), config,
                    progress_bar=False, device="cpu", checkpoint_path=path)
    saved = load_checkpoint(path)
    # Finished: the run was killed during its control tasks; it trains again from scratch.
    assert resume_point(path, config, arch) is None and not path.exists()
    unfinished = {**saved.extra, "finished": False}

    def write_unfinished():
        save_checkpoint(path, model, saved.config, extra=unfinished, state=saved.state)

    write_unfinished()
    assert resume_point(path, dataclasses.replace(config, lr=1e-3), arch) is None
    assert not path.exists()  # other training settings: never continued
    write_unfinished()
    wider = {**arch, "model_config": {**arch["model_config"], "encoder_hidden": [512, 512]}}
    assert resume_point(path, config, wider) is None and not path.exists()
    write_unfinished()
    point = resume_point(path, config, arch)
    assert point.epoch == 1 and point.seconds > 0
    # Written before a config field with a default existed: still continued.
    older_arch = {**saved.architecture, "model_config": {
        k: v for k, v in saved.architecture["model_config"].items()
        if k != "decoder_pixel_shuffle"}}
    older_config = dict(saved.config)
    older_config["train_config"] = {k: v for k, v in saved.config["train_config"].items()
                                    if k != "kl_scale"}
    model.architecture = lambda: older_arch  # as the library described it back then
    save_checkpoint(path, model, older_config, extra=unfinished, state=saved.state)
    del model.architecture
    assert load_checkpoint(path).architecture == older_arch
    assert resume_point(path, config, arch).epoch == 1
    path.write_bytes(b"cut short")
    assert resume_point(path, config, arch) is None and not path.exists()


def test_aggregate_all_and_top1():
    def rec(seed, values):
        return {
            "spec": {
                "env_id": "e",
                "method": "pcc",
                "noise_std": 0.0,
                "preset": "p",
                "seed": seed,
                "model_variant": "paper",
            },
            "percentages": values,
            "train_seconds": 1.0,
        }

    rows = aggregate([rec(0, [0.0, 10.0]), rec(1, [50.0, 70.0])])
    (row,) = rows
    assert row["mean_all"] == 32.5 and row["mean_top1"] == 60.0 and row["top1_seed"] == 1
    assert row["oracle_mean"] is None
    # an oracle run of another preset on the same tasks is the ceiling of this row too
    oracle = rec(0, [40.0, 60.0])
    oracle["spec"] = {**oracle["spec"], "method": "oracle", "preset": "other"}
    with_oracle = aggregate([rec(0, [0.0, 10.0]), oracle])
    assert next(r for r in with_oracle if r["method"] == "pcc")["oracle_mean"] == 50.0
    assert np.isclose(row["se_all"], np.std([0, 10, 50, 70], ddof=1) / 2)
    assert row["n_models"] == 2 and row["n_tasks"] == 2
    assert row["iqm_ci"][0] <= row["iqm"] <= row["iqm_ci"][1]


def test_standard_error_of_one_task_is_undefined_not_zero():
    from pcc_agent.evaluation import format_mean_se, standard_error
    from pcc_bench.tables import markdown_table

    assert standard_error([3.0]) is None and standard_error([]) is None
    assert np.isclose(standard_error([0.0, 10.0]), 5.0)
    assert format_mean_se(42.0, None) == "42.0 ± n/a"
    one_task = {"spec": {"env_id": "e", "method": "pcc", "noise_std": 0.0, "preset": "p",
                         "seed": 0, "model_variant": "paper"},
                "percentages": [42.0], "train_seconds": 1.0}
    (row,) = aggregate([one_task])
    assert row["se_all"] is None and row["se_top1"] is None
    assert json.loads(json.dumps(row))["se_all"] is None  # null in summary.json, not NaN
    assert "| 42.0 ± n/a |" in markdown_table([row])


def test_interquartile_mean():
    assert interquartile_mean(np.array([0, 1, 2, 3, 4, 5, 6, 100])) == 3.5


def test_record_of_other_settings_is_stale(tmp_path):
    spec = tiny_spec()
    path = tmp_path / spec.relative_path
    from pcc_agent.agent import PCCAgent
    from pcc_bench.records import preset_for

    agent = PCCAgent(spec.env_id, method=spec.method, preset=preset_for(spec), seed=spec.seed)
    config = json.loads(json.dumps(agent.config_dict()))  # what execute_run records
    record = {"format": 1, "status": "done", "spec": dataclasses.asdict(spec), "percentages": [],
              "config": config}
    path.parent.mkdir(parents=True)
    path.write_text(json.dumps(record))
    assert load_finished_run(path, spec) is not None
    # Trained with other training, network or data settings than the preset's: stale.
    for section, key, value in (("train", "lr", 1.0), ("model", "latent_dim", 7),
                                ("data", "num_samples", 99)):
        other = {**config, section: {**config[section], key: value}}
        path.write_text(json.dumps({**record, "config": other}))
        assert load_finished_run(path, spec) is None, section
    # A noisy run's record from before the agent reported the data's noise (it said the
    # preset's unused 0.0) still counts: the noise is the spec's.
    noisy = dataclasses.replace(spec, noise_std=1.0)
    noisy_path = tmp_path / noisy.relative_path
    noisy_path.parent.mkdir(parents=True)
    noisy_path.write_text(json.dumps({**record, "spec": dataclasses.asdict(noisy)}))
    assert config["data"]["noise_std"] == 0.0
    assert load_finished_run(noisy_path, noisy) is not None
    # A record written before a config field existed (absent: its default) still counts.
    older_model = {k: v for k, v in config["model"].items() if k != "decoder_pixel_shuffle"}
    path.write_text(json.dumps({**record, "config": {**config, "model": older_model}}))
    assert load_finished_run(path, spec) is not None
    path.write_text(json.dumps(record))
    # Evaluated by an older planner (a record without a revision is revision 1): stale.
    without_revision = {k: v for k, v in config.items() if k != "planner_revision"}
    for old in ({**config, "planner_revision": PLANNER_REVISION - 1}, without_revision):
        path.write_text(json.dumps({**record, "config": old}))
        assert load_finished_run(path, spec) is None
    path.write_text(json.dumps(record))
    # Same file path, but --num-tasks / --max-epochs changed: the old record must not count.
    assert load_finished_run(path, dataclasses.replace(spec, num_tasks=5)) is None
    assert load_finished_run(path, dataclasses.replace(spec, max_epochs=3)) is None
    assert load_finished_run(path, dataclasses.replace(spec, patience=100)) is None
    # A record written before an override existed (key absent) matches a spec leaving it unset.
    older = {key: value for key, value in record["spec"].items() if key != "patience"}
    path.write_text(json.dumps({**record, "spec": older}))
    assert load_finished_run(path, spec) is not None
    assert load_finished_run(path, dataclasses.replace(spec, patience=100)) is None


def test_run_with_old_planner_settings_is_reevaluated_not_retrained(tmp_path):
    spec = tiny_spec(seed=1)
    first = execute_run(spec, tmp_path, str(tmp_path / "data"))
    path = tmp_path / spec.relative_path
    record = json.loads(path.read_text())
    record["config"]["planner"]["plan_length"] = 3  # as if the preset's planner had changed
    path.write_text(json.dumps(record))
    assert load_finished_run(path, spec) is None
    # The status and the cost estimate know that the model only runs its tasks again.
    assert "control tasks to run again" in training_progress(tmp_path, spec)
    control = first["eval_seconds"] * (1 + (spec.validation_tasks or 0) / spec.num_tasks)
    assert reevaluations(tmp_path, [spec]) == {spec: pytest.approx(control)}
    cost = estimate_cost([spec], reevaluated=reevaluations(tmp_path, [spec]))
    assert cost.bases == ("re-evaluation",)
    assert cost.run_seconds == (pytest.approx(control),)
    again = execute_run(spec, tmp_path, str(tmp_path / "data"))
    assert again["reevaluated"] is True and first["config"]["planner_revision"] == PLANNER_REVISION
    assert again["train_seconds"] == first["train_seconds"]
    assert again["config"]["planner"]["plan_length"] == first["config"]["planner"]["plan_length"]
    assert load_finished_run(path, spec) is not None


def test_record_is_reproduced_by_its_float16_weights_alone(tmp_path):
    from pcc_agent.agent import PCCAgent
    from pcc_agent.evaluation import evaluate_control
    from pcc_bench.records import checkpoint_path
    from pcc_bench.weights import export_run, sha256_of

    spec = tiny_spec(seed=2)
    record = execute_run(spec, tmp_path, str(tmp_path / "data"))
    weights = tmp_path / record["weights"]["file"]
    assert record["weights"]["dtype"] == "float16"
    assert record["weights"]["sha256"] == sha256_of(weights)
    evaluation = evaluate_control(PCCAgent.load(weights), spec.env_id, record["task_seeds"])
    assert [t.percent_in_goal for t in evaluation.tasks] == record["percentages"]
    # An evaluation change re-runs from the committed weights, without the float32 checkpoint.
    checkpoint_path(tmp_path, spec).unlink()
    path = tmp_path / spec.relative_path
    changed = json.loads(path.read_text())
    changed["config"]["planner"]["plan_length"] = 3
    path.write_text(json.dumps(changed))
    again = execute_run(spec, tmp_path, str(tmp_path / "data"))
    assert again["reevaluated"] is True and again["percentages"] == record["percentages"]
    # A record made before the weights existed gets them from its float32 checkpoint.
    old = tiny_spec(seed=3)
    execute_run(old, tmp_path, str(tmp_path / "data"))
    old_path = tmp_path / old.relative_path
    stripped = json.loads(old_path.read_text())
    (tmp_path / stripped.pop("weights")["file"]).unlink()
    old_path.write_text(json.dumps(stripped))
    assert export_run(old_path, tmp_path).startswith("exported")
    exported = json.loads(old_path.read_text())
    assert exported["percentages_float32"] == stripped["percentages"]
    assert (tmp_path / exported["weights"]["file"]).exists()
    assert export_run(old_path, tmp_path) == "has weights"


def test_explicit_model_seeds_select_the_grid_cells():
    from pcc_bench.grid import expand_grid
    from pcc_bench.presets import REPRODUCE_PRESETS

    preset = REPRODUCE_PRESETS["paper"].replace(envs=("pcc/Planar-v0",), methods=("pcc", "e2c"),
                                                model_seeds=(3, 7))
    runs = expand_grid(preset, include_oracle=False)
    assert sorted((r.method, r.seed) for r in runs) == [("e2c", 3), ("e2c", 7), ("pcc", 3),
                                                         ("pcc", 7)]
    assert {r.seed for r in expand_grid(preset.replace(model_seeds=None), False)} == set(range(10))


def test_training_overrides_reach_the_trained_model(tmp_path):
    from pcc_bench.grid import expand_grid
    from pcc_bench.presets import REPRODUCE_PRESETS
    from pcc_bench.tables import training_recipe

    long = REPRODUCE_PRESETS["paper-fast-long"].replace(envs=("pcc/Planar-v0",), methods=("pcc",))
    assert {(r.max_epochs, r.patience) for r in expand_grid(long, False)} == {(1000, 100)}
    spec = dataclasses.replace(tiny_spec(), patience=7, max_epochs=2, flush_denormals=True)
    record = execute_run(spec, tmp_path, str(tmp_path / "data"))
    train = record["config"]["train"]
    assert (train["patience"], train["epochs"], train["flush_denormals"]) == (7, 2, True)
    assert "subnormals flushed to zero" in training_recipe(record["config"])
    assert record["spec"]["patience"] == 7
    multistep = dataclasses.replace(tiny_spec(seed=1), max_epochs=1, prediction_horizon=2,
                                    plan_length=3)
    trained = execute_run(multistep, tmp_path, str(tmp_path / "data"))
    assert trained["config"]["train"]["prediction_horizon"] == 2
    assert trained["config"]["planner"]["plan_length"] == 3
    assert "2-step prediction term (weight 1 per extra step)" in training_recipe(
        trained["config"])
    # A record from before the option counts as trained without it, never as this run.
    assert load_finished_run(tmp_path / spec.relative_path, spec) is not None
    unflushed = dataclasses.replace(spec, flush_denormals=None)
    assert load_finished_run(tmp_path / spec.relative_path, unflushed) is None


def test_cost_estimate_uses_finished_runs_of_the_same_kind():
    pcc, rce, e2c = (dataclasses.replace(tiny_spec(9), method=m) for m in ("pcc", "rce", "e2c"))
    finished = [
        {"spec": dataclasses.asdict(dataclasses.replace(pcc, seed=s)), "train_seconds": t,
         "eval_seconds": 1.0}
        for s, t in [(0, 10.0), (1, 30.0), (2, 1000.0)]
    ] + [{"spec": dataclasses.asdict(rce), "train_seconds": 4.0, "eval_seconds": 0.0}]
    nothing_known = estimate_cost([pcc])
    assert nothing_known.runs_from_records == 0
    assert nothing_known.expected_seconds == nothing_known.upper_seconds > 0
    # pcc: mean of its own kind; rce: its own record; e2c: mean over all methods.
    cost = estimate_cost([pcc, rce, e2c], finished)
    assert cost.runs_from_records == 3
    assert np.allclose(cost.run_seconds, [np.mean([11, 31, 1001]), 4.0,
                                          np.mean([11, 31, 1001, 4])])
    assert np.isclose(cost.expected_seconds, sum(cost.run_seconds))
    assert cost.bases == ("same kind", "same kind", "other methods")
    caps = [estimate_cost([spec]).upper_seconds for spec in (pcc, rce, e2c)]
    # The bound is the cap, or the slowest finished run of the kind where that took longer
    # (the 1,001 s pcc run): never below the estimate.
    slowest = [1001.0, 4.0, 1001.0]
    assert caps[0] < 1001.0
    assert np.isclose(cost.upper_seconds, sum(map(max, caps, slowest)))
    assert cost.upper_seconds >= cost.expected_seconds
    # Another epoch budget is another kind: no record applies.
    longer = dataclasses.replace(pcc, max_epochs=2)
    assert estimate_cost([longer], finished).runs_from_records == 0


def test_cost_estimate_charges_a_resumed_run_only_the_epochs_left():
    spec = dataclasses.replace(tiny_spec(9), max_epochs=100)
    fresh = estimate_cost([spec]).run_seconds[0]
    resumed = estimate_cost([spec], resumed={spec: CheckpointedTraining(30, 2.0)})
    assert resumed.run_seconds == (70 * 2.0,) and resumed.bases == ("checkpoint",)
    # Without epoch times in the checkpoint: the other estimate, scaled to the epochs left.
    untimed = estimate_cost([spec], resumed={spec: CheckpointedTraining(30, None)})
    assert np.isclose(untimed.run_seconds[0], fresh * 0.7)


def _sleepy_run(spec: RunSpec, marker_dir: str | Path, seconds: float = 0.3) -> dict:
    """A stand-in run for the pool tests: leaves a marker (its worker's pid), takes a moment."""
    import time

    (Path(marker_dir) / f"{spec.seed}").write_text(str(os.getpid()))
    time.sleep(seconds)
    return {"seed": spec.seed}


def test_stopping_the_pool_cancels_queued_runs(tmp_path):
    """An error or close() in the consumer must not train the rest of the grid."""
    import time

    from pcc_bench.executors import pool_outcomes

    specs = [tiny_spec(seed) for seed in range(16)]
    outcomes = pool_outcomes(_sleepy_run, specs, 2, tmp_path)
    spec, first = next(outcomes)
    assert first == {"seed": spec.seed}
    start = time.perf_counter()
    outcomes.close()
    assert time.perf_counter() - start < 2.0  # did not wait for the queue
    time.sleep(1.5)  # the few runs already handed to the workers have finished by now
    # At most: the finished one, one per worker, and the pool's small hand-over queue.
    started = len(list(tmp_path.iterdir()))
    assert started <= 8, f"{started} of 16 runs started although the grid was stopped"


def _start_sleepy_grid(markers: Path, seconds: float = 5.0) -> subprocess.Popen:
    """A driver process running 8 stand-in runs of ``seconds`` on 2 workers, in its own process
    group and with SIGINT at its default (as under a terminal, even if pytest ignores it);
    returns once both workers are in their first run."""
    import signal
    import time

    code = (
        "import sys; sys.path.insert(0, 'tests/bench'); from test_reproduce import _sleepy_run, "
        "tiny_spec; from pcc_bench.grid import collect_outcomes; from pcc_bench.executors "
        "import interrupt, pool_outcomes; import signal; signal.signal(signal.SIGTERM, interrupt); "
        "specs = [tiny_spec(s) for s in range(8)]; "
        f"collect_outcomes(pool_outcomes(_sleepy_run, specs, 2, {str(markers)!r}, {seconds}), "
        "8)"
    )
    child = subprocess.Popen(
        [sys.executable, "-c", code], cwd=ROOT, start_new_session=True,
        stdout=subprocess.DEVNULL, stderr=subprocess.PIPE, text=True,
        preexec_fn=lambda: signal.signal(signal.SIGINT, signal.SIG_DFL),
    )
    deadline = time.monotonic() + 120
    while len(list(markers.iterdir())) < 2:  # both workers are in their first run
        assert child.poll() is None and time.monotonic() < deadline, child.stderr.read()
        time.sleep(0.02)
    return child


@pytest.mark.parametrize("how", ["SIGINT to the process group", "SIGTERM to the driver"])
def test_stop_signal_stops_the_grid_at_once(tmp_path, how):
    """A terminal's Ctrl-C signals the whole group; ``kill`` or a batch scheduler signals only
    the driver. Either way the runs in progress end, nothing new starts, and the driver exits."""
    import signal
    import time

    markers = tmp_path / "markers"
    markers.mkdir()
    child = _start_sleepy_grid(markers)
    start = time.monotonic()
    if how.startswith("SIGINT"):
        os.killpg(child.pid, signal.SIGINT)
    else:
        os.kill(child.pid, signal.SIGTERM)
    child.wait(timeout=30)
    stderr = child.stderr.read()
    assert time.monotonic() - start < 4.0, "the driver waited for the runs in progress"
    assert child.returncode != 0
    assert "Stopped: queued runs cancelled." in stderr
    assert "InvalidStateError" not in stderr
    time.sleep(1.0)
    assert len(list(markers.iterdir())) == 2, "runs started after the stop signal"


def _is_running(pid: int) -> bool:
    """Whether process ``pid`` exists and has not exited (a zombie has exited)."""
    try:
        with open(f"/proc/{pid}/stat") as handle:
            return handle.read().rsplit(")", 1)[1].split()[0] not in ("Z", "X")
    except FileNotFoundError:
        return False


def _children(pid: int) -> list[int]:
    """The processes whose parent is ``pid`` (from /proc)."""
    children = []
    for entry in Path("/proc").iterdir():
        try:
            if entry.name.isdigit() and int(
                    (entry / "stat").read_text().rsplit(")", 1)[1].split()[1]) == pid:
                children.append(int(entry.name))
        except (OSError, IndexError, ValueError):  # ended meanwhile
            continue
    return children


@pytest.mark.skipif(not sys.platform.startswith("linux"), reason="reads /proc")
def test_killed_driver_leaves_no_worker_running(tmp_path):
    """kill -9 of the driver (no handler runs): its pool workers end too, at once, instead of
    finishing their runs (here a minute each) with nobody left to collect the results; so do
    the pool's helper processes (loky's resource trackers)."""
    import signal
    import time

    markers = tmp_path / "markers"
    markers.mkdir()
    child = _start_sleepy_grid(markers, seconds=60.0)
    deadline = time.monotonic() + 10.0
    while not all(path.read_text() for path in markers.iterdir()):  # pids still being written
        assert time.monotonic() < deadline
        time.sleep(0.01)
    workers = [int(path.read_text()) for path in markers.iterdir()]
    assert len(set(workers)) == 2 and all(map(_is_running, workers))
    helpers = [pid for pid in _children(child.pid) if pid not in workers]
    alive = workers + helpers
    try:
        os.kill(child.pid, signal.SIGKILL)
        child.wait(timeout=30)
        deadline = time.monotonic() + 10.0
        while alive and time.monotonic() < deadline:
            time.sleep(0.05)
            alive = [pid for pid in alive if _is_running(pid)]
        assert not alive, (f"processes {alive} of workers {workers} and helpers {helpers} "
                           "outlived their killed driver")
    finally:
        for pid in alive:  # do not leave them sleeping on the machine when the test fails
            os.kill(pid, signal.SIGKILL)
    assert len(list(markers.iterdir())) == 2, "runs started after the driver died"


def test_interrupted_grid_exits_130_with_how_to_continue(tmp_path, monkeypatch, capsys):
    import pcc_bench.reproduce as reproduce

    def interrupted(*args, **kwargs):
        raise KeyboardInterrupt

    monkeypatch.setattr(reproduce, "run_grid", interrupted)
    code = reproduce.main(["--preset", "quick", "--num-models", "1", "--no-oracle",
                           "--results-dir", str(tmp_path / "res")])
    assert code == 130
    assert "run the same command again to continue" in capsys.readouterr().err
    assert not (tmp_path / "res" / "summary.json").exists()


def test_failed_run_is_reported_after_the_others_and_driver_writes_records(tmp_path):
    from pcc_bench.grid import collect_outcomes

    good = [tiny_spec(0), tiny_spec(2)]
    records = [{"spec": dataclasses.asdict(s), "mean": 50.0, "train_seconds": 1.0,
                "eval_seconds": 1.0, "status": "done", "format": 1} for s in good]
    outcomes = iter([(good[0], records[0]), (tiny_spec(1), ValueError("boom")),
                     (good[1], records[1])])
    with pytest.raises(RuntimeError, match=r"1 run\(s\) failed:\n.*seed=1: ValueError\('boom'\)"):
        collect_outcomes(outcomes, 3, write_to=tmp_path)
    for spec in good:  # both finished runs are kept although one run failed
        assert json.loads((tmp_path / spec.relative_path).read_text())["mean"] == 50.0


def test_overrides_that_change_the_runs_rename_the_preset():
    from pcc_bench.grid import expand_grid
    from pcc_bench.presets import REPRODUCE_PRESETS

    paper = REPRODUCE_PRESETS["paper"]
    # Selecting cells keeps the name: these are cells of the paper grid.
    assert paper.override(envs=("pcc/Planar-v0",), model_seeds=(3,)).name == "paper"
    shorter = paper.override(envs=("pcc/Planar-v0",), max_epochs=5, num_tasks=3)
    assert shorter.name == "paper+num_tasks=3,max_epochs=5" and shorter.base_name == "paper"
    runs = expand_grid(shorter)
    assert {r.preset for r in runs} == {shorter.name}
    assert all("paper+num_tasks=3,max_epochs=5" in str(r.relative_path) for r in runs)
    flushed = paper.override(flush_denormals=True)
    assert flushed.name == "paper+flush_denormals=True"
    assert {r.flush_denormals for r in expand_grid(flushed, include_oracle=False)} == {True}
    multistep = paper.override(prediction_horizon=3, plan_length=50)
    assert multistep.name == "paper+prediction_horizon=3,plan_length=50"
    runs = expand_grid(multistep.replace(envs=("pcc/CartPole-v1",)))
    assert {(r.prediction_horizon, r.plan_length) for r in runs
            if r.method not in ("oracle", "no-action")} == {(3, 50)}
    # The oracle keeps its own horizon: its runs are the preset's.
    assert {(r.prediction_horizon, r.plan_length) for r in runs
            if r.method in ("oracle", "no-action")} == {(None, None)}
    # Table 3 runs Planar at noise variance 1 and 2, the other domains at variance 1.
    noisy = REPRODUCE_PRESETS["paper-noisy"]
    levels = {(r.env_id, r.noise_std) for r in expand_grid(noisy, include_oracle=False)}
    assert ("pcc/Planar-v0", 2.0**0.5) in levels and ("pcc/CartPole-v1", 1.0) in levels
    assert ("pcc/CartPole-v1", 2.0**0.5) not in levels


def test_summary_says_which_table_and_when_the_grid_is_reduced():
    from pcc_bench.tables import models_cell, paper_table

    def rec(method, seed, noise=0.0):
        return {"spec": {"env_id": "pcc/Planar-v0", "method": method, "noise_std": noise,
                         "preset": "paper", "seed": seed, "model_variant": "paper"},
                "percentages": [10.0, 20.0], "train_seconds": 1.0}

    rows = aggregate([rec("pcc", 0), rec("pcc", 1), rec("pcc-amortized", 0),
                      rec("pcc", 0, noise=1.0)])
    by_key = {(r["method"], r["noise_std"]): r for r in rows}
    assert models_cell(by_key[("pcc", 0.0)]) == "2 of 10 x 2 (reduced grid)"
    assert [paper_table(by_key[k])[:7] for k in (("pcc", 0.0), ("pcc-amortized", 0.0),
                                                  ("pcc", 1.0))] == ["Table 1", "Table 2",
                                                                     "Table 3"]
    full = aggregate([rec("pcc", s) for s in range(10)])[0]
    assert models_cell(full) == "10 x 2"
    beyond = aggregate([rec("pcc", s) for s in range(12)])[0]
    assert models_cell(beyond) == "12 x 2 (2 beyond the preset's 10)"


def test_oracle_record_of_other_oracle_or_planner_settings_is_stale(tmp_path):
    from pcc_agent.oracle import oracle_config_for
    from pcc_bench.records import preset_for

    spec = dataclasses.replace(tiny_spec(), method="oracle", num_samples=None, max_epochs=None)
    oracle = json.loads(json.dumps(dataclasses.asdict(oracle_config_for(spec.env_id))))
    planner = json.loads(json.dumps(dataclasses.asdict(preset_for(spec).planner)))
    record = {"format": 1, "status": "done", "spec": dataclasses.asdict(spec), "percentages": [],
              "config": {"oracle": oracle, "planner": planner,
                         "planner_revision": PLANNER_REVISION}}
    path = tmp_path / "oracle.json"
    path.write_text(json.dumps(record))
    assert load_finished_run(path, spec) is not None
    for changed in ({"oracle": {**oracle, "fd_step": 123.0}},
                    {"planner": {**planner, "plan_length": planner["plan_length"] + 1}}):
        path.write_text(json.dumps({**record, "config": {**record["config"], **changed}}))
        assert load_finished_run(path, spec) is None


def test_oracle_record_with_the_oracles_own_horizon_stays_valid(tmp_path):
    from pcc_agent.oracle import oracle_config_for, oracle_planner_for
    from pcc_bench.records import preset_for

    spec = dataclasses.replace(tiny_spec(), env_id="pcc/CartPole-v1", method="oracle",
                               num_samples=None, max_epochs=None)
    oracle = oracle_config_for(spec.env_id)
    agents = preset_for(spec).planner
    assert oracle.plan_length is not None and oracle.plan_length != agents.plan_length
    # Written before OracleConfig had plan_length, with the horizon the oracle keeps: valid.
    older = {k: v for k, v in dataclasses.asdict(oracle).items() if k != "plan_length"}
    record = {"format": 1, "status": "done", "spec": dataclasses.asdict(spec), "percentages": [],
              "config": {"oracle": json.loads(json.dumps(older)),
                         "planner": dataclasses.asdict(oracle_planner_for(spec.env_id)),
                         "planner_revision": PLANNER_REVISION}}
    path = tmp_path / "oracle.json"
    path.write_text(json.dumps(record))
    assert load_finished_run(path, spec) is not None
    # Run with the agents' horizon, it is not this oracle.
    record["config"]["planner"] = dataclasses.asdict(agents)
    path.write_text(json.dumps(record))
    assert load_finished_run(path, spec) is None


def test_summary_keeps_older_planner_rows_apart_with_their_own_oracle(tmp_path):
    from pcc_bench.aggregation import aggregate
    from pcc_bench.records import NO_ACTION, load_records, preset_for

    def write(method, seed, revision, percentages, preset="test"):
        spec = dataclasses.replace(tiny_spec(), method=method, seed=seed, preset=preset,
                                   num_samples=None, max_epochs=None)
        config = {} if method == NO_ACTION else {"planner_revision": revision}
        if method == "pcc":  # what a trained agent records (PCCAgent.config_dict)
            preset = preset_for(spec)
            config.update(train=preset.train.to_dict(), model=preset.model.to_dict(),
                          data=dataclasses.asdict(preset.data))
        record = {"format": 1, "status": "done", "spec": dataclasses.asdict(spec),
                  "percentages": percentages, "train_seconds": 0.0, "config": config}
        path = tmp_path / "runs" / f"{method}_{seed}_r{revision}.json"
        path.parent.mkdir(parents=True, exist_ok=True)
        path.write_text(json.dumps(record))

    write("pcc", 0, PLANNER_REVISION - 1, [10.0])
    write("oracle", 0, PLANNER_REVISION - 1, [50.0])
    write(NO_ACTION, 0, None, [1.0])
    rows = {(r["method"], r["preset"]): r for r in aggregate(load_records(tmp_path))}
    old = f"test [planner r{PLANNER_REVISION - 1}]"
    assert set(rows) == {("pcc", old), ("oracle", old), (NO_ACTION, "test")}
    assert rows[("pcc", old)]["oracle_mean"] == 50.0  # its own revision's ceiling
    assert rows[("pcc", old)]["floor_mean"] == 1.0  # the floor plans nothing: any revision


@pytest.mark.parametrize(
    ("args", "message"),
    [(["--methods", "pcc", "ppo"], "invalid choice: 'ppo'"),
     (["--envs", "pcc/Nope-v0"], "invalid choice: 'pcc/Nope-v0'"),
     (["--num-tasks", "0"], "must be at least 1"),
     (["--noise", "-1"], "must be >= 0, got -1"),
     (["--noise-variance", "-2"], "must be >= 0, got -2"),
     (["--noise", "1", "--noise-variance", "2"], "not allowed with argument --noise"),
     (["--seeds", "3", "1000"], "--seeds must be below 1000"),
     (["--prediction-horizon", "1"], "--prediction-horizon must be at least 2"),
     (["--ray-gpus-per-task", "-1"], "must be >= 0")],
)
def test_bad_command_line_is_refused_before_any_run(tmp_path, capsys, args, message):
    from pcc_bench.reproduce import main

    with pytest.raises(SystemExit) as exit_info:
        main([*args, "--results-dir", str(tmp_path)])
    assert message in capsys.readouterr().err + str(exit_info.value)
    assert not (tmp_path / "runs").exists()


def test_noise_variance_names_the_same_runs_as_the_presets_table3_levels(tmp_path, capsys):
    from pcc_bench.reproduce import main

    def status(*noise_args):
        main(["--preset", "paper-noisy", "--envs", "pcc/Planar-v0", "--methods", "pcc",
              "--num-models", "1", "--no-oracle", *noise_args, "--status",
              "--results-dir", str(tmp_path)])
        return capsys.readouterr().out

    # Table 3's Planar_2 is variance 2: the preset's own level, standard deviation sqrt(2).
    plain = status()
    assert "noise=1.4142135623730951 seed=0" in plain
    # --status also says what the rest of the grid costs, and starts nothing.
    assert "2 runs, 2 to run: estimated" in plain
    assert not (tmp_path / "runs").exists()
    assert "noise=1.4142135623730951 seed=0" in status("--noise-variance", "2")
    assert "noise=2.0 seed=0" in status("--noise", "2")


def test_restarts_preset_keeps_the_training_with_the_lowest_validation_loss():
    from pcc_bench.aggregation import select_restarts
    from pcc_bench.grid import expand_grid
    from pcc_bench.presets import REPRODUCE_PRESETS, RESTART_SEED_STRIDE

    best3 = REPRODUCE_PRESETS["paper-fast-long-best3"].replace(
        envs=("pcc/Planar-v0",), methods=("pcc",), model_seeds=(0, 1))
    runs = expand_grid(best3, include_oracle=False)
    # The trainings are ordinary paper-fast-long runs: seed 0 and 1 exist already there.
    assert {r.preset for r in runs} == {"paper-fast-long"}
    assert sorted(r.seed for r in runs) == [0, 1, 1000, 1001, 2000, 2001]
    long_runs = expand_grid(REPRODUCE_PRESETS["paper-fast-long"].replace(
        envs=("pcc/Planar-v0",), methods=("pcc",), model_seeds=(0,)), include_oracle=False)
    assert runs[0] == long_runs[0]

    def rec(seed, loss, mean, preset="paper-fast-long", max_epochs=1000):
        return {"spec": {"env_id": "pcc/Planar-v0", "method": "pcc", "noise_std": 0.0,
                         "preset": preset, "seed": seed, "model_variant": "fast",
                         "max_epochs": max_epochs, "patience": 100},
                "training": {"best_validation_loss": loss}, "percentages": [mean, mean],
                "mean": mean, "train_seconds": 10.0}

    stride = RESTART_SEED_STRIDE
    records = [rec(0, 140.0, 20.0), rec(stride, 132.0, 75.0), rec(2 * stride, 150.0, 0.0),
               rec(1, 133.0, 70.0), rec(1 + stride, 135.0, 74.0)]  # model 1: one missing
    (model,) = select_restarts(records, [best3])
    assert model["spec"]["preset"] == "paper-fast-long-best3" and model["spec"]["seed"] == 0
    assert model["selected_training_seed"] == stride and model["mean"] == 75.0
    assert model["train_seconds"] == 30.0 and len(model["restarts"]) == 3
    rows = {r["preset"]: r for r in aggregate(records + [model])}
    # The plain preset's row keeps its own models 0 and 1; restart trainings stay out of it.
    assert rows["paper-fast-long"]["seeds"] == [0, 1]
    assert rows["paper-fast-long-best3"]["mean_all"] == 75.0
    assert rows["paper-fast-long-best3"]["n_models_planned"] == 10
    # A training of another recipe filed under the plain name (older code) is not a candidate.
    off_recipe = [rec(1 + 2 * stride, 100.0, 75.0, max_epochs=5)]
    assert len(select_restarts(records + off_recipe, [best3])) == 1
    # Trainings run with an override make the models of the overridden restarts preset.
    short = [rec(k * stride, 140.0 - k, 10.0 * k, "paper-fast-long+max_epochs=5", 5)
             for k in range(3)]
    (overridden,) = select_restarts(short, [best3])
    assert overridden["spec"]["preset"] == "paper-fast-long-best3+max_epochs=5"
    assert overridden["mean"] == 20.0
    assert best3.override(max_epochs=5).name == "paper-fast-long-best3+max_epochs=5"
    assert best3.override(max_epochs=5).runs_preset == "paper-fast-long+max_epochs=5"
    # A preset with fewer restarts uses the first trainings and ignores the third.
    best2 = best3.replace(name="best2", restarts=2)
    picked = {m["spec"]["seed"]: m for m in select_restarts(records, [best2])}
    assert sorted(picked) == [0, 1]
    assert picked[0]["mean"] == 75.0 and len(picked[0]["restarts"]) == 2
    assert picked[1]["selected_training_seed"] == 1 and picked[1]["mean"] == 70.0


def test_grid_has_a_no_action_floor_per_env_and_noise_level():
    from pcc_bench import reproduce
    from pcc_bench.grid import expand_grid
    from pcc_bench.presets import REPRODUCE_PRESETS
    from pcc_bench.records import NO_ACTION

    preset = REPRODUCE_PRESETS["paper-noisy"].override(envs=("pcc/Planar-v0",),
                                                        methods=("pcc",), model_seeds=(0,))
    floors = [r for r in expand_grid(preset) if r.method == NO_ACTION]
    assert sorted(r.noise_std for r in floors) == sorted(preset.noise_levels_for("pcc/Planar-v0"))
    assert not any(r.method == NO_ACTION for r in expand_grid(preset, include_oracle=False))
    only_floor = expand_grid(preset, include_oracle=False, include_floor=True)
    assert {r.method for r in only_floor} == {NO_ACTION, "pcc"}
    # The command line: --no-oracle drops both references unless --floor brings the floor back.
    parse = reproduce.build_parser().parse_args
    for flags, oracle, floor in (([], True, True), (["--no-oracle"], False, False),
                                 (["--no-oracle", "--floor"], False, True),
                                 (["--no-floor"], True, False)):
        args = parse(flags)
        methods = {r.method for r in expand_grid(preset, include_oracle=not args.no_oracle,
                                                 include_floor=args.floor)}
        assert ("oracle" in methods, NO_ACTION in methods) == (oracle, floor), flags


def test_no_action_run_scores_the_starts_inside_the_goal_and_is_skipped_once_done(tmp_path):
    from pcc_bench.records import NO_ACTION
    from pcc_bench.tables import markdown_table

    # CartPole task seed 2020: the first start lies outside the goal, the second inside it.
    spec = RunSpec(env_id="pcc/CartPole-v0", method=NO_ACTION, seed=0, noise_std=0.0,
                   num_tasks=2, task_seed=2020, model_variant="paper", preset="test")
    record = execute_run(spec, tmp_path, str(tmp_path / "data"))
    assert record["train_seconds"] == 0.0 and record["config"] == {"no_action": True}
    assert record["percentages"][0] == 0.0 and record["percentages"][1] > 0.0
    assert not (tmp_path / "data").exists() and not (tmp_path / "checkpoints").exists()
    assert execute_run(spec, tmp_path, str(tmp_path / "data")).get("skipped") is True
    # The floor is a column of every row on the same tasks, beside the oracle's ceiling.
    model = {"spec": {**dataclasses.asdict(spec), "method": "pcc", "preset": "other"},
             "percentages": [5.0, 15.0], "train_seconds": 1.0}
    rows = aggregate([record, model])
    pcc = next(r for r in rows if r["method"] == "pcc")
    assert pcc["floor_mean"] == np.mean(record["percentages"]) and pcc["oracle_mean"] is None
    table = markdown_table(rows)
    assert "| oracle | no action |" in table
    # Noise is shown as the paper's Table 3 shows it, a variance: std sqrt(2) reads 2.
    noisy = markdown_table([{**pcc, "noise_std": 2.0**0.5}])
    assert "| noise variance |" in noisy and "| pcc | 2 |" in noisy
    assert f"| - | {pcc['floor_mean']:.1f} |" in table


def test_stop_reason_of_old_records_is_inferred_and_new_ones_are_read():
    from pcc_bench.records import stop_reason_of

    assert stop_reason_of({"spec": {"method": "oracle"}}) is None  # trained nothing
    old = {"epochs": 209, "converged": True, "diverged": False,
           "message": "Early stopping: no validation improvement for 100 epochs."}
    assert stop_reason_of({"training": old}) == "early_stopping"
    capped = {**old, "converged": False, "message": "Reached the maximum of 250 epochs."}
    assert stop_reason_of({"training": capped}) == "epoch_cap"
    assert stop_reason_of({"training": {**capped, "diverged": True}}) == "diverged"
    assert stop_reason_of({"training": {**capped, "stop_reason": "callback"}}) == "callback"
    # The committed quick records predate the field; the grid's line still says why.
    quick = ROOT / "results" / "quick" / "runs"
    if not quick.exists():
        pytest.skip("no committed results (not a source checkout)")
    lines = sorted(report_line(1, 1, json.loads(p.read_text())) for p in quick.rglob("*.json")
                   if "/pcc/" in p.as_posix())
    assert sum(": 250 epochs, the cap;" in line for line in lines) == 2
    assert sum(": early stop at epoch 209, best 109;" in line for line in lines) == 1


def test_wall_time_places_the_runs_in_order_on_the_first_free_worker():
    from pcc_bench.costs import format_duration, makespan

    # The quick grid's shape: oracle, floor, then three models on two workers.
    assert makespan([6.0, 0.1, 300.0, 300.0, 200.0], 2) == pytest.approx(500.1)
    assert makespan([6.0, 0.1, 300.0, 300.0, 200.0], 1) == pytest.approx(806.1)
    assert makespan([5.0], 8) == 5.0 and makespan([], 2) == 0.0
    assert format_duration(564) == "9.4 min" and format_duration(5.5 * 3600) == "5.5 h"


def _timed_record(spec, train_seconds, epochs, machine, eval_seconds=2.0):
    return {"spec": dataclasses.asdict(spec), "train_seconds": train_seconds,
            "eval_seconds": eval_seconds, "training": {"epochs": epochs}, "machine": machine}


def test_cost_estimate_prefers_this_machine_and_scales_epochs_for_another_cap():
    here = {"cpu": "Fast CPU", "cpu_count": 2}
    elsewhere = {"cpu": "Slow CPU", "cpu_count": 2}
    spec = dataclasses.replace(tiny_spec(0), max_epochs=250, patience=100, num_tasks=10)
    # Three runs on this machine at 1 s/epoch (one stopped early at 200), three elsewhere at 4.
    finished = [_timed_record(spec, 250.0, 250, here), _timed_record(spec, 250.0, 250, here),
                _timed_record(spec, 200.0, 200, here)]
    finished += [_timed_record(spec, 4 * 250.0, 250, elsewhere) for _ in range(3)]
    cost = estimate_cost([spec], finished, machine=here)
    assert cost.bases == ("same kind, this machine",)
    assert cost.run_seconds[0] == pytest.approx(np.mean([252, 252, 202]))
    assert cost.run_upper_seconds[0] == pytest.approx(1.0 * 250 + 2.0)  # to the cap
    assert estimate_cost([spec], finished, machine=elsewhere).run_seconds[0] == (
        pytest.approx(1002.0))
    # Another epoch cap, same model: seconds per epoch times the epochs the runs would train.
    # Cap 300: the capped runs would have gone on (300), the early stop stays at 200.
    longer = dataclasses.replace(spec, max_epochs=300)
    cost = estimate_cost([longer], finished, machine=here)
    assert cost.bases == ("same model, this machine",)
    speed = np.mean([250 / 250, 250 / 250, 200 / 200])
    assert cost.run_seconds[0] == pytest.approx(speed * np.mean([300, 300, 200]) + 2.0)
    # Cap 100: every run trains to it.
    shorter = dataclasses.replace(spec, max_epochs=100)
    assert estimate_cost([shorter], finished, machine=here).run_seconds[0] == (
        pytest.approx(speed * 100 + 2.0))


def test_cost_estimate_of_a_multistep_run_scales_the_one_step_models_epochs():
    here = {"cpu": "Fast CPU", "cpu_count": 2}
    one_step = dataclasses.replace(tiny_spec(0), max_epochs=30, num_tasks=10)
    finished = [_timed_record(one_step, 30 * 20.0, 30, here) for _ in range(3)]
    five_step = dataclasses.replace(one_step, prediction_horizon=5)
    cost = estimate_cost([five_step], finished, machine=here)
    assert cost.bases == ("one-step model, this machine",)
    assert cost.runs_from_records == 1
    factor = multistep_cost_factor(5)
    assert factor == pytest.approx(1 + 4 * MULTISTEP_COST_PER_STEP) and factor > 1
    assert multistep_cost_factor(None) == multistep_cost_factor(1) == 1.0
    assert cost.run_seconds[0] == pytest.approx(factor * 20.0 * 30 + 2.0)
    # Without any record the guess per epoch is scaled by the same factor.
    assert estimate_cost([five_step]).run_seconds[0] == pytest.approx(
        factor * estimate_cost([one_step]).run_seconds[0])


def test_status_of_the_quick_preset_comes_from_its_committed_runs(tmp_path, capsys):
    """The quick grid took 7 min 24 s (results/quick/COMMAND); its runs must estimate about that.

    Other committed grids hold quick runs of other machines and loads (the 10-model Planar row
    trained beside another job on an AMD EPYC, about 1.8 times slower), so ``--status`` on
    this machine is checked against the estimate from every committed record instead.
    """
    from pcc_bench.costs import load_timing_records, timing_directories
    from pcc_bench.grid import expand_grid
    from pcc_bench.paths import COMMITTED_RESULTS_DIR
    from pcc_bench.presets import REPRODUCE_PRESETS
    from pcc_bench.records import machine_info
    from pcc_bench.reproduce import main

    quick = COMMITTED_RESULTS_DIR / "quick"
    if not (quick / "runs").is_dir():
        pytest.skip("no committed results (not a source checkout)")
    measured = 7 * 60 + 24
    runs = expand_grid(REPRODUCE_PRESETS["quick"])
    machine = json.loads(next((quick / "runs").rglob("seed0.json")).read_text())["machine"]
    for here in (machine, None):  # on the machine that ran it, and on an unknown one
        cost = estimate_cost(runs, load_timing_records([quick]), here)
        assert cost.runs_from_records == len(runs) == 6
        assert measured / 1.5 < cost.wall_seconds(2) < measured * 1.5
        assert cost.upper_wall_seconds(2) >= cost.wall_seconds(2)
    expected = estimate_cost(runs, load_timing_records(timing_directories(tmp_path)),
                             machine_info()).wall_seconds(2)
    assert main(["--status", "--results-dir", str(tmp_path), "--workers", "2"]) == 0
    out = capsys.readouterr().out
    line = next(x for x in out.splitlines() if x.startswith("Preset 'quick'"))
    minutes = float(line.split("estimated ")[1].split(" min")[0])
    assert 60 * minutes == pytest.approx(expected, abs=3.0)  # printed to 0.1 min
    assert "Based on: 6 runs from the mean time of finished runs of the same kind" in out
    assert "results/quick" in out or "results/reproduce" in out  # it names its sources


def test_spare_trainings_keep_the_models_that_control_best_on_validation_tasks():
    from pcc_bench.aggregation import choose_models, kept_trainings
    from pcc_bench.grid import expand_grid
    from pcc_bench.presets import REPRODUCE_PRESETS, VALIDATION_TASKS
    from pcc_bench.showcase import selection_lines

    quick = REPRODUCE_PRESETS["quick"]
    assert quick.spare_trainings == 1
    trainings = [r for r in expand_grid(quick) if r.method == "pcc"]
    assert [r.seed for r in trainings] == [0, 1, 2, 3]
    assert {r.validation_tasks for r in trainings} == {VALIDATION_TASKS}
    assert {r.preset for r in trainings} == {"quick"}

    def rec(seed, validation, loss, mean, preset="quick"):
        return {"spec": {"env_id": "pcc/Planar-v0", "method": "pcc", "noise_std": 0.0,
                         "preset": preset, "seed": seed, "model_variant": "fast"},
                "training": {"best_validation_loss": loss}, "percentages": [mean, mean],
                "validation": {"mean": validation}, "mean": mean, "train_seconds": 10.0}

    # Seed 2 folded (0 on validation); seeds 1 and 3 tie on validation, 3 has the lower loss.
    records = [rec(0, 70.0, 135.0, 75.0), rec(1, 60.0, 140.0, 66.0),
               rec(2, 0.0, 138.0, 0.0), rec(3, 60.0, 139.0, 50.0)]
    kept = kept_trainings(records)
    assert [r["spec"]["seed"] for r in kept] == [0, 1, 3]
    assert [t["kept"] for t in kept[0]["selection"]["trainings"]] == [True, True, False, True]
    (row,) = aggregate(choose_models(records))
    assert row["seeds"] == [0, 1, 3] and row["n_models"] == row["n_models_planned"] == 3
    assert row["mean_all"] == pytest.approx((75.0 + 66.0 + 50.0) / 3)
    line = selection_lines({"pcc": {r["spec"]["seed"]: r for r in records}}, "quick")[0]
    assert "the 3 of 4 trainings" in line and "#2 0.0 (left out)" in line
    # The worst of the trainings done so far is left out (a reduced grid); with no more
    # trainings than spares, or a training without a validation score, none is.
    assert [r["spec"]["seed"] for r in kept_trainings(records[:3])] == [0, 1]
    assert kept_trainings(records[:1]) == records[:1]
    unscored = [records[0], records[1], records[2], {**records[3], "validation": None}]
    del unscored[3]["validation"]
    assert kept_trainings(unscored) == unscored
    # Overridden runs ("quick+max_epochs=5") choose among their own trainings; others pass.
    short = [rec(k, 10.0 * k, 140.0, 1.0, "quick+max_epochs=5") for k in range(4)]
    assert [r["spec"]["seed"] for r in kept_trainings(short)] == [1, 2, 3]
    other = [rec(k, 0.0, 140.0, 1.0, "paper-fast") for k in range(4)]
    assert kept_trainings(other) == other
    # Explicit seeds are run as given; restarts and spares do not mix.
    assert quick.replace(model_seeds=(5,)).seeds() == (5,)
    with pytest.raises(ValueError, match="not both"):
        quick.replace(restarts=2)


def test_a_spare_preset_chooses_among_another_presets_runs_and_leaves_their_rows():
    from pcc_bench.aggregation import choose_models
    from pcc_bench.grid import expand_grid
    from pcc_bench.presets import CONTROL_SELECTION_TASKS, REPRODUCE_PRESETS
    from pcc_bench.reproduce import main
    from pcc_bench.tables import settings_table

    spare = REPRODUCE_PRESETS["paper-motion-spare2"].override(keep_best_control_every=5)
    assert spare.name == "paper-motion-spare2+keep_best_control_every=5"
    assert spare.runs_preset == "paper-motion+keep_best_control_every=5"
    # Its 12 trainings are filed (and specified) exactly as paper-motion's with the same
    # override, so the 10 that exist are reused.
    own = REPRODUCE_PRESETS["paper-motion"].override(keep_best_control_every=5)
    assert own.envs == spare.envs
    trainings = [r for r in expand_grid(spare, include_oracle=False)
                 if r.method == "pcc" and r.env_id == "pcc/CartPole-v1"]
    assert [r.seed for r in trainings] == list(range(12))
    assert trainings[:10] == [r for r in expand_grid(own, include_oracle=False)
                              if r.method == "pcc" and r.env_id == "pcc/CartPole-v1"]
    assert {r.validation_tasks for r in trainings} == {CONTROL_SELECTION_TASKS}
    # Without validation scores to choose by it refuses to run.
    with pytest.raises(ValueError, match="--keep-best-control"):
        REPRODUCE_PRESETS["paper-motion-spare2"].override(max_epochs=3)
    with pytest.raises(SystemExit, match="no validation tasks"):
        main(["--preset", "paper-motion-spare2", "--status"])

    def rec(seed, validation):
        return {"spec": {"env_id": "pcc/CartPole-v1", "method": "pcc", "noise_std": 0.0,
                         "preset": spare.runs_preset, "seed": seed, "model_variant": "motion"},
                "training": {"best_validation_loss": 100.0}, "percentages": [validation],
                "validation": {"mean": validation}, "mean": validation, "train_seconds": 1.0}

    # Seeds 3 and 7 control worst on validation: the spare row leaves them out; the
    # paper-motion row keeps its 10 models, without the spares.
    records = [rec(seed, 10.0 if seed in (3, 7) else 50.0 + seed) for seed in range(12)]
    rows = {row["preset"]: row for row in aggregate(choose_models(records))}
    assert rows[spare.runs_preset]["seeds"] == list(range(10))
    chosen = rows[spare.name]
    assert chosen["seeds"] == [0, 1, 2, 4, 5, 6, 8, 9, 10, 11]
    assert chosen["n_models"] == chosen["n_models_planned"] == 10
    assert "the 10 of 12 trainings that control best" in settings_table([chosen])
    # Before a spare has run there is no spare row; an env run beyond the preset's has one.
    rows = {row["preset"] for row in aggregate(choose_models(records[:10]))}
    assert rows == {spare.runs_preset}
    assert "pcc/PendulumBalance-v0" not in spare.envs
    elsewhere = [{**r, "spec": {**r["spec"], "env_id": "pcc/PendulumBalance-v0"}}
                 for r in records]
    rows = {row["preset"]: row for row in aggregate(choose_models(elsewhere))}
    assert rows[spare.name]["seeds"] == chosen["seeds"]


def test_a_run_with_validation_tasks_records_its_validation_control(tmp_path):
    spec = dataclasses.replace(tiny_spec(), validation_tasks=2)
    record = execute_run(spec, tmp_path, str(tmp_path / "data"))
    validation = record["validation"]
    assert len(validation["percentages"]) == 2 and len(validation["task_seeds"]) == 2
    assert validation["mean"] == pytest.approx(sum(validation["percentages"]) / 2)
    assert set(validation["task_seeds"]).isdisjoint(record["task_seeds"])
    # The evaluation tasks are planned exactly as without validation tasks.
    plain = execute_run(tiny_spec(), tmp_path / "plain", str(tmp_path / "data"))
    assert plain["percentages"] == record["percentages"] and "validation" not in plain


def test_settings_table_counts_the_kept_trainings_of_a_grown_spare_grid():
    from pcc_bench.tables import settings_table

    row = {"env": "pcc/Planar-v0", "preset": "quick", "method": "pcc", "n_models": 10,
           "n_tasks": 10, "seeds": [0, 1, *range(3, 11)], "settings": {"planner": {}}}
    assert "the 10 of 11 trainings that control best" in settings_table([row])
