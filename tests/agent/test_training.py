"""Tiny end-to-end training runs, determinism, checkpoints and divergence handling."""

import dataclasses
import json
import math

import numpy as np
import pytest
import torch

from pcc_agent import training
from pcc_agent.checkpoint import CheckpointError, load_checkpoint, load_model, save_checkpoint
from pcc_agent.losses import model_config_for_method
from pcc_agent.model import EmbeddingModel
from pcc_agent.presets import ModelConfig, TrainConfig
from pcc_agent.training import (
    Trainer,
    dataset_arrays,
    denormals_flushed,
    flushed_denormals,
    native_bf16,
    resolve_device,
    train_embedding,
    uses_bf16_autocast,
)

pytestmark = pytest.mark.usefixtures("single_torch_thread")

SIZE = 20
CONFIG = ModelConfig(latent_dim=2, encoder_hidden=(64,), decoder_hidden=(64,),
                     transition_hidden=(16, 16), backward_nz=5, backward_nu=5, backward_nx=32,
                     backward_joint=32)
TRAIN = TrainConfig(epochs=3, batch_size=32, validation_fraction=0.2, patience=0, seed=0,
                    lr=2e-3)


def planar_like(n: int, seed: int = 0):
    """A bright 3x3 square at a random position, moved by the (scaled) action."""
    rng = np.random.default_rng(seed)
    pos = rng.integers(1, SIZE - 2, size=(n, 2))
    action = rng.uniform(-1, 1, size=(n, 2)).astype(np.float32)
    nxt = np.clip(pos + np.round(2 * action).astype(int), 1, SIZE - 2)

    def render(p):
        img = np.zeros((n, 1, SIZE, SIZE), np.uint8)
        for i, (r, c) in enumerate(p):
            img[i, 0, r - 1:r + 2, c - 1:c + 2] = 255
        return img

    return render(pos), action, render(nxt)


def _train(data, method="pcc", config=TRAIN, progress_bar=False, **kwargs):
    model = EmbeddingModel((1, SIZE, SIZE), 2, model_config_for_method(CONFIG, method), seed=0)
    result = train_embedding(model, data, config, method=method, device="cpu",
                             progress_bar=progress_bar, **kwargs)
    return model, result


def test_tiny_training_lowers_the_loss():
    _, result = _train(planar_like(300))
    losses = [row["val/loss"] for row in result.history]
    assert result.epochs == 3 and len(losses) == 3
    assert losses[-1] < 0.8 * losses[0]
    assert all(math.isfinite(v) for row in result.history for v in row.values())
    assert result.best_validation_loss == min(losses)


def test_two_seeded_runs_are_bitwise_identical():
    data = planar_like(160)
    config = dataclasses.replace(TRAIN, epochs=2)
    first, _ = _train(data, config=config)
    second, _ = _train(data, config=config)
    for (name, a), (_, b) in zip(first.state_dict().items(), second.state_dict().items()):
        assert torch.equal(a, b), name
    third, _ = _train(data, config=dataclasses.replace(config, seed=1))
    assert not torch.equal(first.encoder.head.weight, third.encoder.head.weight)


def test_flushed_denormals_is_scoped_and_reaches_the_training():
    assert not denormals_flushed()
    with flushed_denormals():
        assert denormals_flushed()
        with flushed_denormals(False):  # off means "leave the mode alone"
            assert denormals_flushed()
    assert not denormals_flushed()

    modes = []
    _train(planar_like(96), config=dataclasses.replace(TRAIN, flush_denormals=True),
           epoch_callback=lambda epoch, metrics: modes.append(denormals_flushed()))
    assert modes == [True] * TRAIN.epochs and not denormals_flushed()
    modes.clear()
    _train(planar_like(96), config=dataclasses.replace(TRAIN, flush_denormals=False),
           epoch_callback=lambda epoch, metrics: modes.append(denormals_flushed()))
    assert modes == [False] * TRAIN.epochs


@pytest.mark.parametrize("flags, native", [({"amx_bf16", "avx512f"}, True),
                                           ({"avx512_bf16"}, True), ({"avx2", "fma"}, False)])
