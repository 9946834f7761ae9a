"""Training loop of the embedding model: optimizer, validation, early stopping, checkpoints.

Data are numpy arrays (uint8 observations ``(N, F, H, W)``, float32 actions ``(N, n_u)``,
uint8 next observations); :func:`dataset_arrays` also accepts a ``pcc_envs.data``
``TransitionDataset`` (anything with ``obs``, ``action`` and ``next_obs`` attributes).

Determinism: the validation split, the shuffling and every sampled noise come from
``torch.Generator`` objects seeded from ``seed``; nothing touches the global RNGs. On CPU two
runs with the same seed, initial weights and thread count produce bitwise-identical weights.
"""

from __future__ import annotations

import contextlib
import copy
import dataclasses
import functools
import json
import math
import time
import warnings
from collections.abc import Callable, Iterator, Mapping
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np
import torch

from pcc_agent.checkpoint import (
    CheckpointError,
    load_checkpoint,
    load_weights,
    save_checkpoint,
)
from pcc_agent.config import TrainConfig, check_mixed_precision
from pcc_agent.io import atomic_write_text, sb3_logger
from pcc_agent.losses import METHODS, TransitionBatch, get_loss
from pcc_agent.model import EmbeddingModel


@dataclass(frozen=True)
class TransitionArrays:
    """Validated transition arrays.

    Attributes:
        obs: uint8 ``(N, F, H, W)``.
        action: float32 ``(N, n_u)``.
        next_obs: uint8 ``(N, F, H, W)``.
        future_action: float32 ``(N, K - 1, n_u)`` actions ``u_{t+1} .. u_{t+K-1}``, or None
            (one-step data).
        future_obs: uint8 ``(N, K - 1, F, H, W)`` observations ``x_{t+2} .. x_{t+K}``, or None.
    """

    obs: np.ndarray
    action: np.ndarray
    next_obs: np.ndarray
    future_action: np.ndarray | None = None
    future_obs: np.ndarray | None = None

    def __len__(self) -> int:
        return int(self.obs.shape[0])

    @property
    def prediction_horizon(self) -> int:
        """``K``: the consecutive transitions each sample holds (1 for one-step data)."""
        return 1 if self.future_action is None else 1 + int(self.future_action.shape[1])


def dataset_arrays(data: Any) -> TransitionArrays:
    """Convert transitions to :class:`TransitionArrays`.

    Args:
        data: A ``pcc_envs.data.TransitionDataset`` (or any object with ``obs``, ``action``,
            ``next_obs`` attributes, and optionally ``future_action`` and ``future_obs``), a
            mapping with those keys, or a tuple ``(obs, action, next_obs)``.

    Returns:
        The validated arrays (observations uint8, actions float32).

    Raises:
        ValueError: Missing fields, inconsistent lengths or shapes.
    """
    if isinstance(data, TransitionArrays):
        return data
    names = ("obs", "action", "next_obs", "future_action", "future_obs")
    if isinstance(data, Mapping):
        fields = tuple(data.get(name) for name in names)
    elif isinstance(data, tuple | list) and len(data) == 3:
        fields = (*data, None, None)
    else:
        fields = tuple(getattr(data, name, None) for name in names)
    if any(f is None for f in fields[:3]):
        raise ValueError(
            "Expected transitions with obs, action and next_obs (a TransitionDataset, a dict or "
            f"an (obs, action, next_obs) tuple), got {type(data).__name__}."
        )
    obs, action, next_obs = (np.asarray(f) for f in fields[:3])
    if obs.ndim != 4 or obs.shape != next_obs.shape:
        raise ValueError(
            f"obs and next_obs must both be (N, frames, H, W), got {obs.shape} and "
            f"{next_obs.shape}."
        )
    if obs.dtype != np.uint8 or next_obs.dtype != np.uint8:
        raise ValueError(
            f"Observations must be uint8 in [0, 255], got {obs.dtype} / {next_obs.dtype}."
        )
    if action.ndim == 1:
        action = action[:, None]
    if action.ndim != 2 or action.shape[0] != obs.shape[0]:
        raise ValueError(f"action must be (N, n_u) with N={obs.shape[0]}, got {action.shape}.")
    future_action, future_obs = fields[3:]
    if (future_action is None) != (future_obs is None):
        raise ValueError("future_action and future_obs come together (both or neither).")
    if future_action is not None:
        future_action, future_obs = np.asarray(future_action), np.asarray(future_obs)
        if (future_action.shape[:1] + future_action.shape[2:] != action.shape
                or future_obs.shape != (len(obs), future_action.shape[1], *obs.shape[1:])
                or future_obs.dtype != np.uint8):
            raise ValueError(
                f"future_action must be (N, K - 1, n_u) and future_obs uint8 (N, K - 1, frames, "
                f"H, W) for obs {obs.shape} and action {action.shape}; got "
                f"{future_action.shape} and {future_obs.shape} ({future_obs.dtype}).")
        future_action = future_action.astype(np.float32, copy=False)
    return TransitionArrays(obs, action.astype(np.float32, copy=False), next_obs,
                            future_action, future_obs)


