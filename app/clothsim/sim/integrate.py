"""Time integration of the free (unpinned) points, addressed by index."""

from __future__ import annotations

import numpy as np
from numba import njit, prange

from .jit import CHUNKS, KERNEL, PARALLEL
from .team import share


@njit(inline="always", **KERNEL)
def verlet_chunk(pos: np.ndarray, last: np.ndarray, forces: np.ndarray, pins: np.ndarray, h2: float, keep: float,
                 c: int) -> None:
    """Work item ``c`` of :func:`verlet`: the c-th of CHUNKS point ranges, pinned points put back."""
    n = pos.shape[1]
    lo, hi = share(n, c, CHUNKS)
    for ax in range(3):
        x = pos[ax, lo:hi]
        xl = last[ax, lo:hi]
        f = forces[ax, lo:hi]
        for p in range(hi - lo):
            cur = x[p]
            x[p] = cur + keep * (cur - xl[p]) + f[p] * h2
            xl[p] = cur
    for k in range(pins.shape[0]):
        q = pins[k]
        if lo <= q < hi:
            for ax in range(3):
                pos[ax, q] = last[ax, q]


@njit(**PARALLEL)
def verlet(pos: np.ndarray, last: np.ndarray, forces: np.ndarray, pins: np.ndarray, inv_mass: float,
           dt: float, keep: float) -> None:
    """The spec's damped Verlet step, x' = x + keep*(x - x_last) + a*dt^2, for the unpinned points.

    ``keep`` is ``1 - damping/100``; ``pins`` holds the indices of the pinned points. Arrays are
    (3, N). Every point is stepped in one contiguous (vectorised) sweep and the few pinned ones
    are put back afterwards: ``last`` holds their unchanged position, so they never move.
    """
    h2 = dt * dt * inv_mass
    # point ranges in the same order as the force passes, so each core keeps its points in cache
    for c in prange(CHUNKS):
        verlet_chunk(pos, last, forces, pins, h2, keep, c)
