"""Typed configuration: the model, training, data and planner settings of an agent.

Plain frozen dataclasses, validated on construction, with no knowledge of any domain: the
per-domain values live in :mod:`pcc_agent.presets` (a data table), and the command-line tools
build or select them. Every other module imports its config types from here
(:mod:`pcc_agent.presets` and :mod:`pcc_agent.planning` re-export them).

* :class:`ModelConfig` (with :class:`ConvSpec`): the networks;
* :class:`TrainConfig`: the optimization and loss weights;
* :class:`DataConfig`: the training data set;
* :class:`PlannerConfig`: latent iLQR and MPC;
* :class:`EnvPreset`: the four together, for one environment;
* :class:`DomainPresets`: one row of the presets table (both variants of one domain).
"""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass, field
from typing import Any, Literal

__all__ = [
    "ConvSpec",
    "DataConfig",
    "DomainPresets",
    "EnvPreset",
    "ModelConfig",
    "EncoderKind",
    "NetworkKind",
    "PlannerConfig",
    "TrainConfig",
    "TransitionKind",
]

NetworkKind = Literal["mlp", "cnn"]
EncoderKind = Literal["mlp", "cnn", "keypoints", "frame_cnn"]
TransitionKind = Literal["mlp", "e2c_linear"]


@dataclass(frozen=True)
class ConvSpec:
    """One convolutional layer (always followed by a ReLU, padding keeps 'same' size at stride 1).

    Attributes:
        channels: Output channels.
        kernel_size: Square kernel size.
        stride: Stride (the padding is ``kernel_size // 2``).
    """

    channels: int
    kernel_size: int = 5
    stride: int = 1


