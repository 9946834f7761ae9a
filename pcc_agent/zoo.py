"""Pretrained agents shipped with the package: load one and control at once.

Each entry is a model of a committed benchmark row, stored as float16 control-only
safetensors weights (the encoder and the latent dynamics, all that planning uses; see
:mod:`pcc_agent.checkpoint`) inside the package (``pcc_agent/pretrained/``). Its
``percentages`` are those measured with that very file on the env's 10 evaluation tasks,
so evaluating it reproduces them exactly on a CPU with the same vector instructions as the
one that measured them (:meth:`PretrainedModel.measured_on_this_cpu`). Other CPUs round
differently, and a swing-up is sensitive to it: ``pendulum-swingup-pcc`` scores 80.75 % on
every task on an AMD EPYC with AVX-512 against 93.75 % on the Intel Xeon that recorded it.

Example:
    >>> from pcc_agent.zoo import load_pretrained
    >>> agent = load_pretrained("planar-pcc")  # doctest: +SKIP
    >>> action, _ = agent.predict(obs)  # doctest: +SKIP

From the shell: ``pcc evaluate planar-pcc``.
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING, Any

if TYPE_CHECKING:
    from pcc_agent.agent import PCCAgent

__all__ = ["PRETRAINED", "PretrainedModel", "load_pretrained", "pretrained_path"]

_DIRECTORY = Path(__file__).resolve().parent / "pretrained"


@dataclass(frozen=True)
class PretrainedModel:
    """One shipped agent and what it scored.

    Attributes:
        name: Registry name (``pcc evaluate NAME``).
        env_id: The env it was trained on and controls.
        method: Its loss (``pcc``, ``e2c``, ...).
        file: File name in ``pcc_agent/pretrained/``.
        sha256: Digest of the file (checked on load).
        task_seed: Base seed of the evaluation tasks it was scored on (10 tasks).
        percentages: % of steps in goal per task, measured with this file.
        source: The committed record it is the model of, and the command that trained it.
        machine: The CPU that measured ``percentages``.
        torch_cpu_capability: Torch's CPU kernel level on that machine
            (``torch.backends.cpu.get_cpu_capability()``).
        simd_flags: That CPU's vector-instruction flags (:func:`pcc_agent.training.simd_flags`):
            with the kernel level, what decides how the arithmetic rounds.
    """

    name: str
    env_id: str
    method: str
    file: str
    sha256: str
    task_seed: int
    percentages: tuple[float, ...]
    source: str
    machine: str
    torch_cpu_capability: str
    simd_flags: tuple[str, ...]

    def measured_on_this_cpu(self) -> bool:
        """Whether this CPU rounds as the one that measured ``percentages`` (same kernels)."""
        import torch

        from pcc_agent.training import simd_flags

        return (torch.backends.cpu.get_cpu_capability() == self.torch_cpu_capability
                and simd_flags() == self.simd_flags)

    @property
    def mean(self) -> float:
        """Mean % in goal over the evaluation tasks."""
        return sum(self.percentages) / len(self.percentages)


#: The vector-instruction flags of the 2-core Intel Xeon that measured the shipped agents
#: (``machine.simd_flags`` of their records).
_INTEL_XEON_AMX_FLAGS = (
    "amx_bf16", "amx_int8", "amx_tile", "avx", "avx2", "avx512_bf16", "avx512_bitalg",
    "avx512_fp16", "avx512_vbmi2", "avx512_vnni", "avx512_vpopcntdq", "avx512bw", "avx512cd",
    "avx512dq", "avx512f", "avx512ifma", "avx512vbmi", "avx512vl", "avx_vnni", "fma")

#: The shipped agents, one row each.
PRETRAINED: dict[str, PretrainedModel] = {
    model.name: model
    for model in (
        PretrainedModel(
            name="planar-pcc",
            env_id="pcc/Planar-v0",
            method="pcc",
            file="planar_pcc.safetensors",
            sha256="2569ee6996292e742eeb745d1278457c7f0ddaaf2966075be78d9e8299dc47fb",
            task_seed=2020,
            percentages=(75.0,) * 10,
            source="results/quick/runs/quick/pcc_Planar-v0/noise0.0/pcc/seed0.json "
                   "(`pcc reproduce`, the quick preset, model 0; 250 epochs on one core)",
            machine="2-core Intel Xeon (AVX-512, AMX)",
            torch_cpu_capability="AVX512",
            simd_flags=_INTEL_XEON_AMX_FLAGS,
        ),
        PretrainedModel(
            name="pendulum-swingup-pcc",
            env_id="pcc/PendulumSwingUp-v0",
            method="pcc",
            file="pendulum_swingup_pcc.safetensors",
            sha256="f62b1fc577c1e573ab011f6d80544c335a8e65219bb15ce38cca82558ef68bcc",
            task_seed=2020,
            percentages=(93.75,) * 10,
            source="results/reproduce/runs/paper+max_epochs=150,flush_denormals=True/"
                   "pcc_PendulumSwingUp-v0/noise0.0/pcc/seed0.json (`pcc reproduce --preset "
                   "paper --max-epochs 150 --flush-denormals`, model 0; 45 min on one core)",
            machine="2-core Intel Xeon (AVX-512, AMX)",
            torch_cpu_capability="AVX512",
            simd_flags=_INTEL_XEON_AMX_FLAGS,
        ),
    )
}


def pretrained_path(name: str) -> Path:
    """The file of a shipped agent, its digest checked.

    Raises:
        KeyError: No shipped agent has this name (the message lists them).
        FileNotFoundError: The package was installed without its data files.
        ValueError: The file's digest differs from the registry's (damaged or replaced).
    """
    if name not in PRETRAINED:
        raise KeyError(f"No pretrained agent named {name!r}; shipped: {sorted(PRETRAINED)}.")
    entry = PRETRAINED[name]
    path = _DIRECTORY / entry.file
    if not path.is_file():
        raise FileNotFoundError(
            f"Pretrained agent file {path} is missing: the package was installed without its "
            "data files. Reinstall pcc-control."
        )
    from pcc_agent.io import sha256_of

    digest = sha256_of(path)
    if digest != entry.sha256:
        raise ValueError(f"Pretrained agent file {path} is damaged or was replaced (SHA-256 "
                         f"{digest}, expected {entry.sha256}). Reinstall pcc-control.")
    return path


def load_pretrained(name: str, env: Any = None, device: str = "auto") -> PCCAgent:
    """Load a shipped agent (see :data:`PRETRAINED`), ready to ``predict``.

    Args:
        name: Registry name, e.g. ``"planar-pcc"``.
        env: The env to control (default: ``gym.make`` of the agent's env id).
        device: Torch device (``"auto"``: a GPU when present).
    """
    from pcc_agent.agent import PCCAgent

    return PCCAgent.load(pretrained_path(name), env=env, device=device)
