"""Where the runs of a grid execute: one interface, three backends.

An :class:`Executor` calls ``run(spec, *args)`` for every spec and yields ``(spec, record or
error)`` in completion order; a failed run is an outcome, not an exception, so one failure
never stops the others. :class:`SerialExecutor` runs in this process; :class:`LokyExecutor`
on this machine, in a `loky <https://loky.readthedocs.io>`_ pool of worker processes (one
core each, ended with the driver at Ctrl-C or ``kill -9``): the default of ``pcc reproduce``
for more than one worker; :class:`RayExecutor` as Ray tasks on a Ray cluster, for many
machines or GPUs (``pip install 'pcc-control[ray]'``). Stopping the iteration early (Ctrl-C,
``close()``) cancels the queued runs on every backend. A run's record does not depend on the
backend: each run seeds itself from its spec and uses one torch thread on every backend.
"""

from __future__ import annotations

import os
import signal
import sys
import threading
from abc import ABC, abstractmethod
from collections.abc import Callable, Iterator, Sequence
from concurrent.futures import as_completed
from typing import Any

import loky

from pcc_bench.worker_lifetime import end_with_driver

#: What a backend reports per run, in completion order: the record, or the run's error.
Outcome = tuple[Any, dict[str, Any] | Exception]


def worker_init() -> None:
    """Set up a worker for one run: one OpenMP and one torch thread."""
    os.environ.setdefault("OMP_NUM_THREADS", "1")
    import torch

    torch.set_num_threads(1)


def _pool_worker_init(parent_ignores_sigint: bool = False, driver_pid: int | None = None,
                      forked_by_main_thread: bool = False) -> None:
    """Set up a loky worker: it ends at Ctrl-C and with its driver, and uses one thread.

    Ctrl-C (the terminal signals the whole process group) ends the worker at once: Python's
    default would raise KeyboardInterrupt inside the run, which would come back as that run's
    result. The run's training checkpoint is kept, so re-running the grid continues it. A grid
    started in the background by a non-interactive shell ignores SIGINT; its workers then
    ignore it too, so a stray SIGINT cannot kill them under a main process that keeps going.
    A worker also ends when the driver ``driver_pid`` ends without stopping it (``kill -9``):
    see :func:`pcc_bench.worker_lifetime.end_with_driver`.
    """
    signal.signal(signal.SIGINT, signal.SIG_IGN if parent_ignores_sigint else signal.SIG_DFL)
    signal.signal(signal.SIGTERM, signal.SIG_DFL)  # not the main process's graceful handler
    if driver_pid is not None:
        end_with_driver(driver_pid, forked_by_main_thread)
    worker_init()


def interrupt(signum: int, frame: Any) -> None:
    """Signal handler: stop the grid the way Ctrl-C does (raise KeyboardInterrupt)."""
    raise KeyboardInterrupt(signal.Signals(signum).name)


def pool_outcomes(
    run: Any, todo: Sequence[Any], workers: int, *args: Any
) -> Iterator[Outcome]:
    """``run(spec, *args)`` for every spec in a loky pool of ``workers`` processes.

    The workers are fresh interpreters (loky starts them by fork and exec, so no lock or
    thread of this process is copied into them); each outcome comes back as soon as its run
    ends. If the consumer stops early (Ctrl-C, an error, ``close()``), the queued runs are
    cancelled and the runs in progress end (their last epoch checkpoint is kept) before this
    returns, instead of being trained silently before the program exits. If this process is
    killed outright (``kill -9``), the workers end with it.
    """
    parent_ignores_sigint = signal.getsignal(signal.SIGINT) is signal.SIG_IGN
    # loky starts the workers at the first submit below, in this same thread (one it starts
    # later in place of a lost worker comes from its manager thread, which outlives them).
    main_thread = threading.current_thread() is threading.main_thread()
    pool = loky.ProcessPoolExecutor(
        max_workers=workers, initializer=_pool_worker_init,
        initargs=(parent_ignores_sigint, os.getpid(), main_thread),
    )
    try:
        futures = {pool.submit(run, spec, *args): spec for spec in todo}
        for future in as_completed(futures):
            try:
                outcome: dict[str, Any] | Exception = future.result()
            except Exception as error:  # one failed run must not stop or hang the grid
                outcome = error
            yield futures[future], outcome
    except BaseException:
        # kill_workers: the queued runs fail with ShutdownExecutorError (nobody reads them)
        # and the workers are killed, also when the signal reached only this process
        # (SIGTERM, or SIGINT sent to one pid). The futures are not cancelled here: loky's
        # manager thread fails on a future that was cancelled behind its back.
        pool.shutdown(wait=True, kill_workers=True)
        print("Stopped: queued runs cancelled.", file=sys.stderr, flush=True)
        raise
    pool.shutdown()


