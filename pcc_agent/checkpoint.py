"""Atomic, safe checkpoints of an :class:`~pcc_agent.model.EmbeddingModel`.

A checkpoint is one file, in one of two formats:

* ``*.pt`` (the default): written with ``torch.save`` and read with
  ``torch.load(weights_only=True)``, so no pickled code is ever executed;
* ``*.safetensors``: the `safetensors <https://huggingface.co/docs/safetensors>`_ format
  (tensors and a JSON header, nothing executable by construction), optionally with the weights
  stored in float16 to halve the file (the pretrained models shipped with the package and the
  weights behind committed benchmark rows). Loading casts them back to float32; no training
  state is stored. A *control-only* file keeps just the encoder and the latent dynamics
  (:data:`CONTROL_PARTS`), all that planning needs: a third or less of the file, the same
  actions; the model loaded from it cannot be trained further or decode.

It holds:

* ``state_dict``: the model weights;
* ``architecture_json``: observation shape, action dimension and ``ModelConfig`` (enough to
  rebuild the model without the caller knowing its preset);
* ``config_json``: the caller's configuration (training config, method, env id, ...);
* ``extra_json``: any JSON-serializable metadata (epoch, history, ...);
* ``state``: optional weights-only-safe training state (optimizer state dict, RNG state).

Writes go to a temporary file in the same directory, are flushed to disk, then moved over the
destination with ``os.replace``, so a crash never leaves a half-written checkpoint.
"""

from __future__ import annotations

import json
import os
import pickle
import re
import zipfile
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import torch

from pcc_agent.config import ModelConfig
from pcc_agent.io import atomic_torch_save, atomic_write_bytes, atomic_write_text
from pcc_agent.model import EmbeddingModel

#: The atomic writers live in :mod:`pcc_agent.io`; re-exported here for older imports.
__all__ = [
    "Checkpoint", "CheckpointError", "atomic_torch_save", "atomic_write_text", "load_checkpoint",
    "load_model", "load_weights", "save_checkpoint", "torch_load_safely",
]

#: File suffix of the safetensors format; every other suffix is written with ``torch.save``.
SAFETENSORS_SUFFIX = ".safetensors"

#: The modules latent control uses (``predict``: encode the observation and the goal, plan
#: with the latent dynamics), by state-dict prefix; a control-only file stores only these.
CONTROL_PARTS = ("encoder.", "dynamics.")

FORMAT_NAME = "pcc_agent.checkpoint"
FORMAT_VERSION = 1


class CheckpointError(RuntimeError):
    """A checkpoint is missing, empty, truncated, corrupt, unsafe or does not fit the model."""


@dataclass
class Checkpoint:
    """Contents of a checkpoint file.

    Attributes:
        path: Where it was read from.
        state_dict: Model weights.
        architecture: ``{"obs_shape", "action_dim", "model_config"}``.
        config: The caller's configuration dict.
        extra: JSON metadata.
        state: Training state (optimizer / RNG), empty when not saved.
        control_only: Only the :data:`CONTROL_PARTS` weights are stored.
    """

    path: Path
    state_dict: dict[str, torch.Tensor]
    architecture: dict[str, Any]
    config: dict[str, Any]
    extra: dict[str, Any] = field(default_factory=dict)
    state: dict[str, Any] = field(default_factory=dict)
    control_only: bool = False

    @property
    def model_config(self) -> ModelConfig:
        """The :class:`ModelConfig` the weights belong to."""
        return ModelConfig.from_dict(self.architecture["model_config"])

    def build_model(self, device: torch.device | str = "cpu") -> EmbeddingModel:
        """Rebuild the model and load the weights.

        Raises:
            CheckpointError: The weights do not fit the stored architecture.
        """
        model = EmbeddingModel(
            tuple(self.architecture["obs_shape"]), int(self.architecture["action_dim"]),
            self.model_config,
        )
        load_weights(model, self)
        return model.to(device)


