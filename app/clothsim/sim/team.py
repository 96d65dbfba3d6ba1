"""A team of threads that stays together for a whole frame, meeting at spin barriers.

Each ``prange`` loop costs a fork and a join: 2.5 us on this project's 2-core machine, about
70 us per substep for the seven parallel passes of a self-colliding cloth. A frame is instead one
``prange`` over the team's members; members split each pass between them and wait for each
other at a barrier (70 ns) before the next pass reads what the last one wrote.

A barrier only works if every member runs at the same time on its own thread. OpenMP (Numba's
usual threading layer) gives each of ``prange(n)``'s n iterations its own thread, but a layer
may also run iterations one after another (TBB can), where the first member would wait forever.
So members first answer a roll call: once all have arrived, they are known to run side by side
and work as a team; if they have not all arrived within :data:`ROLL_CALL_NS` (10 ms, read from
the monotonic clock), the first member to give up runs the frame alone and the others find it
taken and leave. The caller then runs alone for a while and tries the team again later (see
:class:`TeamPlan`), so one slow roll call on a busy machine does not cost the threads for good.

Every wait is bounded in time: a member that has waited :data:`BARRIER_NS` (2 s) at a barrier
for a member that never comes (one that failed, or a thread the system stopped) raises the
``ABORT`` flag, and every member leaves at its next barrier. The caller restores the state the
frame started from and runs it again alone. Waits spin, then yield the core, so a machine with
more threads than cores (many runs side by side) is slowed, not stalled.

Results never depend on the team size: every pass is cut into the same work items (see
:data:`clothsim.jit.CHUNKS`) whoever runs them.
"""

from __future__ import annotations

import platform
import time

import numba
import numpy as np
from llvmlite import ir
from numba import njit, types
from numba.core import cgutils
from numba.extending import intrinsic

from ..jit import EXACT
from ..jit.compile import available_cores

# Slots of the ``sync`` array (int64); 8 apart keeps the counters on their own cache line.
ARRIVED = 0   # members at the current barrier
GENERATION = 8  # barriers completed
ROLL = 16      # members that answered the roll call
MODE = 24      # 0 gathering, 1 team, 2 one member alone
ABORT = 32     # set when a member gave up waiting at a barrier: everyone leaves
FAILED = 40    # set when a member failed (could not allocate its work space)
SYNC_SIZE = 48

_GATHERING, _TEAM = 0, 1
#: ``sync[MODE]`` after a frame whose members could not run side by side.
ALONE = 2
# Spins before a waiting member starts yielding its core (and reading the clock).
_SPINS = 200
#: How long the first member waits at the roll call for the others before running alone.
ROLL_CALL_NS = 10_000_000
#: How long a member waits at a barrier before it gives the frame up (a member is missing).
BARRIER_NS = 2_000_000_000
#: Frames run alone after a failed roll call before the team is tried again; doubles with each
#: failure in a row, up to :data:`MAX_BACKOFF`.
FIRST_BACKOFF = 8
MAX_BACKOFF = 1024


def new_sync() -> np.ndarray:
    """The counters one team uses (zeroed by the frame kernel at each start)."""
    return np.zeros(SYNC_SIZE, dtype=np.int64)


def team_size() -> int:
    """Members for the next frame: Numba's thread count (``NUMBA_NUM_THREADS``), capped at the
    useful size. A pass has :data:`~clothsim.jit.CHUNKS` work items, so more members than
    that only wait at every barrier; more members than cores take turns on a core while the
    rest spin."""
    from ..jit import CHUNKS

    return max(1, min(int(numba.get_num_threads()), CHUNKS, available_cores()))


class TeamPlan:
    """How many members the next frame gets, recovering from failed roll calls.

    A roll call fails when the members could not all start within 10 ms (a loaded machine, or a
    threading layer that runs them one after another). The frame then ran alone, correctly; the
    next :data:`FIRST_BACKOFF` frames run alone too, then the team is tried again. Each failure
    in a row doubles the wait (up to :data:`MAX_BACKOFF` frames); a frame the team ran resets it.
    """

    def __init__(self) -> None:
        self.backoff = 0
        self.alone_for = 0
        self.failed_roll_calls = 0
        self.aborted_frames = 0

    def size(self) -> int:
        """Members for the next kernel call."""
        if self.alone_for > 0:
            self.alone_for -= 1
            return 1
        return team_size()

    def after(self, sync: np.ndarray, size: int) -> None:
        """Record how a kernel call with ``size`` members went."""
        if size <= 1:
            return
        if sync[MODE] == ALONE or sync[ABORT] != 0:
            self.failed_roll_calls += sync[MODE] == ALONE
            self.aborted_frames += sync[ABORT] != 0
            self.backoff = min(MAX_BACKOFF, FIRST_BACKOFF if self.backoff == 0 else 2 * self.backoff)
            self.alone_for = self.backoff
        else:
            self.backoff = 0


def _element_pointer(context, builder, arr_type, arr, idx):  # noqa: ANN001, ANN202
    ary = context.make_array(arr_type)(context, builder, arr)
    return cgutils.get_item_pointer(context, builder, arr_type, ary, [idx])


@intrinsic
def atomic_add(typingctx, arr, idx, val):  # noqa: ANN001, ANN201
    """arr[idx] += val atomically (sequentially consistent); returns the old value."""
    sig = types.int64(arr, idx, val)

    def codegen(context, builder, sig, args):  # noqa: ANN001, ANN202
        ptr = _element_pointer(context, builder, sig.args[0], args[0], args[1])
        return builder.atomic_rmw("add", ptr, args[2], "seq_cst")

    return sig, codegen


