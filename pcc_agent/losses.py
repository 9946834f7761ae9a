"""Training objectives of PCC, E2C and RCE, one function per method, selected by name.

Notation (per transition ``(x_t, u_t, x_{t+1})``; every term is summed over its dimensions and
averaged over the batch):

* ``E(z | x)``: encoder, diagonal Gaussian ``N(mu(x), diag(sigma^2(x)))``.
* ``F(z' | z, u)``: latent transition with mean ``f(z, u)``.
* ``D(x | z)``: Bernoulli decoder.
* ``Q(z_t | z_hat_{t+1}, x_t, u_t)``: backward model (recognition of z_t).
* ``z_hat_{t+1} ~ E(. | x_{t+1})`` (the paper's ``Q(z_hat_{t+1} | x_{t+1})``, shared with the
  encoder), ``z_t ~ Q(. | z_hat_{t+1}, x_t, u_t)``.

Every loss has the signature ``loss(model, batch, config, generator=None) -> (loss, metrics)``
where ``batch`` is a :class:`TransitionBatch`, ``config`` a
:class:`pcc_agent.presets.TrainConfig`, ``generator`` the ``torch.Generator`` all noise is drawn
from, and ``metrics`` maps term names to Python floats.
"""

from __future__ import annotations

import dataclasses
from collections.abc import Callable
from typing import Any, NamedTuple, Protocol

import torch

from pcc_agent._forward_ad import jvp
from pcc_agent.config import ModelConfig, TrainConfig
from pcc_agent.distributions import (
    gaussian_entropy,
    gaussian_kl,
    gaussian_kl_standard,
    gaussian_log_prob,
    gaussian_rsample,
)
from pcc_agent.model import EmbeddingModel
from pcc_agent.networks import E2CTransition, to_float_image

Metrics = dict[str, float]


class TransitionBatch(NamedTuple):
    """A mini-batch of transitions.

    Attributes:
        obs: ``x_t``, uint8 ``(B, F, H, W)``.
        action: ``u_t``, float32 ``(B, n_u)``.
        next_obs: ``x_{t+1}``, uint8 ``(B, F, H, W)``.
        future_action: ``u_{t+1} .. u_{t+K-1}``, float32 ``(B, K - 1, n_u)``, or None.
        future_obs: ``x_{t+2} .. x_{t+K}``, uint8 ``(B, K - 1, F, H, W)``, or None.
    """

    obs: torch.Tensor
    action: torch.Tensor
    next_obs: torch.Tensor
    future_action: torch.Tensor | None = None
    future_obs: torch.Tensor | None = None


class LossFunction(Protocol):
    """Signature shared by every loss of the registry."""

    def __call__(
        self, model: EmbeddingModel, batch: TransitionBatch, config: TrainConfig,
        generator: torch.Generator | None = None,
    ) -> tuple[torch.Tensor, Metrics]:
        """Return the scalar loss and its named terms."""
        ...


def _metrics(**terms: torch.Tensor) -> Metrics:
    """Detach scalar tensors into floats with a single device transfer."""
    values = torch.stack([t.detach().float() for t in terms.values()]).tolist()
    return dict(zip(terms.keys(), values))


