"""Closed-form helpers for diagonal Gaussians and Bernoulli likelihoods from logits.

A diagonal Gaussian is given by its mean ``mu`` and log-variance ``logvar`` (same shape
``(..., n)``); every function sums over the last dimension and keeps the leading ones.
"""

from __future__ import annotations

import math

import torch
import torch.nn.functional as F

_LOG_2PI = math.log(2.0 * math.pi)


def gaussian_kl(
    mean_q: torch.Tensor, logvar_q: torch.Tensor, mean_p: torch.Tensor, logvar_p: torch.Tensor
) -> torch.Tensor:
    """KL(q || p) between diagonal Gaussians, summed over the last dimension.

    ``KL = 0.5 * sum(logvar_p - logvar_q + (var_q + (mean_q - mean_p)^2) / var_p - 1)``.

    Args:
        mean_q: Mean of q, shape ``(..., n)``.
        logvar_q: Log-variance of q.
        mean_p: Mean of p.
        logvar_p: Log-variance of p.

    Returns:
        Tensor of shape ``(...)``.
    """
    inv_var_p = torch.exp(-logvar_p)
    terms = logvar_p - logvar_q + (torch.exp(logvar_q) + (mean_q - mean_p).pow(2)) * inv_var_p - 1.0
    return 0.5 * terms.sum(dim=-1)


def gaussian_kl_standard(mean: torch.Tensor, logvar: torch.Tensor) -> torch.Tensor:
    """KL(N(mean, exp(logvar)) || N(0, I)), summed over the last dimension."""
    return 0.5 * (torch.exp(logvar) + mean.pow(2) - 1.0 - logvar).sum(dim=-1)


def gaussian_entropy(logvar: torch.Tensor) -> torch.Tensor:
    """Entropy ``0.5 * sum(log(2 pi e) + logvar)`` of a diagonal Gaussian, shape ``(...)``."""
    return 0.5 * (logvar + _LOG_2PI + 1.0).sum(dim=-1)


def gaussian_log_prob(
    value: torch.Tensor, mean: torch.Tensor, logvar: torch.Tensor
) -> torch.Tensor:
    """Log-density of ``value`` under a diagonal Gaussian, summed over the last dimension."""
    return -0.5 * ((value - mean).pow(2) * torch.exp(-logvar) + logvar + _LOG_2PI).sum(dim=-1)


def gaussian_rsample(
    mean: torch.Tensor, logvar: torch.Tensor, generator: torch.Generator | None = None
) -> torch.Tensor:
    """Reparameterized sample ``mean + exp(logvar / 2) * eps`` with ``eps`` from ``generator``."""
    eps = torch.randn(mean.shape, generator=generator, dtype=mean.dtype, device=mean.device)
    return mean + torch.exp(0.5 * logvar) * eps


def bernoulli_log_likelihood(logits: torch.Tensor, target: torch.Tensor) -> torch.Tensor:
    """Bernoulli log-likelihood of ``target`` in [0, 1] given ``logits``, summed per sample.

    Uses ``binary_cross_entropy_with_logits`` (log-sum-exp form), which is numerically safe in
    float32 for any logit magnitude.

    Args:
        logits: Logits, shape ``(B, ...)``.
        target: Targets in [0, 1] (soft targets allowed), same shape.

    Returns:
        Tensor of shape ``(B,)``: the sum over all non-batch dimensions.
    """
    bce = F.binary_cross_entropy_with_logits(logits, target, reduction="none")
    return -bce.flatten(start_dim=1).sum(dim=1)
