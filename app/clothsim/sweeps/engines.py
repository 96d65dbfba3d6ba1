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
import threading
import time
from collections.abc import Iterator
from concurrent.futures import Executor, ProcessPoolExecutor

from ..errors import ClothsimError

__all__ = ["CLUSTER_HINT", "default_workers", "open_executor"]

CLUSTER_HINT = "pip install 'clothsim[cluster]'"
_WATCH_SECONDS = 0.5  # how often a worker checks that the command is still running
_REAP_SECONDS = 5.0  # how long an ended sweep waits for its killed workers and the pool's thread


def default_workers() -> int:
    """The number of cores this process may use."""
    try:
        return max(1, len(os.sched_getaffinity(0)))
    except (AttributeError, OSError):  # pragma: no cover - not Linux
        return max(1, os.cpu_count() or 1)


def _init_worker(parent: int, render_threads: int) -> None:
    # Ctrl-C reaches the whole process group: the command handles it (and stops the workers),
    # a worker must not print its own traceback.
    signal.signal(signal.SIGINT, signal.SIG_IGN)
    _leave_stdout()
    _follow_parent(parent)
    # One Numba thread per worker process: the processes are the parallelism. Results are
    # bit-identical for any thread count, so this changes the speed only.
    import numba

    numba.set_num_threads(1)
    # The software renderer (Mesa's llvmpipe) starts one thread per core in every process that
    # draws: two workers on two cores then ran four render threads and scaled 1.40x instead of
    # nearer 2x (4 views x every channel, 256x256). Each worker gets its share of the cores; a
    # user's value wins. The images do not depend on it (llvmpipe's tiles are the same bits).
    os.environ.setdefault("LP_NUM_THREADS", str(render_threads))


def _leave_stdout() -> None:
    """Point the worker's standard output at its standard error, and its input at /dev/null.

    A spawned worker inherits the command's descriptors. Holding its stdout would keep a pipe
    such as ``clothsim sweep ... | tail`` open after the command has ended (killed, say), so the
    reader would wait for the workers. Nothing a worker prints is the command's output; anything
    it does print (a library's notice) still reaches the terminal, as a diagnostic.
    """
    sys.stdout.flush()
    os.dup2(2, 1)
    with contextlib.suppress(OSError):
        null = os.open(os.devnull, os.O_RDONLY)
        os.dup2(null, 0)
        os.close(null)