def resolve_device(device: torch.device | str = "auto") -> torch.device:
    """``"auto"`` -> CUDA when available, else CPU; other values are passed to torch.device."""
    if isinstance(device, torch.device):
        return device
    if device == "auto":
        return torch.device("cuda" if torch.cuda.is_available() else "cpu")
    return torch.device(device)


@dataclass
class TrainResult:
    """Outcome of :func:`train_embedding`.

    Attributes:
        history: One dict per epoch: ``epoch``, ``train/<term>`` means, ``val/loss``, ``time``.
        best_validation_loss: Lowest validation loss (training loss without a validation split).
        best_epoch: Epoch (1-based) of that loss; its weights are in the model on return.
        epochs: Epochs run in total (including resumed ones).
        wall_time: Seconds spent in this call (a resumed run's earlier sittings excluded).
        converged: Early stopping triggered (no improvement for ``patience`` epochs).
        diverged: Training stopped on a non-finite or exploding loss.
        message: Human-readable reason of the stop, one line (the line the progress bar
            prints when training ends), e.g. ``"stopped at epoch 212 of 250: no validation
            improvement for 100 epochs (best 171.3 at epoch 112); restored the best
            weights"``.
        stop_reason: Why training ended, one of :data:`STOP_REASONS`: ``"epoch_cap"``,
            ``"early_stopping"``, ``"diverged"`` or ``"callback"`` (the epoch callback
            returned False: a time budget, an SB3 callback). An interrupted training (Ctrl-C)
            returns no result; its bar prints ``"interrupted"`` as the reason.
    """

    history: list[dict[str, float]] = field(default_factory=list)
    best_validation_loss: float = math.inf
    best_epoch: int = 0
    epochs: int = 0
    wall_time: float = 0.0
    converged: bool = False
    diverged: bool = False
    message: str = ""
    stop_reason: str = ""

    def seconds_per_epoch(self) -> float | None:
        """Mean wall-clock seconds of one epoch, over every epoch of every sitting.

        Taken from the per-epoch times in ``history``, which a resumed run restores, so that
        a run resumed near its end does not report its last sitting's time spread over all
        epochs. Falls back to ``wall_time / epochs`` for a history without times.
        """
        times = [row["time/epoch_seconds"] for row in self.history
                 if "time/epoch_seconds" in row]
        if times:
            return float(sum(times) / len(times))
        return self.wall_time / self.epochs if self.epochs else None

    def summary(self) -> dict[str, Any]:
        """JSON-serializable outcome without the per-epoch history (last epoch's terms kept).

        Returns:
            ``epochs, best_epoch, best_validation_loss, wall_time, seconds_per_epoch,
            converged, diverged, stop_reason, message, final`` (the last history row).
        """
        return {
            "epochs": self.epochs,
            "best_epoch": self.best_epoch,
            "best_validation_loss": (self.best_validation_loss
                                     if math.isfinite(self.best_validation_loss) else None),
            "wall_time": self.wall_time,
            "seconds_per_epoch": self.seconds_per_epoch(),
            "converged": self.converged,
            "diverged": self.diverged,
            "stop_reason": self.stop_reason,
            "message": self.message,
            "final": dict(self.history[-1]) if self.history else {},
        }


