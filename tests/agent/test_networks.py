"""Shapes of every preset's networks, Jacobians of the latent dynamics, preset lookups."""

import dataclasses

import gymnasium as gym
import numpy as np
import pytest
import torch

from pcc_agent.model import EmbeddingModel
from pcc_agent.networks import build_networks, to_float_image
from pcc_agent.presets import (
    ACTION_DIMS,
    OBS_SHAPES,
    PRESETS,
    ModelConfig,
    default_preset_for_spaces,
    get_preset,
)

SMALL = ModelConfig(latent_dim=3, encoder_hidden=(32,), decoder_hidden=(32,),
                    transition_hidden=(16, 16), backward_nz=4, backward_nu=4, backward_nx=16,
                    backward_joint=16)

pytestmark = pytest.mark.usefixtures("single_torch_thread")


@pytest.mark.parametrize(
    ("env_id", "variant"), [(e, v) for e in PRESETS for v in PRESETS[e]]
)
def test_preset_networks_have_the_right_shapes(env_id, variant):
    preset = get_preset(env_id, variant)
    obs_shape, nu = OBS_SHAPES[env_id], ACTION_DIMS[env_id]
    nz = preset.model.latent_dim
    nets = build_networks(obs_shape, nu, preset.model)
    obs = torch.randint(0, 256, (2, *obs_shape), dtype=torch.uint8)
    u = torch.zeros(2, nu)
    with torch.no_grad():
        mean, logvar = nets.encoder(obs)
        assert mean.shape == logvar.shape == (2, nz)
        assert nets.decoder(mean).shape == (2, *obs_shape)
        out = nets.transition(mean, u)
        assert out.mean.shape == out.logvar.shape == (2, nz)
        back_mean, back_logvar = nets.backward(mean, obs, u)
        assert back_mean.shape == back_logvar.shape == (2, nz)


def test_paper_planar_architecture_sizes():
    model = EmbeddingModel((1, 40, 40), 2, get_preset("pcc/Planar-v0").model)
    linears = [m for m in model.encoder.modules() if isinstance(m, torch.nn.Linear)]
    assert [(m.in_features, m.out_features) for m in linears] == [(1600, 300), (300, 300),
                                                                  (300, 4)]
    linears = [m for m in model.decoder.modules() if isinstance(m, torch.nn.Linear)]
    assert [(m.in_features, m.out_features) for m in linears] == [(2, 300), (300, 300),
                                                                  (300, 1600)]
    assert {e: get_preset(e).model.latent_dim for e in PRESETS} == {
        "pcc/Planar-v0": 2, "pcc/PendulumSwingUp-v0": 3, "pcc/PendulumBalance-v0": 3,
        "pcc/CartPole-v0": 8, "pcc/CartPole-v1": 8, "pcc/TwoLink-v0": 8, "pcc/ThreeLink-v0": 8,
        "pcc/ThreeLink-v1": 8, "pcc/LaneKeeping-v0": 8}


def test_uint8_observations_are_scaled_inside_the_model():
    obs = torch.full((1, 1, 8, 8), 255, dtype=torch.uint8)
    assert to_float_image(obs).max().item() == 1.0
    model = EmbeddingModel((1, 8, 8), 2, SMALL, seed=0)
    with torch.no_grad():
        torch.testing.assert_close(model.encode(obs)[0], model.encode(obs.float() / 255)[0])


@pytest.mark.parametrize("kind", ["mlp", "e2c_linear"])
def test_linearize_matches_per_sample_jacobians(kind):
    config = dataclasses.replace(SMALL, transition_kind=kind)
    model = EmbeddingModel((1, 8, 8), 2, config, seed=0)
    g = torch.Generator().manual_seed(0)
    z, u = torch.randn(4, 3, generator=g), torch.randn(4, 2, generator=g)
    a_mat, b_mat = model.linearize(z, u, exact=True)
    assert a_mat.shape == (4, 3, 3) and b_mat.shape == (4, 3, 2)
    for i in range(4):
        ja, jb = torch.autograd.functional.jacobian(
            lambda a, b: model.transition_mean(a, b), (z[i], u[i]))
        torch.testing.assert_close(a_mat[i], ja)  # row = output, column = input (not A^T)
        torch.testing.assert_close(b_mat[i], jb)
    if kind == "e2c_linear":
        heads_a, heads_b = model.linearize(z, u)
        v, r, b_net, _, _ = model.dynamics.components(z)
        torch.testing.assert_close(heads_a, torch.eye(3) + v.unsqueeze(-1) * r.unsqueeze(-2))
        torch.testing.assert_close(heads_b, b_net)