def save_checkpoint(
    path: str | os.PathLike[str],
    model: EmbeddingModel,
    config_dict: dict[str, Any] | None = None,
    extra: dict[str, Any] | None = None,
    state: dict[str, Any] | None = None,
    half: bool = False,
    control_only: bool = False,
) -> Path:
    """Save a model atomically to one file.

    Args:
        path: Destination file (parent directories are created). A ``.safetensors`` suffix
            selects the safetensors format, any other ``torch.save``'s.
        model: The model.
        config_dict: JSON-serializable configuration (training config, method, env id, ...).
        extra: JSON-serializable metadata.
        state: Optional training state made only of tensors and plain Python containers /
            numbers (e.g. ``optimizer.state_dict()``, ``generator.get_state()``). Not
            stored in the safetensors format.
        half: Store floating-point weights as float16 (safetensors format only): half the
            size; the model loaded from it computes with the rounded weights.
        control_only: Store only the :data:`CONTROL_PARTS` weights (safetensors format
            only), for an agent that will plan but not train or decode.

    Returns:
        The path written.

    Raises:
        TypeError: ``config_dict`` or ``extra`` is not JSON-serializable.
        ValueError: ``half`` or ``state`` asked of a ``torch.save`` / safetensors file that
            cannot hold it.
    """
    if Path(path).suffix == SAFETENSORS_SUFFIX:
        if state:
            raise ValueError(
                f"{path}: the safetensors format stores weights only, not training state; "
                "save training checkpoints as .pt files."
            )
        return _save_safetensors(Path(path), model, config_dict, extra, half, control_only)
    if half or control_only:
        raise ValueError(
            f"{path}: float16 and control-only weights are stored in the safetensors format "
            f"only; give the file the {SAFETENSORS_SUFFIX} suffix."
        )
    payload = {
        "format": FORMAT_NAME,
        "version": FORMAT_VERSION,
        "state_dict": {k: v.detach().cpu() for k, v in model.state_dict().items()},
        "architecture_json": json.dumps(model.architecture()),
        "config_json": json.dumps(config_dict or {}),
        "extra_json": json.dumps(extra or {}),
        "state": state or {},
    }
    atomic_torch_save(payload, path)
    return Path(path)


def _save_safetensors(
    path: Path, model: EmbeddingModel, config_dict: dict[str, Any] | None,
    extra: dict[str, Any] | None, half: bool, control_only: bool = False,
) -> Path:
    """Write the weights and the JSON fields as a safetensors file, atomically."""
    from safetensors.torch import save

    tensors = {}
    for name, value in model.state_dict().items():
        if control_only and not name.startswith(CONTROL_PARTS):
            continue
        value = value.detach().cpu()
        if half and value.is_floating_point():
            value = value.to(torch.float16)
        tensors[name] = value.contiguous()
    metadata = {
        "format": FORMAT_NAME,
        "version": str(FORMAT_VERSION),
        "architecture_json": json.dumps(model.architecture()),
        "config_json": json.dumps(config_dict or {}),
        "extra_json": json.dumps(extra or {}),
        "weights_dtype": "float16" if half else "float32",
        "parts": "control" if control_only else "all",
    }
    atomic_write_bytes(path, save(tensors, metadata=metadata))
    return path


def _load_safetensors(path: Path, map_location: torch.device | str) -> Checkpoint:
    """Read a safetensors checkpoint; float16 weights come back as float32."""
    from safetensors import SafetensorError, safe_open

    if path.stat().st_size == 0:
        raise CheckpointError(f"Checkpoint {path} is empty (0 bytes): it was never written. "
                              f"{_REMEDY}")
    try:
        with safe_open(path, framework="pt") as handle:
            metadata = handle.metadata() or {}
            tensors = {name: handle.get_tensor(name) for name in handle.keys()}
    except (SafetensorError, OSError, ValueError) as error:
        raise CheckpointError(
            f"Checkpoint {path} is not a readable safetensors file ({_reason(error)}): it is "
            f"truncated or corrupt. {_REMEDY}"
        ) from error
    if metadata.get("format") != FORMAT_NAME or metadata.get("version") != str(FORMAT_VERSION):
        raise CheckpointError(
            f"{path} is not a pcc_agent checkpoint of format version {FORMAT_VERSION} (its "
            f"metadata: format={metadata.get('format')!r}, version={metadata.get('version')!r})."
        )
    state_dict = {
        name: (value.to(torch.float32) if value.dtype == torch.float16 else value)
        .to(map_location)
        for name, value in tensors.items()
    }
    try:
        return Checkpoint(
            path=path,
            state_dict=state_dict,
            architecture=json.loads(metadata["architecture_json"]),
            config=json.loads(metadata["config_json"]),
            extra=json.loads(metadata["extra_json"]),
            control_only=metadata.get("parts") == "control",
        )
    except (KeyError, json.JSONDecodeError) as error:
        raise CheckpointError(f"Checkpoint {path} is missing or has damaged fields: {error}.") \
            from error


_REMEDY = "Re-train or restore it from a backup."
_ZIP_MAGIC = b"PK\x03\x04"
_PICKLE_PROTO = b"\x80"  # a pickle of protocol 2 or later (torch's legacy format) starts so