def curvature_penalty(
    f: Callable[[torch.Tensor, torch.Tensor], torch.Tensor],
    z: torch.Tensor,
    u: torch.Tensor,
    eps_z: torch.Tensor,
    eps_u: torch.Tensor,
    jacobians: tuple[torch.Tensor, torch.Tensor] | None = None,
    expand_at_perturbed: bool = True,
) -> torch.Tensor:
    """Per-sample local-linearity residual of the latent dynamics (paper Eq. for R_LLC).

    ``|| f(z_bar, u_bar) - (A eps_z + B eps_u) - f(z, u) ||^2`` with ``z_bar = z + eps_z``,
    ``u_bar = u + eps_u`` and the true Jacobians ``A = df/dz`` (``A[i, j] = df_i / dz_j``),
    ``B = df/du``, evaluated at ``(z_bar, u_bar)`` (the paper's practical variant, Section 4.2)
    or, with ``expand_at_perturbed=False``, at ``(z, u)`` (the Section 3 definition). The
    Jacobian-vector products come from one batched forward-mode pass (``torch.func.jvp``);
    with ``jacobians`` given (amortized PCC) the supplied A ``(B, n_z, n_z)`` and B
    ``(B, n_z, n_u)``, evaluated at the same point, are used instead.

    Args:
        f: Deterministic dynamics ``(z, u) -> z'`` on batches.
        z: Latent states ``(B, n_z)``.
        u: Actions ``(B, n_u)``.
        eps_z: Latent perturbations ``(B, n_z)``.
        eps_u: Action perturbations ``(B, n_u)``.
        jacobians: Optional ``(A, B)`` evaluated at the expansion point.
        expand_at_perturbed: Expand around ``(z_bar, u_bar)`` (True) or ``(z, u)`` (False).

    Returns:
        Residuals ``(B,)``.
    """
    z_bar, u_bar = z + eps_z, u + eps_u
    point, other = ((z_bar, u_bar), (z, u)) if expand_at_perturbed else ((z, u), (z_bar, u_bar))
    if jacobians is None:
        primal_and_tangent = jvp(f, point, (eps_z, eps_u))
        f_point, linear = primal_and_tangent[0], primal_and_tangent[1]
    else:
        a_mat, b_mat = jacobians
        f_point = f(*point)
        linear = (a_mat @ eps_z.unsqueeze(-1) + b_mat @ eps_u.unsqueeze(-1)).squeeze(-1)
    f_other = f(*other)
    f_bar, f_nominal = (f_point, f_other) if expand_at_perturbed else (f_other, f_point)
    return (f_bar - linear - f_nominal).pow(2).sum(dim=-1)


def _check_transition(model: EmbeddingModel, kind: str, method: str) -> None:
    if model.config.transition_kind != kind:
        raise ValueError(
            f"Method {method!r} needs a model with transition_kind={kind!r}, got "
            f"{model.config.transition_kind!r}. Build the model with "
            f"model_config_for_method(config, {method!r})."
        )


class _Posteriors(NamedTuple):
    """The samples shared by the PCC and RCE bounds (see :func:`_sample_posteriors`)."""

    x_t: torch.Tensor
    x_next: torch.Tensor
    mu_t: torch.Tensor
    lv_t: torch.Tensor
    lv_next: torch.Tensor
    z_hat_next: torch.Tensor
    back_mean: torch.Tensor
    back_logvar: torch.Tensor
    z_t: torch.Tensor
    z_vae: torch.Tensor


def _sample_posteriors(
    model: EmbeddingModel, batch: TransitionBatch, generator: torch.Generator | None
) -> _Posteriors:
    """Encode both frames in one pass; draw ``z_hat_{t+1}``, ``z_t`` and the VAE sample.

    ``z_hat_{t+1} ~ E(. | x_{t+1})``, ``z_t ~ Q(. | z_hat_{t+1}, x_t, u_t)``, ``z ~ E(. | x_t)``.
    """
    x_t, u, x_next = batch.obs, batch.action, batch.next_obs
    n = x_t.shape[0]
    images = to_float_image(torch.cat([x_t, x_next], dim=0))  # converted once, reused below
    x_t, x_next = images[:n], images[n:]
    mean_all, logvar_all = model.encode_pair(x_t, x_next)
    mu_t, mu_n = mean_all[:n], mean_all[n:]
    lv_t, lv_n = logvar_all[:n], logvar_all[n:]
    z_hat_next = gaussian_rsample(mu_n, lv_n, generator)
    back_mean, back_logvar = model.backward_posterior(z_hat_next, x_t, u)
    z_t = gaussian_rsample(back_mean, back_logvar, generator)
    z_vae = gaussian_rsample(mu_t, lv_t, generator)
    return _Posteriors(x_t, x_next, mu_t, lv_t, lv_n, z_hat_next, back_mean, back_logvar, z_t,
                       z_vae)


