"""The one clock of prescribed motion, and the one compiled evaluation of a motion track
(:func:`clothsim.motion.position_at`): moving pins, the wind's gusts, and the poses of moving
colliders of every kind (spheres, planes, capsules, boxes, meshes) all read time from here.

The clock is a (2,) array owned by the :class:`~clothsim.sim.Simulation`: (time at the last
re-plan, substeps run since), and the substep length ``dt`` of the plan. Substep ``s`` of a call
starts at ``clock[0] + (clock[1] + s) * dt``: computed, not summed up, so a run gives the same
times however its substeps are grouped into calls (frames, single substeps in the blow-up replay,
pass by pass in the profiler).

One dispatcher for the track on purpose: Numba's on-disk cache files a function's compiled
versions under the function and its argument types, not its options, so two dispatchers of the
same Python function with different options load each other's code (a pin then landed one ulp
off its track). ``fastmath=False`` is said explicitly: Numba compiles a callee that does not set
it with its caller's fast-math flags, and the frame kernel's contracted arithmetic put a pin one
ulp off rest + ``Track.at(t)``, the Python evaluation the tests compare with.
"""

from __future__ import annotations

import numpy as np
from numba import njit

from ..motion import position_at
from ..jit import EXACT

IEEE = {**EXACT, "fastmath": False}

track_at = njit(**IEEE)(position_at)


@njit(**IEEE)
def substep_time(clock: np.ndarray, step: int, dt: float) -> float:
    """Time (s) at the start of substep ``step`` of a call (``step`` may be one past the last, for
    the time at a substep's end): clock = (base time, substeps since)."""
    return clock[0] + (clock[1] + step) * dt
