"""The training-speed benchmark: its synthetic data and its multi-step rows."""

from __future__ import annotations

import json

import numpy as np
import pytest

from pcc_agent.presets import OBS_SHAPES
from pcc_bench.train_speed import main, synthetic_data


def test_synthetic_multistep_data_are_consecutive_transitions_of_one_square():
    one_step = synthetic_data("pcc/CartPole-v1", 8, seed=3)
    data = synthetic_data("pcc/CartPole-v1", 8, seed=3, prediction_horizon=4)
    assert one_step.future_obs is None and one_step.prediction_horizon == 1
    assert data.prediction_horizon == 4
    assert data.future_obs.shape == (8, 3, *OBS_SHAPES["pcc/CartPole-v1"])
    assert data.future_action.shape == (8, 3, 1)  # CartPole has one action
    # The first transition is the one-step data's; each later observation shifts one frame.
    np.testing.assert_array_equal(data.obs, one_step.obs)
    np.testing.assert_array_equal(data.next_obs, one_step.next_obs)
    np.testing.assert_array_equal(data.action, one_step.action)
    chain = [data.obs, data.next_obs, *data.future_obs.transpose(1, 0, 2, 3, 4)]
    for earlier, later in zip(chain, chain[1:]):
        np.testing.assert_array_equal(later[:, :-1], earlier[:, 1:])
    assert all(frame.any() for frame in chain)  # the square is drawn in every frame


def test_a_multistep_row_names_its_horizon(tmp_path):
    output = tmp_path / "speed.json"
    args = ["--envs", "pcc/Planar-v0", "--variants", "fast", "--max-samples", "64",
            "--epochs", "1", "--threads", "1", "--output", str(output)]
    rows = main([*args, "--prediction-horizon", "3"])
    assert rows[0]["prediction_horizon"] == 3 and rows[0]["seconds_per_epoch"] > 0
    # --append keeps the rows of another horizon apart.
    main([*args, "--append"])
    assert sorted(row["prediction_horizon"] for row in json.loads(output.read_text())) == [1, 3]


def test_a_prediction_horizon_below_one_is_refused(tmp_path, capsys):
    with pytest.raises(SystemExit):
        main(["--prediction-horizon", "0", "--output", str(tmp_path / "speed.json")])
    assert "--prediction-horizon must be at least 1, got 0" in capsys.readouterr().err


def test_a_bfloat16_row_says_whether_autocast_ran(tmp_path):
    from pcc_agent.training import native_bf16

    output = tmp_path / "speed.json"
    args = ["--envs", "pcc/Planar-v0", "--variants", "fast", "--max-samples", "64",
            "--epochs", "1", "--threads", "1", "--output", str(output)]
    (row,) = main([*args, "--mixed-precision", "auto"])
    assert row["mixed_precision"] == "auto" and row["bf16_autocast"] == native_bf16("cpu")
    assert row["flush_denormals"] is True and row["cpu"]
    # --append keeps float32 and bfloat16 rows apart.
    main([*args, "--append"])
    rows = json.loads(output.read_text())
    assert sorted(row["mixed_precision"] for row in rows) == ["auto", "off"]