def _consistency_terms(
    p: _Posteriors, trans_mean: torch.Tensor, trans_logvar: torch.Tensor
) -> tuple[torch.Tensor, torch.Tensor, torch.Tensor]:
    """``KL(Q || E(z_t | x_t))``, ``H(E(. | x_{t+1}))`` and ``-log F(z_hat_{t+1} | z_t, u_t)``."""
    kl_backward = gaussian_kl(p.back_mean, p.back_logvar, p.mu_t, p.lv_t).mean()
    entropy = gaussian_entropy(p.lv_next).mean()
    transition_nll = -gaussian_log_prob(p.z_hat_next, trans_mean, trans_logvar).mean()
    return kl_backward, entropy, transition_nll


def pcc_loss(
    model: EmbeddingModel,
    batch: TransitionBatch,
    config: TrainConfig,
    generator: torch.Generator | None = None,
    *,
    consistency: bool = True,
    curvature: bool = True,
    amortized: bool = False,
) -> tuple[torch.Tensor, Metrics]:
    """PCC objective (paper Eq. PCC loss, Section 4 and Appendix "Implementation").

    ``L = lambda_p R'_3 + lambda_c R''_2 + lambda_cur R_LLC + vae_coef L_VAE + det_coef L_det``:

    * prediction bound ``R'_3 = -log D(x_{t+1} | z_hat_{t+1}) + KL(Q(z_t | z_hat_{t+1}, x_t,
      u_t) || E(z_t | x_t)) - H(E(. | x_{t+1})) - log F(z_hat_{t+1} | z_t, u_t)``;
    * consistency bound ``R''_2 = KL(Q || E(z_t | x_t)) - H(E(. | x_{t+1})) - log F(z_hat_{t+1}
      | z_t, u_t)`` (the same terms without reconstruction);
    * curvature ``R_LLC = || f(z_bar, u_bar) - (A eps_z + B eps_u) - f(z, u) ||^2`` with
      ``eps ~ N(0, delta^2 I)``, ``z ~ E(. | x_t)`` (detached: the term shapes F only, as in the
      authors' implementation), A, B the true Jacobians at ``(z_bar, u_bar)`` (or at ``(z, u)``
      with ``config.curvature_expansion="nominal"``; the amortized heads when ``amortized``);
    * ``L_VAE = -log D(x_t | z) + KL(E(z | x_t) || N(0, I))``, ``z ~ E(. | x_t)``;
    * ``L_det = -log D(x_{t+1} | f(mu(x_t), u_t))`` (deterministic cross-entropy).

    Args:
        model: Model with ``transition_kind="mlp"`` (and ``amortized=True`` for the heads).
        batch: Transitions.
        config: Weights ``lambda_p, lambda_c, lambda_cur, curvature_delta, vae_coef,
            deterministic_ce_coef``.
        generator: Source of all sampling noise.
        consistency: Include R''_2 (False: ablation "pcc-no-consistency").
        curvature: Include R_LLC (False: ablation "pcc-no-curvature").
        amortized: Use the A, B heads in R_LLC ("pcc-amortized").

    Returns:
        ``(loss, metrics)``; metrics: loss, prediction, consistency, curvature, vae,
        deterministic, reconstruction, kl_backward, entropy, transition_nll.
    """
    _check_transition(model, "mlp", "pcc")
    if amortized and not model.config.amortized:
        raise ValueError("Amortized curvature needs ModelConfig(amortized=True).")
    u = batch.action
    n = u.shape[0]
    p = _sample_posteriors(model, batch, generator)
    x_t, x_next, mu_t, lv_t, z_vae = p.x_t, p.x_next, p.mu_t, p.lv_t, p.z_vae

    # One transition pass for F(. | z_t, u) and f(mu(x_t), u); one decoder pass for all images.
    f_mean, f_logvar = model.transition(torch.cat([p.z_t, mu_t]), torch.cat([u, u]))
    trans_mean, trans_logvar, det_next = f_mean[:n], f_logvar[:n], f_mean[n:]
    log_lik = model.log_likelihood(torch.cat([p.z_hat_next, z_vae, det_next]),
                                   torch.cat([x_next, x_t, x_next]))
    recon_next, recon_t, det_ll = log_lik[:n], log_lik[n:2 * n], log_lik[2 * n:]

    kl_backward, entropy, transition_nll = _consistency_terms(p, trans_mean, trans_logvar)
    reconstruction = -recon_next.mean()
    beta = config.kl_scale
    consistency_term = kl_backward - entropy + transition_nll
    prediction = reconstruction + beta * consistency_term
    vae = -recon_t.mean() + beta * gaussian_kl_standard(mu_t, lv_t).mean()
    deterministic = -det_ll.mean()

    if curvature:
        z_c, u_c = z_vae.detach(), u
        eps_z = config.curvature_delta * torch.randn(
            z_c.shape, generator=generator, dtype=z_c.dtype, device=z_c.device)
        eps_u = config.curvature_delta * torch.randn(
            u_c.shape, generator=generator, dtype=u_c.dtype, device=u_c.device)
        at_perturbed = config.curvature_expansion == "perturbed"
        jacobians = None
        if amortized:
            out = (model.transition_full(z_c + eps_z, u_c + eps_u) if at_perturbed
                   else model.transition_full(z_c, u_c))
            assert out.A is not None and out.B is not None
            jacobians = (out.A, out.B)
        curvature_term = curvature_penalty(
            model.transition_mean, z_c, u_c, eps_z, eps_u, jacobians, at_perturbed).mean()
    else:
        curvature_term = torch.zeros((), dtype=mu_t.dtype, device=mu_t.device)

    loss = (
        config.lambda_p * prediction
        + (config.lambda_c * beta * consistency_term if consistency else 0.0)
        + (config.lambda_cur * curvature_term if curvature else 0.0)
        + config.vae_coef * vae
        + config.deterministic_ce_coef * deterministic
    )
    loss, multistep = _with_multistep(loss, model, batch, config, mu_t, det_next)
    return loss, _metrics(
        loss=loss, prediction=prediction, consistency=consistency_term,
        curvature=curvature_term, vae=vae, deterministic=deterministic,
        reconstruction=reconstruction, kl_backward=kl_backward, entropy=entropy,
        transition_nll=transition_nll, **multistep,
    )