def test_mixed_precision_is_bf16_only_where_the_cpu_multiplies_it(monkeypatch, flags, native):
    monkeypatch.setattr(training, "cpu_flags", lambda: frozenset(flags))
    assert native_bf16("cpu") is native
    assert uses_bf16_autocast("off", "cpu") is False
    assert uses_bf16_autocast("auto", "cpu") is native
    if native:
        assert uses_bf16_autocast("bf16", "cpu") is True
    else:
        with pytest.warns(RuntimeWarning, match="emulated"):
            assert uses_bf16_autocast("bf16", "cpu") is True
    with pytest.raises(ValueError, match="mixed_precision"):
        TrainConfig(mixed_precision="fp16")


def test_bf16_training_computes_in_bf16_keeps_float32_weights_and_is_deterministic(
        monkeypatch):
    monkeypatch.setattr(training, "cpu_flags", lambda: frozenset({"amx_bf16"}))
    config = dataclasses.replace(TRAIN, epochs=2, mixed_precision="bf16")
    dtypes = []
    hook = torch.nn.modules.module.register_module_forward_hook(
        lambda module, args, output: dtypes.append(output.dtype)
        if isinstance(module, torch.nn.Linear) else None)
    try:
        first, result = _train(planar_like(160), config=config)
    finally:
        hook.remove()
    assert torch.bfloat16 in dtypes  # the products ran in bfloat16
    assert all(p.dtype == torch.float32 for p in first.parameters())
    assert all(math.isfinite(row["val/loss"]) for row in result.history)
    second, _ = _train(planar_like(160), config=config)
    for (name, a), (_, b) in zip(first.state_dict().items(), second.state_dict().items()):
        assert torch.equal(a, b), name
    fp32, _ = _train(planar_like(160), config=dataclasses.replace(config, mixed_precision="off"))
    assert not torch.equal(first.encoder.head.weight, fp32.encoder.head.weight)
    model = EmbeddingModel((1, SIZE, SIZE), 2, CONFIG, seed=0)
    assert Trainer(model, config, device="cpu")._config_dict()["bf16_autocast"] is True


@pytest.mark.parametrize("method", ["e2c", "rce"])
def test_baselines_train(method):
    _, result = _train(planar_like(128), method=method,
                       config=dataclasses.replace(TRAIN, epochs=2))
    assert result.epochs == 2 and not result.diverged


def test_checkpoint_round_trip_and_resume(tmp_path):
    data = planar_like(160)
    path = tmp_path / "model.pt"
    config = dataclasses.replace(TRAIN, epochs=2)
    model, _ = _train(data, config=config, checkpoint_path=path)
    assert json.loads(path.with_suffix(".json").read_text())["method"] == "pcc"
    loaded, checkpoint = load_model(path, obs_shape=(1, SIZE, SIZE), action_dim=2)
    assert checkpoint.extra["finished"] and checkpoint.extra["epochs"] == 2
    obs = torch.from_numpy(data[0][:8])
    with torch.no_grad():
        torch.testing.assert_close(loaded.encode(obs)[0], model.encode(obs)[0], rtol=0, atol=0)
    resumed_model, resumed = _train(data, config=dataclasses.replace(config, epochs=3),
                                    checkpoint_path=path, resume=True)
    assert resumed.epochs == 3 and len(resumed.history) == 3
    # The speed covers all three epochs, not this sitting's one epoch spread over three.
    epoch_times = [row["time/epoch_seconds"] for row in resumed.history]
    assert resumed.summary()["seconds_per_epoch"] == pytest.approx(sum(epoch_times) / 3)
    straight, _ = _train(data, config=dataclasses.replace(config, epochs=3))
    for a, b in zip(straight.state_dict().values(), resumed_model.state_dict().values()):
        assert torch.equal(a, b)  # resuming continues exactly where an uninterrupted run is