class Executor(ABC):
    """Runs ``run(spec, *args)`` for every spec; yields ``(spec, record or error)``."""

    #: Whether the driver must write the records it receives (the runs execute elsewhere).
    driver_writes: bool = False

    @abstractmethod
    def outcomes(
        self, run: Callable[..., dict[str, Any]], todo: Sequence[Any], *args: Any
    ) -> Iterator[Outcome]:
        """``run(spec, *args)`` for each spec of ``todo``, in completion order.

        Closing the iterator before its end cancels the runs not started yet.
        """


class SerialExecutor(Executor):
    """The runs one after another in this process (one torch thread)."""

    def outcomes(
        self, run: Callable[..., dict[str, Any]], todo: Sequence[Any], *args: Any
    ) -> Iterator[Outcome]:
        """See :meth:`Executor.outcomes`."""
        worker_init()
        for spec in todo:
            try:
                yield spec, run(spec, *args)
            except Exception as error:  # one failed run must not stop the grid
                yield spec, error


class LokyExecutor(Executor):
    """A local loky pool of ``workers`` processes, one core each (see :func:`pool_outcomes`).

    The workers end with the driver, however it ends: at Ctrl-C or SIGTERM the runs in
    progress are stopped and the queued ones cancelled; at ``kill -9`` each worker's
    parent-death guard (:func:`pcc_bench.worker_lifetime.end_with_driver`) ends it.
    """

    def __init__(self, workers: int) -> None:
        if workers < 1:
            raise ValueError(f"workers must be at least 1, got {workers}")
        self.workers = workers

    def outcomes(
        self, run: Callable[..., dict[str, Any]], todo: Sequence[Any], *args: Any
    ) -> Iterator[Outcome]:
        """See :meth:`Executor.outcomes`."""
        return pool_outcomes(run, todo, self.workers, *args)


#: The earlier name of :class:`LokyExecutor` (the local process pool), kept for callers.
ProcessExecutor = LokyExecutor


def _ray_call(run: Callable[..., dict[str, Any]], argv: list[str], spec: Any,
              *args: Any) -> dict[str, Any]:
    """``run(spec, *args)`` in a Ray worker, which sees the driver's command line ``argv``.

    A record names the command that made it (``sys.argv``): the driver's, as in a local
    worker, not the Ray worker's own.
    """
    worker_init()
    worker_argv = sys.argv
    sys.argv = list(argv)
    try:
        return run(spec, *args)
    finally:
        sys.argv = worker_argv


class RayExecutor(Executor):
    """The runs as Ray tasks, for a cluster: one CPU and ``gpus_per_task`` GPUs each.

    Args:
        address: The cluster (``"auto"``, ``"ray://host:10001"``); None starts or joins a
            local Ray instance.
        gpus_per_task: GPUs reserved per run (0: Ray hides the GPUs, runs train on CPU).
        num_cpus: CPUs of a local instance started here (None: all of this machine's).
    """

    driver_writes = True  # Ray workers may run on other machines

    def __init__(self, address: str | None = None, gpus_per_task: float = 0.0,
                 num_cpus: int | None = None) -> None:
        if gpus_per_task < 0:
            raise ValueError(f"gpus_per_task must be >= 0, got {gpus_per_task}")
        self.address = address
        self.gpus_per_task = gpus_per_task
        self.num_cpus = num_cpus

    def outcomes(
        self, run: Callable[..., dict[str, Any]], todo: Sequence[Any], *args: Any
    ) -> Iterator[Outcome]:
        """See :meth:`Executor.outcomes`."""
        try:
            import ray
        except ImportError as exc:  # depends on the optional extra
            raise SystemExit("The Ray backend needs Ray: pip install 'pcc-control[ray]'") from exc
        if not ray.is_initialized():
            local = {} if self.address is not None or self.num_cpus is None else {
                "num_cpus": self.num_cpus}
            ray.init(address=self.address, **local)
        task = ray.remote(num_cpus=1, num_gpus=self.gpus_per_task)(_ray_call)
        pending = {task.remote(run, sys.argv, spec, *args): spec for spec in todo}
        try:
            while pending:
                (ref,), _ = ray.wait(list(pending), num_returns=1)
                spec = pending.pop(ref)
                try:
                    outcome: dict[str, Any] | Exception = ray.get(ref)
                except Exception as error:  # a failed task must not lose the others' results
                    outcome = error
                yield spec, outcome
        except BaseException:
            for ref in pending:
                ray.cancel(ref)
            raise


def make_executor(backend: str = "process", workers: int = 1, ray_address: str | None = None,
                  ray_gpus_per_task: float = 0.0) -> Executor:
    """The executor of a backend name.

    ``"process"``: this machine, a :class:`LokyExecutor` of ``workers`` processes (a
    :class:`SerialExecutor` for one worker); ``"ray"``: a :class:`RayExecutor` at
    ``ray_address``.
    """
    if backend == "ray":
        return RayExecutor(ray_address, ray_gpus_per_task)
    if backend != "process":
        raise ValueError(f"unknown backend {backend!r}: use 'process' or 'ray'")
    return SerialExecutor() if workers <= 1 else LokyExecutor(workers)