def pcc_no_consistency_loss(
    model: EmbeddingModel, batch: TransitionBatch, config: TrainConfig,
    generator: torch.Generator | None = None,
) -> tuple[torch.Tensor, Metrics]:
    """PCC without the consistency bound: ``lambda_p R'_3 + lambda_cur R_LLC + VAE + det``."""
    return pcc_loss(model, batch, config, generator, consistency=False)


def pcc_no_curvature_loss(
    model: EmbeddingModel, batch: TransitionBatch, config: TrainConfig,
    generator: torch.Generator | None = None,
) -> tuple[torch.Tensor, Metrics]:
    """PCC without the curvature loss: ``lambda_p R'_3 + lambda_c R''_2 + VAE + det``."""
    return pcc_loss(model, batch, config, generator, curvature=False)


def pcc_amortized_loss(
    model: EmbeddingModel, batch: TransitionBatch, config: TrainConfig,
    generator: torch.Generator | None = None,
) -> tuple[torch.Tensor, Metrics]:
    """PCC with the amortized curvature loss R_LLC-Amor (A, B heads of the transition)."""
    return pcc_loss(model, batch, config, generator, amortized=True)


def locally_linear_kl(
    mean: torch.Tensor, v: torch.Tensor, r: torch.Tensor, logvar: torch.Tensor,
    mean_next: torch.Tensor, logvar_next: torch.Tensor,
) -> torch.Tensor:
    """KL(N(mean, A Sigma A^T) || N(mean_next, diag(exp(logvar_next)))) with A = I + v r^T.

    ``Sigma = diag(exp(logvar))``. Uses ``log det(A Sigma A^T) = 2 log|1 + r^T v| + sum logvar``
    (matrix determinant lemma) and ``tr(S^-1 A Sigma A^T) = sum_ij A_ij^2 Sigma_j / S_i``.

    Args:
        mean: Mean of the transition distribution, ``(B, n_z)``.
        v: Rank-one factor ``(B, n_z)``.
        r: Rank-one factor ``(B, n_z)``.
        logvar: Log-variance of the encoder distribution that A maps, ``(B, n_z)``.
        mean_next: Mean of the encoder distribution of x_{t+1}.
        logvar_next: Its log-variance.

    Returns:
        KL per sample, ``(B,)``.
    """
    n_z = mean.shape[-1]
    eye = torch.eye(n_z, dtype=v.dtype, device=v.device)
    a_mat = eye + v.unsqueeze(-1) * r.unsqueeze(-2)
    inv_var_next = torch.exp(-logvar_next)
    trace = (a_mat.pow(2) * torch.exp(logvar).unsqueeze(-2) * inv_var_next.unsqueeze(-1)).sum(
        (-2, -1))
    maha = ((mean_next - mean).pow(2) * inv_var_next).sum(-1)
    log_det_a = torch.log((1.0 + (r * v).sum(-1)).abs().clamp_min(1e-8))
    return 0.5 * (trace + maha - n_z + logvar_next.sum(-1) - logvar.sum(-1) - 2.0 * log_det_a)


