"""The springs of a cloth made from a triangle mesh, and their stretch limit.

A grid cloth's springs are whole-grid streams (:mod:`.springs`): every spring of a block joins a
point to the point a fixed offset further. A mesh's springs join arbitrary pairs, so they come
as lists: spring ``s`` joins ``si[s]`` to ``sj[s]``. Two passes, as the grid's:

1. per spring (:func:`spring_work`): the Hooke force ``k (|e| - rest) e / |e|``, ``e = x_j - x_i``,
   into ``buf[:, s]`` (a member writes its own ranges of springs: no cache line written by two);
2. per point (:func:`gather`): the forces of its springs, read through a table of each point's
   springs (``start``/``spring``/``sign``, in the order of the springs' indices), added to what
   the grid's gather and the other forces left there, then scaled to the point's own mass.

A mesh's points do not all weigh the same (a third of each adjacent triangle's area times the
density), while every integrator divides the forces by one mass, the mean ``m``. So the gather
leaves ``(m / m_p) F_p`` for point p, with ``F_p`` its whole force (gravity ``m_p g`` included):
divided by ``m``, that is ``F_p / m_p``. Every entry is summed in a fixed order, so the result does
not depend on the number of threads.

Provot's limit runs over the structural springs (:func:`stretch_limit`), Gauss-Seidel in the
springs' order, on one thread.
"""

from __future__ import annotations

from typing import NamedTuple

import numpy as np
from numba import njit

from ...jit import CHUNKS, KERNEL
from ..team import share


class MeshSprings(NamedTuple):
    """A mesh cloth's springs (see the module's notes): ends, stiffness, rest lengths and the
    per-spring force buffer (3, S); each point's springs
    (``start`` (N + 1,), ``spring``, ``sign``);
    the mass factors ``ratio = m / m_p`` and ``extra = m_p - m``; and Provot's springs (the
    structural ones: ends and rest lengths)."""

    si: np.ndarray
    sj: np.ndarray
    k: np.ndarray
    rest: np.ndarray
    buf: np.ndarray
    start: np.ndarray
    spring: np.ndarray
    sign: np.ndarray
    ratio: np.ndarray
    extra: np.ndarray
    gravity: np.ndarray
    pi: np.ndarray
    pj: np.ndarray
    prest: np.ndarray


def pack_mesh_springs(si: np.ndarray, sj: np.ndarray, k: np.ndarray, rest: np.ndarray, structural: np.ndarray,
                      point_mass: np.ndarray, gravity: np.ndarray) -> MeshSprings:
    """The group for springs ``si``-``sj`` with stiffness ``k`` and rest lengths ``rest``
    (``structural``: which of them Provot limits) on points of masses ``point_mass``."""
    n = point_mass.shape[0]
    # unsigned indices: a load through one needs no wrap-around check (a signed one is a gather
    # with a test for a negative index)
    si = np.ascontiguousarray(si, dtype=np.uint64)
    sj = np.ascontiguousarray(sj, dtype=np.uint64)
    ends = np.concatenate([si, sj]).astype(np.int64)
    springs = np.concatenate([np.arange(si.shape[0]), np.arange(sj.shape[0])])
    signs = np.concatenate([np.ones(si.shape[0]), -np.ones(sj.shape[0])])
    order = np.lexsort((springs, ends))
    start = np.zeros(n + 1, dtype=np.uint64)
    np.cumsum(np.bincount(ends, minlength=n), out=start[1:])
    mean = float(point_mass.mean())
    return MeshSprings(si, sj, np.ascontiguousarray(k, dtype=np.float64), np.ascontiguousarray(rest, dtype=np.float64),
                       np.zeros((3, si.shape[0])), start, np.ascontiguousarray(springs[order], dtype=np.uint64),
                       np.ascontiguousarray(signs[order]), mean / point_mass, point_mass - mean,
                       np.asarray(gravity, dtype=np.float64), np.ascontiguousarray(si[structural]),
                       np.ascontiguousarray(sj[structural]), np.ascontiguousarray(rest[structural], dtype=np.float64))


@njit(**KERNEL)
def spring_work(g: MeshSprings, pos: np.ndarray, c0: int, c1: int) -> None:
    """Work items ``c0..c1-1`` (of CHUNKS spring ranges) of the per-spring pass.

    Each range in two loops: the springs' end-to-end vectors gathered into ``buf``, then the forces
    from them in place, a loop over contiguous arrays that the compiler vectorises (the square
    root and the division, four springs at once: 31 against 55 us a substep for 14,406 springs on
    one core). A range is the same whatever the number of members, so the same springs take the
    vector path and the same the remainder's: the bits do not depend on the thread count.

    (The Hooke force has the shape of the grid's ``spring_job``, which the duplicate-code scan
    pairs; that one reads both ends as slices at a fixed offset, this one gathers them first.)"""
    si, sj, k, rest = g.si, g.sj, g.k, g.rest
    px, py, pz = pos[0], pos[1], pos[2]
    ex, ey, ez = g.buf[0], g.buf[1], g.buf[2]
    count = si.shape[0]
    for c in range(c0, c1):
        # slices and an index from 0: an index the compiler cannot prove >= 0 gets a wrap-around
        # test on every load, and the loop is not vectorised
        lo, hi = share(count, c, CHUNKS)
        ia, ib, kk, rl = si[lo:hi], sj[lo:hi], k[lo:hi], rest[lo:hi]
        ox, oy, oz = ex[lo:hi], ey[lo:hi], ez[lo:hi]
        for t in range(hi - lo):
            a = ia[t]
            b = ib[t]
            ox[t] = px[b] - px[a]
            oy[t] = py[b] - py[a]
            oz[t] = pz[b] - pz[a]
        for t in range(hi - lo):
            x = ox[t]
            y = oy[t]
            z = oz[t]
            d = np.sqrt(x * x + y * y + z * z)
            f = kk[t] * (d - rl[t]) / d if d > 0.0 else 0.0
            ox[t] = f * x
            oy[t] = f * y
            oz[t] = f * z