def test_transition_mean_has_skip_connection_and_amortized_heads():
    config = dataclasses.replace(SMALL, amortized=True)
    model = EmbeddingModel((1, 8, 8), 2, config, seed=0)
    for module in (model.dynamics.head,):
        torch.nn.init.zeros_(module.weight)
        torch.nn.init.zeros_(module.bias)
    z, u = torch.randn(5, 3), torch.randn(5, 2)
    torch.testing.assert_close(model.transition_mean(z, u), z)
    a_mat, b_mat = model.linearize(z, u)
    assert a_mat.shape == (5, 3, 3) and b_mat.shape == (5, 3, 2)
    with pytest.raises(ValueError, match="no A/B heads"):
        EmbeddingModel((1, 8, 8), 2, SMALL).linearize(z, u, exact=False)


def test_get_preset_errors_list_known_ids():
    with pytest.raises(ValueError, match="pcc/Planar-v0"):
        get_preset("Planar")
    with pytest.raises(ValueError, match="fast"):
        get_preset("pcc/Planar-v0", "huge")
    paper, fast = get_preset("pcc/Planar-v0", "paper"), get_preset("pcc/Planar-v0", "fast")
    # Planar's fast variant: the paper's networks, trained with the faster-forming recipe
    assert dataclasses.replace(fast.model, input_standardization=False) == paper.model
    assert fast.model.input_standardization and fast.train.warmup_epochs > 0
    assert not paper.model.input_standardization and paper.train.warmup_epochs == 0


def test_default_preset_for_foreign_spaces():
    act = gym.spaces.Box(-1, 1, (2,), np.float32)
    small = default_preset_for_spaces(gym.spaces.Box(0, 255, (2, 32, 32), np.uint8), act)
    large = default_preset_for_spaces(gym.spaces.Box(0, 255, (3, 96, 72), np.uint8), act)
    assert small.model.encoder_kind == "mlp" and large.model.encoder_kind == "cnn"
    model = EmbeddingModel((3, 96, 72), 2, large.model, seed=0)
    with torch.no_grad():
        z = model.encode(torch.zeros(1, 3, 96, 72, dtype=torch.uint8))[0]
        assert model.decode_logits(z).shape == (1, 3, 96, 72)
    fast = default_preset_for_spaces(gym.spaces.Box(0, 255, (3, 96, 72), np.uint8), act,
                                     variant="fast")
    model = EmbeddingModel((3, 96, 72), 2, fast.model, seed=0)
    with torch.no_grad():
        z = model.encode(torch.zeros(1, 3, 96, 72, dtype=torch.uint8))[0]
        assert model.decode_logits(z).shape == (1, 3, 96, 72)
        assert model.log_likelihood(z, torch.zeros(1, 3, 96, 72)).shape == (1,)
    with pytest.raises(ValueError, match="image observation"):
        default_preset_for_spaces(gym.spaces.Box(-1, 1, (4,), np.float32), act)


def test_model_config_round_trip():
    for env_id in PRESETS:
        for preset in PRESETS[env_id].values():
            assert ModelConfig.from_dict(preset.model.to_dict()) == preset.model


@pytest.mark.parametrize("env_id", ["pcc/Planar-v0", "pcc/CartPole-v0"])
def test_low_resolution_likelihood_is_exact(env_id):
    from pcc_agent.distributions import bernoulli_log_likelihood

    config = get_preset(env_id, "fast").model
    model = EmbeddingModel(OBS_SHAPES[env_id], ACTION_DIMS[env_id], config, seed=0)
    g = torch.Generator().manual_seed(0)
    z = torch.randn(3, config.latent_dim, generator=g)
    obs = torch.randint(0, 256, (3, *OBS_SHAPES[env_id]), dtype=torch.uint8, generator=g)
    expected = bernoulli_log_likelihood(model.decode_logits(z), obs.float() / 255)
    torch.testing.assert_close(model.log_likelihood(z, obs), expected, rtol=1e-5, atol=1e-2)


