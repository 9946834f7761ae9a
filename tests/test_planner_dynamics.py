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
