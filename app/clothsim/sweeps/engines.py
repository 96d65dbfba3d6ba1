"""Where a sweep's runs execute: local worker processes, or an existing Dask distributed cluster.

Both are a :class:`concurrent.futures.Executor`: a ``ProcessPoolExecutor`` whose workers each set
Numba to one thread and keep one renderer for their lifetime (see :mod:`.runner`), or the
executor of a ``dask.distributed.Client`` connected to the scheduler's address. The caller
submits :func:`.runner.run` and collects results with ``concurrent.futures.as_completed``; the
results (arrays, images) come back to it, so a cluster needs no shared file system.
"""

from __future__ import annotations

import contextlib
import multiprocessing
import os
import signal
import sys
from collections.abc import Iterator
from concurrent.futures import Executor, ProcessPoolExecutor

from ..errors import ClothsimError

__all__ = ["CLUSTER_HINT", "default_workers", "open_executor"]

CLUSTER_HINT = "pip install 'clothsim[cluster]'"


def default_workers() -> int:
    """The number of cores this process may use."""
    try:
        return max(1, len(os.sched_getaffinity(0)))
    except (AttributeError, OSError):  # pragma: no cover - not Linux
        return max(1, os.cpu_count() or 1)


def _init_worker() -> None:
    # Ctrl-C reaches the whole process group: the command handles it (and stops the workers),
    # a worker must not print its own traceback.
    signal.signal(signal.SIGINT, signal.SIG_IGN)
    # One Numba thread per worker process: the processes are the parallelism. Results are
    # bit-identical for any thread count, so this changes the speed only.
    import numba

    numba.set_num_threads(1)


def import_distributed(label: str = "--scheduler") -> object:
    """``dask.distributed``, or one line naming the extra to install."""
    try:
        import distributed
    except ImportError:
        raise ClothsimError(f"{label}: needs dask.distributed, which is not installed: {CLUSTER_HINT}") from None
    return distributed


def _start_workers(executor: ProcessPoolExecutor, count: int) -> None:
    """Start every worker now, with Ctrl-C ignored from their first instruction, and wait until
    they answer: a worker that cannot start is one clear error here, not a run lost later.

    The pool starts a process per submitted task until it has ``count``; a process started while
    SIGINT is ignored inherits that (across exec), so a Ctrl-C during its start-up cannot print a
    traceback from inside multiprocessing. The command's own handler is back right after.
    """
    import threading
    from concurrent.futures import wait

    main = threading.current_thread() is threading.main_thread()
    previous = signal.getsignal(signal.SIGINT) if main else None
    if main and previous is not None:
        signal.signal(signal.SIGINT, signal.SIG_IGN)
    try:
        started = [executor.submit(os.getpid) for _ in range(count)]
    finally:
        if main and previous is not None:
            signal.signal(signal.SIGINT, previous)
    wait(started)
    if any(f.exception() is not None for f in started):
        raise ClothsimError(f"the sweep's worker processes stopped while starting{_start_hint()}")


def _start_hint() -> str:
    # A spawned worker first imports the caller's main script; a script that calls sweep() at
    # its top level then starts a sweep inside every worker, which multiprocessing refuses.
    main = sys.modules.get("__main__")
    path = getattr(main, "__file__", None)
    spec = getattr(getattr(main, "__spec__", None), "name", "") or ""
    if path is None or spec.startswith("clothsim") or os.path.basename(path) == "clothsim":
        return " (see the messages above)"
    return (f" (see the messages above): a script such as {os.path.basename(path)} must call clothsim.sweep "
            "under 'if __name__ == \"__main__\":', since each worker process imports the main script")


@contextlib.contextmanager
def open_executor(workers: int | None = None, scheduler: str | None = None) -> Iterator[Executor]:
    """An executor for the runs: ``workers`` local processes, or the Dask cluster at ``scheduler``."""
    if scheduler is not None:
        distributed = import_distributed()
        try:
            client = distributed.Client(scheduler, timeout="20s", set_as_default=False)
        except (OSError, TimeoutError, ValueError) as exc:
            reason = " ".join(str(exc).split()) or type(exc).__name__
            raise ClothsimError(f"--scheduler {scheduler}: cannot connect: {reason}") from None
        try:
            with client.get_executor() as executor:
                yield executor
        finally:
            client.close()
        return
    # spawn, not fork: a parent that ran Numba's parallel kernels (the bench's plain loop, a
    # notebook) holds a threading layer that is not safe to fork.
    context = multiprocessing.get_context("spawn")
    count = workers or default_workers()
    executor = ProcessPoolExecutor(max_workers=count, mp_context=context, initializer=_init_worker)
    try:
        _start_workers(executor, count)
        yield executor
    except BaseException:
        # Interrupted or failed: stop the workers now rather than wait for their runs to end.
        _stop_workers(executor, signal.SIGKILL)
        executor.shutdown(wait=False, cancel_futures=True)
        raise
    # Every result is in and a worker keeps nothing worth saving (it writes no file), so it is
    # ended here instead of tearing down its interpreter: a spawned worker's exit unloads
    # Numba and the kernels, 0.2-0.35 s that the sweep would otherwise wait for at its end.
    if not getattr(executor, "_pending_work_items", None):
        _stop_workers(executor, signal.SIGTERM)
    executor.shutdown(wait=True)


def _stop_workers(executor: ProcessPoolExecutor, how: signal.Signals) -> None:
    for process in list((getattr(executor, "_processes", None) or {}).values()):
        with contextlib.suppress(Exception):
            os.kill(process.pid, how)
