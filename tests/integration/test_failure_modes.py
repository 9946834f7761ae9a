"""Fault injection: every refusal says why, every wrong input is refused (docs/failure_modes.md).

The kill -9 tests of the grid's driver and its workers live in ``test_reproduce.py`` beside
the other signal tests; the SB3 callback timing test in ``test_agent.py``.
"""

from __future__ import annotations

import dataclasses
import os
import subprocess
import sys
import traceback
from pathlib import Path

import numpy as np
import pytest
import torch

import pcc_envs  # noqa: F401
from pcc_agent import PCCAgent
from pcc_agent.checkpoint import CheckpointError, load_checkpoint, save_checkpoint
from pcc_agent.model import EmbeddingModel
from pcc_agent.planning.config import PlannerConfig
from pcc_agent.presets import ModelConfig, get_preset

ROOT = Path(__file__).resolve().parents[2]
ENV_ID = "pcc/Planar-v0"
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


# ------------------------------------------------------------------ predict's warm start
@pytest.fixture(scope="module")
def untrained_agent():
    """An untrained agent with a goal: predict() runs, nothing is learned (fast)."""
    preset = get_preset(ENV_ID)
    preset = dataclasses.replace(
        preset, model=SMALL,
        planner=PlannerConfig(plan_length=4, iterations=1, mpc_iterations=1, num_candidates=1))
    agent = PCCAgent(ENV_ID, preset=preset, seed=0, device="cpu")
    obs, _ = agent.env.reset(seed=0)
    agent.set_goal(obs)
    return agent, obs


def test_predict_accepts_its_own_state_back(untrained_agent):
    agent, obs = untrained_agent
    batch = np.stack([obs, obs])
    _, state = agent.predict(batch)
    assert state.shape == (2, 4, 2) and state.dtype == np.float32
    actions, state2 = agent.predict(batch, state=state, episode_start=np.array([False, True]))
    assert actions.shape == (2, 2) and state2.shape == state.shape
    _, single_state = agent.predict(obs)
    action, _ = agent.predict(obs, state=single_state, episode_start=np.array([False]))
    assert action.shape == (2,)
    agent.predict(obs, state=single_state.astype(np.float64))  # any float precision


@pytest.mark.parametrize(
    ("state", "message"),
    [
        (np.zeros((2, 3, 2), np.float32), r"state has shape \(2, 3, 2\); expected \(2, 4, 2\)"),
        (np.zeros((1, 4, 2), np.float32), r"state has shape \(1, 4, 2\); expected \(2, 4, 2\)"),
        (np.zeros((2, 4, 3), np.float32), r"state has shape \(2, 4, 3\); expected \(2, 4, 2\)"),
        (np.zeros((4, 2), np.float32), r"state has shape \(4, 2\); expected \(2, 4, 2\)"),
        (np.zeros((2, 4, 2), np.int64), "state must be a float array"),
        (np.zeros((2, 4, 2), bool), "state must be a float array"),
        (np.array("warm"), "state must be a float array"),
        (np.full((2, 4, 2), np.nan, np.float32), "state has non-finite values"),
    ],
    ids=["plan-length", "batch-size", "action-dim", "unbatched", "int", "bool", "str", "nan"],
)
def test_predict_refuses_a_wrong_state(untrained_agent, state, message):
    agent, obs = untrained_agent
    with pytest.raises(ValueError, match=message):
        agent.predict(np.stack([obs, obs]), state=state)


def test_predict_refuses_a_wrong_episode_start(untrained_agent):
    agent, obs = untrained_agent
    batch = np.stack([obs, obs])
    with pytest.raises(ValueError, match=r"episode_start has 3 entries; expected 2"):
        agent.predict(batch, episode_start=np.array([True, False, True]))
    with pytest.raises(ValueError, match=r"episode_start has 1 entries; expected 2"):
        agent.predict(batch, episode_start=np.array([True]))
    with pytest.raises(ValueError, match="episode_start must be booleans"):
        agent.predict(batch, episode_start=np.array([0.5, 0.5]))
    agent.predict(batch, episode_start=np.array([1, 0]))  # 0/1 flags, as SB3's envs give them


# ------------------------------------------------------------------ learn's callback
@pytest.mark.parametrize("callback", [42, "checkpoint", [print, None]], ids=["int", "str", "list"])
def test_learn_refuses_what_is_not_a_callback_before_any_work(untrained_agent, callback):
    agent, obs = untrained_agent
    data = (np.stack([obs] * 4), np.zeros((4, 2), np.float32), np.stack([obs] * 4))
    before = [p.detach().clone() for p in agent.model.parameters()]
    with pytest.raises(TypeError, match="callback must be an SB3 BaseCallback, a function"):
        agent.learn(dataset=data, callback=callback)
    assert all(torch.equal(a, b) for a, b in zip(before, agent.model.parameters()))


# ------------------------------------------------------------------ torch's own deprecation
_JVP = ("import torch; from torch.func import jvp; "
        "jvp(torch.tanh, (torch.ones(2),), (torch.ones(2),))")


def _python(code: str) -> subprocess.CompletedProcess:
    """Run ``code`` in a fresh interpreter (torch loads its jvp decompositions once per process)."""
    return subprocess.run([sys.executable, "-W", "error::DeprecationWarning", "-c", code],
                          cwd=ROOT, capture_output=True, text=True, timeout=120)


def test_our_forward_mode_ad_emits_no_deprecation_warning():
    """Curvature loss and transition JVPs run with DeprecationWarnings turned into errors."""
    code = (
        "import torch; from pcc_agent.losses import curvature_penalty; "
        "from pcc_agent.model import EmbeddingModel; from pcc_agent.presets import ModelConfig; "
        "z, u = torch.ones(3, 2), torch.ones(3, 1); "
        "print(curvature_penalty(lambda z, u: torch.tanh(z) * u, z, u, z, u).shape); "
        "m = EmbeddingModel((1, 40, 40), 1, ModelConfig(latent_dim=2)); "
        "print(m.transition_jvp(z, u, z, u)[1].shape)"
    )
    done = _python(code)
    assert done.returncode == 0, done.stderr
    assert "DeprecationWarning" not in done.stderr


def test_torch_still_warns_about_its_own_jit_script_call():
    """Pins why ``pcc_agent._forward_ad`` silences one torch warning.

    ``torch.func.jvp`` loads ``torch._decomp.decompositions_for_jvp`` on its first use, and
    that module calls the deprecated ``torch.jit.script``: torch's code, not ours. When this
    test fails, torch no longer does that: delete ``pcc_agent._forward_ad`` (use
    ``torch.func.jvp`` directly) and this test.
    """
    done = _python(_JVP)
    assert done.returncode != 0 and "`torch.jit.script` is" in done.stderr, done.stderr
    assert "decompositions_for_jvp" in done.stderr, done.stderr