def _follow_parent(parent: int) -> None:
    """End this worker when the command that started it is gone (killed with ``kill -9``, say).

    On Linux the operating system sends SIGKILL when the thread that started the worker ends
    (``PR_SET_PDEATHSIG``; this works even while a Numba kernel holds the interpreter lock, and
    the sweep's calling thread outlives its workers). Everywhere, a thread checks every half
    second that the parent is still this process's parent. A worker writes no file, so ending
    it at once loses nothing the command could still use.
    """
    with contextlib.suppress(Exception):
        import ctypes

        libc = ctypes.CDLL(None, use_errno=True)
        arg = ctypes.c_ulong
        libc.prctl(1, arg(int(signal.SIGKILL)), arg(0), arg(0), arg(0))  # PR_SET_PDEATHSIG
    if os.getppid() != parent:  # already gone before the line above took effect
        os._exit(1)

    def watch() -> None:
        while os.getppid() == parent:
            time.sleep(_WATCH_SECONDS)
        os._exit(1)

    threading.Thread(target=watch, name="clothsim-parent-watch", daemon=True).start()


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

    The pool starts a process per submitted task until it has ``count``. Meanwhile SIGINT is
    blocked in this thread, and a process started then inherits that (across exec): a Ctrl-C
    during a worker's start-up cannot print a traceback from inside multiprocessing, and the
    worker ignores it once started. A Ctrl-C that reaches this process meanwhile is held, not
    dropped, and raised as soon as the workers are up (it used to be ignored here, and a Ctrl-C
    in that window was lost: the sweep ran on).
    """
    import threading
    from concurrent.futures import wait

    main = threading.current_thread() is threading.main_thread()
    previous = signal.getsignal(signal.SIGINT) if main else None
    held: list[int] = []
    if main and previous is not None:
        signal.signal(signal.SIGINT, lambda signum, frame: held.append(signum))
        signal.pthread_sigmask(signal.SIG_BLOCK, {signal.SIGINT})
    try:
        started = [executor.submit(os.getpid) for _ in range(count)]
    finally:
        if main and previous is not None:
            # A Ctrl-C held for this thread is taken here, still blocked: unblocked, it would run
            # the handler above only at the interpreter's next check, which may come after the
            # previous handler is back (then a SIG_IGN drops it, "ignored due to race condition").
            if signal.SIGINT in signal.sigpending() and signal.sigtimedwait({signal.SIGINT}, 0) is not None:
                held.append(signal.SIGINT)
            signal.pthread_sigmask(signal.SIG_UNBLOCK, {signal.SIGINT})
            signal.signal(signal.SIGINT, previous)
    if held:
        raise KeyboardInterrupt
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
            executor = client.get_executor()
            try:
                yield executor
            except BaseException:
                # Interrupted or failed: cancel the queued and running runs now. Leaving the
                # executor's block would wait for every one of them (shutdown(wait=True)), and
                # their results would be thrown away.
                with contextlib.suppress(Exception):
                    executor.shutdown(wait=False)
                raise
            executor.shutdown(wait=True)
        finally:
            client.close()
        return
    # spawn, not fork: a parent that ran Numba's parallel kernels (the bench's plain loop, a
    # notebook) holds a threading layer that is not safe to fork.
    context = multiprocessing.get_context("spawn")
    count = workers or default_workers()
    _start_tracker()
    executor = ProcessPoolExecutor(max_workers=count, mp_context=context, initializer=_init_worker,
                                   initargs=(os.getpid(), max(1, default_workers() // count)))
    try:
        _start_workers(executor, count)
        yield executor
    except BaseException:
        # Interrupted or failed: stop the workers now rather than wait for their runs to end.
        internals = _internals(executor)  # shutdown() forgets them
        _stop_workers(executor, signal.SIGKILL)
        executor.shutdown(wait=False, cancel_futures=True)
        _unblock_pool(*internals)
        raise
    # Every result is in and a worker keeps nothing worth saving (it writes no file), so it is
    # ended here instead of tearing down its interpreter: a spawned worker's exit unloads
    # Numba and the kernels, 0.2-0.35 s that the sweep would otherwise wait for at its end.
    if not getattr(executor, "_pending_work_items", None):
        _stop_workers(executor, signal.SIGTERM)
    executor.shutdown(wait=True)


def _start_tracker() -> None:
    """Start multiprocessing's resource tracker without its warning about leaked semaphores.

    The tracker outlives a command killed with ``kill -9`` until its workers have followed it
    (well under a second), then removes the pool's semaphores and would print a two-line
    ``UserWarning`` about each "leak" under whatever the user typed next; the semaphores are
    removed either way. The tracker takes its warning options from this process's when it
    starts, so the filter is added for that moment only.
    """
    from multiprocessing import resource_tracker

    options = list(sys.warnoptions)
    sys.warnoptions.append("ignore:resource_tracker:UserWarning")
    try:
        with contextlib.suppress(Exception):
            resource_tracker.ensure_running()
    finally:
        sys.warnoptions[:] = options


def _stop_workers(executor: ProcessPoolExecutor, how: signal.Signals) -> None:
    for process in list((getattr(executor, "_processes", None) or {}).values()):
        with contextlib.suppress(Exception):
            os.kill(process.pid, how)


def _internals(executor: ProcessPoolExecutor) -> tuple[list, object, object]:
    return (list((getattr(executor, "_processes", None) or {}).values()),
            getattr(executor, "_result_queue", None), getattr(executor, "_executor_manager_thread", None))


def _unblock_pool(processes: list, result_queue: object, thread: object) -> None:
    """Let the pool's manager thread end after its workers were killed, and wait for it.

    A worker killed while sending a result leaves half a message in the result pipe; the
    manager thread then blocks reading the rest, for ever, since this process holds the
    pipe's write end too, and the interpreter joins that thread at exit: the command would
    print its error and never return. Once the workers are dead, closing this process's
    write end turns that read into an end of file, which the thread handles as a broken pool.
    """
    deadline = time.monotonic() + _REAP_SECONDS
    for process in processes:
        with contextlib.suppress(Exception):
            process.join(max(0.0, deadline - time.monotonic()))
    with contextlib.suppress(Exception):
        result_queue._writer.close()  # type: ignore[attr-defined]
    if isinstance(thread, threading.Thread):
        thread.join(max(0.0, deadline - time.monotonic()))