def _make_adam(model: torch.nn.Module, config: TrainConfig) -> torch.optim.Adam:
    """Adam with coupled L2 weight decay; the fused kernel when this torch build has one."""
    try:
        return torch.optim.Adam(model.parameters(), lr=config.lr, betas=config.betas,
                                eps=config.eps, weight_decay=config.weight_decay, fused=True)
    except (RuntimeError, TypeError):  # fused Adam unsupported for this device / version
        return torch.optim.Adam(model.parameters(), lr=config.lr, betas=config.betas,
                                eps=config.eps, weight_decay=config.weight_decay)


EpochCallback = Callable[[int, dict[str, float]], bool | None]

#: Why a training ended (:attr:`TrainResult.stop_reason`); ``"interrupted"`` (Ctrl-C) is only
#: printed, an interrupted training returns no result.
STOP_REASONS = ("epoch_cap", "early_stopping", "diverged", "callback", "interrupted")


def stop_line(reason: str, epochs: int, cap: int, best_loss: float, best_epoch: int,
              detail: str = "") -> str:
    """The one line that says why a training ended.

    E.g. ``"stopped at epoch 212 of 250: no validation improvement for 100 epochs (best 171.3
    at epoch 112); restored the best weights"``.

    Args:
        reason: One of :data:`STOP_REASONS`.
        epochs: Epochs run (resumed ones included).
        cap: The epoch cap (``TrainConfig.epochs``).
        best_loss: Best validation loss (inf: no epoch finished).
        best_epoch: Its epoch (0: none).
        detail: The cause, for ``"early_stopping"`` (the patience) and ``"diverged"``.
    """
    best = (f"best {best_loss:.4g} at epoch {best_epoch}" if best_epoch > 0
            and math.isfinite(best_loss) else "no finished epoch")
    if reason == "interrupted":
        return f"interrupted at epoch {epochs} of {cap} ({best}); nothing returned"
    cause = {
        "epoch_cap": "reached the epoch cap",
        "early_stopping": f"no validation improvement for {detail} epochs",
        "diverged": f"training diverged in epoch {epochs + 1} ({detail})",
        "callback": "the epoch callback asked to stop (a time budget, an SB3 callback)",
    }[reason]
    if reason == "diverged":
        weights = "restored the weights of the best epoch" if best_epoch > 0 else (
            "kept the initial weights")
    elif best_epoch == epochs:
        weights = "the last epoch is the best"
    elif best_epoch > 0:
        weights = "restored the best weights"
    else:
        weights = "no epoch finished"
    return f"stopped at epoch {epochs} of {cap}: {cause} ({best}); {weights}"


class TrainingDivergedError(RuntimeError):
    """Raised internally when the loss becomes non-finite or explodes."""