@dataclass(frozen=True)
class ModelConfig:
    """Architecture of the encoder, decoder, latent transition and backward model.

    Attributes:
        latent_dim: Dimension n_z of the latent space.
        encoder_kind: ``"mlp"`` (flattened image -> hidden layers), ``"cnn"``, or
            ``"keypoints"``: the convolutions run on each frame alone (shared weights), the
            last one's channels are heatmaps whose spatial soft-argmax gives one (x, y)
            keypoint per channel, and the hidden layers see the newest frame's keypoints and
            their motion between frames. Sub-pixel motions, the velocity signal of a frame
            pair, become differences of coordinates (a spatial softmax as in Levine et al.,
            2016; not the paper's encoder). ``"frame_cnn"``: the convolutions run on each
            frame alone, a linear layer makes ``encoder_frame_features`` features of each
            frame, and the hidden layers see the newest frame's and their change between
            frames (also not the paper's).
        encoder_convs: CNN encoder convolutions (ignored for ``"mlp"``); for ``"keypoints"``
            the last one has no ReLU and its channels are the keypoints.
        encoder_hidden: Hidden fully-connected layers (after the convolutions for ``"cnn"``);
            a final linear layer outputs the mean and log-variance (``2 * latent_dim``).
        encoder_downsample: Average-pooling factor applied to the image inside the encoder and
            the backward model's image path before anything else (1 = full resolution).
        decoder_kind: ``"mlp"`` (hidden layers -> one logit per pixel) or ``"cnn"``.
        decoder_hidden: Hidden fully-connected layers. For ``"cnn"`` a further linear layer maps
            to a ``decoder_grid_channels`` x h0 x w0 grid, where h0, w0 are the output size
            divided by ``2 ** (len(decoder_convs) - 1) * decoder_output_upsample`` (rounded up).
        decoder_grid_channels: Channels of that grid (CNN decoder only).
        decoder_convs: CNN decoder convolutions; a 2x nearest upsampling follows every one but
            the last, whose channels must equal the number of observation frames.
        decoder_output_upsample: Final upsampling factor k of the logits (1 = none); the
            logits are cropped to the observation size.
        decoder_pixel_shuffle: How the last k x upsampling is done. False: nearest
            upsampling, so every k x k block of pixels shares one logit (the likelihood is
            exact and cheap at low resolution, but blind to shifts smaller than a block).
            True: the last convolution outputs ``frames * k * k`` channels, rearranged by a
            pixel shuffle into one logit per full-resolution pixel, at little extra cost; the
            likelihood then sees one-pixel motions, the velocity signal of a frame pair.
        transition_kind: ``"mlp"``: Gaussian MLP with a skip connection (PCC, mean = z + MLP);
            ``"e2c_linear"``: locally-linear ``z' = A(z) z + B(z) u + o(z)``, A = I + v r^T
            (E2C and RCE).
        transition_hidden: Hidden layers of the transition network.
        amortized: Whether the MLP transition also outputs A (n_z x n_z) and B (n_z x n_u)
            heads for the amortized curvature loss.
        backward_nz: Width N_z of the backward model's z_hat_{t+1} path.
        backward_nu: Width N_u of its action path.
        backward_nx: Width N_x of its observation path.
        backward_joint: Width N_joint of the joint layer.
        input_standardization: Standardize the encoder's and backward model's image input
            per pixel with statistics of the training images (a fixed preprocessing layer,
            no learned parameters; not in the paper, see ``docs/training.md``).
        encoder_frame_features: Features per frame of the ``"frame_cnn"`` encoder.
        encoder_motion_gain: With a value g > 0, the encoder sees each older frame as
            ``g * (newest - older)`` beside the newest frame instead of the raw frames: the
            same information, with the frame-to-frame change (the velocity signal, a small
            grey-level difference at 20 ms) magnified from the first step. 0: raw frames (the
            paper). The backward model's image input is unchanged.
        decoder_bias_init: Before training, set the decoder's output biases to the logits of
            the training images' mean pixel values, so that the decoder starts from the mean
            image (the static background) and the first gradient steps go to the moving
            parts; an initialization only, not in the paper. Measured on Planar: it does not
            shorten the collapsed plateau (``docs/training.md``).
        min_logvar: Lower clamp of every predicted log-variance (numerical safety).
        max_logvar: Upper clamp of every predicted log-variance.
    """

    latent_dim: int
    encoder_kind: EncoderKind = "mlp"
    encoder_convs: tuple[ConvSpec, ...] = ()
    encoder_hidden: tuple[int, ...] = (300, 300)
    encoder_downsample: int = 1
    decoder_kind: NetworkKind = "mlp"
    decoder_hidden: tuple[int, ...] = (300, 300)
    decoder_grid_channels: int = 10
    decoder_convs: tuple[ConvSpec, ...] = ()
    decoder_output_upsample: int = 1
    decoder_pixel_shuffle: bool = False
    transition_kind: TransitionKind = "mlp"
    transition_hidden: tuple[int, ...] = (20, 20)
    amortized: bool = False
    backward_nz: int = 5
    backward_nu: int = 5
    backward_nx: int = 100
    backward_joint: int = 100
    input_standardization: bool = False
    encoder_motion_gain: float = 0.0
    encoder_frame_features: int = 32
    decoder_bias_init: bool = False
    min_logvar: float = -12.0
    max_logvar: float = 8.0

    def __post_init__(self) -> None:
        """Validate the values, with messages that say how to fix them."""
        if self.latent_dim < 1:
            raise ValueError(f"latent_dim must be >= 1, got {self.latent_dim}.")
        if self.encoder_kind not in ("mlp", "cnn", "keypoints", "frame_cnn"):
            raise ValueError(f"encoder_kind must be 'mlp', 'cnn', 'keypoints' or 'frame_cnn', "
                             f"got {self.encoder_kind!r}.")
        if self.decoder_kind not in ("mlp", "cnn"):
            raise ValueError(f"decoder_kind must be 'mlp' or 'cnn', got {self.decoder_kind!r}.")
        if self.transition_kind not in ("mlp", "e2c_linear"):
            raise ValueError(
                f"transition_kind must be 'mlp' or 'e2c_linear', got {self.transition_kind!r}."
            )
        if self.encoder_kind != "mlp" and not self.encoder_convs:
            raise ValueError(f"encoder_kind={self.encoder_kind!r} needs at least one ConvSpec "
                             f"in encoder_convs.")
        if self.decoder_kind == "cnn" and not self.decoder_convs:
            raise ValueError("decoder_kind='cnn' needs at least one ConvSpec in decoder_convs.")
        if self.encoder_downsample < 1 or self.decoder_output_upsample < 1:
            raise ValueError("encoder_downsample and decoder_output_upsample must be >= 1.")
        if self.decoder_pixel_shuffle and (
            self.decoder_kind != "cnn" or self.decoder_output_upsample < 2
        ):
            raise ValueError(
                "decoder_pixel_shuffle needs decoder_kind='cnn' and decoder_output_upsample >= 2."
            )
        if not self.encoder_motion_gain >= 0.0:
            raise ValueError(f"encoder_motion_gain must be >= 0, got {self.encoder_motion_gain}.")
        if self.encoder_motion_gain and self.encoder_kind in ("keypoints", "frame_cnn"):
            raise ValueError(f"encoder_kind={self.encoder_kind!r} takes each frame's motion "
                             f"itself; leave encoder_motion_gain at 0.")
        if self.encoder_frame_features < 1:
            raise ValueError(f"encoder_frame_features must be >= 1, got "
                             f"{self.encoder_frame_features}.")
        if self.amortized and self.transition_kind != "mlp":
            raise ValueError("amortized A/B heads only apply to transition_kind='mlp'.")

    def to_dict(self) -> dict[str, Any]:
        """Return a JSON-serializable dict (inverse of :meth:`from_dict`)."""
        return dataclasses.asdict(self)

    @classmethod
    def from_dict(cls, data: dict[str, Any]) -> ModelConfig:
        """Build a config from :meth:`to_dict` output (lists become tuples, convs ConvSpec)."""
        known = {f.name for f in dataclasses.fields(cls)}
        unknown = set(data) - known
        if unknown:
            raise ValueError(
                f"Unknown ModelConfig fields {sorted(unknown)}; known: {sorted(known)}."
            )
        values = dict(data)
        for key in ("encoder_convs", "decoder_convs"):
            if key in values:
                values[key] = tuple(
                    c if isinstance(c, ConvSpec) else ConvSpec(**c) for c in values[key]
                )
        for key in ("encoder_hidden", "decoder_hidden", "transition_hidden"):
            if key in values:
                values[key] = tuple(int(v) for v in values[key])
        return cls(**values)


