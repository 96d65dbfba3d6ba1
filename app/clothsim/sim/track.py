"""The one compiled evaluation of a motion track (:func:`clothsim.motion.position_at`), shared by
moving pins, moving colliders and moving meshes.

One dispatcher on purpose: Numba's on-disk cache files a function's compiled versions under the
function and its argument types, not its options, so two dispatchers of the same Python function
with different options load each other's code (a pin then landed one ulp off its track).
``fastmath=False`` is said explicitly: Numba compiles a callee that does not set it with its
caller's fast-math flags, and the frame kernel's contracted arithmetic put a pin one ulp off rest +
``Track.at(t)``, the Python evaluation the tests compare with.
"""

from __future__ import annotations

from numba import njit

from ..motion import position_at
from ..jit import EXACT

IEEE = {**EXACT, "fastmath": False}

track_at = njit(**IEEE)(position_at)