class Trainer:
    """Fits an :class:`EmbeddingModel` with one of the :data:`pcc_agent.losses.METHODS`.

    Args:
        model: The model (its ``ModelConfig`` must suit the method, see
            :func:`pcc_agent.losses.model_config_for_method`).
        config: Optimization and loss hyper-parameters.
        method: Registry name, e.g. ``"pcc"``.
        device: ``"auto"``, ``"cpu"``, ``"cuda"``, or a ``torch.device``.
        progress_bar: Show a tqdm bar over whole epochs (total: the epoch cap; the remaining
            time is tqdm's, from the epoch times so far) whose postfix holds the last epoch's
            training and validation losses and the best validation loss with its epoch
            (``best=171.3@112``); when training ends (also on Ctrl-C), one line under it says
            why (:attr:`TrainResult.message`).
        log_dir: Directory of the Stable-Baselines3 logger (stdout, csv, tensorboard when
            installed); None disables logging.
        checkpoint_path: File written atomically every ``checkpoint_every`` epochs (current
            weights plus the optimizer and RNG state; at the end the best weights, with the
            last epoch's weights kept for resuming, so that a resumed run continues exactly
            where an uninterrupted one would be). A JSON copy of
            the configuration is written beside it (same name, ``.json`` suffix).
        run_info: Extra JSON-serializable information stored in the checkpoint config.
        checkpoint_every: Epochs between resumable checkpoints (the final one is always
            written).
        epoch_callback: Called after every epoch as ``epoch_callback(epoch, metrics)`` with
            the epoch's mean training terms (``loss``, ``prediction``, ...) plus ``val_loss``
            and ``epoch_seconds``; returning ``False`` stops training.
    """

    def __init__(
        self,
        model: EmbeddingModel,
        config: TrainConfig,
        method: str = "pcc",
        device: torch.device | str = "auto",
        progress_bar: bool = True,
        log_dir: str | Path | None = None,
        checkpoint_path: str | Path | None = None,
        run_info: dict[str, Any] | None = None,
        checkpoint_every: int = 1,
        epoch_callback: EpochCallback | None = None,
    ) -> None:
        self.loss_fn = get_loss(method)
        required = METHODS[method].model_options
        mismatch = {k: v for k, v in required.items() if getattr(model.config, k) != v}
        if mismatch:
            raise ValueError(
                f"Method {method!r} needs ModelConfig fields {mismatch}; build the model with "
                f"pcc_agent.losses.model_config_for_method(config, {method!r})."
            )
        self.method = method
        self.config = config
        self.device = resolve_device(device)
        self.model = model.to(device=self.device, dtype=torch.float32)
        self.optimizer = _make_adam(self.model, config)
        self.progress_bar = progress_bar
        self.log_dir = None if log_dir is None else Path(log_dir)
        self.checkpoint_path = None if checkpoint_path is None else Path(checkpoint_path)
        self.run_info = dict(run_info or {})
        self.checkpoint_every = max(1, int(checkpoint_every))
        self.epoch_callback = epoch_callback
        self.shuffle_generator = torch.Generator().manual_seed(config.seed)
        self.noise_generator = torch.Generator(device=self.device).manual_seed(config.seed + 1)
        self.bf16_autocast = uses_bf16_autocast(config.mixed_precision, self.device)
        self._logger: Any = None

    # ------------------------------------------------------------------ helpers
    def _epoch_config(self, epochs_done: int) -> TrainConfig:
        """The config of the next epoch: ``kl_scale`` ramps up during ``warmup_epochs``."""
        if self.config.warmup_epochs <= 0:
            return self.config
        scale = min(1.0, (epochs_done + 1) / self.config.warmup_epochs)
        return dataclasses.replace(self.config, kl_scale=scale * self.config.kl_scale)

    def _config_dict(self) -> dict[str, Any]:
        return {"method": self.method, "train_config": self.config.to_dict(),
                "model": self.model.architecture(), "bf16_autocast": self.bf16_autocast,
                **self.run_info}

    def _loss(self, batch: TransitionBatch, config: TrainConfig,
              generator: torch.Generator) -> tuple[torch.Tensor, dict[str, float]]:
        """The method's loss on ``batch``, under bfloat16 autocast when that is on.

        With ``config.prediction_horizon`` above 1 the loss holds the multi-step prediction
        term (metric ``multistep``; :func:`pcc_agent.losses.multistep_prediction`).
        """
        with torch.autocast(self.device.type, dtype=torch.bfloat16,
                            enabled=self.bf16_autocast):
            return self.loss_fn(self.model, batch, config, generator)

    def _make_logger(self) -> Any:
        if self.log_dir is None:
            return None
        return sb3_logger(self.log_dir, ["stdout", "csv", "tensorboard?"])

    def _split(self, n: int) -> tuple[torch.Tensor, torch.Tensor]:
        split_generator = torch.Generator().manual_seed(self.config.seed + 2)
        order = torch.randperm(n, generator=split_generator)
        n_val = int(round(n * self.config.validation_fraction))
        if self.config.validation_fraction > 0 and n > 1:
            n_val = min(max(n_val, 1), n - 1)
        return order[n_val:], order[:n_val]

    def _batch(self, tensors: tuple[torch.Tensor, ...], idx: torch.Tensor) -> TransitionBatch:
        return TransitionBatch(*(t[idx] for t in tensors))

    def _check(self, value: float, reference: float) -> None:
        if not math.isfinite(value):
            raise TrainingDivergedError(f"loss became {value}")
        if math.isfinite(reference) and abs(value) > self.config.divergence_factor * max(
            abs(reference), 1e-8
        ):
            raise TrainingDivergedError(
                f"loss {value:.4g} exceeds {self.config.divergence_factor:g} x the best loss "
                f"{reference:.4g}"
            )

    def _validate(self, tensors: tuple[torch.Tensor, ...], idx: torch.Tensor) -> float:
        """Mean validation loss, with fixed noise so epochs are comparable."""
        generator = torch.Generator(device=self.device).manual_seed(self.config.seed + 3)
        total, count = 0.0, 0
        self.model.eval()
        with torch.no_grad():
            for start in range(0, len(idx), self.config.batch_size):
                chunk = idx[start:start + self.config.batch_size]
                loss, _ = self._loss(self._batch(tensors, chunk), self.config, generator)
                total += float(loss) * len(chunk)
                count += len(chunk)
        self.model.train()
        return total / max(count, 1)

    def _save(
        self, result: TrainResult, state: dict[str, Any], finished: bool,
        current_state_dict: dict[str, torch.Tensor] | None = None,
    ) -> None:
        """Write the checkpoint: the model's weights plus everything needed to resume exactly.

        ``current_state_dict`` (final save only) holds the weights training would continue
        from when the model itself has been reset to the best epoch's weights.
        """
        if self.checkpoint_path is None:
            return
        extra = {
            "epochs": result.epochs, "best_epoch": result.best_epoch,
            "best_validation_loss": result.best_validation_loss, "history": result.history,
            "finished": finished, "converged": result.converged, "diverged": result.diverged,
            "bad_epochs": state["bad_epochs"],
        }
        training_state: dict[str, Any] = {
            "optimizer": self.optimizer.state_dict(),
            "shuffle_rng": self.shuffle_generator.get_state(),
            "noise_rng": self.noise_generator.get_state().cpu(),
            "best_state_dict": state["best_state_dict"],
        }
        if current_state_dict is not None:
            training_state["current_state_dict"] = current_state_dict
        save_checkpoint(self.checkpoint_path, self.model, self._config_dict(),
                        extra=json.loads(json.dumps(extra, default=float)),
                        state=training_state)
        atomic_write_text(json.dumps(self._config_dict(), indent=2),
                          self.checkpoint_path.with_suffix(".json"))

    def _resume(self, result: TrainResult, state: dict[str, Any]) -> None:
        assert self.checkpoint_path is not None
        if not self.checkpoint_path.exists():
            return
        checkpoint = load_checkpoint(self.checkpoint_path, map_location=self.device)
        load_weights(self.model, checkpoint)
        if checkpoint.config.get("method") != self.method:
            raise CheckpointError(
                f"Cannot resume: {self.checkpoint_path} was trained with method "
                f"{checkpoint.config.get('method')!r}, not {self.method!r}."
            )
        extra = checkpoint.extra
        result.history = list(extra.get("history", []))
        result.epochs = int(extra.get("epochs", 0))
        result.best_epoch = int(extra.get("best_epoch", 0))
        result.best_validation_loss = float(extra.get("best_validation_loss", math.inf))
        state["bad_epochs"] = int(extra.get("bad_epochs", 0))
        saved = checkpoint.state
        if saved:
            self.optimizer.load_state_dict(saved["optimizer"])
            self.shuffle_generator.set_state(saved["shuffle_rng"])
            self.noise_generator.set_state(saved["noise_rng"])
            state["best_state_dict"] = saved["best_state_dict"]
            if "current_state_dict" in saved:  # finished run: continue from its last epoch
                self.model.load_state_dict(saved["current_state_dict"])
        else:
            state["best_state_dict"] = copy.deepcopy(self.model.state_dict())

    # ------------------------------------------------------------------ main loop
    def fit(self, data: Any, resume: bool = False) -> TrainResult:
        """Train until ``config.epochs``, early stopping or divergence.

        Args:
            data: Transitions (see :func:`dataset_arrays`).
            resume: Continue from ``checkpoint_path`` when it exists.

        Returns:
            The :class:`TrainResult`; the model holds the best-validation weights.
        """
        with flushed_denormals(self.config.flush_denormals):
            return self._fit(data, resume)

    def _fit(self, data: Any, resume: bool) -> TrainResult:
        arrays = dataset_arrays(data)
        if tuple(arrays.obs.shape[1:]) != self.model.obs_shape:
            raise ValueError(
                f"Observations have shape {arrays.obs.shape[1:]}, the model expects "
                f"{self.model.obs_shape}."
            )
        if arrays.action.shape[1] != self.model.action_dim:
            raise ValueError(
                f"Actions have dimension {arrays.action.shape[1]}, the model expects "
                f"{self.model.action_dim}."
            )
        if resume and self.checkpoint_path is None:
            raise ValueError("resume=True needs a checkpoint_path.")
        horizon = self.config.prediction_horizon
        if arrays.prediction_horizon < horizon:
            raise ValueError(
                f"prediction_horizon {horizon} needs {horizon - 1} further steps per "
                f"transition; the data hold {arrays.prediction_horizon - 1}. Collect them with "
                f"pcc_envs.data.collect_transitions(..., prediction_horizon={horizon}).")
        start_time = time.perf_counter()
        parts = [arrays.obs, arrays.action, arrays.next_obs]
        if horizon > 1:  # only the steps the term uses
            assert arrays.future_action is not None and arrays.future_obs is not None
            parts += [arrays.future_action[:, :horizon - 1], arrays.future_obs[:, :horizon - 1]]
        tensors = tuple(torch.from_numpy(np.ascontiguousarray(part)).to(self.device)
                        for part in parts)
        train_idx, val_idx = self._split(len(arrays))
        if not resume:  # a resumed run restores the statistics with the weights
            self.model.fit_input_statistics(tensors[0][train_idx.to(self.device)])
        result = TrainResult()
        state: dict[str, Any] = {
            "bad_epochs": 0, "best_state_dict": copy.deepcopy(self.model.state_dict())
        }
        if resume:
            self._resume(result, state)
        self._logger = self._make_logger()
        last_good = copy.deepcopy(self.model.state_dict())
        best_train = min((h["train/loss"] for h in result.history), default=math.inf)
        bar = None
        if self.progress_bar:
            from tqdm.auto import tqdm

            # Whole epochs: the rate and the remaining time are tqdm's, from the epoch times.
            bar = tqdm(total=self.config.epochs, initial=result.epochs,
                       desc=f"{self.method} training", unit="epoch", dynamic_ncols=True)
            if result.history:  # a resumed run shows where it stands from the start
                bar.set_postfix(self._postfix(result.history[-1], result), refresh=False)
        self.model.train()
        ending = ""  # the line printed under the bar
        try:
            while result.epochs < self.config.epochs:
                epoch_start = time.perf_counter()
                sums: dict[str, float] = {}
                seen = 0
                order = train_idx[torch.randperm(len(train_idx), generator=self.shuffle_generator)]
                epoch_config = self._epoch_config(result.epochs)
                try:
                    for start in range(0, len(order), self.config.batch_size):
                        idx = order[start:start + self.config.batch_size].to(self.device)
                        loss, metrics = self._loss(self._batch(tensors, idx), epoch_config,
                                                   self.noise_generator)
                        self._check(metrics["loss"], best_train)
                        self.optimizer.zero_grad(set_to_none=True)
                        loss.backward()
                        if self.config.grad_clip_norm is not None:
                            torch.nn.utils.clip_grad_norm_(self.model.parameters(),
                                                           self.config.grad_clip_norm)
                        self.optimizer.step()
                        for key, value in metrics.items():
                            sums[key] = sums.get(key, 0.0) + value * len(idx)
                        seen += len(idx)
                    if not all(math.isfinite(float(p.detach().sum()))
                               for p in self.model.parameters()):
                        raise TrainingDivergedError("weights became non-finite")
                except TrainingDivergedError as error:
                    self.model.load_state_dict(last_good)
                    result.diverged = True
                    self._stop(result, "diverged", str(error))
                    result.message += (
                        ". Try a lower TrainConfig.lr, set grad_clip_norm, or check the data "
                        "(uint8 images, actions in [-1, 1])"
                    )
                    break
                result.epochs += 1
                row = {"epoch": float(result.epochs)}
                row.update({f"train/{k}": v / max(seen, 1) for k, v in sums.items()})
                best_train = min(best_train, row["train/loss"])
                val_loss = (self._validate(tensors, val_idx) if len(val_idx)
                            else row["train/loss"])
                row["val/loss"] = val_loss
                row["time/epoch_seconds"] = time.perf_counter() - epoch_start
                result.history.append(row)
                last_good = copy.deepcopy(self.model.state_dict())
                if val_loss < result.best_validation_loss - self.config.min_delta:
                    result.best_validation_loss = val_loss
                    result.best_epoch = result.epochs
                    state["best_state_dict"] = last_good
                    state["bad_epochs"] = 0
                else:
                    state["bad_epochs"] += 1
                self._log(row)
                if bar is not None:
                    bar.set_postfix(self._postfix(row, result), refresh=False)
                    bar.update(1)
                if self.epoch_callback is not None:
                    metrics = {k.split("/", 1)[1]: v for k, v in row.items()
                               if k.startswith("train/")}
                    metrics.update(val_loss=val_loss,
                                   epoch_seconds=row["time/epoch_seconds"])
                    if self.epoch_callback(result.epochs, metrics) is False:
                        self._stop(result, "callback")
                        break
                if (self.config.patience > 0 and state["bad_epochs"] >= self.config.patience
                        and result.epochs >= self.config.min_epochs):
                    result.converged = True
                    self._stop(result, "early_stopping", str(self.config.patience))
                    break
                if result.epochs % self.checkpoint_every == 0:
                    self._save(result, state, finished=False)
            else:
                self._stop(result, "epoch_cap")
            ending = result.message
        except KeyboardInterrupt:
            ending = stop_line("interrupted", result.epochs, self.config.epochs,
                               result.best_validation_loss, result.best_epoch)
            raise
        finally:
            if bar is not None:
                bar.close()
                if ending:  # one line under the bar on why training ended
                    print(ending, flush=True)
            if self._logger is not None:
                self._logger.close()
        current = None
        if self.checkpoint_path is not None:
            current = {k: v.detach().cpu().clone() for k, v in self.model.state_dict().items()}
        if result.best_epoch > 0:
            self.model.load_state_dict(state["best_state_dict"])
        result.wall_time = time.perf_counter() - start_time
        self._save(result, state, finished=True, current_state_dict=current)
        return result

    def _stop(self, result: TrainResult, reason: str, detail: str = "") -> None:
        """Record why training ended: ``result.stop_reason`` and its line, ``result.message``."""
        result.stop_reason = reason
        result.message = stop_line(reason, result.epochs, self.config.epochs,
                                   result.best_validation_loss, result.best_epoch, detail)

    @staticmethod
    def _postfix(row: Mapping[str, float], result: TrainResult) -> dict[str, str]:
        """The bar's postfix: the epoch's training and validation losses, the best so far."""
        postfix = {"loss": f"{row['train/loss']:.4g}", "val": f"{row['val/loss']:.4g}"}
        if result.best_epoch > 0:
            postfix["best"] = f"{result.best_validation_loss:.4g}@{result.best_epoch}"
        return postfix

    def _log(self, row: Mapping[str, float]) -> None:
        if self._logger is None:
            return
        for key, value in row.items():
            if key != "epoch":
                self._logger.record(key, value)
        self._logger.dump(int(row["epoch"]))