MIXED_PRECISION_MODES = ("off", "bf16", "auto")  #: values of TrainConfig.mixed_precision


def check_mixed_precision(mode: str) -> None:
    """Raise ``ValueError`` unless ``mode`` is one of :data:`MIXED_PRECISION_MODES`."""
    if mode not in MIXED_PRECISION_MODES:
        raise ValueError(f"mixed_precision must be one of {MIXED_PRECISION_MODES}, got {mode!r}.")


@dataclass(frozen=True)
class TrainConfig:
    """Optimization and loss hyper-parameters (paper Appendix "Training Hyper-Parameters").

    Attributes:
        lr: Adam learning rate.
        betas: Adam betas.
        eps: Adam epsilon.
        weight_decay: L2 regularization coefficient (Adam's ``weight_decay``).
        batch_size: Mini-batch size.
        epochs: Maximum number of epochs.
        validation_fraction: Fraction of the data held out for validation / early stopping.
        seed: Seed of the shuffling, initialization-independent noise and validation split.
        lambda_p: Weight of the prediction bound R'_3.
        lambda_c: Weight of the consistency bound R''_2.
        lambda_cur: Weight of the curvature loss R_LLC.
        curvature_delta: Standard deviation delta of the curvature perturbations.
        curvature_expansion: Point of the Taylor expansion in the curvature loss:
            ``"perturbed"`` (``(z + eps_z, u + eps_u)``, the paper's practical variant,
            Section 4.2) or ``"nominal"`` (``(z, u)``, the Section 3 definition).
        vae_coef: Weight of the auxiliary VAE loss (all methods).
        deterministic_ce_coef: Weight of the deterministic cross-entropy term (PCC).
        e2c_lambda: Weight lambda of the E2C transition KL.
        patience: Epochs without validation improvement before early stopping (0 disables).
        min_epochs: Early stopping never triggers before this many epochs. A small-object
            domain such as Planar sits on a flat plateau (a collapsed latent space) for its
            first ~100 epochs and only then improves; stopping on that plateau leaves a
            useless model (see ``docs/training.md``).
        min_delta: Improvement smaller than this does not reset the patience counter.
        grad_clip_norm: Optional gradient-norm clip (None = no clipping, as in the paper).
        divergence_factor: Training stops when a loss exceeds this factor times the best loss.
        warmup_epochs: Epochs over which the latent-regularization terms (KL divergences,
            entropy and transition likelihood of every method, PCC's consistency) are scaled
            linearly from 0 to 1 (beta-annealing against posterior collapse, the failure
            that leaves short trainings with a collapsed latent space); 0 disables it.
        kl_scale: Current scale of those terms (set per epoch by the trainer during warm-up;
            1.0 is the paper's objective).
        flush_denormals: Train with the CPU's flush-to-zero and denormals-are-zero modes on
            (:func:`torch.set_flush_denormal`). Weight decay drives the weights of pixels that
            are never lit (most of a Pendulum frame) into the subnormal range, where Intel
            CPUs run matrix products many times slower (16x measured for Pendulum's first
            layer). On by default since version 0.3 (the weights' bits differ from a run
            without it: values below 1.18e-38 become zero); configs saved before the field
            existed read as off, as they were trained. The benchmark grids keep it off unless
            asked (``--flush-denormals``), so their committed rows keep their recipe. It
            applies to the training thread (the grid runs one torch thread per worker).
        mixed_precision: ``"off"`` (float32 throughout, the default), ``"bf16"`` (the
            losses' forward pass under ``torch.autocast`` with bfloat16: matrix products and
            convolutions in bfloat16, reductions and the weights in float32) or ``"auto"``
            (bfloat16 only where the hardware multiplies it natively: a CPU with AMX or
            AVX512-BF16, or a CUDA GPU that supports it; float32 elsewhere). On a 2-core Intel
            Xeon with AMX it makes a Pendulum-size MLP step 1.6x faster; a CPU without native
            bfloat16 emulates it, slower than float32, so ``"bf16"`` warns there. A named
            variant of the training, not the paper's float32 recipe.
        prediction_horizon: ``K``. Above 1, the loss gains ``multistep_coef`` times the
            multi-step prediction term
            ``sum_{k=2..K} -log D(x_{t+k} | f(...f(f(mu(x_t), u_t), u_{t+1})..., u_{t+k-1}))``
            (:func:`pcc_agent.losses.multistep_prediction`), on data that hold ``K``
            consecutive transitions per sample (``pcc_envs.data.collect_transitions(...,
            prediction_horizon=K)``). Why: a rate that moves the picture by under a pixel
            per step (CartPole-v1's cart, the arms' outer joints) changes a one-step
            prediction too little for the code to keep it, and its effect grows with ``k``.
            A named variant of the objective, not the paper's (1).
        multistep_coef: Weight of each extra step of that term.
    """

    lr: float = 5e-4
    betas: tuple[float, float] = (0.9, 0.999)
    eps: float = 1e-8
    weight_decay: float = 1e-3
    batch_size: int = 128
    epochs: int = 500
    validation_fraction: float = 0.1
    seed: int = 0
    lambda_p: float = 1.0
    lambda_c: float = 7.0
    lambda_cur: float = 1.0
    curvature_delta: float = 0.1
    curvature_expansion: Literal["perturbed", "nominal"] = "perturbed"
    vae_coef: float = 0.01
    deterministic_ce_coef: float = 0.3
    e2c_lambda: float = 0.25
    patience: int = 30
    min_epochs: int = 0
    min_delta: float = 0.0
    grad_clip_norm: float | None = None
    divergence_factor: float = 1e3
    warmup_epochs: int = 0
    kl_scale: float = 1.0
    flush_denormals: bool = True
    mixed_precision: Literal["off", "bf16", "auto"] = "off"
    prediction_horizon: int = 1
    multistep_coef: float = 1.0

    def __post_init__(self) -> None:
        """Validate the values, with messages that say how to fix them."""
        if self.batch_size < 1 or self.epochs < 1:
            raise ValueError("batch_size and epochs must be >= 1.")
        if isinstance(self.prediction_horizon, bool) or not isinstance(
                self.prediction_horizon, int) or self.prediction_horizon < 1:
            raise ValueError(f"prediction_horizon must be an integer >= 1, got "
                             f"{self.prediction_horizon!r}.")
        if not self.multistep_coef >= 0:
            raise ValueError(f"multistep_coef must be >= 0, got {self.multistep_coef}.")
        if self.min_epochs < 0 or self.patience < 0:
            raise ValueError(
                f"min_epochs and patience must be >= 0, got {self.min_epochs} and "
                f"{self.patience}."
            )
        if not 0.0 <= self.validation_fraction < 1.0:
            raise ValueError(
                f"validation_fraction must be in [0, 1), got {self.validation_fraction}."
            )
        if self.curvature_delta <= 0:
            raise ValueError(f"curvature_delta must be > 0, got {self.curvature_delta}.")
        if self.curvature_expansion not in ("perturbed", "nominal"):
            raise ValueError(
                "curvature_expansion must be 'perturbed' or 'nominal', got "
                f"{self.curvature_expansion!r}."
            )
        check_mixed_precision(self.mixed_precision)

    def to_dict(self) -> dict[str, Any]:
        """Return a JSON-serializable dict."""
        return dataclasses.asdict(self)

    @classmethod
    def from_dict(cls, data: dict[str, Any]) -> TrainConfig:
        """Inverse of :meth:`to_dict`.

        A config saved before ``flush_denormals`` existed (every run before version 0.3)
        trained with it off and reads so.
        """
        values = dict(data)
        values.setdefault("flush_denormals", False)
        if "betas" in values:
            values["betas"] = tuple(values["betas"])
        return cls(**values)


