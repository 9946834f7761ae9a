"""Pool workers that end with the process that started them, however it ends.

``kill -9`` (or the OOM killer) ends a grid's driver without running any handler: its loky
workers would go on computing runs nobody collects, keeping the CPUs busy for hours, and then
wait for more work forever (loky does not end them: they are re-parented and block on their
call queue). A worker calls :func:`end_with_driver` from the pool's initializer.
"""

from __future__ import annotations

import contextlib
import ctypes
import os
import select
import signal
import sys
import threading
import time

__all__ = ["end_with_driver"]

_PR_SET_PDEATHSIG = 1  # <linux/prctl.h>


def end_with_driver(driver_pid: int, forked_by_main_thread: bool) -> None:
    """End this process as soon as process ``driver_pid`` has ended, even by SIGKILL.

    Two guards. On Linux the kernel sends SIGKILL when the parent dies (``PR_SET_PDEATHSIG``):
    immediate, and no Python code of this process has to run. It is set only when the driver
    is this process's parent and forked it from its main thread (the kernel fires it when the
    forking *thread* ends, and only the main thread lives as long as the process). Everywhere
    a daemon thread also waits for the driver's end (on a Linux pidfd, else by polling) and
    exits: that covers the other start methods (a forkserver parent) and platforms.

    Args:
        driver_pid: ``os.getpid()`` of the driver, passed in the pool's ``initargs``.
        forked_by_main_thread: Whether the driver creates the workers from its main thread.
    """
    if forked_by_main_thread and os.getppid() == driver_pid and sys.platform.startswith("linux"):
        with contextlib.suppress(OSError, AttributeError):
            ctypes.CDLL(None, use_errno=True).prctl(_PR_SET_PDEATHSIG, signal.SIGKILL, 0, 0, 0)
    threading.Thread(target=_exit_when_ended, args=(driver_pid,), daemon=True,
                     name="end-with-driver").start()


def _exit_when_ended(pid: int) -> None:
    """Block until process ``pid`` has ended (at once if it already has), then exit."""
    try:
        pidfd = os.pidfd_open(pid)  # readable once the process has ended (Linux 5.3+)
    except ProcessLookupError:
        os._exit(1)
    except (AttributeError, OSError):  # no pidfd here: poll
        pidfd = None
    if pidfd is not None:
        select.select([pidfd], [], [])
    elif os.name == "posix":
        parent = os.getppid()
        while os.getppid() == parent and _exists(pid):
            time.sleep(0.5)
    else:  # pragma: no cover - Windows: no safe probe of another process
        return
    os._exit(1)


def _exists(pid: int) -> bool:
    try:
        os.kill(pid, 0)
    except ProcessLookupError:
        return False
    except PermissionError:
        return True
    return True