@functools.cache
def cpu_flags() -> frozenset[str]:
    """The CPU's feature flags from ``/proc/cpuinfo`` (empty where there is none: not Linux)."""
    try:
        text = Path("/proc/cpuinfo").read_text(encoding="utf-8")
    except OSError:
        return frozenset()
    for line in text.splitlines():
        if line.startswith("flags"):
            return frozenset(line.split(":", 1)[1].split())
    return frozenset()


def simd_flags() -> tuple[str, ...]:
    """The CPU's vector-instruction flags (``avx*``, ``amx*``, ``fma``), sorted.

    Kernels for different instruction sets round differently, so results are bit-identical
    only between hosts with the same flags (and torch CPU capability).
    """
    return tuple(sorted(flag for flag in cpu_flags() if flag.startswith(("avx", "amx", "fma"))))


def native_bf16(device: torch.device | str = "cpu") -> bool:
    """Whether ``device`` multiplies bfloat16 in hardware.

    A CPU does with AMX (``amx_bf16``) or AVX512-BF16 (``avx512_bf16``), read from
    ``/proc/cpuinfo`` (other systems: False); a CUDA device when
    :func:`torch.cuda.is_bf16_supported` says so.
    """
    device = torch.device(device)
    if device.type == "cuda":
        return bool(torch.cuda.is_bf16_supported())
    if device.type != "cpu":
        return False
    return bool(cpu_flags() & {"amx_bf16", "avx512_bf16"})