@dataclass(frozen=True)
class DataConfig:
    """Size and noise of the training data set (paper Appendix "Data Collection Process").

    Attributes:
        num_samples: Number of (x_t, u_t, x_{t+1}) triples.
        noise_std: Standard deviation sigma of the Gaussian noise added to the next state.
            The data are sampled from the agent's env, so ``PCCAgent`` sets this to the env's
            process noise (``env_kwargs={"noise_std": ...}``); 0 here means "the env's", and
            another value that disagrees with the env is an error.
    """

    num_samples: int
    noise_std: float = 0.0


@dataclass(frozen=True)
class PlannerConfig:
    """Settings of the latent iLQR solver and of receding-horizon (MPC) planning.

    The cost is ``sum_t (z_t - g)^T Q (z_t - g) + u_t^T R u_t + (z_T - g)^T Q_T (z_T - g)``
    with ``Q = kappa * I``, ``R = r_weight * I`` and ``Q_T = terminal_weight * kappa * I``.

    Attributes:
        plan_length: Planning horizon T (number of actions in a plan).
        kappa: State cost weight: ``Q = kappa * I``.
        r_weight: Action cost weight: ``R = r_weight * I``.
        terminal_weight: Multiplier of ``Q`` for the terminal cost: ``Q_T = terminal_weight * Q``.
        iterations: iLQR iterations for a plan computed from scratch (first MPC step).
        mpc_iterations: iLQR iterations per MPC step after a warm start.
        replan_every: Actions executed from one plan before the MPC plans again (1: replan
            at every step). Between replans the carried plan's next action is applied open
            loop; a longer horizon costs less per step when it is replanned less often.
        num_candidates: Initial plans optimized together as a batch when planning from scratch;
            the first ``num_extreme`` are extreme plans and the rest are uniform random in the
            action box (when ``num_candidates <= num_extreme``, all are uniform). The plan with
            the lowest final cost is kept.
        num_extreme: How many of the candidates are extreme plans: the constant plans at
            ``action_low`` and at ``action_high``, then random bang-bang plans (every action
            component drawn from ``{action_low, action_high}``).
        line_search_steps: Step sizes alpha tried, all in one batched rollout, by the forward
            pass; the best one that decreases the cost is accepted.
        mu_init: Initial Levenberg-Marquardt regularization added to ``Q_uu``.
        mu_min: Lower bound of the regularization (below it, mu is set to 0).
        mu_max: Upper bound of the regularization; a problem whose mu would exceed it stops
            with status ``no_improvement``.
        mu_factor: Multiplicative increase (on failure) and decrease (on success) of mu.
        action_low: Lower bound of every action dimension. ``PCCAgent`` plans in actions
            scaled to ``[-1, 1]`` by the env's ``Box`` (-1 is the env's low, 1 its high), so
            the default -1 is the env's own lower bound, whatever its units.
        action_high: Upper bound of every action dimension (default 1: the env's high).
        tolerance: Convergence threshold on the relative cost decrease of an accepted step.
    """

    plan_length: int = 10
    kappa: float = 1.0
    r_weight: float = 1.0
    terminal_weight: float = 1.0
    iterations: int = 4
    mpc_iterations: int = 2
    replan_every: int = 1
    num_candidates: int = 6
    num_extreme: int = 2
    line_search_steps: tuple[float, ...] = (1.0, 0.5, 0.25, 0.1, 0.03)
    mu_init: float = 1e-6
    mu_min: float = 1e-6
    mu_max: float = 1e10
    mu_factor: float = 10.0
    action_low: float = -1.0
    action_high: float = 1.0
    tolerance: float = 1e-6

    def __post_init__(self) -> None:
        """Validate the values, with messages that say how to fix them."""
        if self.plan_length < 1:
            raise ValueError(f"plan_length must be >= 1, got {self.plan_length}.")
        if self.iterations < 1 or self.mpc_iterations < 1:
            raise ValueError(
                "iterations and mpc_iterations must be >= 1, got "
                f"{self.iterations} and {self.mpc_iterations}."
            )
        if self.num_candidates < 1:
            raise ValueError(f"num_candidates must be >= 1, got {self.num_candidates}.")
        if self.num_extreme < 0:
            raise ValueError(f"num_extreme must be >= 0, got {self.num_extreme}.")
        if not 1 <= self.replan_every <= self.plan_length:
            raise ValueError(
                f"replan_every must be between 1 and plan_length ({self.plan_length}), got "
                f"{self.replan_every}: a plan cannot be executed for longer than it lasts."
            )
        if not self.line_search_steps or any(a <= 0 for a in self.line_search_steps):
            raise ValueError(
                f"line_search_steps must be non-empty and positive, got {self.line_search_steps}."
            )
        if not self.action_low < self.action_high:
            raise ValueError(
                f"action_low ({self.action_low}) must be below action_high ({self.action_high})."
            )
        if self.kappa < 0 or self.r_weight < 0 or self.terminal_weight < 0:
            raise ValueError("kappa, r_weight and terminal_weight must be non-negative.")
        if self.mu_factor <= 1.0:
            raise ValueError(f"mu_factor must be > 1, got {self.mu_factor}.")


