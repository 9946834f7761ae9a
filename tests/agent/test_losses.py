"""Oracles for the distributions helpers and the PCC / E2C / RCE losses."""

import pytest
import torch
from torch import distributions as td

from pcc_agent.distributions import (
    bernoulli_log_likelihood,
    gaussian_entropy,
    gaussian_kl,
    gaussian_kl_standard,
    gaussian_log_prob,
)
from pcc_agent.losses import (
    METHODS,
    TransitionBatch,
    curvature_penalty,
    get_loss,
    locally_linear_kl,
    model_config_for_method,
    multistep_prediction,
)
from pcc_agent.model import EmbeddingModel
from pcc_agent.presets import ModelConfig, TrainConfig

pytestmark = pytest.mark.usefixtures("single_torch_thread")

SMALL = ModelConfig(latent_dim=3, encoder_hidden=(32,), decoder_hidden=(32,),
                    transition_hidden=(16, 16), backward_nz=4, backward_nu=4, backward_nx=16,
                    backward_joint=16)


def _normal(mean, logvar):
    return td.Independent(td.Normal(mean, torch.exp(0.5 * logvar)), 1)


def test_gaussian_helpers_match_torch_distributions():
    g = torch.Generator().manual_seed(0)
    mq, lq, mp, lp, x = (torch.randn(7, 4, generator=g) for _ in range(5))
    q, p = _normal(mq, lq), _normal(mp, lp)
    torch.testing.assert_close(gaussian_kl(mq, lq, mp, lp), td.kl_divergence(q, p))
    torch.testing.assert_close(gaussian_entropy(lq), q.entropy())
    torch.testing.assert_close(gaussian_log_prob(x, mq, lq), q.log_prob(x))
    std = _normal(torch.zeros(7, 4), torch.zeros(7, 4))
    torch.testing.assert_close(gaussian_kl_standard(mq, lq), td.kl_divergence(q, std))


def test_bernoulli_log_likelihood_matches_and_is_finite_for_huge_logits():
    g = torch.Generator().manual_seed(1)
    logits = 5 * torch.randn(3, 2, 4, 4, generator=g)
    target = torch.randint(0, 2, (3, 2, 4, 4), generator=g).float()
    expected = td.Bernoulli(logits=logits).log_prob(target).flatten(1).sum(1)
    torch.testing.assert_close(bernoulli_log_likelihood(logits, target), expected)
    extreme = torch.full((1, 1, 2, 2), 1e4)
    value = bernoulli_log_likelihood(extreme, torch.zeros(1, 1, 2, 2))
    assert torch.isfinite(value).all() and value.item() == pytest.approx(-4e4)


def test_locally_linear_kl_matches_full_covariance_kl():
    g = torch.Generator().manual_seed(2)
    mean, v, r, lv, mn, lvn = (torch.randn(5, 3, generator=g) for _ in range(6))
    a_mat = torch.eye(3) + v.unsqueeze(-1) * r.unsqueeze(-2)
    cov = a_mat @ torch.diag_embed(torch.exp(lv)) @ a_mat.transpose(-1, -2)
    q = td.MultivariateNormal(mean, covariance_matrix=cov)
    p = td.MultivariateNormal(mn, covariance_matrix=torch.diag_embed(torch.exp(lvn)))
    torch.testing.assert_close(locally_linear_kl(mean, v, r, lv, mn, lvn),
                               td.kl_divergence(q, p), rtol=1e-4, atol=1e-4)


