"""The learned model as planner dynamics: analytic Jacobians equal autograd's."""

from __future__ import annotations

import torch

from pcc_agent.losses import model_config_for_method
from pcc_agent.model import EmbeddingModel
from pcc_agent.planning.dynamics import MLPDynamics
from pcc_agent.presets import get_preset


def test_mlp_transition_planner_dynamics_match_model():
    config = model_config_for_method(get_preset("pcc/PendulumSwingUp-v0").model, "pcc")
    model = EmbeddingModel((2, 48, 48), 1, config)
    dynamics = model.planner_dynamics()
    assert isinstance(dynamics, MLPDynamics)
    z, u = torch.randn(7, 3), torch.rand(7, 1) * 2 - 1
    with torch.no_grad():
        torch.testing.assert_close(dynamics.step(z, u), model.transition_mean(z, u))
    A, B = dynamics.jacobians(z, u)
    A_ref, B_ref = model.linearize(z, u, exact=True)
    torch.testing.assert_close(A, A_ref)
    torch.testing.assert_close(B, B_ref)


def test_e2c_planner_dynamics_use_the_model_heads():
    config = model_config_for_method(get_preset("pcc/Planar-v0").model, "e2c")
    model = EmbeddingModel((1, 40, 40), 2, config)
    z, u = torch.randn(4, 2), torch.zeros(4, 2)
    A, _ = model.planner_dynamics().jacobians(z, u)
    torch.testing.assert_close(A, model.linearize(z, u)[0])


def test_input_standardization_is_fitted_and_saved(tmp_path):
    import dataclasses

    import numpy as np

    from pcc_agent.checkpoint import load_model, save_checkpoint
    from pcc_agent.training import train_embedding

    preset = get_preset("pcc/Planar-v0")
    config = dataclasses.replace(preset.model, input_standardization=True)
    model = EmbeddingModel((1, 40, 40), 2, config, seed=0)
    rng = np.random.default_rng(0)
    obs = (rng.random((64, 1, 40, 40)) < 0.1).astype(np.uint8) * 255
    before = model.encoder.backbone[0][0].scale.clone()
    train_embedding(model, (obs, np.zeros((64, 2), np.float32), obs),
                    dataclasses.replace(preset.train, epochs=1), progress_bar=False,
                    device="cpu")
    scale = model.encoder.backbone[0][0].scale
    assert not torch.equal(scale, before) and torch.all(scale > 0)
    path = save_checkpoint(tmp_path / "m.pt", model)
    loaded, _ = load_model(path)
    torch.testing.assert_close(loaded.encoder.backbone[0][0].scale, scale)
    x = torch.as_tensor(obs[:3])
    torch.testing.assert_close(loaded.encode(x)[0], model.encode(x)[0])
