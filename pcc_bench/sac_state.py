"""Resumable SAC runs: save and restore everything an SB3 SAC training needs to go on.

A SAC run of the comparison takes one to several hours on one CPU core, longer than a working
session may last. Its training state is written every few thousand environment steps and
after every evaluation, and a run started again continues from it instead of from scratch.

The state is a plain ``torch.save`` dict of tensors, numbers, strings and lists (loaded with
``weights_only=True``, never pickle): the policy's and optimizers' state dicts (SB3's
``get_parameters()``), the entropy coefficient, the filled part of the replay buffer, the step
and update counters, the learning curve so far and the settings of the run, which must match
for a state to be used.

What a resumed run does not restore: the episode that was under way (the resumed run starts a
new episode; the transitions already stored stay in the buffer) and the random streams, which
are reseeded from the run's seed and the steps done (so a resumed run is deterministic, but
not identical to an uninterrupted one).
"""

from __future__ import annotations

import os
from pathlib import Path
from typing import Any

import numpy as np
import torch

from pcc_agent.checkpoint import CheckpointError, torch_load_safely
from pcc_agent.io import atomic_torch_save

STATE_FORMAT = 1

#: Replay-buffer arrays saved (up to the fill mark) and restored.
_BUFFER_ARRAYS = ("observations", "next_observations", "actions", "rewards", "dones", "timeouts")


def state_path(record_path: Path) -> Path:
    """Where the training state of the run whose record is ``record_path`` lives."""
    return record_path.with_name(record_path.stem + ".state.pt")


def save_state(
    path: Path,
    model: Any,
    steps_done: int,
    settings: dict[str, Any],
    curve: list[dict[str, Any]],
    train_seconds: float,
    resumed_at: list[int],
) -> None:
    """Write the state of ``model`` after ``steps_done`` fully processed environment steps.

    Args:
        path: The state file (written atomically).
        model: The SB3 SAC model.
        steps_done: Environment steps whose transitions are stored and trained on.
        settings: What defines the run (env, observation, reward, seed, budget, tasks...);
            a state is only resumed by a run with equal settings.
        curve: The evaluations made so far.
        train_seconds: Wall-clock seconds spent so far (over all sittings).
        resumed_at: Step counts at which earlier sittings resumed.
    """
    buffer = model.replay_buffer
    filled = buffer.buffer_size if buffer.full else buffer.pos
    arrays = {
        name: torch.from_numpy(np.ascontiguousarray(getattr(buffer, name)[:filled]))
        for name in _BUFFER_ARRAYS
        if getattr(buffer, name, None) is not None
    }
    state = {
        "format": STATE_FORMAT,
        "settings": settings,
        "steps_done": int(steps_done),
        "n_updates": int(model._n_updates),
        "episode_num": int(model._episode_num),
        "parameters": model.get_parameters(),
        "log_ent_coef": (model.log_ent_coef.detach().cpu()
                         if getattr(model, "log_ent_coef", None) is not None else None),
        "buffer": arrays,
        "buffer_pos": int(buffer.pos),
        "buffer_full": bool(buffer.full),
        "curve": curve,
        "train_seconds": float(train_seconds),
        "resumed_at": list(resumed_at),
    }
    atomic_torch_save(state, path)


def load_state(path: Path, settings: dict[str, Any]) -> dict[str, Any] | None:
    """The saved state of a run with these settings, or None.

    A file that cannot be read, was written by another format or belongs to a run with other
    settings is deleted (it can never be resumed) and None returned.
    """
    if not path.exists():
        return None
    try:
        # mmap: the replay buffer is read from the file as it is copied into SB3's buffer,
        # not held twice in memory (an 80x80x2 image buffer takes gigabytes).
        state = torch_load_safely(path, map_location="cpu", mmap=True)
    except (CheckpointError, OSError) as error:  # unreadable or unsafe: discarded alike
        print(f"Discarding unreadable SAC state: {error}")
        os.unlink(path)
        return None
    if not isinstance(state, dict) or state.get("format") != STATE_FORMAT:
        print(f"Discarding SAC state {path}: not a state of format {STATE_FORMAT}.")
        os.unlink(path)
        return None
    saved = state.get("settings") or {}
    differing = sorted(k for k in {*saved, *settings} if saved.get(k) != settings.get(k))
    if differing:
        print(f"Discarding SAC state {path}: made with other {', '.join(differing)}; the run "
              "starts afresh.")
        os.unlink(path)
        return None
    return state


def restore_state(model: Any, state: dict[str, Any]) -> None:
    """Load a saved state into a freshly built SAC model of the same settings."""
    model.set_parameters(state["parameters"], exact_match=True, device=model.device)
    if state["log_ent_coef"] is not None:
        with torch.no_grad():
            model.log_ent_coef.copy_(state["log_ent_coef"].to(model.device))
    buffer = model.replay_buffer
    for name, values in state["buffer"].items():
        target = getattr(buffer, name)
        if values.shape[1:] != target.shape[1:] or values.shape[0] > target.shape[0]:
            raise ValueError(
                f"SAC state's replay buffer {name} has shape {tuple(values.shape)}, which "
                f"does not fit the run's buffer {target.shape}."
            )
        target[: values.shape[0]] = values.numpy()
    buffer.pos, buffer.full = state["buffer_pos"], state["buffer_full"]
    model.num_timesteps = state["steps_done"]
    model._n_updates = state["n_updates"]
    model._episode_num = state["episode_num"]