def _pixel_shuffle_config(last_channels: int = 2 * 16) -> ModelConfig:
    """The CartPole fast CNN with a pixel-shuffled 4x output instead of nearest upsampling."""
    base = get_preset("pcc/CartPole-v0", "fast").model
    convs = (*base.decoder_convs[:-1], dataclasses.replace(base.decoder_convs[-1],
                                                           channels=last_channels))
    return dataclasses.replace(base, decoder_convs=convs, decoder_pixel_shuffle=True)


def test_pixel_shuffle_decoder_gives_every_pixel_its_own_logit():
    """Nearest upsampling repeats one logit over each 4x4 block; the pixel shuffle does not,
    and its likelihood (computed before the shuffle, against the unshuffled target) is the
    plain full-resolution one."""
    from pcc_agent.distributions import bernoulli_log_likelihood

    shape = OBS_SHAPES["pcc/CartPole-v0"]
    g = torch.Generator().manual_seed(0)
    z = torch.randn(3, 8, generator=g)
    obs = torch.randint(0, 256, (3, *shape), dtype=torch.uint8, generator=g)
    model = EmbeddingModel(shape, 1, _pixel_shuffle_config(), seed=0)
    logits = model.decode_logits(z)
    assert logits.shape == (3, *shape)
    blocks = logits.unfold(2, 4, 4).unfold(3, 4, 4).reshape(3, 2, 20, 20, 16)
    assert (blocks.std(dim=-1) > 0).all(), "a 4x4 block shares one logit"
    expected = bernoulli_log_likelihood(logits, obs.float() / 255)
    torch.testing.assert_close(model.log_likelihood(z, obs), expected)


def test_pixel_shuffle_checks_its_configuration():
    shape = OBS_SHAPES["pcc/CartPole-v0"]
    with pytest.raises(ValueError, match=r"32 channels \(4\^2 per observation frame"):
        EmbeddingModel(shape, 1, _pixel_shuffle_config(last_channels=2), seed=0)
    with pytest.raises(ValueError, match="decoder_pixel_shuffle needs"):
        dataclasses.replace(get_preset("pcc/Planar-v0").model, decoder_pixel_shuffle=True)


def test_pixel_shuffle_output_bias_starts_from_each_frames_mean():
    shape = OBS_SHAPES["pcc/CartPole-v0"]
    model = EmbeddingModel(shape, 1, _pixel_shuffle_config(), seed=0)
    images = torch.zeros(4, *shape)
    images[:, 0, :20] = 1.0  # frame 0: a quarter of its pixels on, frame 1: none
    model.decoder.init_output_bias(images, eps=1e-3)  # pixel means are clamped to [eps, 1-eps]
    first = torch.logit(torch.tensor(0.25 * (1 - 1e-3) + 0.75 * 1e-3))
    second = torch.logit(torch.tensor(1e-3))
    bias = model.decoder.convs[-1].bias
    torch.testing.assert_close(bias, torch.cat([first.repeat(16), second.repeat(16)]))


def test_keypoints_locate_a_dot_and_its_motion_between_frames():
    """With a sharp heatmap of the image itself, the soft-argmax is the dot's position and the
    motion features are the scaled shift between the two frames."""
    from pcc_agent.config import ConvSpec
    from pcc_agent.networks import MOTION_SCALE, _Keypoints

    keypoints = _Keypoints((ConvSpec(1, 1, 1),))
    with torch.no_grad():  # heatmap = 50 x image: a softmax close to a one-hot at the dot
        keypoints.heatmaps.weight.fill_(50.0)
        keypoints.heatmaps.bias.zero_()
    images = torch.zeros(1, 2, 21, 21)
    images[0, 0, 10, 5] = 1.0   # oldest frame: row 10, column 5
    images[0, 1, 4, 15] = 1.0   # newest frame: row 4, column 15
    out = keypoints(images)
    assert out.shape == (1, 4)  # newest (x, y), then the motion (dx, dy)
    newest = torch.tensor([15 / 10 - 1, 4 / 10 - 1])
    oldest = torch.tensor([5 / 10 - 1, 10 / 10 - 1])
    torch.testing.assert_close(out[0, :2], newest, atol=1e-4, rtol=0)
    torch.testing.assert_close(out[0, 2:], MOTION_SCALE * (newest - oldest),
                               atol=1e-3, rtol=0)