def e2c_loss(
    model: EmbeddingModel,
    batch: TransitionBatch,
    config: TrainConfig,
    generator: torch.Generator | None = None,
) -> tuple[torch.Tensor, Metrics]:
    """Embed to Control (Watter et al., 2015) with the paper's extra VAE term.

    With ``z_t ~ E(. | x_t) = N(mu_t, Sigma_t)``, locally-linear ``A = I + v r^T``, B, o from the
    transition network at ``z_t``, and ``z_hat_{t+1} = A z_t + B u_t + o``, so that
    ``z_hat_{t+1} ~ Q = N(A mu_t + B u_t + o, A Sigma_t A^T)``::

        L = -log D(x_t | z_t) - log D(x_{t+1} | z_hat_{t+1}) + KL(E(. | x_t) || N(0, I))
            + lambda KL(Q || E(. | x_{t+1})) + vae_coef L_VAE

    ``KL(Q || N(mu_n, S_n)) = 0.5 (tr(S_n^-1 A Sigma_t A^T) + (mu_n - m)^T S_n^-1 (mu_n - m)
    - n_z + log det S_n - log det Sigma_t - 2 log |1 + r^T v|)`` using the matrix determinant
    lemma ``det A = 1 + r^T v`` once. ``L_VAE`` re-uses the first and third terms.

    Args:
        model: Model with ``transition_kind="e2c_linear"``.
        batch: Transitions.
        config: ``e2c_lambda`` and ``vae_coef``.
        generator: Source of the sampling noise.

    Returns:
        ``(loss, metrics)``; metrics: loss, reconstruction, prediction, kl_prior, kl_transition.
    """
    _check_transition(model, "e2c_linear", "e2c")
    x_t, u, x_next = batch.obs, batch.action, batch.next_obs
    n = x_t.shape[0]
    images = to_float_image(torch.cat([x_t, x_next], dim=0))
    mean_all, logvar_all = model.encode_pair(images[:n], images[n:])
    mu_t, mu_n = mean_all[:n], mean_all[n:]
    lv_t, lv_n = logvar_all[:n], logvar_all[n:]
    z_t = gaussian_rsample(mu_t, lv_t, generator)

    dynamics = model.dynamics
    assert isinstance(dynamics, E2CTransition)
    v, r, b_mat, o, _ = dynamics.components(z_t)
    bu_o = (b_mat @ u.unsqueeze(-1)).squeeze(-1) + o
    z_hat_next = z_t + v * (r * z_t).sum(-1, keepdim=True) + bu_o
    m = mu_t + v * (r * mu_t).sum(-1, keepdim=True) + bu_o

    log_lik = model.log_likelihood(torch.cat([z_t, z_hat_next]), images)
    reconstruction = -log_lik[:n].mean()
    prediction = -log_lik[n:].mean()
    kl_prior = gaussian_kl_standard(mu_t, lv_t).mean()

    kl_transition = locally_linear_kl(m, v, r, lv_t, mu_n, lv_n).mean()

    beta = config.kl_scale
    vae = reconstruction + beta * kl_prior
    loss = (reconstruction + prediction + beta * (kl_prior + config.e2c_lambda * kl_transition)
            + config.vae_coef * vae)
    loss, multistep = _with_multistep(loss, model, batch, config, mu_t)
    return loss, _metrics(loss=loss, reconstruction=reconstruction, prediction=prediction,
                          kl_prior=kl_prior, kl_transition=kl_transition, **multistep)