@intrinsic
def atomic_load(typingctx, arr, idx):  # noqa: ANN001, ANN201
    """arr[idx] read with acquire ordering (sees every write made before the matching release)."""
    sig = types.int64(arr, idx)

    def codegen(context, builder, sig, args):  # noqa: ANN001, ANN202
        ptr = _element_pointer(context, builder, sig.args[0], args[0], args[1])
        return builder.load_atomic(ptr, "acquire", 8)

    return sig, codegen


@intrinsic
def atomic_cas(typingctx, arr, idx, expected, new):  # noqa: ANN001, ANN201
    """Set arr[idx] = new if it equals expected; returns the value found."""
    sig = types.int64(arr, idx, expected, new)

    def codegen(context, builder, sig, args):  # noqa: ANN001, ANN202
        ptr = _element_pointer(context, builder, sig.args[0], args[0], args[1])
        pair = builder.cmpxchg(ptr, args[2], args[3], "seq_cst", "seq_cst")
        return builder.extract_value(pair, 0)

    return sig, codegen


@intrinsic
def yield_core(typingctx):  # noqa: ANN001, ANN201
    """sched_yield(): let another runnable thread have this core."""
    sig = types.int32()

    def codegen(context, builder, sig, args):  # noqa: ANN001, ANN202
        fn = cgutils.get_or_insert_function(builder.module, ir.FunctionType(ir.IntType(32), []), "sched_yield")
        return builder.call(fn, [])

    return sig, codegen


_CLOCK = getattr(time, "CLOCK_MONOTONIC", 1)


@intrinsic
def monotonic_ns(typingctx):  # noqa: ANN001, ANN201
    """clock_gettime(CLOCK_MONOTONIC) in nanoseconds (a vDSO call: no system call, ~20 ns)."""
    sig = types.int64()

    def codegen(context, builder, sig, args):  # noqa: ANN001, ANN202
        i64 = ir.IntType(64)
        timespec = ir.LiteralStructType([i64, i64])
        fn = cgutils.get_or_insert_function(
            builder.module, ir.FunctionType(ir.IntType(32), [ir.IntType(32), timespec.as_pointer()]),
            "clock_gettime")
        ts = cgutils.alloca_once(builder, timespec)
        builder.call(fn, [ir.Constant(ir.IntType(32), _CLOCK), ts])
        sec = builder.load(cgutils.gep_inbounds(builder, ts, 0, 0))
        nsec = builder.load(cgutils.gep_inbounds(builder, ts, 0, 1))
        return builder.add(builder.mul(sec, ir.Constant(i64, 1_000_000_000)), nsec)

    return sig, codegen


_X86 = platform.machine().lower() in ("x86_64", "amd64", "i686", "i386")


@intrinsic
def spin_pause(typingctx):  # noqa: ANN001, ANN201
    """The CPU's spin-wait hint (x86 ``pause``): a waiting member leaves the core's execution
    units, and a sibling hardware thread, to the members still working."""
    sig = types.void()

    def codegen(context, builder, sig, args):  # noqa: ANN001, ANN202
        if _X86:
            fn = cgutils.get_or_insert_function(builder.module, ir.FunctionType(ir.VoidType(), []),
                                                "llvm.x86.sse2.pause")
            builder.call(fn, [])
        return context.get_dummy_value()

    return sig, codegen


@njit(**EXACT)
def roll_call(sync: np.ndarray, size: int) -> int:
    """Called once by every member; returns the team size to work with, or 0: leave at once.

    Returns ``size`` when all members arrived (they run concurrently), 1 to the single member
    that runs the frame alone when they did not arrive within :data:`ROLL_CALL_NS`, 0 to the rest.
    """
    if size == 1:
        return 1
    if atomic_add(sync, ROLL, 1) == size - 1:
        atomic_cas(sync, MODE, _GATHERING, _TEAM)
    waited = 0
    began = 0
    while True:
        mode = atomic_load(sync, MODE)
        if mode == _TEAM:
            return size
        if mode == ALONE:
            return 0
        waited += 1
        spin_pause()
        if waited > _SPINS:
            yield_core()
            now = monotonic_ns()
            if began == 0:
                began = now
            elif now - began > ROLL_CALL_NS and atomic_cas(sync, MODE, _GATHERING, ALONE) == _GATHERING:
                return 1


@njit(**EXACT)
def barrier(sync: np.ndarray, size: int, generation: int) -> int:
    """Wait until all ``size`` members have arrived; returns the next generation number, or -1
    when the frame was given up (``sync[ABORT]``): the member must then leave at once.

    Every member passes its own count of barriers met; the last to arrive resets the arrival
    count and then advances the shared generation, which releases the others (and publishes
    everything written before the barrier to them). A member that waits longer than
    :data:`BARRIER_NS` sets ``sync[ABORT]``, which releases everyone.
    """
    if size == 1:
        return generation + 1
    if atomic_load(sync, ABORT) != 0:
        return -1
    if atomic_add(sync, ARRIVED, 1) == size - 1:
        sync[ARRIVED] = 0
        atomic_add(sync, GENERATION, 1)
        return generation + 1
    waited = 0
    began = 0
    while atomic_load(sync, GENERATION) == generation:
        spin_pause()
        waited += 1
        if waited > _SPINS:
            yield_core()
            if atomic_load(sync, ABORT) != 0:
                return -1
            now = monotonic_ns()
            if began == 0:
                began = now
            elif now - began > BARRIER_NS:
                atomic_cas(sync, ABORT, 0, 1)
                return -1
    return generation + 1


@njit(**EXACT)
def share(count: int, member: int, size: int) -> tuple[int, int]:
    """The member's contiguous part [lo, hi) of ``count`` work items."""
    return member * count // size, (member + 1) * count // size
