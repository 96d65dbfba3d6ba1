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

import numba
import numpy as np
from numba import njit

from ..jit import CHUNKS, EXACT
from ..jit.compile import available_cores
from ..jit.internals import atomic_add, atomic_cas, atomic_load, monotonic_ns, spin_pause, yield_core

# Slots of the ``sync`` array (int64); 8 apart keeps the counters on their own cache line.
ARRIVED = 0   # members at the current barrier
GENERATION = 8  # barriers completed
ROLL = 16      # members that answered the roll call
MODE = 24      # 0 gathering, 1 team, 2 one member alone
ABORT = 32     # set when a member gave up waiting at a barrier: everyone leaves
FAILED = 40    # set when a member failed (could not allocate its work space)
# A timed frame (see :func:`barrier`): TIMED set for the whole frame, RELEASED the clock when the
# last barrier let the members go, ARRIVALS the sum of the members' clocks on arriving at this one.
TIMED = 48
RELEASED = 50
ARRIVALS = 56
#: Where a timed frame's laps are summed, two slots a lap: the nanoseconds from the barrier before
#: it to the one that ends it (the slowest member's work), and the members' nanoseconds spent
#: waiting at the one that ends it.
LAPS = 64
#: Laps a frame may time (the barriers of one substep).
MOST_LAPS = 16
#: The ``lap`` of a timed frame's first barrier, which only starts the clock.
START = -1
SYNC_SIZE = LAPS + 2 * MOST_LAPS

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
def barrier(sync: np.ndarray, size: int, generation: int, lap: int) -> int:
    """Wait until all ``size`` members have arrived; returns the next generation number, or -1
    when the frame was given up (``sync[ABORT]``): the member must then leave at once.

    Every member passes its own count of barriers met; the last to arrive resets the arrival
    count and then advances the shared generation, which releases the others (and publishes
    everything written before the barrier to them). A member that waits longer than
    :data:`BARRIER_NS` sets ``sync[ABORT]``, which releases everyone.

    In a timed frame (``sync[TIMED]``) each member adds its clock on arriving, and the last to
    arrive adds to the slots of ``lap`` (the pass the barrier ends) the time since the last
    release and the members' time spent waiting (:func:`_lap_done`). ``lap`` :data:`START` only
    starts the clock once the whole team is there: a member the system starts late would
    otherwise have its lateness counted as the others' waiting in the first lap.
    """
    timed = sync[TIMED] != 0
    if size == 1:
        if timed:
            _lap_done(sync, lap, monotonic_ns(), 0)
        return generation + 1
    if atomic_load(sync, ABORT) != 0:
        return -1
    if timed:
        atomic_add(sync, ARRIVALS, monotonic_ns())
    if atomic_add(sync, ARRIVED, 1) == size - 1:
        if timed:
            now = monotonic_ns()
            _lap_done(sync, lap, now, size * now - sync[ARRIVALS])
            sync[ARRIVALS] = 0
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


@njit(inline="always", **EXACT)
def _lap_done(sync: np.ndarray, lap: int, now: int, waited: int) -> None:
    # ``lap`` ends at ``now`` (its last member has arrived), the members having waited ``waited``
    # ns at its barrier; the next lap starts
    if lap >= 0:
        k = LAPS + 2 * lap
        sync[k] += now - sync[RELEASED]
        sync[k + 1] += waited
    sync[RELEASED] = now


@njit(**EXACT)
def share(count: int, member: int, size: int) -> tuple[int, int]:
    """The member's contiguous part [lo, hi) of ``count`` work items."""
    return member * count // size, (member + 1) * count // size


@njit(inline="always", **EXACT)
def chunk_of(items: np.ndarray, c: int) -> np.ndarray:
    """Work item ``c`` of :data:`~clothsim.jit.CHUNKS`: the c-th contiguous part of ``items``."""
    lo, hi = share(items.shape[0], c, CHUNKS)
    return items[lo:hi]
