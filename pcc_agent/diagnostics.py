"""Diagnostics of a trained embedding, measured on transitions, before any control is run.

Latent iLQR plans by rolling the latent dynamics forward from the encoded observation, so it
needs two things of the model: the dynamics must agree with the encoder along real
transitions (the paper's *consistency*), and they must be close to linear at the scale of a
planning step (the paper's *curvature*). :func:`latent_diagnostics` measures both on held-out
transitions:

* ``consistency_error``: ``|| f(mu(x_t), u_t) - mu(x_{t+1}) ||^2`` averaged over the
  transitions and divided by ``latent_scale^2``, so models with latent spaces of different
  sizes compare. ``f`` is the mean of the latent dynamics and ``mu`` the encoder mean.
* ``curvature``: the curvature loss ``R_LLC`` of the training objective,
  ``|| f(z + e_z, u + e_u) - (A e_z + B e_u) - f(z, u) ||^2`` with ``e ~ N(0, delta^2 I)``
  at ``z = mu(x_t)``. It comes from :func:`pcc_agent.losses.curvature_penalty`, with the true
  Jacobians, for every method.
* ``latent_scale``: the mean per-dimension standard deviation of ``mu(x_t)``.

On Planar (``benchmarks/latent_diagnostics.py``, docs/training.md) the consistency error
tells the models that control well from those that do not.
"""

from __future__ import annotations

from dataclasses import asdict, dataclass
from typing import Any

import numpy as np
import torch

from pcc_agent.losses import curvature_penalty
from pcc_agent.model import EmbeddingModel

__all__ = ["LatentDiagnostics", "latent_diagnostics"]


@dataclass(frozen=True)
class LatentDiagnostics:
    """What :func:`latent_diagnostics` measured (see the module docstring)."""

    latent_scale: float
    consistency_error: float
    curvature: float
    num_samples: int

    def to_dict(self) -> dict[str, Any]:
        """JSON-friendly representation."""
        return asdict(self)


def latent_diagnostics(
    model: EmbeddingModel,
    obs: np.ndarray,
    action: np.ndarray,
    next_obs: np.ndarray,
    delta: float = 0.1,
    seed: int = 0,
    batch_size: int = 500,
) -> LatentDiagnostics:
    """Consistency error, curvature and latent scale of ``model`` on transitions.

    Args:
        model: A trained embedding model (any method).
        obs: Observations ``uint8 (N, *obs_shape)``; best held out from the training data.
        action: Actions ``(N, action_dim)`` in the model's action scale.
        next_obs: Next observations, like ``obs``.
        delta: Standard deviation of the curvature perturbations (the training's 0.1).
        seed: Seed of the perturbations.
        batch_size: Transitions per forward pass.

    Returns:
        The :class:`LatentDiagnostics`.
    """
    if not (len(obs) == len(action) == len(next_obs)) or len(obs) == 0:
        raise ValueError(
            f"Need the same non-zero number of observations, actions and next observations, "
            f"got {len(obs)}, {len(action)} and {len(next_obs)}."
        )
    if tuple(obs.shape[1:]) != model.obs_shape or tuple(next_obs.shape[1:]) != model.obs_shape:
        raise ValueError(
            f"Observations have shapes {obs.shape[1:]} and {next_obs.shape[1:]}, the model "
            f"expects {model.obs_shape}."
        )
    if action.ndim != 2 or action.shape[1] != model.action_dim:
        raise ValueError(f"Actions must be (N, {model.action_dim}), got {action.shape}.")
    device = next(model.parameters()).device
    generator = torch.Generator().manual_seed(seed)
    was_training = model.training
    model.eval()
    means, errors, curvatures = [], [], []
    try:
        for start in range(0, len(obs), batch_size):
            part = slice(start, start + batch_size)
            x_t = torch.as_tensor(obs[part], device=device)
            x_next = torch.as_tensor(next_obs[part], device=device)
            u = torch.as_tensor(action[part], dtype=torch.float32, device=device)
            with torch.no_grad():
                mu_t = model.encode(x_t)[0]
                mu_next = model.encode(x_next)[0]
                predicted = model.transition_mean(mu_t, u)
            eps_z = delta * torch.randn(mu_t.shape, generator=generator).to(device)
            eps_u = delta * torch.randn(u.shape, generator=generator).to(device)
            residual = curvature_penalty(model.transition_mean, mu_t, u, eps_z, eps_u)
            means.append(mu_t)
            errors.append((predicted - mu_next).pow(2).sum(-1))
            curvatures.append(residual.detach())
    finally:
        model.train(was_training)
    latent = torch.cat(means)
    scale = float(latent.std(dim=0).mean()) if len(latent) > 1 else 1.0
    return LatentDiagnostics(
        latent_scale=scale,
        consistency_error=float(torch.cat(errors).mean()) / max(scale, 1e-12) ** 2,
        curvature=float(torch.cat(curvatures).mean()),
        num_samples=len(obs),
    )