@dataclass(frozen=True)
class EnvPreset:
    """Everything needed to learn and control one environment.

    Attributes:
        env_id: Gymnasium id.
        model: Architecture.
        train: Training hyper-parameters.
        data: Data set size.
        planner: Latent iLQR / MPC settings (tuned by the benchmark; values here are defaults).
    """

    env_id: str
    model: ModelConfig
    train: TrainConfig
    data: DataConfig
    planner: PlannerConfig = field(default_factory=PlannerConfig)

    @classmethod
    def from_dict(cls, data: dict[str, Any]) -> EnvPreset:
        """The preset of a saved agent's config (JSON lists become tuples).

        Reads the keys ``env_id``, ``model``, ``train``, ``data`` and ``planner``.

        Raises:
            KeyError, TypeError, ValueError: A missing key, an unknown field or a bad value.
        """
        planner = {k: tuple(v) if isinstance(v, list) else v for k, v in data["planner"].items()}
        return cls(
            env_id=data["env_id"],
            model=ModelConfig.from_dict(data["model"]),
            train=TrainConfig.from_dict(data["train"]),
            data=DataConfig(**data["data"]),
            planner=PlannerConfig(**planner),
        )

    def with_training(self, **changes: Any) -> EnvPreset:
        """A copy with some training settings changed.

        Example:
            >>> from pcc_agent.presets import get_preset
            >>> quick = get_preset("pcc/Planar-v0", "fast").with_training(lr=1.5e-3, epochs=250)
            >>> quick.train.lr, quick.train.epochs
            (0.0015, 250)

        Raises:
            TypeError: A name that is not a :class:`TrainConfig` field.
            ValueError: A value :class:`TrainConfig` refuses.
        """
        return dataclasses.replace(self, train=dataclasses.replace(self.train, **changes))


