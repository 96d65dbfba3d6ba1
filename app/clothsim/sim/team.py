"""A team of threads that stays together for a whole frame, meeting at spin barriers.

Each ``prange`` loop costs a fork and a join: 2.5 us on this project's 2-core machine, about
70 us per substep for the seven parallel passes of a self-colliding cloth. A frame is instead one
``prange`` over the team's members; members split each pass between them and wait for each
other at a barrier (70 ns) before the next pass reads what the last one wrote.

A barrier only works if every member runs at the same time on its own thread. OpenMP (Numba's
usual threading layer) gives each of ``prange(n)``'s n iterations its own thread, but a layer
may also run iterations one after another (TBB can), where the first member would wait forever.
So members first answer a roll call: once all have arrived, they are known to run side by side
and work as a team; if they have not all arrived after a while (10.4-10.6 ms measured here), the
first member to give up runs the frame alone, the others find it taken and leave, and the caller
uses one member from then on. Waits spin, then yield the core, so a machine with more threads than cores (many runs
side by side) is slowed, not stalled.

Results never depend on the team size: every pass is cut into the same work items (see
:data:`clothsim.sim.jit.CHUNKS`) whoever runs them.
"""

from __future__ import annotations

import platform

import numba
import numpy as np
from llvmlite import ir
from numba import njit, types
from numba.core import cgutils
from numba.extending import intrinsic

from .jit import EXACT

# Slots of the ``sync`` array (int64); 8 apart keeps the counters on their own cache line.
ARRIVED = 0   # members at the current barrier
GENERATION = 8  # barriers completed
ROLL = 16      # members that answered the roll call
MODE = 24      # 0 gathering, 1 team, 2 one member alone
SYNC_SIZE = 32

_GATHERING, _TEAM = 0, 1
#: ``sync[MODE]`` after a frame whose members could not run side by side.
ALONE = 2
# Spins before a waiting member starts yielding its core, and yields before a roll call gives up.
_SPINS = 200
_ROLL_YIELDS = 20000


def new_sync() -> np.ndarray:
    """The counters one team uses (zeroed by the frame kernel at each start)."""
    return np.zeros(SYNC_SIZE, dtype=np.int64)


def team_size() -> int:
    """Members for the next frame: Numba's thread count (``NUMBA_NUM_THREADS``)."""
    return int(numba.get_num_threads())


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
    that runs the frame alone when they did not, 0 to the rest.
    """
    if size == 1:
        return 1
    if atomic_add(sync, ROLL, 1) == size - 1:
        atomic_cas(sync, MODE, _GATHERING, _TEAM)
    waited = 0
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
            if waited > _SPINS + _ROLL_YIELDS and atomic_cas(sync, MODE, _GATHERING, ALONE) == _GATHERING:
                return 1


@njit(**EXACT)
def barrier(sync: np.ndarray, size: int, generation: int) -> int:
    """Wait until all ``size`` members have arrived; returns the next generation number.

    Every member passes its own count of barriers met; the last to arrive resets the arrival
    count and then advances the shared generation, which releases the others (and publishes
    everything written before the barrier to them).
    """
    if size == 1:
        return generation + 1
    if atomic_add(sync, ARRIVED, 1) == size - 1:
        sync[ARRIVED] = 0
        atomic_add(sync, GENERATION, 1)
    else:
        waited = 0
        while atomic_load(sync, GENERATION) == generation:
            spin_pause()
            waited += 1
            if waited > _SPINS:
                yield_core()
    return generation + 1


@njit(**EXACT)
def share(count: int, member: int, size: int) -> tuple[int, int]:
    """The member's contiguous part [lo, hi) of ``count`` work items."""
    return member * count // size, (member + 1) * count // size