def _check_readable(path: Path) -> None:
    """Refuse an empty file, a truncated zip archive, or a file in neither of torch's formats.

    ``torch.save`` writes a zip archive (a legacy-format file is a pickle); the archive's index
    is at its end, so a file cut short has none.
    """
    size = path.stat().st_size
    if size == 0:
        raise CheckpointError(
            f"Checkpoint {path} is empty (0 bytes): it was never written. {_REMEDY}"
        )
    with open(path, "rb") as handle:
        head = handle.read(len(_ZIP_MAGIC))
    if head == _ZIP_MAGIC and not zipfile.is_zipfile(path):
        raise CheckpointError(
            f"Checkpoint {path} is truncated ({size} bytes, the end of the archive is missing): "
            f"it was cut short while being written or copied. {_REMEDY}"
        )
    if head != _ZIP_MAGIC and not head.startswith(_PICKLE_PROTO):
        raise CheckpointError(
            f"Checkpoint {path} is corrupt: its {size} bytes are not a file torch.save writes "
            f"(neither a zip archive nor a pickle). {_REMEDY}"
        )


def _reason(error: BaseException) -> str:
    """A one-line description of a low-level error, never empty."""
    text = str(error).strip().splitlines()[0] if str(error).strip() else ""
    return f"{type(error).__name__}: {text}" if text else type(error).__name__


def _refusal(path: Path, error: Exception) -> str:
    """The message for a file the weights-only unpickler refused: what it holds, what to do."""
    text = str(error)
    named = re.search(r"GLOBAL ([\w.]+)", text)
    opcode = re.search(r"Unsupported operand (\d+)", text)
    if named:
        what = f"code objects (it would call {named.group(1)}) that the loader will not execute"
    elif opcode:
        what = (f"pickled data the safe loader does not read (opcode {opcode.group(1)}), "
                "possibly code objects, which the loader will not execute")
    else:
        what = "objects that are not plain data, possibly code objects, which the loader " \
               "will not execute"
    return (
        f"Refused to load checkpoint {path}: it holds {what}. Checkpoints are read as plain "
        "data only (tensors, numbers, strings, lists, dicts), so nothing in this file was run. "
        "pcc_agent never writes code into a checkpoint: this file was made by another program "
        "or altered. Use a checkpoint written by PCCAgent.save or save_checkpoint."
    )


def torch_load_safely(
    path: str | os.PathLike[str], map_location: torch.device | str = "cpu", mmap: bool = False
) -> Any:
    """``torch.load(path, weights_only=True)`` with errors that say what is wrong with the file.

    Nothing in the file is executed: a file holding code objects is refused. Torch's own
    message for that case (which advises an unsafe reload) is not passed on.

    Args:
        path: The file.
        map_location: Device the tensors are loaded to.
        mmap: Map the tensors' storage from the file instead of reading it (zip format only).

    Returns:
        The loaded object (tensors and plain Python containers / numbers / strings).

    Raises:
        CheckpointError: Missing, empty, truncated or corrupt file, or a file holding code
            objects (the message names the file and the reason).
    """
    path = Path(path)
    if not path.is_file():
        raise CheckpointError(f"Checkpoint {path} does not exist (or is not a file).")
    _check_readable(path)
    try:
        return torch.load(path, map_location=map_location, weights_only=True, mmap=mmap)
    except Exception as error:  # torch raises many types for damaged archives
        if isinstance(error, pickle.UnpicklingError) or "Weights only load failed" in str(error):
            # torch's own message advises the unsafe reload: it must not reach the user, not
            # even as the chained cause in the traceback.
            raise CheckpointError(_refusal(path, error)) from None
        if isinstance(error, EOFError) or "unexpected EOF" in str(error):
            raise CheckpointError(
                f"Checkpoint {path} is truncated ({path.stat().st_size} bytes, the data end "
                f"early): it was cut short while being written or copied. {_REMEDY}"
            ) from error
        raise CheckpointError(
            f"Checkpoint {path} is corrupt and cannot be read ({_reason(error)}). {_REMEDY}"
        ) from error


