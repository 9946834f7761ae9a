"""Fault injection: every refusal says why, every wrong input is refused (docs/failure_modes.md).

The kill -9 tests of the grid's driver and its workers live in ``test_reproduce.py`` beside
the other signal tests; the SB3 callback timing test in ``test_agent.py``.
"""

from __future__ import annotations

import os
import traceback
from pathlib import Path

import pytest
import torch

import pcc_envs  # noqa: F401
from pcc_agent import PCCAgent
from pcc_agent.checkpoint import CheckpointError, load_checkpoint, save_checkpoint
from pcc_agent.model import EmbeddingModel
from pcc_agent.presets import ModelConfig

SMALL = ModelConfig(latent_dim=2, encoder_hidden=(16,), decoder_hidden=(16,),
                    transition_hidden=(8,), backward_nz=4, backward_nu=4, backward_nx=8,
                    backward_joint=8)


class _MakesDirectory:
    """Unpickling this object would call ``os.mkdir(path)``: code a loader must not run."""

    def __init__(self, path: Path) -> None:
        self.path = str(path)

    def __reduce__(self):
        return os.mkdir, (self.path,)


def _full_text(error: BaseException) -> str:
    """Everything a user sees of an error: message, chained causes and traceback."""
    return "".join(traceback.format_exception(error))


# ------------------------------------------------------------------ unsafe / damaged checkpoints
@pytest.mark.parametrize("legacy", [False, True], ids=["zip", "legacy-format"])
def test_checkpoint_with_code_is_refused_unexecuted_and_says_why(tmp_path, legacy):
    marker = tmp_path / "code-ran"
    path = tmp_path / "agent.pt"
    with open(path, "wb") as handle:
        torch.save({"format": "pcc_agent.checkpoint", "payload": _MakesDirectory(marker)},
                   handle, _use_new_zipfile_serialization=not legacy)
    for load in (load_checkpoint, PCCAgent.load):
        with pytest.raises(CheckpointError) as caught:
            load(path)
        assert not marker.exists(), "the checkpoint's code was executed"
        message = str(caught.value)
        assert str(path) in message
        assert "code objects" in message and "will not execute" in message
        assert "mkdir" in message  # which code it tried to run
        assert "corrupt" not in message and "truncated" not in message
        # Neither the message nor the chained torch error advises the unsafe reload.
        assert "weights_only=False" not in _full_text(caught.value)
        assert "weights_only` set to `False`" not in _full_text(caught.value)


def test_empty_truncated_and_garbage_checkpoints_say_which(tmp_path):
    model = EmbeddingModel((1, 40, 40), 2, SMALL, seed=0)
    good = save_checkpoint(tmp_path / "good.pt", model, {"method": "pcc"})
    empty = tmp_path / "empty.pt"
    empty.write_bytes(b"")
    truncated = tmp_path / "truncated.pt"
    truncated.write_bytes(good.read_bytes()[: good.stat().st_size * 9 // 10])
    garbage = tmp_path / "garbage.pt"
    garbage.write_bytes(b"definitely not a checkpoint")
    cases = {empty: "is empty (0 bytes)", truncated: "is truncated", garbage: "is corrupt"}
    for path, wanted in cases.items():
        with pytest.raises(CheckpointError) as caught:
            load_checkpoint(path)
        message = str(caught.value)
        assert f"{path} {wanted}" in message, message
        assert "()" not in message and "( " not in message, message
        assert "weights_only=False" not in _full_text(caught.value)
    assert load_checkpoint(good).config == {"method": "pcc"}
