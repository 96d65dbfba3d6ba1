"""A cold start on two cores: compile one kernel in a second process while this one compiles the
rest (:func:`compile_elsewhere`), and the small kernels every run meets after its first frame
(:func:`warm_side_kernels`), which the layers above register here (:func:`on_warm`); and one
compile of a plan for all the processes that start it at once (:func:`compiling_alone`).

Kernels are compiled for this CPU the first time a scene needs them and cached on disk (next to
the installed package, or in Numba's user-wide cache when that folder is read-only). A warm
cache compiles nothing.
"""

from __future__ import annotations

import fcntl
import hashlib
import os
import pickle
import subprocess
import sys
from collections.abc import Callable, Iterator
from contextlib import contextmanager
from typing import Any

from .internals import cache_folder, is_cached

__all__ = ["JOBS_VARIABLE", "available_cores", "compile_elsewhere", "compiling_alone", "on_warm",
           "side_kernels_beside", "warm_side_kernels"]

#: Set to 1 to compile everything in this process (no second process on a cold start).
JOBS_VARIABLE = "CLOTHSIM_COMPILE_JOBS"
_CHILD = ("import importlib, pickle, sys\nfor module, name, argtypes in pickle.load(sys.stdin.buffer): "
          "getattr(importlib.import_module(module), name).compile(argtypes)")

_WARMERS: dict[str, Callable[[], None]] = {}
_BESIDE: dict[str, tuple[tuple[Any, tuple], ...]] = {}


def available_cores() -> int:
    """Cores this process may run on (its CPU affinity, else the machine's count)."""
    try:
        return len(os.sched_getaffinity(0))
    except (AttributeError, OSError):
        return os.cpu_count() or 1


def on_warm(name: str, warm: Callable[[], None], beside: tuple[tuple[Any, tuple], ...] = ()) -> None:
    """Register ``warm`` (compiles or loads a small kernel with the argument types it will get)
    under ``name``, to run in :func:`warm_side_kernels`; a module registers its own when imported.
    ``beside``: the (dispatcher, argtypes) ``warm`` compiles, where a cold start may compile them
    in its second process instead (:func:`side_kernels_beside`)."""
    _WARMERS[name] = warm
    if beside:
        _BESIDE[name] = beside


def side_kernels_beside() -> tuple[tuple[Any, tuple], ...]:
    """The registered side kernels a cold start compiles in its second process (see
    :func:`compile_elsewhere`'s ``also``): those whose warm-up would otherwise add to the first
    process's share."""
    return tuple(kernel for name in sorted(_BESIDE) for kernel in _BESIDE[name])


def warm_side_kernels(beside: bool | None = None) -> None:
    """Compile (or load) the small kernels registered with :func:`on_warm`, in name order: the
    blow-up guard, the rest detector and (once the renderer is imported) its kernels. ``beside``
    False: only those a cold start does not compile in its second process; True: only those it
    does (:func:`side_kernels_beside`); None: all."""
    for name in sorted(_WARMERS):
        if beside is None or beside == (name in _BESIDE):
            _WARMERS[name]()


def compile_elsewhere(dispatcher: Any, argtypes: tuple, meanwhile: Callable[[], None],
                      also: tuple[tuple[Any, tuple], ...] = (), before: tuple[tuple[Any, tuple], ...] = ()) -> None:
    """Compile each (dispatcher, argtypes) of ``before``, then ``dispatcher`` for ``argtypes``, then
    each of ``also``, into the on-disk cache in a second process while ``meanwhile()`` compiles the
    rest here; the caller then loads them from the cache (``also`` and ``before`` are for sharing
    the work out evenly: ``before`` holds callees that ``meanwhile`` reaches last, by then cached).

    Numba compiles one function at a time per process (a global lock), so a cold start on two
    cores otherwise leaves one idle. (A fork of this process, which skips the 0.7 s import, was
    slower: 19.7-20.8 s against 16.2-18.0 s for a cold ``simulate``, alternated; copy-on-write
    faults of two processes both busy in Python, presumably.) The wait shows as the kernel's own
    compile (the notice and ``clothsim bench compile`` see it so). With one core, with ``CLOTHSIM_COMPILE_JOBS=1``, when
    the kernel is cached already, or when the second process fails, nothing is done here and the
    caller's compile happens in this process as usual.
    """
    from numba.core import event

    if os.environ.get(JOBS_VARIABLE) == "1" or available_cores() < 2 or is_cached(dispatcher, argtypes):
        meanwhile()
        return
    try:
        child = subprocess.Popen([sys.executable, "-c", _CHILD], stdin=subprocess.PIPE, stdout=subprocess.DEVNULL,
                                 stderr=subprocess.DEVNULL)
        jobs = [(d.py_func.__module__, d.py_func.__name__, types) for d, types in (*before, (dispatcher, argtypes),
                                                                                     *also)]
        child.stdin.write(pickle.dumps(jobs))
        child.stdin.close()
    except OSError:
        meanwhile()
        return
    try:
        meanwhile()
        with event.trigger_event("numba:compile", data={"dispatcher": dispatcher, "args": argtypes,
                                                        "return_type": None}):
            child.wait()
    finally:
        if child.poll() is None:  # interrupted: the second process goes too
            child.kill()
            child.wait()


@contextmanager
def compiling_alone(dispatcher: Any, argtypes: tuple) -> Iterator[None]:
    """Hold a lock, for as long as the body runs, that every process sharing ``dispatcher``'s
    cache folder takes for the same kernel and argument types.

    The body compiles the kernel (and what goes with it) into the cache. Processes that start
    the same plan at once on a cold cache (the test suite's workers, a sweep's local workers)
    otherwise all compiled it, each on its own core; now the first compiles and the others wait,
    then load it. Uncontended, the lock costs a file open (cheaper than asking the cache whether
    the kernel is there); a cache folder where no lock file can be made takes none. The lock goes
    with its process (a killed process leaves nothing held).
    """
    folder = cache_folder(dispatcher)
    if folder is None:
        yield
        return
    func = dispatcher.py_func
    key = hashlib.sha256(f"{func.__module__}.{func.__qualname__}{argtypes}".encode()).hexdigest()[:20]
    try:
        fd = os.open(os.path.join(folder, f"{func.__name__}.{key}.compiling"), os.O_RDWR | os.O_CREAT, 0o644)
    except OSError:
        yield
        return
    try:
        try:
            fcntl.flock(fd, fcntl.LOCK_EX)
        except OSError:  # a file system without locks (some network mounts): compile unlocked
            pass
        yield
    finally:
        os.close(fd)  # releases the lock
