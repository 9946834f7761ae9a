"""Encoder, decoder, latent transition and backward model, built by one factory.

Shapes: observations are uint8 ``(B, F, H, W)`` (``F`` frames, oldest first), converted to float
in [0, 1] inside the networks; latent states ``z`` are ``(B, n_z)``; actions ``u`` ``(B, n_u)``.

* Encoder E(z | x): backbone (MLP on the flattened image, CNN, or a CNN on each frame alone
  whose keypoints or features and their change between frames go on) + a linear layer to the
  mean and log-variance of a diagonal Gaussian.
* Decoder D(x | z): backbone + logits of a Bernoulli per pixel, shaped like the observation.
* Transition F(z' | z, u): either a Gaussian MLP whose mean has a skip connection
  (``mean = z + g(z, u)``), optionally with amortized Jacobian heads A (n_z x n_z) and
  B (n_z x n_u); or the E2C / RCE locally-linear form ``z' = A z + B u + o`` with
  ``A = I + v r^T`` and (v, r, B, o) computed by an MLP on z.
* Backward model Q(z_t | z_hat_{t+1}, x_t, u_t): each input through its own layer
  (N_z, N_u, N_x units), concatenated, a joint layer (N_joint), then mean and log-variance.

ReLU follows every hidden layer. Sizes come from the spaces and a :class:`ModelConfig`; CNN
flatten sizes are found with a dummy forward pass.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from typing import NamedTuple

import torch
import torch.nn.functional as F
from torch import nn

from pcc_agent.config import ConvSpec, ModelConfig
from pcc_agent.distributions import bernoulli_log_likelihood


def to_float_image(obs: torch.Tensor) -> torch.Tensor:
    """Convert observations to float32 in [0, 1].

    Args:
        obs: uint8 images in [0, 255], or floating images already scaled to [0, 1].

    Returns:
        A float32 tensor of the same shape.
    """
    if obs.dtype == torch.uint8:
        return obs.to(torch.float32) / 255.0
    return obs.to(torch.float32)


def mlp(sizes: Sequence[int], activate_last: bool = False) -> nn.Sequential:
    """Fully-connected network ``sizes[0] -> ... -> sizes[-1]`` with ReLU between layers.

    Args:
        sizes: Layer widths including the input width.
        activate_last: Whether a ReLU also follows the last layer.

    Returns:
        The network (empty ``Sequential`` = identity when ``len(sizes) == 1``).
    """
    layers: list[nn.Module] = []
    for i in range(len(sizes) - 1):
        layers.append(nn.Linear(sizes[i], sizes[i + 1]))
        if i < len(sizes) - 2 or activate_last:
            layers.append(nn.ReLU())
    return nn.Sequential(*layers)


class _ImageInput(nn.Module):
    """uint8 -> float in [0, 1], optional per-pixel standardization, optional downsampling.

    With ``standardize`` the input becomes ``(x - mean) * scale`` with per-pixel statistics
    of the training images (buffers, saved with the weights; identity until
    :meth:`set_statistics` is called). A small moving object then gives the first layer a
    large, centred signal instead of a few bright pixels on a constant background, which is
    what lets a 2-d latent code form in minutes rather than hours.
    """

    def __init__(self, obs_shape: tuple[int, int, int], downsample: int,
                 standardize: bool = False, motion_gain: float = 0.0) -> None:
        super().__init__()
        self.downsample = downsample
        self.standardize = standardize
        self.motion_gain = motion_gain
        if standardize:
            self.register_buffer("mean", torch.zeros(obs_shape))
            self.register_buffer("scale", torch.ones(obs_shape))

    @torch.no_grad()
    def set_statistics(self, images: torch.Tensor, eps: float = 0.05) -> None:
        """Fit ``mean`` and ``scale = 1 / (std + eps)`` on float images ``(N, F, H, W)``."""
        if self.standardize:
            self.mean.copy_(images.mean(0))
            self.scale.copy_(1.0 / (images.std(0) + eps))

    def forward(self, obs: torch.Tensor) -> torch.Tensor:
        x = to_float_image(obs)
        if self.standardize:
            x = (x - self.mean) * self.scale
        if self.downsample > 1:
            x = F.avg_pool2d(x, self.downsample, ceil_mode=True)
        if self.motion_gain and x.shape[1] > 1:  # older frames -> gain x (newest - them)
            newest = x[:, -1:]
            x = torch.cat([self.motion_gain * (newest - x[:, :-1]), newest], dim=1)
        return x


def _conv_stack(in_channels: int, convs: Sequence[ConvSpec]) -> nn.Sequential:
    layers: list[nn.Module] = []
    for spec in convs:
        layers += [
            nn.Conv2d(in_channels, spec.channels, spec.kernel_size, spec.stride,
                      padding=spec.kernel_size // 2),
            nn.ReLU(),
        ]
        in_channels = spec.channels
    return nn.Sequential(*layers)


#: Factor on the frame-to-frame motion of per-frame features (:class:`_PerFrameMotion`). A
#: keypoint moves a few hundredths of its [-1, 1] range per step (CartPole's pole tip a fraction
#: of a pixel of 80), so unscaled motions would reach the first hidden layer a hundred times
#: weaker than the positions.
MOTION_SCALE = 20.0


class _PerFrameMotion(nn.Module):
    """Frames -> features of each frame alone (shared weights) -> newest features and motion.

    The output is the newest frame's features followed by ``MOTION_SCALE`` times each later
    frame's features minus the frame's before. Subclasses define :meth:`per_frame`.
    """

    def per_frame(self, frames: torch.Tensor) -> torch.Tensor:
        """``(N, 1, H, W)`` single frames -> ``(N, D)`` features."""
        raise NotImplementedError

    def frame_features(self, x: torch.Tensor) -> torch.Tensor:
        """``(B, F, H, W)`` float images -> ``(B, F, D)`` features of each frame alone."""
        batch, frames, height, width = x.shape
        features = self.per_frame(x.reshape(batch * frames, 1, height, width))
        return features.reshape(batch, frames, -1)

    @staticmethod
    def combine(features: torch.Tensor) -> torch.Tensor:
        """``(B, F, D)`` per-frame features -> ``(B, D F)``: the newest and the motions."""
        motion = (features[:, 1:] - features[:, :-1]) * MOTION_SCALE
        return torch.cat([features[:, -1], motion.flatten(1)], dim=1)

    def forward(self, x: torch.Tensor) -> torch.Tensor:
        """``(B, F, H, W)`` float images -> ``(B, D F)`` features."""
        return self.combine(self.frame_features(x))


class _Keypoints(_PerFrameMotion):
    """Per-frame keypoints by spatial soft-argmax (``encoder_kind="keypoints"``).

    The convolutions run on every frame alone; the last one's ``K`` channels are heatmaps, and
    each heatmap's softmax-weighted mean pixel position (in [-1, 1], with a learned temperature
    per heatmap) is a keypoint: ``2K`` features per frame.
    """

    def __init__(self, convs: Sequence[ConvSpec]) -> None:
        super().__init__()
        *hidden, last = convs
        self.features = _conv_stack(1, hidden)
        self.heatmaps = nn.Conv2d(hidden[-1].channels if hidden else 1, last.channels,
                                  last.kernel_size, last.stride, padding=last.kernel_size // 2)
        self.log_temperature = nn.Parameter(torch.zeros(last.channels))

    def per_frame(self, frames: torch.Tensor) -> torch.Tensor:
        maps = self.heatmaps(self.features(frames))
        rows, cols = maps.shape[-2:]
        weights = torch.softmax(
            maps.flatten(2) * torch.exp(-self.log_temperature)[:, None], dim=-1
        ).view(len(frames), -1, rows, cols)
        ys = torch.linspace(-1.0, 1.0, rows, device=frames.device, dtype=weights.dtype)
        xs = torch.linspace(-1.0, 1.0, cols, device=frames.device, dtype=weights.dtype)
        points = torch.stack([(weights.sum(2) * xs).sum(-1), (weights.sum(3) * ys).sum(-1)], -1)
        return points.flatten(1)


class _FrameEmbedding(_PerFrameMotion):
    """Per-frame CNN embedding (``encoder_kind="frame_cnn"``).

    Convolutions, then a linear map to ``width`` features (no ReLU, so that small motions
    change them smoothly).
    """

    def __init__(self, frame_shape: tuple[int, int], convs: Sequence[ConvSpec],
                 width: int) -> None:
        super().__init__()
        self.convs = nn.Sequential(_conv_stack(1, convs), nn.Flatten())
        with torch.no_grad():
            flat = self.convs(torch.zeros(1, 1, *frame_shape)).shape[1]
        self.linear = nn.Linear(flat, width)

    def per_frame(self, frames: torch.Tensor) -> torch.Tensor:
        return self.linear(self.convs(frames))


def _image_backbone(
    obs_shape: tuple[int, int, int], kind: str, convs: Sequence[ConvSpec],
    hidden: Sequence[int], downsample: int, standardize: bool = False,
    motion_gain: float = 0.0, frame_features: int = 0,
) -> tuple[nn.Sequential, int]:
    """Image -> features; returns the module and its output width (found by a dummy pass)."""
    layers: list[nn.Module] = [_ImageInput(obs_shape, downsample, standardize, motion_gain)]
    if kind == "cnn":
        layers.append(_conv_stack(obs_shape[0], convs))
    elif kind == "keypoints":
        layers.append(_Keypoints(convs))
    elif kind == "frame_cnn":
        frame_shape = (math.ceil(obs_shape[1] / downsample), math.ceil(obs_shape[2] / downsample))
        layers.append(_FrameEmbedding(frame_shape, convs, frame_features))
    layers.append(nn.Flatten())
    trunk = nn.Sequential(*layers)
    with torch.no_grad():
        flat = trunk(torch.zeros((1, *obs_shape), dtype=torch.uint8)).shape[1]
    head = mlp([flat, *hidden], activate_last=True)
    width = hidden[-1] if hidden else flat
    return nn.Sequential(trunk, head), width


class GaussianEncoder(nn.Module):
    """E(z | x): image -> (mean, logvar), each ``(B, n_z)``."""

    def __init__(self, obs_shape: tuple[int, int, int], config: ModelConfig) -> None:
        super().__init__()
        self.backbone, width = _image_backbone(
            obs_shape, config.encoder_kind, config.encoder_convs, config.encoder_hidden,
            config.encoder_downsample, config.input_standardization,
            config.encoder_motion_gain, config.encoder_frame_features,
        )
        self.head = nn.Linear(width, 2 * config.latent_dim)
        self.min_logvar, self.max_logvar = config.min_logvar, config.max_logvar

    def forward(self, obs: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor]:
        """Return the mean and log-variance of E(z | obs)."""
        return self._gaussian(self.backbone(obs))

    def _gaussian(self, features: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor]:
        mean, logvar = self.head(features).chunk(2, dim=-1)
        return mean, logvar.clamp(self.min_logvar, self.max_logvar)

    def forward_pair(
        self, obs: torch.Tensor, next_obs: torch.Tensor
    ) -> tuple[torch.Tensor, torch.Tensor]:
        """``forward(torch.cat([obs, next_obs]))``, each shared frame embedded once.

        In a transition of stacked frames ``next_obs`` usually repeats all frames of ``obs``
        but the oldest. An encoder that embeds every frame alone (``"keypoints"``,
        ``"frame_cnn"``, without input standardization, whose statistics differ per frame
        position) then needs ``F + 1`` frame embeddings per transition instead of ``2F``: a
        quarter of its work saved for two frames. Any other input takes the plain path.
        """
        trunk, hidden = self.backbone
        image_input, per_frame = trunk[0], trunk[1]
        if (isinstance(per_frame, _PerFrameMotion) and not image_input.standardize
                and obs.shape[1] > 1 and obs.shape == next_obs.shape
                and torch.equal(obs[:, 1:], next_obs[:, :-1])):
            chain = torch.cat([obs, next_obs[:, -1:]], dim=1)
            features = per_frame.frame_features(image_input(chain))
            frames = obs.shape[1]
            both = torch.cat([per_frame.combine(features[:, :frames]),
                              per_frame.combine(features[:, 1:])])
            return self._gaussian(hidden(both))
        return self(torch.cat([obs, next_obs]))


class BernoulliDecoder(nn.Module):
    """D(x | z): latent ``(B, n_z)`` -> logits ``(B, F, H, W)``."""

    def __init__(self, obs_shape: tuple[int, int, int], config: ModelConfig) -> None:
        super().__init__()
        self.obs_shape = tuple(obs_shape)
        frames, height, width = obs_shape
        self.kind = config.decoder_kind
        if self.kind == "mlp":
            self.net = mlp([config.latent_dim, *config.decoder_hidden, frames * height * width])
            return
        self.output_upsample = config.decoder_output_upsample
        self.pixel_shuffle = config.decoder_pixel_shuffle
        out_channels = frames * self.output_upsample**2 if self.pixel_shuffle else frames
        if config.decoder_convs[-1].channels != out_channels:
            per_frame = (f"{self.output_upsample}^2 per observation frame, for the pixel shuffle"
                         if self.pixel_shuffle else "one per observation frame")
            raise ValueError(
                f"The last decoder ConvSpec must have {out_channels} channels ({per_frame}), "
                f"got {config.decoder_convs[-1].channels}."
            )
        scale = 2 ** (len(config.decoder_convs) - 1) * config.decoder_output_upsample
        self.grid = (config.decoder_grid_channels, math.ceil(height / scale),
                     math.ceil(width / scale))
        self.fc = mlp(
            [config.latent_dim, *config.decoder_hidden, math.prod(self.grid)], activate_last=True
        )
        layers: list[nn.Module] = []
        channels = config.decoder_grid_channels
        for i, spec in enumerate(config.decoder_convs):
            layers.append(nn.Conv2d(channels, spec.channels, spec.kernel_size, 1,
                                    padding=spec.kernel_size // 2))
            if i < len(config.decoder_convs) - 1:
                layers += [nn.ReLU(), nn.Upsample(scale_factor=2, mode="nearest")]
            channels = spec.channels
        self.convs = nn.Sequential(*layers)

    @torch.no_grad()
    def init_output_bias(self, images: torch.Tensor, eps: float = 1e-3) -> None:
        """Set the output biases to the logits of the mean of float images ``(N, F, H, W)``.

        The MLP decoder gets one bias per pixel (the mean image); the CNN decoder, whose last
        convolution has one bias per frame (per frame and sub-pixel position with the pixel
        shuffle), gets the logit of each frame's mean intensity.
        """
        mean = images.mean(0).clamp(eps, 1.0 - eps)
        if self.kind == "mlp":
            self.net[-1].bias.copy_(torch.logit(mean).reshape(-1))
            return
        per_frame = torch.logit(mean.mean(dim=(1, 2)))
        if self.pixel_shuffle:
            per_frame = per_frame.repeat_interleave(self.output_upsample**2)
        self.convs[-1].bias.copy_(per_frame)

    def _low_resolution(self, z: torch.Tensor) -> torch.Tensor:
        """The CNN decoder's logits before the output upsampling or pixel shuffle."""
        return self.convs(self.fc(z).view(z.shape[0], *self.grid))

    def forward(self, z: torch.Tensor) -> torch.Tensor:
        """Return the Bernoulli logits of D(x | z), shaped ``(B, F, H, W)``."""
        if self.kind == "mlp":
            return self.net(z).view(z.shape[0], *self.obs_shape)
        x = self._low_resolution(z)
        if self.pixel_shuffle:
            x = F.pixel_shuffle(x, self.output_upsample)
        elif self.output_upsample > 1:
            x = F.interpolate(x, scale_factor=self.output_upsample, mode="nearest")
        return x[..., : self.obs_shape[1], : self.obs_shape[2]]

    def log_likelihood(self, z: torch.Tensor, target: torch.Tensor) -> torch.Tensor:
        """``log D(target | z)`` summed per sample, ``(B,)``; ``target`` float in [0, 1].

        Two exact shortcuts for a CNN decoder whose low-resolution map covers the image by a
        factor k (no cropping). Nearest-neighbour upsampling: each low-resolution logit l
        covers k*k pixels and ``sum_i BCE(l, t_i) = k^2 BCE(l, mean_i t_i)``, so the
        likelihood is computed at low resolution against the average-pooled target (k^2
        times cheaper). Pixel shuffle: it only moves logits, so they are compared before it
        with the target rearranged by the inverse shuffle (the same sum, without shuffling
        the logits and their gradients).
        """
        k = self.output_upsample if self.kind == "cnn" else 1
        _, height, width = self.obs_shape
        if k > 1 and height % k == 0 and width % k == 0:
            low = self._low_resolution(z)
            if low.shape[-2:] == (height // k, width // k):
                if self.pixel_shuffle:
                    return bernoulli_log_likelihood(low, F.pixel_unshuffle(target, k))
                return (k * k) * bernoulli_log_likelihood(low, F.avg_pool2d(target, k))
        return bernoulli_log_likelihood(self(z), target)


class TransitionOutput(NamedTuple):
    """Output of a transition network.

    Attributes:
        mean: Mean of F(z' | z, u), ``(B, n_z)``.
        logvar: Log-variance, ``(B, n_z)``.
        A: ``(B, n_z, n_z)`` matrix (amortized Jacobian or E2C's A), or None.
        B: ``(B, n_z, n_u)`` matrix, or None.
    """

    mean: torch.Tensor
    logvar: torch.Tensor
    A: torch.Tensor | None
    B: torch.Tensor | None


class MLPTransition(nn.Module):
    """Gaussian MLP transition, ``mean = z + g(z, u)``, optional amortized A, B heads."""

    def __init__(self, latent_dim: int, action_dim: int, config: ModelConfig) -> None:
        super().__init__()
        self.nz, self.nu = latent_dim, action_dim
        hidden = config.transition_hidden
        self.backbone = mlp([latent_dim + action_dim, *hidden], activate_last=True)
        width = hidden[-1] if hidden else latent_dim + action_dim
        self.head = nn.Linear(width, 2 * latent_dim)
        self.amortized = config.amortized
        if self.amortized:
            self.jacobian_head = nn.Linear(width, latent_dim * (latent_dim + action_dim))
        self.min_logvar, self.max_logvar = config.min_logvar, config.max_logvar

    def forward(self, z: torch.Tensor, u: torch.Tensor) -> TransitionOutput:
        """Return mean, logvar (and A, B when amortized) of F(z' | z, u)."""
        h = self.backbone(torch.cat([z, u], dim=-1))
        delta, logvar = self.head(h).chunk(2, dim=-1)
        a_mat = b_mat = None
        if self.amortized:
            jac = self.jacobian_head(h).view(-1, self.nz, self.nz + self.nu)
            a_mat, b_mat = jac[..., : self.nz], jac[..., self.nz:]
        return TransitionOutput(z + delta, logvar.clamp(self.min_logvar, self.max_logvar),
                                a_mat, b_mat)

    def mean(self, z: torch.Tensor, u: torch.Tensor) -> torch.Tensor:
        """Mean only (cheaper: skips the Jacobian heads)."""
        delta = self.head(self.backbone(torch.cat([z, u], dim=-1)))[..., : self.nz]
        return z + delta

    def mean_layers(self) -> tuple[list[torch.Tensor], list[torch.Tensor]]:
        """Weights and biases of the mean path ``z + W_L relu(... relu(W_1 [z; u]))``.

        Used to build an analytic-Jacobian planner model
        (:class:`pcc_agent.planning.dynamics.MLPDynamics` with ``residual=True``).
        """
        linears = [m for m in self.backbone if isinstance(m, nn.Linear)]
        weights = [m.weight for m in linears] + [self.head.weight[: self.nz]]
        biases = [m.bias for m in linears] + [self.head.bias[: self.nz]]
        return weights, biases


class E2CTransition(nn.Module):
    """Locally-linear transition of E2C / RCE: ``z' = A(z) z + B(z) u + o(z)``.

    ``A = I + v r^T`` (rank-one perturbation of the identity, so ``det A = 1 + r^T v``); the
    log-variance head gives the transition noise used by RCE (E2C propagates the encoder's
    covariance instead: ``A Sigma A^T``).
    """

    def __init__(self, latent_dim: int, action_dim: int, config: ModelConfig) -> None:
        super().__init__()
        self.nz, self.nu = latent_dim, action_dim
        hidden = config.transition_hidden
        self.backbone = mlp([latent_dim, *hidden], activate_last=True)
        width = hidden[-1] if hidden else latent_dim
        # v, r, o, logvar (n_z each) and B (n_z * n_u)
        self.head = nn.Linear(width, 4 * latent_dim + latent_dim * action_dim)
        self.min_logvar, self.max_logvar = config.min_logvar, config.max_logvar

    def components(
        self, z: torch.Tensor
    ) -> tuple[torch.Tensor, torch.Tensor, torch.Tensor, torch.Tensor, torch.Tensor]:
        """Return ``(v, r, B, o, logvar)`` at ``z``; B is ``(B, n_z, n_u)``."""
        out = self.head(self.backbone(z))
        nz = self.nz
        v, r, o, logvar = out[..., :nz], out[..., nz:2 * nz], out[..., 2 * nz:3 * nz], \
            out[..., 3 * nz:4 * nz]
        b_mat = out[..., 4 * nz:].reshape(*z.shape[:-1], nz, self.nu)
        return v, r, b_mat, o, logvar.clamp(self.min_logvar, self.max_logvar)

    def forward(self, z: torch.Tensor, u: torch.Tensor) -> TransitionOutput:
        """Return mean ``A z + B u + o``, the noise log-variance, A and B."""
        v, r, b_mat, o, logvar = self.components(z)
        # A z = z + v (r . z): no need to build A for the mean.
        mean = z + v * (r * z).sum(-1, keepdim=True) + (b_mat @ u.unsqueeze(-1)).squeeze(-1) + o
        eye = torch.eye(self.nz, dtype=z.dtype, device=z.device)
        a_mat = eye + v.unsqueeze(-1) * r.unsqueeze(-2)
        return TransitionOutput(mean, logvar, a_mat, b_mat)

    def mean(self, z: torch.Tensor, u: torch.Tensor) -> torch.Tensor:
        """Mean ``A z + B u + o`` only."""
        v, r, b_mat, o, _ = self.components(z)
        return z + v * (r * z).sum(-1, keepdim=True) + (b_mat @ u.unsqueeze(-1)).squeeze(-1) + o


class BackwardModel(nn.Module):
    """Q(z_t | z_hat_{t+1}, x_t, u_t) -> (mean, logvar), each ``(B, n_z)``."""

    def __init__(self, obs_shape: tuple[int, int, int], action_dim: int,
                 config: ModelConfig) -> None:
        super().__init__()
        nz = config.latent_dim
        self.z_path = mlp([nz, config.backward_nz], activate_last=True)
        self.u_path = mlp([action_dim, config.backward_nu], activate_last=True)
        self.x_path, _ = _image_backbone(
            obs_shape, "mlp", (), (config.backward_nx,), config.encoder_downsample,
            config.input_standardization,
        )
        self.joint = mlp(
            [config.backward_nz + config.backward_nu + config.backward_nx, config.backward_joint],
            activate_last=True,
        )
        self.head = nn.Linear(config.backward_joint, 2 * nz)
        self.min_logvar, self.max_logvar = config.min_logvar, config.max_logvar

    def forward(self, z_next: torch.Tensor, obs: torch.Tensor,
                u: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor]:
        """Return the mean and log-variance of Q(z_t | z_next, obs, u)."""
        h = torch.cat([self.z_path(z_next), self.u_path(u), self.x_path(obs)], dim=-1)
        mean, logvar = self.head(self.joint(h)).chunk(2, dim=-1)
        return mean, logvar.clamp(self.min_logvar, self.max_logvar)


class Networks(NamedTuple):
    """The four networks of an embedding model."""

    encoder: GaussianEncoder
    decoder: BernoulliDecoder
    transition: MLPTransition | E2CTransition
    backward: BackwardModel


def build_networks(obs_shape: Sequence[int], action_dim: int, config: ModelConfig) -> Networks:
    """Build encoder, decoder, transition and backward model for the given spaces.

    Args:
        obs_shape: Observation shape ``(frames, H, W)``.
        action_dim: Action dimension n_u.
        config: Architecture.

    Returns:
        A :class:`Networks` tuple.

    Raises:
        ValueError: ``obs_shape`` is not ``(frames, H, W)`` or ``action_dim < 1``.
    """
    if len(obs_shape) != 3:
        raise ValueError(
            f"obs_shape must be (frames, H, W), got {tuple(obs_shape)}; add a channel axis for "
            "single-frame images."
        )
    if action_dim < 1:
        raise ValueError(f"action_dim must be >= 1, got {action_dim}.")
    shape = (int(obs_shape[0]), int(obs_shape[1]), int(obs_shape[2]))
    transition_cls = MLPTransition if config.transition_kind == "mlp" else E2CTransition
    return Networks(
        encoder=GaussianEncoder(shape, config),
        decoder=BernoulliDecoder(shape, config),
        transition=transition_cls(config.latent_dim, action_dim, config),
        backward=BackwardModel(shape, action_dim, config),
    )
