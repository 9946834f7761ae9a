"""``torch.func.jvp`` without torch's own ``torch.jit.script`` DeprecationWarning.

The first forward-mode AD call of a process makes torch import
``torch._decomp.decompositions_for_jvp``, and that module calls the deprecated
``torch.jit.script`` (torch 2.13 does). The warning is about torch's code, not ours,
and nothing we write can avoid it except not using forward-mode AD. So we trigger that one
import ourselves with exactly this warning ignored, and nothing else is filtered: a deprecated
call of our own still warns.

``test_torch_still_warns_about_its_own_jit_script_call`` (tests/integration/test_failure_modes.py)
fails once torch stops emitting the warning: then delete this module and use ``torch.func.jvp``.
"""

from __future__ import annotations

import warnings
from typing import Any

import torch.func

__all__ = ["jvp"]

# Python 3.14+ words it "`torch.jit.script` is not supported in Python 3.14+ and may break".
_TORCH_JIT_SCRIPT_WARNING = r"`torch\.jit\.script` is (deprecated|not supported)"
_loaded = False


def _load_jvp_decompositions() -> None:
    """Let torch load its jvp decompositions once, hiding only its jit.script warning."""
    global _loaded
    if _loaded:
        return
    try:
        from torch.autograd.forward_ad import _maybe_load_decompositions
    except ImportError:  # another torch: it loads them (or not) itself, warning or not
        _maybe_load_decompositions = None
    if _maybe_load_decompositions is not None:
        with warnings.catch_warnings():
            warnings.filterwarnings("ignore", _TORCH_JIT_SCRIPT_WARNING, DeprecationWarning)
            _maybe_load_decompositions()
    _loaded = True


def jvp(func: Any, primals: tuple[Any, ...], tangents: tuple[Any, ...]) -> tuple[Any, Any]:
    """``torch.func.jvp(func, primals, tangents)``: ``(func(*primals), J @ tangents)``."""
    _load_jvp_decompositions()
    return torch.func.jvp(func, primals, tangents)