def test_curvature_zero_for_linear_dynamics_with_nonsymmetric_matrix():
    g = torch.Generator().manual_seed(3)
    a_true = torch.tensor([[1.0, 2.0, 0.0], [-0.5, 1.0, 3.0], [0.0, 0.0, 1.0]])  # not symmetric
    b_true = torch.randn(3, 2, generator=g)

    def f(z, u):
        return z @ a_true.T + u @ b_true.T

    z, u = torch.randn(8, 3, generator=g), torch.randn(8, 2, generator=g)
    ez, eu = 0.1 * torch.randn(8, 3, generator=g), 0.1 * torch.randn(8, 2, generator=g)
    assert curvature_penalty(f, z, u, ez, eu).abs().max() < 1e-10
    exact = (a_true.expand(8, 3, 3), b_true.expand(8, 3, 2))
    assert curvature_penalty(f, z, u, ez, eu, exact).abs().max() < 1e-10
    transposed = (a_true.T.expand(8, 3, 3), b_true.expand(8, 3, 2))
    assert curvature_penalty(f, z, u, ez, eu, transposed).min() > 1e-6


@pytest.mark.parametrize("at_perturbed", [True, False])
def test_curvature_of_quadratic_dynamics_is_positive_and_exact(at_perturbed):
    # f(z, u) = z^2 + u: residual = || eps_z^2 ||^2 = sum eps_z^4 at either expansion point.
    g = torch.Generator().manual_seed(4)
    z, u = torch.randn(6, 2, generator=g), torch.randn(6, 2, generator=g)
    ez, eu = 0.1 * torch.randn(6, 2, generator=g), 0.1 * torch.randn(6, 2, generator=g)
    value = curvature_penalty(lambda a, b: a.pow(2) + b, z, u, ez, eu,
                              expand_at_perturbed=at_perturbed)
    torch.testing.assert_close(value, ez.pow(4).sum(-1))
    assert (value > 0).all()
    linear = curvature_penalty(lambda a, b: a @ torch.tensor([[1.0, 2.0], [0.0, 3.0]]) + b,
                               z, u, ez, eu, expand_at_perturbed=at_perturbed)
    assert linear.abs().max() < 1e-10


def test_amortized_curvature_equals_exact_with_true_jacobians():
    model = EmbeddingModel((1, 8, 8), 2, SMALL, seed=0)
    g = torch.Generator().manual_seed(5)
    z, u = torch.randn(10, 3, generator=g), torch.randn(10, 2, generator=g)
    ez, eu = 0.1 * torch.randn(10, 3, generator=g), 0.1 * torch.randn(10, 2, generator=g)
    jac = model.linearize(z + ez, u + eu)
    exact = curvature_penalty(model.transition_mean, z, u, ez, eu)
    amortized = curvature_penalty(model.transition_mean, z, u, ez, eu, jac)
    torch.testing.assert_close(amortized, exact, rtol=1e-5, atol=1e-9)
    jac0 = model.linearize(z, u)
    exact0 = curvature_penalty(model.transition_mean, z, u, ez, eu, expand_at_perturbed=False)
    torch.testing.assert_close(
        curvature_penalty(model.transition_mean, z, u, ez, eu, jac0, expand_at_perturbed=False),
        exact0, rtol=1e-5, atol=1e-9)


@pytest.mark.parametrize("method", sorted(METHODS))
def test_every_loss_is_finite_with_gradients(method):
    model = EmbeddingModel((2, 8, 8), 2, model_config_for_method(SMALL, method), seed=0)
    g = torch.Generator().manual_seed(6)
    batch = TransitionBatch(
        torch.randint(0, 256, (16, 2, 8, 8), dtype=torch.uint8, generator=g),
        torch.rand(16, 2, generator=g) * 2 - 1,
        torch.randint(0, 256, (16, 2, 8, 8), dtype=torch.uint8, generator=g),
    )
    loss, metrics = get_loss(method)(model, batch, TrainConfig(), g)
    assert torch.isfinite(loss) and loss.ndim == 0
    assert metrics["loss"] == pytest.approx(loss.item())
    assert all(isinstance(v, float) for v in metrics.values())
    loss.backward()
    for name, param in model.named_parameters():
        if method == "e2c" and name.startswith("backward_model"):
            continue  # E2C has no backward (recognition) model
        assert param.grad is not None, f"{method}: no gradient for {name}"
        assert torch.isfinite(param.grad).all(), name
    if method == "pcc-amortized":
        assert model.dynamics.jacobian_head.weight.grad.abs().sum() > 0