def uses_bf16_autocast(mixed_precision: str, device: torch.device | str) -> bool:
    """Whether :attr:`TrainConfig.mixed_precision` turns bfloat16 autocast on for ``device``.

    ``"off"``: never; ``"auto"``: where :func:`native_bf16`; ``"bf16"``: always, with a
    warning where the hardware would emulate it (slower than float32).
    """
    check_mixed_precision(mixed_precision)
    if mixed_precision == "off":
        return False
    native = native_bf16(device)
    if mixed_precision == "auto":
        return native
    if not native:
        warnings.warn(f"mixed_precision='bf16' on {torch.device(device)}, which has no native "
                      "bfloat16: it is emulated and slower than float32 ('auto' would use "
                      "float32 here).", RuntimeWarning, stacklevel=3)
    return True


def denormals_flushed() -> bool:
    """Whether this thread's CPU flushes subnormal floats to zero (FTZ/DAZ on)."""
    return float(torch.tensor([1e-40], dtype=torch.float32).mul(1.0)) == 0.0


@contextlib.contextmanager
def flushed_denormals(enabled: bool = True) -> Iterator[None]:
    """Flush subnormal floats to zero inside the block, then restore the previous mode.

    Does nothing when ``enabled`` is false, or on a CPU without the modes (then it warns).
    """
    if not enabled:
        yield
        return
    before = denormals_flushed()
    if not torch.set_flush_denormal(True):
        warnings.warn("This CPU cannot flush denormals to zero; training runs with them.",
                      RuntimeWarning, stacklevel=3)
    try:
        yield
    finally:
        torch.set_flush_denormal(before)


