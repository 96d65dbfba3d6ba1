"""The one clock of prescribed motion, and the one compiled evaluation of a motion track
(:func:`clothsim.motion.position_at`): moving pins, the wind's gusts, and the poses of moving
colliders of every kind (spheres, planes, capsules, boxes, meshes) all read time from here.

The clock is a (2,) array owned by the :class:`~clothsim.sim.Simulation`: (time at the last
re-plan, substeps run since), and the substep length ``dt`` of the plan. Substep ``s`` of a call
starts at ``clock[0] + (clock[1] + s) * dt``: computed, not summed up, so a run gives the same
times however its substeps are grouped into calls (frames, single substeps in the blow-up replay,
pass by pass in the profiler).

Moving spheres, planes, capsules and boxes count a substep's times from the call's start
(:func:`call_time` plus ``step`` substep lengths, the end one substep length later), the others
from the clock's base (:func:`substep_time`): each is the arithmetic its motion had before they
shared this clock, so no scene's numbers changed when they did (the two differ in the last bits).

One dispatcher for the track on purpose: Numba's on-disk cache files a function's compiled
versions under the function and its argument types, not its options, so two dispatchers of the
same Python function with different options load each other's code (a pin then landed one ulp
off its track). Like every :data:`~clothsim.jit.EXACT` kernel it is compiled without fast-math
whoever calls it: the frame kernel's contracted arithmetic once put a pin one ulp off rest +
``Track.at(t)``, the Python evaluation the tests compare with.
"""

from __future__ import annotations

import numpy as np
from numba import njit

from ..motion import position_at
from ..jit import EXACT

track_at = njit(**EXACT)(position_at)


@njit(**EXACT)
def substep_time(clock: np.ndarray, step: int, dt: float) -> float:
    """Time (s) at the start of substep ``step`` of a call (``step`` may be one past the last, for
    the time at a substep's end): clock = (base time, substeps since)."""
    return clock[0] + (clock[1] + step) * dt


@njit(**EXACT)
def call_time(clock: np.ndarray, dt: float) -> float:
    """Time (s) at the start of a call: the simulation's ``time``."""
    return clock[0] + clock[1] * dt
