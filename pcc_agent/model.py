"""The embedding model: encoder, latent transition, decoder and backward model (no loss code).

Notation: observations x are uint8 ``(B, F, H, W)``; latent states z ``(B, n_z)``; actions
u ``(B, n_u)``. The planner only needs :meth:`EmbeddingModel.encode`,
:meth:`EmbeddingModel.transition_mean` and :meth:`EmbeddingModel.linearize`.
"""

from __future__ import annotations

from collections.abc import Sequence
from typing import Any

import torch
from torch import nn
from torch.func import jacrev, vmap

from pcc_agent._forward_ad import jvp
from pcc_agent.config import ModelConfig
from pcc_agent.networks import TransitionOutput, build_networks, to_float_image


class EmbeddingModel(nn.Module):
    """E(z|x), F(z'|z,u), D(x|z) and Q(z_t|z_hat_{t+1},x_t,u_t) for one observation space.

    Args:
        obs_shape: Observation shape ``(frames, H, W)``.
        action_dim: Action dimension n_u.
        config: Architecture (:class:`pcc_agent.presets.ModelConfig`).
        seed: Optional seed of the weight initialization (drawn inside ``fork_rng``, so the
            global torch RNG state is left untouched); None uses the global RNG.

    Example:
        >>> import torch
        >>> from pcc_agent.presets import get_preset
        >>> model = EmbeddingModel((1, 40, 40), 2, get_preset("pcc/Planar-v0").model)
        >>> mean, logvar = model.encode(torch.zeros(5, 1, 40, 40, dtype=torch.uint8))
        >>> A, B = model.linearize(mean, torch.zeros(5, 2))
        >>> tuple(A.shape), tuple(B.shape)
        ((5, 2, 2), (5, 2, 2))
    """

    def __init__(
        self, obs_shape: Sequence[int], action_dim: int, config: ModelConfig,
        seed: int | None = None,
    ) -> None:
        super().__init__()
        self.obs_shape = tuple(int(s) for s in obs_shape)
        self.action_dim = int(action_dim)
        self.config = config
        if seed is None:
            nets = build_networks(self.obs_shape, self.action_dim, config)
        else:
            with torch.random.fork_rng(devices=[]):
                torch.manual_seed(seed)
                nets = build_networks(self.obs_shape, self.action_dim, config)
        self.encoder = nets.encoder
        self.decoder = nets.decoder
        self.dynamics = nets.transition
        self.backward_model = nets.backward

    @property
    def latent_dim(self) -> int:
        """Latent dimension n_z."""
        return self.config.latent_dim

    def architecture(self) -> dict[str, Any]:
        """JSON-serializable description used to rebuild the model from a checkpoint."""
        return {
            "obs_shape": list(self.obs_shape),
            "action_dim": self.action_dim,
            "model_config": self.config.to_dict(),
        }

    def encode(self, obs: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor]:
        """Mean and log-variance of E(z | x) for a batch of observations ``(B, F, H, W)``."""
        return self.encoder(obs)

    def encode_pair(
        self, obs: torch.Tensor, next_obs: torch.Tensor
    ) -> tuple[torch.Tensor, torch.Tensor]:
        """``encode(torch.cat([obs, next_obs]))`` for transitions ``(B, F, H, W)`` each.

        Per-frame encoders embed the frames that ``next_obs`` shares with ``obs`` once (see
        :meth:`pcc_agent.networks.GaussianEncoder.forward_pair`); the result is the same.
        """
        return self.encoder.forward_pair(obs, next_obs)

    def transition(self, z: torch.Tensor, u: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor]:
        """Mean and log-variance of F(z' | z, u)."""
        out = self.dynamics(z, u)
        return out.mean, out.logvar

    def transition_full(self, z: torch.Tensor, u: torch.Tensor) -> TransitionOutput:
        """Mean, log-variance and the A, B matrices (amortized or E2C; None otherwise)."""
        return self.dynamics(z, u)

    def transition_mean(self, z: torch.Tensor, u: torch.Tensor) -> torch.Tensor:
        """Deterministic latent dynamics ``f(z, u)`` (the mean of F), any leading shape."""
        return self.dynamics.mean(z, u)

    def transition_jvp(
        self, z: torch.Tensor, u: torch.Tensor, dz: torch.Tensor, du: torch.Tensor
    ) -> tuple[torch.Tensor, torch.Tensor]:
        """Return ``f(z, u)`` and ``df/dz dz + df/du du`` with one forward-mode pass.

        Differentiable with respect to the parameters and to ``z``, ``u`` (used by the
        curvature loss).
        """
        out = jvp(self.transition_mean, (z, u), (dz, du))
        return out[0], out[1]

    def linearize(
        self, z: torch.Tensor, u: torch.Tensor, exact: bool | None = None
    ) -> tuple[torch.Tensor, torch.Tensor]:
        """Jacobians ``A = df/dz`` ``(B, n_z, n_z)`` and ``B = df/du`` ``(B, n_z, n_u)``.

        Args:
            z: Latent states ``(..., n_z)`` (any leading batch shape).
            u: Actions ``(..., n_u)``.
            exact: True: Jacobians of :meth:`transition_mean` (batched ``vmap(jacrev)``).
                False: the network's A, B heads (amortized PCC, or E2C/RCE's locally-linear
                A, B). None (default): the heads when the model has them, else exact.

        Returns:
            ``(A, B)`` shaped ``(..., n_z, n_z)`` and ``(..., n_z, n_u)``; ``A[i, j] =
            d f_i / d z_j`` (rows index outputs).
        """
        use_heads = (self.config.amortized or self.config.transition_kind == "e2c_linear")
        if exact is None:
            exact = not use_heads
        if not exact:
            if not use_heads:
                raise ValueError(
                    "This model has no A/B heads; use exact=True (or build it with "
                    "ModelConfig(amortized=True))."
                )
            out = self.dynamics(z, u)
            return out.A, out.B
        lead = z.shape[:-1]
        a_mat, b_mat = vmap(jacrev(self.transition_mean, argnums=(0, 1)))(
            z.reshape(-1, z.shape[-1]), u.reshape(-1, u.shape[-1]))
        return (a_mat.reshape(*lead, *a_mat.shape[1:]), b_mat.reshape(*lead, *b_mat.shape[1:]))

    @torch.no_grad()
    def fit_input_statistics(self, obs: torch.Tensor) -> None:
        """Fit the data-dependent parts on training images ``(N, F, H, W)`` (uint8).

        The per-pixel input standardization (``config.input_standardization``) and the
        decoder's output-bias initialization (``config.decoder_bias_init``); a no-op when both
        are off (the paper's setting).
        """
        if not (self.config.input_standardization or self.config.decoder_bias_init):
            return
        images = to_float_image(obs)
        if self.config.input_standardization:
            for module in self.modules():
                if hasattr(module, "set_statistics"):
                    module.set_statistics(images)
        if self.config.decoder_bias_init:
            self.decoder.init_output_bias(images)

    def planner_dynamics(self) -> Any:
        """The deterministic latent dynamics as the planner should use them.

        An MLP transition without A, B heads becomes an
        :class:`~pcc_agent.planning.dynamics.MLPDynamics` with analytic Jacobians (exactly
        :meth:`transition_mean` and its Jacobians, several times faster than ``vmap(jacrev)``
        on the planner's small batches); otherwise (amortized heads, E2C/RCE's locally-linear
        transition) the model itself, whose :meth:`linearize` uses the heads.
        """
        from pcc_agent.planning.dynamics import MLPDynamics, ModelDynamics

        if self.config.transition_kind == "mlp" and not self.config.amortized:
            weights, biases = self.dynamics.mean_layers()
            return MLPDynamics(weights, biases, activation="relu", residual=True)
        return ModelDynamics(self)

    def decode_logits(self, z: torch.Tensor) -> torch.Tensor:
        """Bernoulli logits of D(x | z), shaped ``(B, F, H, W)``."""
        return self.decoder(z)

    def log_likelihood(self, z: torch.Tensor, obs: torch.Tensor) -> torch.Tensor:
        """``log D(obs | z)`` per sample, ``(B,)``; ``obs`` uint8 or float in [0, 1].

        Equal to ``bernoulli_log_likelihood(decode_logits(z), obs / 255)`` but computed at the
        decoder's native resolution when its logits are upsampled (see
        :meth:`pcc_agent.networks.BernoulliDecoder.log_likelihood`).
        """
        return self.decoder.log_likelihood(z, to_float_image(obs))

    def decode(self, z: torch.Tensor) -> torch.Tensor:
        """Pixel probabilities ``sigmoid(logits)`` in [0, 1]."""
        return torch.sigmoid(self.decoder(z))

    def backward_posterior(
        self, z_next: torch.Tensor, obs: torch.Tensor, u: torch.Tensor
    ) -> tuple[torch.Tensor, torch.Tensor]:
        """Mean and log-variance of Q(z_t | z_hat_{t+1}, x_t, u_t)."""
        return self.backward_model(z_next, obs, u)