def train_embedding(
    model: EmbeddingModel,
    data: Any,
    train_config: TrainConfig,
    method: str = "pcc",
    device: torch.device | str = "auto",
    seed: int | None = None,
    progress_bar: bool = True,
    log_dir: str | Path | None = None,
    checkpoint_path: str | Path | None = None,
    resume: bool = False,
    epoch_callback: EpochCallback | None = None,
    checkpoint_every: int = 1,
) -> TrainResult:
    """Train ``model`` on transitions with a method of :data:`pcc_agent.losses.METHODS`.

    Args:
        model: The model (see :class:`Trainer` for the method requirements).
        data: ``(obs, action, next_obs)`` arrays, dict, or a ``TransitionDataset``.
        train_config: Hyper-parameters.
        method: ``"pcc"``, ``"e2c"``, ``"rce"``, ``"pcc-no-consistency"``,
            ``"pcc-no-curvature"`` or ``"pcc-amortized"``.
        device: ``"auto"`` (CUDA when available), ``"cpu"``, ``"cuda"``.
        seed: Overrides ``train_config.seed`` when given.
        progress_bar: Show a tqdm bar over epochs and the line on why training stopped
            (see :class:`Trainer`).
        log_dir: Stable-Baselines3 logger directory (None: no logging).
        checkpoint_path: Atomic checkpoint file (None: no checkpoints).
        resume: Continue from ``checkpoint_path``.
        epoch_callback: ``epoch_callback(epoch, metrics) -> bool | None`` after every epoch;
            ``False`` stops training (see :class:`Trainer`).
        checkpoint_every: Epochs between resumable checkpoints.

    Returns:
        :class:`TrainResult`; the model holds the best-validation weights.

    Example:
        >>> import numpy as np
        >>> from pcc_agent.model import EmbeddingModel
        >>> from pcc_agent.presets import TrainConfig, get_preset
        >>> model = EmbeddingModel((1, 40, 40), 2, get_preset("pcc/Planar-v0").model, seed=0)
        >>> obs = np.zeros((64, 1, 40, 40), np.uint8)
        >>> result = train_embedding(model, (obs, np.zeros((64, 2), np.float32), obs),
        ...                          TrainConfig(epochs=1), progress_bar=False, device="cpu")
        >>> result.epochs
        1
    """
    if seed is not None:
        import dataclasses

        train_config = dataclasses.replace(train_config, seed=seed)
    trainer = Trainer(model, train_config, method, device=device, progress_bar=progress_bar,
                      log_dir=log_dir, checkpoint_path=checkpoint_path,
                      checkpoint_every=checkpoint_every, epoch_callback=epoch_callback)
    return trainer.fit(data, resume=resume)