@njit(**KERNEL)
def gather(g: MeshSprings, forces: np.ndarray, c: int) -> None:
    """The c-th point range's forces made whole and scaled (see the module's notes)."""
    lo, hi = share(forces.shape[1], c, CHUNKS)
    # slices and indices from 0 or unsigned: no wrap-around test on the loads (see spring_work)
    bx, by, bz, spring, sign = g.buf[0], g.buf[1], g.buf[2], g.spring, g.sign
    start, extra, ratio = g.start[lo : hi + 1], g.extra[lo:hi], g.ratio[lo:hi]
    fxs, fys, fzs = forces[0, lo:hi], forces[1, lo:hi], forces[2, lo:hi]
    gx = g.gravity[0]
    gy = g.gravity[1]
    gz = g.gravity[2]
    for p in range(hi - lo):
        fx = fxs[p] + extra[p] * gx
        fy = fys[p] + extra[p] * gy
        fz = fzs[p] + extra[p] * gz
        for t in range(start[p], start[p + 1]):
            s = spring[t]
            w = sign[t]
            fx += w * bx[s]
            fy += w * by[s]
            fz += w * bz[s]
        r = ratio[p]
        fxs[p] = fx * r
        fys[p] = fy * r
        fzs[p] = fz * r


@njit(**KERNEL)
def add_spring_forces(g: MeshSprings | None, pos: np.ndarray, forces: np.ndarray) -> None:
    """Both passes over the whole cloth when ``g`` is a mesh's springs (nothing for a grid:
    the branch is pruned), after the grid's springs and the other forces."""
    if g is None:
        return
    spring_work(g, pos, 0, CHUNKS)
    for c in range(CHUNKS):
        gather(g, forces, c)


@njit(**KERNEL)
def stretch_limit(pos: np.ndarray, pinned: np.ndarray, g: MeshSprings, limit: float) -> None:
    """Provot's limit over the structural springs, in place, spring after spring: a spring longer
    than ``limit`` x rest is shortened to it, the correction split evenly or given wholly to the
    free end; springs with both ends pinned are left alone (the grid's rule, :mod:`.provot`).

    (The correction of one spring repeats the grid's ``_provot_row``, which the duplicate-code
    scan pairs: the grid's row is slices of a band read at fixed offsets, after a vectorised scan;
    this is one list reached through indices; a shared helper would hand six coordinates back and
    forth, and the grid's compiled row, which keeps its bits, would change.)"""
    lim2 = limit * limit
    pi, pj, prest = g.pi, g.pj, g.prest
    px, py, pz = pos[0], pos[1], pos[2]
    for s in range(pi.shape[0]):
        a = pi[s]
        b = pj[s]
        ex = px[b] - px[a]
        ey = py[b] - py[a]
        ez = pz[b] - pz[a]
        d2 = ex * ex + ey * ey + ez * ez
        r = prest[s]
        if d2 <= lim2 * r * r:
            continue
        pa = pinned[a]
        pb = pinned[b]
        if pa and pb:
            continue
        d = np.sqrt(d2)
        excess = (d - limit * r) / d
        wa = 0.0 if pa else (1.0 if pb else 0.5)
        wb = 1.0 - wa if (pa or pb) else 0.5
        px[a] += ex * excess * wa
        py[a] += ey * excess * wa
        pz[a] += ez * excess * wa
        px[b] -= ex * excess * wb
        py[b] -= ey * excess * wb
        pz[b] -= ez * excess * wb


# The calls the shared passes make, with the cloth's mesh group (None for a grid cloth) as an
# argument: Numba prunes a branch on an argument that is None, so a grid cloth compiles none of
# this module's code. (Not inlined: inlined, the group is no longer an argument, and the branch
# is typed for None.)


@njit(**KERNEL)
def mesh_work(g: MeshSprings | None, pos: np.ndarray, c0: int, c1: int) -> None:
    """:func:`spring_work` for a mesh cloth; nothing for a grid."""
    if g is None:
        return
    spring_work(g, pos, c0, c1)


@njit(**KERNEL)
def mesh_gather(g: MeshSprings | None, forces: np.ndarray, c: int) -> None:
    """:func:`gather` for a mesh cloth; nothing for a grid."""
    if g is None:
        return
    gather(g, forces, c)


@njit(**KERNEL)
def mesh_limit(pos: np.ndarray, pinned: np.ndarray, g: MeshSprings | None, limit: float, run: bool) -> bool:
    """For a mesh cloth, :func:`stretch_limit` (when ``run``: the member that runs it) and True;
    False for a grid (whose caller runs the grid's Provot instead)."""
    if g is None:
        return False
    if run:
        stretch_limit(pos, pinned, g, limit)
    return True
