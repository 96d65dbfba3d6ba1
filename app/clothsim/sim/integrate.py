"""Time integration of the free (unpinned) points, addressed by index."""

from __future__ import annotations

import numpy as np
from numba import njit

from .jit import FASTMATH


@njit(cache=True, fastmath=FASTMATH)
def verlet(pos: np.ndarray, last: np.ndarray, forces: np.ndarray, free: np.ndarray, inv_mass: float,
           dt: float, keep: float) -> None:
    """The spec's damped Verlet step, x' = x + keep*(x - x_last) + a*dt^2, for points in ``free``.

    ``keep`` is ``1 - damping/100``. Pinned points are not in ``free`` and never move.
    Arrays are (3, N).
    """
    h2 = dt * dt * inv_mass
    for c in range(3):
        x = pos[c]
        xl = last[c]
        f = forces[c]
        for k in range(free.shape[0]):
            p = free[k]
            cur = x[p]
            x[p] = cur + keep * (cur - xl[p]) + f[p] * h2
            xl[p] = cur
