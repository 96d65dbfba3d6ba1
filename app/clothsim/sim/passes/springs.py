"""Force accumulation: uniform external acceleration plus Hooke springs.

State is struct-of-arrays: ``pos`` and ``forces`` are (3, N). The springs come as whole-grid
streams (:func:`clothsim.cloth.spring_streams`): block g joins every point ``a`` to
``a + offset[g]``, with zero stiffness where the grid has no such spring. Two passes, each
split over the cores:

1. per spring: the Hooke force of the spring starting at ``a`` goes to ``buf[g, :, a + offset]``;
2. per point: ``F[p] = m g + sum_g buf[g, :, p + offset] - buf[g, :, p]`` (the spring that starts
   at p pulls it one way, the one that ends at p the other).

Every entry of either pass depends on its own inputs only and is summed in a fixed block order,
so the result is bit-for-bit the same whatever the number of threads. Both passes read and
write contiguous slices: an index such as ``pos[a0 + t]`` would be treated as possibly
negative, and Numba's wraparound check turns such loads into slow gathers.
"""

from __future__ import annotations

import numpy as np
from numba import njit, prange

from ...jit import CHUNKS, KERNEL, PARALLEL
from ..team import share



@njit(inline="always", **KERNEL)
def spring_job(pos: np.ndarray, offsets: np.ndarray, k: np.ndarray, rest: np.ndarray, buf: np.ndarray,
               job: int) -> None:
    """Work item ``job`` of :func:`spring_pass`: one point range (``job // blocks``) of one block."""
    n = pos.shape[1]
    blocks = offsets.shape[0]
    c = job // blocks
    g = job % blocks
    off = offsets[g]
    m = n - off
    lo, hi = share(m, c, CHUNKS)
    ln = hi - lo
    ax = pos[0, lo:hi]
    ay = pos[1, lo:hi]
    az = pos[2, lo:hi]
    bx = pos[0, lo + off : hi + off]
    by = pos[1, lo + off : hi + off]
    bz = pos[2, lo + off : hi + off]
    kk = k[g, lo:hi]
    rl = rest[g, lo:hi]
    ox = buf[g, 0, lo + off : hi + off]
    oy = buf[g, 1, lo + off : hi + off]
    oz = buf[g, 2, lo + off : hi + off]
    for t in range(ln):
        ex = bx[t] - ax[t]
        ey = by[t] - ay[t]
        ez = bz[t] - az[t]
        d = np.sqrt(ex * ex + ey * ey + ez * ez)
        f = kk[t] * (d - rl[t]) / d if d > 0.0 else 0.0
        ox[t] = f * ex
        oy[t] = f * ey
        oz[t] = f * ez


@njit(**KERNEL)
def spring_jobs(pos: np.ndarray, offsets: np.ndarray, k: np.ndarray, rest: np.ndarray, buf: np.ndarray,
                lo: int, hi: int) -> None:
    """Work items ``lo`` to ``hi`` of :func:`spring_pass`, compiled on its own: the thread team's
    member calls it by address (:mod:`clothsim.sim.solvers.frame`)."""
    for job in range(lo, hi):
        spring_job(pos, offsets, k, rest, buf, job)


@njit(**PARALLEL)
def spring_pass(pos: np.ndarray, offsets: np.ndarray, k: np.ndarray, rest: np.ndarray, buf: np.ndarray) -> None:
    """buf[g, :, a + offset[g]] = k * (|d| - rest) * d / |d| with d = pos[b] - pos[a], b = a + offset[g]."""
    # point range major, so each core writes the part of ``buf`` it gathers next
    for job in prange(offsets.shape[0] * CHUNKS):
        spring_job(pos, offsets, k, rest, buf, job)


@njit(inline="always", **KERNEL)
def gather_chunk(offsets: np.ndarray, buf: np.ndarray, mass: float, gravity: np.ndarray, forces: np.ndarray,
                 c: int) -> None:
    """Work item ``c`` of :func:`gather_pass`: the forces on the c-th of CHUNKS point ranges."""
    n = forces.shape[1]
    lo, hi = share(n, c, CHUNKS)
    for ax in range(3):
        f = forces[ax, lo:hi]
        f[:] = mass * gravity[ax]
        for g in range(offsets.shape[0]):
            off = offsets[g]
            pulled = buf[g, ax, lo + off : hi + off]
            pushed = buf[g, ax, lo:hi]
            for t in range(hi - lo):
                f[t] += pulled[t] - pushed[t]


@njit(**KERNEL)
def gather_one(offsets: np.ndarray, buf: np.ndarray, mass: float, gravity: np.ndarray, forces: np.ndarray,
               c: int) -> None:
    """:func:`gather_chunk` compiled on its own, for a call by address."""
    gather_chunk(offsets, buf, mass, gravity, forces, c)


@njit(**PARALLEL)
def gather_pass(offsets: np.ndarray, buf: np.ndarray, mass: float, gravity: np.ndarray, forces: np.ndarray) -> None:
    """forces[:, p] = mass * gravity + sum over blocks of buf[g, :, p + offset] - buf[g, :, p]."""
    for c in prange(CHUNKS):
        gather_chunk(offsets, buf, mass, gravity, forces, c)


@njit(**KERNEL)
def accumulate_forces(pos: np.ndarray, forces: np.ndarray, stream: tuple, mass: float, gravity: np.ndarray) -> None:
    """forces = mass * gravity + the sum of the Hooke forces ``k * (length - rest)`` of all springs.

    ``stream`` is the tuple returned by :func:`clothsim.cloth.spring_streams` (bending blocks'
    stiffness already scaled).
    """
    offsets, k, rest, buf = stream
    spring_pass(pos, offsets, k, rest, buf)
    gather_pass(offsets, buf, mass, gravity, forces)
