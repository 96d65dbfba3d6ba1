"""Verlet's advance rules: the spec's damped step (:func:`verlet_chunk`, the fast path's, run by
the thread team) and, for ``damping_mode = "rate"``, the second-order start and the rate-damped step.

Rate damping solves x'' = F/m - c x' with f = exp(-c dt) per substep. The velocity term is scaled
by f and the force term by phi = (1 - f)/(c dt), which keeps the scheme second order (at c = 0,
phi = 1 and f = 1: plain Verlet).
"""

from __future__ import annotations

from typing import NamedTuple

import numpy as np
from numba import njit

from ...jit import CHUNKS, KERNEL
from ..team import share


class VerletRate(NamedTuple):
    """The rate-damped Verlet rule: 1 / mass."""

    inv_mass: float


@njit(inline="always", **KERNEL)
def verlet_chunk(pos: np.ndarray, last: np.ndarray, forces: np.ndarray, pins: np.ndarray, h2: float, keep: float,
                 c: int) -> None:
    """Work item ``c`` of the spec's damped step x' = x + keep*(x - x_last) + a*dt^2: the c-th
    of CHUNKS point ranges, stepped in one contiguous (vectorised) sweep; the pinned points
    (``pins``) are put back afterwards (``last`` holds their unchanged position)."""
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


@njit(**KERNEL)
def verlet_one(pos: np.ndarray, last: np.ndarray, forces: np.ndarray, pins: np.ndarray, h2: float, keep: float,
               c: int) -> None:
    """:func:`verlet_chunk` compiled on its own, for a call by address."""
    verlet_chunk(pos, last, forces, pins, h2, keep, c)


@njit(**KERNEL)
def verlet_start(pos: np.ndarray, last: np.ndarray, vel: np.ndarray, forces: np.ndarray, free: np.ndarray,
                 inv_mass: float, dt: float, c: float) -> None:
    """Second-order start: last = x0 - v0*dt + a0*dt^2/2 with a0 = F/m - c*v0 (free points)."""
    for ax in range(3):
        for k in range(free.shape[0]):
            p = free[k]
            a0 = forces[ax, p] * inv_mass - c * vel[ax, p]
            last[ax, p] = pos[ax, p] - vel[ax, p] * dt + 0.5 * a0 * dt * dt


@njit(**KERNEL)
def verlet_rate_step(pos: np.ndarray, last: np.ndarray, forces: np.ndarray, free: np.ndarray, inv_mass: float,
                     dt: float, f: float, phi: float) -> None:
    """x' = x + f*(x - x_last) + phi*a*dt^2 for free points; last <- x."""
    h2 = dt * dt * inv_mass * phi
    for ax in range(3):
        x = pos[ax]
        xl = last[ax]
        fa = forces[ax]
        for k in range(free.shape[0]):
            p = free[k]
            cur = x[p]
            x[p] = cur + f * (cur - xl[p]) + fa[p] * h2
            xl[p] = cur