@pytest.mark.parametrize("kind", ["keypoints", "frame_cnn"])
def test_per_frame_encoders_are_a_model_config_choice(kind):
    from pcc_agent.config import ConvSpec

    config = dataclasses.replace(
        get_preset("pcc/CartPole-v0", "fast").model, encoder_kind=kind,
        encoder_convs=(ConvSpec(8, 5, 2), ConvSpec(6, 1, 1)), encoder_frame_features=5)
    model = EmbeddingModel(OBS_SHAPES["pcc/CartPole-v0"], 1, config, seed=0)
    obs = torch.randint(0, 256, (3, *OBS_SHAPES["pcc/CartPole-v0"]), dtype=torch.uint8)
    mean, logvar = model.encode(obs)
    assert mean.shape == logvar.shape == (3, 8)
    trunk = model.encoder.backbone[0]
    still = trunk(obs[:, -1:].repeat(1, 2, 1, 1))  # both frames the same: no motion
    width = still.shape[1] // 2
    assert width == (12 if kind == "keypoints" else 5)  # 6 keypoints (x, y); 5 features
    assert torch.count_nonzero(still[:, width:]) == 0
    assert torch.count_nonzero(trunk(obs)[:, width:]) > 0
    assert ModelConfig.from_dict(config.to_dict()) == config
    with pytest.raises(ValueError, match=f"'{kind}' needs at least one ConvSpec"):
        dataclasses.replace(config, encoder_convs=())
    with pytest.raises(ValueError, match="leave encoder_motion_gain at 0"):
        dataclasses.replace(config, encoder_motion_gain=5.0)
    with pytest.raises(ValueError, match="encoder_kind must be 'mlp', 'cnn', 'keypoints' or"):
        dataclasses.replace(config, encoder_kind="resnet")


@pytest.mark.parametrize("variant", ["motion", "fast"])
def test_encode_pair_embeds_shared_frames_once_with_the_same_result(variant, monkeypatch):
    """A transition's next observation repeats the newer frame: per-frame encoders embed the
    three frames once (3 embeddings per transition, not 4); the codes are the same."""
    shape = OBS_SHAPES["pcc/CartPole-v0"]
    model = EmbeddingModel(shape, 1, get_preset("pcc/CartPole-v0", variant).model, seed=0)
    g = torch.Generator().manual_seed(0)
    chain = torch.randint(0, 256, (3, 3, *shape[1:]), dtype=torch.uint8, generator=g)
    obs, next_obs = chain[:, :2], chain[:, 1:]
    embedded: list[int] = []
    per_frame = model.encoder.backbone[0][1]
    if variant == "motion":
        original = per_frame.per_frame
        monkeypatch.setattr(per_frame, "per_frame",
                            lambda frames: embedded.append(len(frames)) or original(frames))
    with torch.no_grad():
        expected = model.encode(torch.cat([obs, next_obs]))
        embedded.clear()
        pair = model.encode_pair(obs, next_obs)
        assert embedded == ([3 * 3] if variant == "motion" else [])
        for got, want in zip(pair, expected):
            torch.testing.assert_close(got, want, rtol=1e-6, atol=1e-6)
        unrelated = torch.randint(0, 256, (3, *shape), dtype=torch.uint8, generator=g)
        embedded.clear()
        pair = model.encode_pair(obs, unrelated)  # nothing shared: the plain path
        assert embedded == ([2 * 3 * 2] if variant == "motion" else [])
        for got, want in zip(pair, model.encode(torch.cat([obs, unrelated]))):
            torch.testing.assert_close(got, want)


def test_motion_gain_shows_the_encoder_the_change_between_frames():
    from pcc_agent.networks import _ImageInput

    frames = torch.rand(2, 2, 6, 6)
    shown = _ImageInput((2, 6, 6), downsample=1, motion_gain=10.0)(frames)
    torch.testing.assert_close(shown[:, 1], frames[:, 1])
    torch.testing.assert_close(shown[:, 0], 10.0 * (frames[:, 1] - frames[:, 0]))
    with pytest.raises(ValueError, match="encoder_motion_gain must be >= 0"):
        dataclasses.replace(SMALL, encoder_motion_gain=-1.0)
