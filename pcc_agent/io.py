"""Small input/output helpers shared by the library and the benchmarks.

* :func:`atomic_write` and its specialisations (:func:`atomic_write_text`,
  :func:`atomic_write_json`, :func:`atomic_torch_save`, :func:`atomic_save_figure`): the file
  is written to a temporary file in the destination's directory, flushed to disk, then moved
  over the destination with ``os.replace``, so a reader (or a crash) never sees half a file.
* :func:`versions`: the versions of the packages a result depends on, recorded with it.
* :func:`sb3_logger`: a Stable-Baselines3 logger writing to a folder.
"""

from __future__ import annotations

import json
import os
import platform
import sys
import tempfile
from collections.abc import Callable, Sequence
from pathlib import Path
from typing import IO, Any

__all__ = [
    "atomic_save_figure",
    "atomic_torch_save",
    "atomic_write",
    "atomic_write_bytes",
    "atomic_write_json",
    "atomic_write_text",
    "sb3_logger",
    "sha256_of",
    "versions",
]


def atomic_write(
    path: str | os.PathLike[str], write: Callable[[IO[Any]], None], binary: bool = False
) -> Path:
    """Write a file atomically: ``write(handle)`` into a temporary file, fsync, ``os.replace``.

    Args:
        path: The destination; its parent directories are created.
        write: Writes the content to the open handle it is given.
        binary: Open the temporary file in binary mode (else UTF-8 text).

    Returns:
        The destination path.
    """
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    fd, tmp = tempfile.mkstemp(prefix=f".{path.name}.", suffix=".tmp", dir=path.parent)
    try:
        with os.fdopen(fd, "wb" if binary else "w", **({} if binary else {"encoding": "utf-8"})
                       ) as handle:
            write(handle)
            handle.flush()
            os.fsync(handle.fileno())
        os.replace(tmp, path)
    except BaseException:
        if os.path.exists(tmp):
            os.unlink(tmp)
        raise
    return path


def atomic_write_text(text: str, path: str | os.PathLike[str]) -> Path:
    """Write a text file atomically (UTF-8)."""
    return atomic_write(path, lambda handle: handle.write(text))


def sha256_of(path: str | os.PathLike[str]) -> str:
    """The SHA-256 digest of a file, hex (the digests of shipped and committed weights)."""
    import hashlib

    return hashlib.sha256(Path(path).read_bytes()).hexdigest()


def atomic_write_bytes(path: str | os.PathLike[str], data: bytes) -> Path:
    """Write bytes to a file atomically."""
    return atomic_write(path, lambda handle: handle.write(data), binary=True)


def atomic_write_json(path: str | os.PathLike[str], payload: Any, indent: int = 1) -> Path:
    """Write ``payload`` as JSON atomically (``indent`` spaces per level)."""
    return atomic_write(path, lambda handle: json.dump(payload, handle, indent=indent))


def atomic_torch_save(obj: Any, path: str | os.PathLike[str]) -> Path:
    """``torch.save`` ``obj`` to ``path`` atomically."""
    import torch

    return atomic_write(path, lambda handle: torch.save(obj, handle), binary=True)


def atomic_save_figure(fig: Any, path: str | os.PathLike[str], dpi: int = 120) -> Path:
    """``fig.savefig`` atomically, in the format of the path's suffix (default PNG)."""
    path = Path(path)
    image_format = path.suffix.lstrip(".") or "png"
    return atomic_write(
        path,
        lambda handle: fig.savefig(handle, dpi=dpi, format=image_format, bbox_inches="tight"),
        binary=True,
    )


def versions() -> dict[str, str]:
    """The versions of this package, its main dependencies and Python, for a result record."""
    import gymnasium
    import numpy
    import stable_baselines3
    import torch

    import pcc_agent

    return {
        "pcc_control": pcc_agent.__version__,
        "torch": torch.__version__,
        "gymnasium": gymnasium.__version__,
        "stable_baselines3": stable_baselines3.__version__,
        "numpy": numpy.__version__,
        "python": platform.python_version(),
    }


def sb3_logger(folder: str | os.PathLike[str] | None, formats: Sequence[str]) -> Any:
    """A Stable-Baselines3 logger writing ``formats`` under ``folder``.

    Args:
        folder: The log directory; None is allowed only for ``["stdout"]`` (SB3's own
            ``configure(None, ...)`` would create an empty ``SB3-<date>`` folder in the
            temporary directory).
        formats: SB3 output formats: ``"stdout"``, ``"csv"``, ``"log"``, ``"json"``,
            ``"tensorboard"``; ``"tensorboard?"`` adds TensorBoard only when it is installed.

    Raises:
        ValueError: Formats that write files without a folder.
    """
    from stable_baselines3.common.logger import HumanOutputFormat, Logger, configure

    wanted = []
    for name in formats:
        if name == "tensorboard?":
            try:
                import tensorboard  # noqa: F401
            except ImportError:
                continue
            name = "tensorboard"
        wanted.append(name)
    if folder is not None:
        return configure(str(folder), wanted)
    if any(name != "stdout" for name in wanted):
        raise ValueError(f"logger formats {list(formats)} write files and need a folder")
    return Logger(folder=None, output_formats=[HumanOutputFormat(sys.stdout)] if wanted
                  else [])