def test_corrupt_and_mismatched_checkpoints_raise(tmp_path):
    model = EmbeddingModel((1, SIZE, SIZE), 2, CONFIG, seed=0)
    path = save_checkpoint(tmp_path / "ok.pt", model, {"method": "pcc"})
    truncated = tmp_path / "truncated.pt"
    truncated.write_bytes(path.read_bytes()[: path.stat().st_size // 2])
    with pytest.raises(CheckpointError, match="is truncated"):
        load_checkpoint(truncated)
    garbage = tmp_path / "garbage.pt"
    garbage.write_bytes(b"not a checkpoint at all")
    with pytest.raises(CheckpointError):
        load_checkpoint(garbage)
    with pytest.raises(CheckpointError, match="does not exist"):
        load_checkpoint(tmp_path / "missing.pt")
    with pytest.raises(CheckpointError, match="shape"):
        load_model(path, obs_shape=(2, SIZE, SIZE))
    with pytest.raises(CheckpointError, match="action"):
        load_model(path, action_dim=3)
    other = EmbeddingModel((1, SIZE, SIZE), 2, dataclasses.replace(CONFIG, latent_dim=3))
    from pcc_agent.checkpoint import load_weights

    with pytest.raises(CheckpointError, match="does not match"):
        load_weights(other, load_checkpoint(path))


def test_divergence_stops_and_restores_last_good_weights():
    config = dataclasses.replace(TRAIN, epochs=3, divergence_factor=1e-3)
    model, result = _train(planar_like(96), config=config)
    assert result.diverged and result.epochs == 1 and result.stop_reason == "diverged"
    assert result.message.startswith("stopped at epoch 1 of 3: training diverged in epoch 2")
    assert all(torch.isfinite(p).all() for p in model.parameters())


def test_dataset_arrays_accepts_dataset_like_objects():
    obs, action, next_obs = planar_like(10)

    class Dataset:
        pass

    ds = Dataset()
    ds.obs, ds.action, ds.next_obs = obs, action, next_obs
    arrays = dataset_arrays(ds)
    assert len(arrays) == 10 and arrays.action.dtype == np.float32
    assert len(dataset_arrays({"obs": obs, "action": action, "next_obs": next_obs})) == 10
    with pytest.raises(ValueError, match="uint8"):
        dataset_arrays((obs.astype(np.float32), action, next_obs))
    assert resolve_device("cpu") == torch.device("cpu")


def test_plot_latent_map_writes_png(tmp_path):
    from pcc_agent.plots import observations_for_states, planar_grid, plot_latent_map, state_colors

    states = planar_grid((1, 1), (SIZE - 2, SIZE - 2), num=5)

    def render(state):
        img = np.zeros((1, SIZE, SIZE), np.uint8)
        r, c = int(state[0]), int(state[1])
        img[0, r - 1:r + 2, c - 1:c + 2] = 255
        return img

    obs = observations_for_states(states, render)
    model = EmbeddingModel((1, SIZE, SIZE), 2, CONFIG, seed=0)
    path = plot_latent_map(model, obs, state_colors(states), tmp_path / "map.png", "planar")
    assert path.stat().st_size > 1000


def test_plot_env_latent_map_uses_the_env_protocol(tmp_path):
    from pcc_agent.plots import plot_env_latent_map

    class Core:
        def sample_states(self, rng, num):
            return rng.uniform(1, SIZE - 2, (num, 2))

        def observations_of(self, states):
            return np.stack([planar_like(1, seed=int(s[0] * 100))[0][0] for s in states])

    class Env:
        unwrapped = Core()

    class Agent:
        model = EmbeddingModel((1, SIZE, SIZE), 2, CONFIG, seed=0)
        env = Env()

    path = plot_env_latent_map(Agent(), tmp_path / "env_map.png", num_states=20)
    assert path.exists()
    with pytest.raises(ValueError, match="pcc_envs environment"):
        plot_env_latent_map(Agent.model, tmp_path / "x.png", env=object())


def test_epoch_callback_receives_metrics_and_can_stop():
    seen = []

    def callback(epoch, metrics):
        seen.append((epoch, dict(metrics)))
        return epoch < 2

    _, result = _train(planar_like(96), epoch_callback=callback)
    assert result.epochs == 2 and [e for e, _ in seen] == [1, 2]
    assert {"loss", "prediction", "curvature", "val_loss", "epoch_seconds"} <= set(seen[0][1])
    assert "callback" in result.message and result.stop_reason == "callback"
    summary = result.summary()
    assert json.loads(json.dumps(summary))["epochs"] == 2 and "history" not in summary


class RecordingBar:
    """A stand-in for tqdm that keeps what the trainer showed."""

    bars: list["RecordingBar"] = []

    def __init__(self, total=None, initial=0, unit="it", **kwargs):
        self.total, self.n, self.unit = total, initial, unit
        self.steps: list[int] = []
        self.postfixes: list[dict] = []
        self.closed = False
        RecordingBar.bars.append(self)

    def update(self, n=1):
        self.steps.append(n)
        self.n += n

    def set_postfix(self, ordered_dict=None, refresh=True, **kwargs):
        self.postfixes.append(dict(ordered_dict or {}, **kwargs))

    def close(self):
        self.closed = True


@pytest.fixture
def recording_bar(monkeypatch):
    import tqdm.auto

    RecordingBar.bars = []
    monkeypatch.setattr(tqdm.auto, "tqdm", RecordingBar)
    return RecordingBar.bars


def test_progress_bar_counts_whole_epochs_and_prints_why_it_stopped(recording_bar, capsys):
    _, result = _train(planar_like(96), progress_bar=True)
    (bar,) = recording_bar
    assert bar.unit == "epoch" and bar.total == TRAIN.epochs and bar.closed
    assert bar.steps == [1, 1, 1] and bar.n == result.epochs == 3  # one step per epoch
    last = bar.postfixes[-1]
    assert set(last) == {"loss", "val", "best"}
    assert float(last["val"]) == pytest.approx(result.history[-1]["val/loss"], rel=1e-3)
    assert last["best"] == f"{result.best_validation_loss:.4g}@{result.best_epoch}"
    assert result.stop_reason == "epoch_cap" and result.summary()["stop_reason"] == "epoch_cap"
    printed = capsys.readouterr().out.splitlines()
    assert printed == [result.message]  # one line, under the bar
    assert result.message.startswith("stopped at epoch 3 of 3: reached the epoch cap (best ")


def test_early_stop_says_why_and_where(recording_bar, capsys):
    # lr = 0: the validation loss never improves after epoch 1; patience 1 stops at epoch 2.
    config = dataclasses.replace(TRAIN, epochs=8, lr=0.0, patience=1)
    _, result = _train(planar_like(96), config=config, progress_bar=True)
    assert result.stop_reason == "early_stopping" and result.converged
    assert recording_bar[0].n == result.epochs == 2 and recording_bar[0].total == 8
    best = f"{result.best_validation_loss:.4g}"
    assert result.message == (
        f"stopped at epoch 2 of 8: no validation improvement for 1 epochs (best {best} at "
        "epoch 1); restored the best weights")
    assert capsys.readouterr().out.splitlines() == [result.message]


def test_no_bar_prints_nothing_and_an_interrupt_is_said_under_the_bar(recording_bar, capsys):
    _, quiet = _train(planar_like(96))
    assert not recording_bar and capsys.readouterr().out == ""
    assert quiet.stop_reason == "epoch_cap"

    def interrupt(epoch, metrics):
        raise KeyboardInterrupt

    with pytest.raises(KeyboardInterrupt):
        _train(planar_like(96), progress_bar=True, epoch_callback=interrupt)
    printed = capsys.readouterr().out.splitlines()
    assert len(printed) == 1 and printed[0].startswith("interrupted at epoch 1 of 3 (best ")


@pytest.mark.parametrize("min_epochs, expected", [(0, 2), (5, 5)])
def test_early_stopping_waits_for_min_epochs(min_epochs, expected):
    # lr = 0: the validation loss never improves after epoch 1, so patience 1 stops at epoch 2
    # unless min_epochs holds training on the plateau.
    config = dataclasses.replace(TRAIN, epochs=8, lr=0.0, patience=1, min_epochs=min_epochs)
    _, result = _train(planar_like(96), config=config)
    assert result.converged and result.epochs == expected


def test_decoder_bias_init_starts_from_the_mean_image():
    obs, action, next_obs = planar_like(64)
    config = dataclasses.replace(CONFIG, decoder_bias_init=True)
    model = EmbeddingModel((1, SIZE, SIZE), 2, config, seed=0)
    model.fit_input_statistics(torch.from_numpy(obs))
    mean = np.clip(obs.astype(np.float64).mean(0) / 255.0, 1e-3, 1 - 1e-3)
    bias = model.decoder.net[-1].bias.detach().numpy().reshape(mean.shape)
    np.testing.assert_allclose(bias, np.log(mean / (1 - mean)), atol=1e-4)


def test_latent_formation_benchmark_logs_r2(tmp_path):
    from pcc_bench.latent_formation import main

    out = tmp_path / "formation.json"
    main(["--epochs", "1", "--every", "1", "--probe", "200", "--data-dir", str(tmp_path),
          "--model", "input_standardization=true", "--output", str(out)])
    payload = json.loads(out.read_text())
    (row,) = payload["rows"]
    assert row["epoch"] == 1 and -1.0 <= row["r2"] <= 1.0 and row["encoder_std"] > 0
    assert payload["model_config"]["input_standardization"] is True


def test_subnormal_flushing_is_on_by_default_and_off_for_configs_saved_before_it():
    from pcc_agent.config import TrainConfig

    assert TrainConfig().flush_denormals is True
    saved = TrainConfig().to_dict()
    del saved["flush_denormals"]  # as written before the field existed
    assert TrainConfig.from_dict(saved).flush_denormals is False
    assert TrainConfig.from_dict(TrainConfig().to_dict()).flush_denormals is True


def test_a_prediction_horizon_adds_the_multistep_term_and_needs_its_data():
    from pcc_envs.data import collect_transitions

    data = collect_transitions("pcc/Planar-v0", 96, seed=0, prediction_horizon=3)
    config = dataclasses.replace(TRAIN, prediction_horizon=3, multistep_coef=0.5, epochs=1)
    model = EmbeddingModel((1, 40, 40), 2, CONFIG, seed=0)
    trainer = training.Trainer(model, config, device="cpu", progress_bar=False)
    batch = trainer._batch(tuple(torch.from_numpy(a) for a in (
        data.obs, data.action, data.next_obs, data.future_action, data.future_obs)),
        torch.arange(8))
    loss, metrics = trainer._loss(batch, config, torch.Generator().manual_seed(0))
    one_step, _ = trainer._loss(batch, dataclasses.replace(config, prediction_horizon=1),
                                torch.Generator().manual_seed(0))
    assert metrics["multistep"] > 0
    assert loss.item() == pytest.approx(one_step.item() + 0.5 * metrics["multistep"], rel=1e-5)
    assert metrics["loss"] == pytest.approx(loss.item())
    result = trainer.fit(data)
    assert result.epochs == 1 and result.history[0]["train/multistep"] > 0
    # Horizon 2 trains on the same data with its first further step only.
    two = dataclasses.replace(config, prediction_horizon=2)
    assert train_embedding(EmbeddingModel((1, 40, 40), 2, CONFIG, seed=0), data, two,
                           device="cpu", progress_bar=False).epochs == 1
    with pytest.raises(ValueError, match="prediction_horizon 3 needs 2 further steps per "
                       "transition; the data hold 0"):
        train_embedding(model, (data.obs, data.action, data.next_obs), config, device="cpu",
                        progress_bar=False)
    with pytest.raises(ValueError, match="prediction_horizon must be an integer >= 1"):
        TrainConfig(prediction_horizon=0)
    with pytest.raises(ValueError, match="multistep_coef must be >= 0"):
        TrainConfig(multistep_coef=-1.0)