def rce_loss(
    model: EmbeddingModel,
    batch: TransitionBatch,
    config: TrainConfig,
    generator: torch.Generator | None = None,
) -> tuple[torch.Tensor, Metrics]:
    """Robust Controllable Embedding (Banijamali et al., 2018), Eq. 16 ELBO optimized directly.

    With the locally-linear Gaussian transition ``F(z' | z, u) = N(A(z) z + B(z) u + o(z),
    diag(sigma_F^2(z)))``, ``z_hat_{t+1} ~ E(. | x_{t+1})`` and ``z_t ~ Q(. | z_hat_{t+1}, x_t,
    u_t)``::

        L = -log D(x_{t+1} | z_hat_{t+1}) + KL(Q(z_t | z_hat_{t+1}, x_t, u_t) || E(z_t | x_t))
            - H(E(. | x_{t+1})) - log F(z_hat_{t+1} | z_t, u_t) + vae_coef L_VAE

    (no weighting or annealing of the middle terms, as in the PCC paper's comparison).

    Args:
        model: Model with ``transition_kind="e2c_linear"``.
        batch: Transitions.
        config: ``vae_coef``.
        generator: Source of the sampling noise.

    Returns:
        ``(loss, metrics)``; metrics: loss, elbo, reconstruction, kl_backward, entropy,
        transition_nll, vae.
    """
    _check_transition(model, "e2c_linear", "rce")
    n = batch.action.shape[0]
    p = _sample_posteriors(model, batch, generator)
    mu_t, lv_t = p.mu_t, p.lv_t
    trans_mean, trans_logvar = model.transition(p.z_t, batch.action)

    log_lik = model.log_likelihood(torch.cat([p.z_hat_next, p.z_vae]),
                                   torch.cat([p.x_next, p.x_t]))
    reconstruction = -log_lik[:n].mean()
    kl_backward, entropy, transition_nll = _consistency_terms(p, trans_mean, trans_logvar)
    elbo = -(reconstruction + kl_backward - entropy + transition_nll)
    beta = config.kl_scale
    vae = -log_lik[n:].mean() + beta * gaussian_kl_standard(mu_t, lv_t).mean()
    loss = reconstruction + beta * (kl_backward - entropy + transition_nll) + config.vae_coef * vae
    loss, multistep = _with_multistep(loss, model, batch, config, mu_t)
    return loss, _metrics(loss=loss, elbo=elbo, reconstruction=reconstruction,
                          kl_backward=kl_backward, entropy=entropy,
                          transition_nll=transition_nll, vae=vae, **multistep)


def multistep_prediction(model: EmbeddingModel, batch: TransitionBatch, horizon: int,
                         first_prediction: torch.Tensor | None = None) -> torch.Tensor:
    """The multi-step prediction term of ``TrainConfig.prediction_horizon`` (not the paper's).

    ``sum_{k=2..K} -log D(x_{t+k} | z_k)`` with ``z_1 = f(mu(x_t), u_t)`` and
    ``z_k = f(z_{k-1}, u_{t+k-1})``: PCC's deterministic cross-entropy carried ``K - 1`` steps
    further through the mean latent dynamics. A state coordinate the code leaves out shows
    here as an error that grows with ``k``. Works with every transition kind (it uses
    ``transition_mean`` only).

    Args:
        model: The model being trained.
        batch: Transitions with ``future_action`` and ``future_obs`` of at least
            ``horizon - 1`` steps.
        horizon: ``K >= 2``.
        first_prediction: ``z_1 = f(mu(x_t), u_t)`` where the caller has computed it already
            (every loss of the registry has ``mu(x_t)``; PCC's ``L_det`` has ``z_1``): it saves
            encoding ``x_t`` a second time. None: computed here.

    Returns:
        The term (a scalar tensor), summed over the extra steps, averaged over the batch.

    Raises:
        ValueError: ``horizon`` below 2, or the batch holds fewer than ``horizon - 1`` further
            steps.
    """
    steps = 0 if batch.future_action is None else batch.future_action.shape[1]
    if horizon < 2 or steps < horizon - 1:
        raise ValueError(f"A multi-step prediction over {horizon} steps needs horizon >= 2 and "
                         f"{horizon - 1} further steps per transition; the batch has {steps}.")
    assert batch.future_action is not None and batch.future_obs is not None
    if first_prediction is None:
        first_prediction = model.transition_mean(model.encode(batch.obs)[0], batch.action)
    z = first_prediction
    total = torch.zeros((), dtype=z.dtype, device=z.device)
    for j in range(horizon - 1):
        z = model.transition_mean(z, batch.future_action[:, j])
        total = total - model.log_likelihood(z, batch.future_obs[:, j]).mean()
    return total


