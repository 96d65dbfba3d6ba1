"""Time integration of the free (unpinned) points, addressed by index."""

from __future__ import annotations

import numpy as np
from numba import njit, prange

from .jit import CHUNKS, PARALLEL


@njit(**PARALLEL)
def verlet(pos: np.ndarray, last: np.ndarray, forces: np.ndarray, pins: np.ndarray, inv_mass: float,
           dt: float, keep: float) -> None:
    """The spec's damped Verlet step, x' = x + keep*(x - x_last) + a*dt^2, for the unpinned points.

    ``keep`` is ``1 - damping/100``; ``pins`` holds the indices of the pinned points. Arrays are
    (3, N). Every point is stepped in one contiguous (vectorised) sweep and the few pinned ones
    are put back afterwards: ``last`` holds their unchanged position, so they never move.
    """
    h2 = dt * dt * inv_mass
    n = pos.shape[1]
    # point range major, matching the force passes, so each core keeps its points in cache
    for job in prange(3 * CHUNKS):
        c = job % 3
        lo = (job // 3) * n // CHUNKS
        hi = (job // 3 + 1) * n // CHUNKS
        x = pos[c, lo:hi]
        xl = last[c, lo:hi]
        f = forces[c, lo:hi]
        for p in range(hi - lo):
            cur = x[p]
            x[p] = cur + keep * (cur - xl[p]) + f[p] * h2
            xl[p] = cur
    for c in range(3):
        for k in range(pins.shape[0]):
            pos[c, pins[k]] = last[c, pins[k]]