@dataclass(frozen=True)
class DomainPresets:
    """One row of the presets table: everything about one domain, all its variants.

    The ``"paper"`` variant is ``(model, train)``, the ``"fast"`` variant
    ``(fast_model, fast_train)``, the ``"motion"`` variant (CNN domains)
    ``(motion_model, fast_train)``; all share the data size and the planner.

    Attributes:
        obs_shape: Observation shape ``(frames, H, W)`` of the registered env.
        action_dim: Action dimension of the registered env.
        num_samples: Training data set size (paper Appendix "Data Collection Process").
        model: The paper's architecture.
        fast_model: The ``"fast"`` variant's architecture.
        train: The paper's training recipe.
        fast_train: The ``"fast"`` variant's training recipe.
        planner: Latent iLQR / MPC settings (every variant).
        motion_model: The ``"motion"`` variant's architecture (trained with ``fast_train``),
            on the CNN domains only: a CNN that sees each frame's motion.
    """

    obs_shape: tuple[int, int, int]
    action_dim: int
    num_samples: int
    model: ModelConfig
    fast_model: ModelConfig
    train: TrainConfig
    fast_train: TrainConfig
    planner: PlannerConfig
    motion_model: ModelConfig | None = None

    def variants(self, env_id: str) -> dict[str, EnvPreset]:
        """The row's presets by variant name.

        ``"paper"``, ``"fast"`` and, where the row has a ``motion_model``, ``"motion"``.
        """
        data = DataConfig(num_samples=self.num_samples)
        found = {
            "paper": EnvPreset(env_id, self.model, self.train, data, self.planner),
            "fast": EnvPreset(env_id, self.fast_model, self.fast_train, data, self.planner),
        }
        if self.motion_model is not None:
            found["motion"] = EnvPreset(env_id, self.motion_model, self.fast_train, data,
                                        self.planner)
        return found