def _with_multistep(
    loss: torch.Tensor, model: EmbeddingModel, batch: TransitionBatch, config: TrainConfig,
    obs_mean: torch.Tensor, first_prediction: torch.Tensor | None = None,
) -> tuple[torch.Tensor, dict[str, torch.Tensor]]:
    """``loss`` plus ``config.multistep_coef`` times the multi-step term, and that term by name.

    With ``config.prediction_horizon`` 1 (the paper's objective): ``loss`` unchanged and no
    term. The caller's ``obs_mean = mu(x_t)`` (or its ``first_prediction``) is reused, so the
    term costs no encoder pass.
    """
    if config.prediction_horizon <= 1:
        return loss, {}
    if first_prediction is None:
        first_prediction = model.transition_mean(obs_mean, batch.action)
    term = multistep_prediction(model, batch, config.prediction_horizon, first_prediction)
    return loss + config.multistep_coef * term, {"multistep": term}


@dataclasses.dataclass(frozen=True)
class MethodSpec:
    """A training method: its loss and the model options it needs.

    Attributes:
        name: Registry name.
        loss: The loss function.
        model_options: ``ModelConfig`` fields the method requires (applied by
            :func:`model_config_for_method`).
    """

    name: str
    loss: LossFunction
    model_options: dict[str, Any]


_MLP = {"transition_kind": "mlp", "amortized": False}
_LINEAR = {"transition_kind": "e2c_linear", "amortized": False}

#: Registry of training methods (``pcc``, ``e2c``, ``rce`` and the PCC ablations).
METHODS: dict[str, MethodSpec] = {
    spec.name: spec
    for spec in (
        MethodSpec("pcc", pcc_loss, _MLP),
        MethodSpec("e2c", e2c_loss, _LINEAR),
        MethodSpec("rce", rce_loss, _LINEAR),
        MethodSpec("pcc-no-consistency", pcc_no_consistency_loss, _MLP),
        MethodSpec("pcc-no-curvature", pcc_no_curvature_loss, _MLP),
        MethodSpec("pcc-amortized", pcc_amortized_loss,
                   {"transition_kind": "mlp", "amortized": True}),
    )
}
LOSSES = METHODS  # name used in docs/ARCHITECTURE.md


def _spec(method: str) -> MethodSpec:
    if method not in METHODS:
        raise ValueError(f"Unknown method {method!r}; choose one of {sorted(METHODS)}.")
    return METHODS[method]


def get_loss(method: str) -> LossFunction:
    """Return the loss function of a method name (see :data:`METHODS`).

    Raises:
        ValueError: Unknown name; the message lists the known ones.
    """
    return _spec(method).loss


def model_config_for_method(config: ModelConfig, method: str) -> ModelConfig:
    """Return ``config`` with the transition options that ``method`` needs.

    Example:
        >>> from pcc_agent.presets import get_preset
        >>> model_config_for_method(get_preset("pcc/Planar-v0").model, "e2c").transition_kind
        'e2c_linear'
    """
    return dataclasses.replace(config, **_spec(method).model_options)


__all__ = [
    "LOSSES",
    "METHODS",
    "LossFunction",
    "MethodSpec",
    "TransitionBatch",
    "curvature_penalty",
    "e2c_loss",
    "get_loss",
    "locally_linear_kl",
    "model_config_for_method",
    "multistep_prediction",
    "pcc_amortized_loss",
    "pcc_loss",
    "pcc_no_consistency_loss",
    "pcc_no_curvature_loss",
    "rce_loss",
]