def load_checkpoint(
    path: str | os.PathLike[str], map_location: torch.device | str = "cpu"
) -> Checkpoint:
    """Read a checkpoint written by :func:`save_checkpoint`.

    Args:
        path: The file (``.safetensors``: that format; else ``torch.save``'s).
        map_location: Device the tensors are loaded to.

    Returns:
        The :class:`Checkpoint`.

    Raises:
        CheckpointError: Missing, empty, truncated or corrupt file; a file holding code
            objects (refused, nothing of it is executed); or not a pcc_agent checkpoint.
    """
    path = Path(path)
    if path.suffix == SAFETENSORS_SUFFIX:
        if not path.is_file():
            raise CheckpointError(f"Checkpoint {path} does not exist (or is not a file).")
        return _load_safetensors(path, map_location)
    payload = torch_load_safely(path, map_location)
    if not isinstance(payload, dict) or payload.get("format") != FORMAT_NAME:
        raise CheckpointError(
            f"{path} is not a pcc_agent checkpoint (expected a dict with format={FORMAT_NAME!r})."
        )
    if payload.get("version") != FORMAT_VERSION:
        raise CheckpointError(
            f"{path} has checkpoint format version {payload.get('version')}, this pcc_agent "
            f"reads version {FORMAT_VERSION}."
        )
    try:
        return Checkpoint(
            path=path,
            state_dict=payload["state_dict"],
            architecture=json.loads(payload["architecture_json"]),
            config=json.loads(payload["config_json"]),
            extra=json.loads(payload["extra_json"]),
            state=payload.get("state", {}),
        )
    except (KeyError, TypeError, json.JSONDecodeError) as error:
        raise CheckpointError(f"Checkpoint {path} is missing or has damaged fields: {error}.") \
            from error


def load_weights(model: EmbeddingModel, checkpoint: Checkpoint) -> None:
    """Load a checkpoint's weights into an existing model after checking they fit.

    Raises:
        CheckpointError: Different observation shape, action dimension, architecture, or
            tensor shapes.
    """
    arch = checkpoint.architecture
    if list(arch.get("obs_shape", [])) != list(model.obs_shape):
        raise CheckpointError(
            f"Checkpoint {checkpoint.path} was trained on observations of shape "
            f"{tuple(arch.get('obs_shape', []))}, the model expects {model.obs_shape}. Use the "
            "environment (and frame stacking) the model was trained on."
        )
    if int(arch.get("action_dim", -1)) != model.action_dim:
        raise CheckpointError(
            f"Checkpoint {checkpoint.path} has action dimension {arch.get('action_dim')}, the "
            f"model expects {model.action_dim}."
        )
    own = model.state_dict()
    if checkpoint.control_only:  # the other parts keep their initial values
        own = {k: v for k, v in own.items() if k.startswith(CONTROL_PARTS)}
    missing = sorted(set(own) - set(checkpoint.state_dict))
    unexpected = sorted(set(checkpoint.state_dict) - set(own))
    wrong = sorted(
        f"{k}: {tuple(checkpoint.state_dict[k].shape)} vs {tuple(v.shape)}"
        for k, v in own.items()
        if k in checkpoint.state_dict and checkpoint.state_dict[k].shape != v.shape
    )
    if missing or unexpected or wrong:
        raise CheckpointError(
            f"Checkpoint {checkpoint.path} does not match the model architecture "
            f"(missing={missing[:5]}, unexpected={unexpected[:5]}, wrong shapes={wrong[:5]}). "
            "Build the model from checkpoint.model_config (Checkpoint.build_model())."
        )
    model.load_state_dict(checkpoint.state_dict, strict=not checkpoint.control_only)


def load_model(
    path: str | os.PathLike[str],
    obs_shape: tuple[int, ...] | None = None,
    action_dim: int | None = None,
    device: torch.device | str = "cpu",
) -> tuple[EmbeddingModel, Checkpoint]:
    """Rebuild a model from a checkpoint, optionally checking it fits an environment's spaces.

    Args:
        path: The checkpoint file.
        obs_shape: Expected observation shape (e.g. ``env.observation_space.shape``).
        action_dim: Expected action dimension.
        device: Device of the returned model.

    Returns:
        ``(model, checkpoint)``.

    Raises:
        CheckpointError: Unreadable file, or spaces that differ from the checkpoint's.
    """
    checkpoint = load_checkpoint(path)
    arch = checkpoint.architecture
    if obs_shape is not None and tuple(arch["obs_shape"]) != tuple(obs_shape):
        raise CheckpointError(
            f"Checkpoint {path} expects observations of shape {tuple(arch['obs_shape'])}, the "
            f"environment gives {tuple(obs_shape)}."
        )
    if action_dim is not None and int(arch["action_dim"]) != int(action_dim):
        raise CheckpointError(
            f"Checkpoint {path} expects {arch['action_dim']} action dimensions, the environment "
            f"has {action_dim}."
        )
    try:
        model = checkpoint.build_model(device)
    except (TypeError, ValueError) as error:
        raise CheckpointError(f"Checkpoint {path} has an invalid model config: {error}.") \
            from error
    return model, checkpoint
