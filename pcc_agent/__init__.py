"""Controllable embeddings (PCC, E2C, RCE) and latent iLQR-MPC control.

The main entry point is :class:`PCCAgent`; it is imported lazily so that importing a
submodule (e.g. :mod:`pcc_agent.planning`) stays light.
"""

from typing import Any

__version__ = "0.3.2"

__all__ = ["PCCAgent", "__version__", "load_pretrained"]


def __getattr__(name: str) -> Any:
    if name == "PCCAgent":
        from pcc_agent.agent import PCCAgent

        return PCCAgent
    if name == "load_pretrained":
        from pcc_agent.zoo import load_pretrained

        return load_pretrained
    raise AttributeError(f"module 'pcc_agent' has no attribute {name!r}")