def test_unknown_method_and_wrong_model_raise_clear_errors():
    with pytest.raises(ValueError, match="choose one of"):
        get_loss("pcc2")
    model = EmbeddingModel((1, 8, 8), 2, SMALL, seed=0)
    batch = TransitionBatch(torch.zeros(2, 1, 8, 8, dtype=torch.uint8), torch.zeros(2, 2),
                            torch.zeros(2, 1, 8, 8, dtype=torch.uint8))
    with pytest.raises(ValueError, match="model_config_for_method"):
        get_loss("e2c")(model, batch, TrainConfig())


def _model_and_chains(method: str, further_steps: int, seed: int):
    """A small model of ``method`` and 16 random 8x8 transitions with ``further_steps`` more."""
    model = EmbeddingModel((2, 8, 8), 2, model_config_for_method(SMALL, method), seed=0)
    g = torch.Generator().manual_seed(seed)

    def images(*shape):
        return torch.randint(0, 256, (*shape, 2, 8, 8), dtype=torch.uint8, generator=g)

    batch = TransitionBatch(images(16), torch.rand(16, 2, generator=g) * 2 - 1, images(16),
                            torch.rand(16, further_steps, 2, generator=g) * 2 - 1,
                            images(16, further_steps))
    return model, batch


@pytest.mark.parametrize("method", ["pcc", "e2c"])
def test_multistep_prediction_rolls_the_mean_dynamics_through_the_further_steps(method):
    model, batch = _model_and_chains(method, 3, seed=7)
    z = model.transition_mean(model.encode(batch.obs)[0], batch.action)
    expected = []
    for j in range(3):
        z = model.transition_mean(z, batch.future_action[:, j])
        expected.append(-model.log_likelihood(z, batch.future_obs[:, j]).mean())
    assert torch.allclose(multistep_prediction(model, batch, 2), expected[0])
    assert torch.allclose(multistep_prediction(model, batch, 4), sum(expected))
    with pytest.raises(ValueError, match="over 5 steps needs horizon >= 2 and 4 further steps"
                       ".*the batch has 3"):
        multistep_prediction(model, batch, 5)
    with pytest.raises(ValueError, match="the batch has 0"):
        multistep_prediction(model, TransitionBatch(*batch[:3]), 2)
    with pytest.raises(ValueError, match="needs horizon >= 2"):
        multistep_prediction(model, batch, 1)


@pytest.mark.parametrize("method", ["pcc", "e2c", "rce", "pcc-no-curvature"])
def test_every_loss_adds_the_multistep_term_of_its_config_from_its_own_encoding(method):
    # The losses reuse their mu(x_t) (PCC: its f(mu(x_t), u_t)) for the multi-step term; the
    # term must equal the one computed from a fresh encoding.
    model, batch = _model_and_chains(method, 2, seed=3)
    config = TrainConfig(prediction_horizon=3, multistep_coef=0.5)
    loss, metrics = get_loss(method)(model, batch, config, torch.Generator().manual_seed(0))
    one_step, one_step_metrics = get_loss(method)(
        model, batch, TrainConfig(prediction_horizon=1), torch.Generator().manual_seed(0))
    term = multistep_prediction(model, batch, 3)
    assert "multistep" not in one_step_metrics
    assert metrics["multistep"] == pytest.approx(term.item(), rel=1e-5)
    assert loss.item() == pytest.approx(one_step.item() + 0.5 * term.item(), rel=1e-5)
    assert metrics["loss"] == pytest.approx(loss.item())
    # The term's gradient reaches the encoder through the reused code.
    (loss - one_step).backward()
    assert any(p.grad is not None and p.grad.abs().sum() > 0 for p in model.encoder.parameters())
