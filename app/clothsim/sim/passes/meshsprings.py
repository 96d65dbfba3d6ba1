"""The springs of a cloth made from a triangle mesh, and their stretch limit.

A grid cloth's springs are whole-grid streams (:mod:`.springs`): every spring of a block joins a
point to the point a fixed offset further. A mesh's springs join arbitrary pairs; those of an
offset (larger index less smaller) that many points share still make a stream, in the grid's
layout and through the grid's kernels (:func:`mesh_streams`: a mesh made row by row, such as a
sheet or a tube, puts nearly all its springs there). The rest come as a list: spring ``s`` joins
``si[s]`` to ``sj[s]``, ``si[s] < sj[s]``, sorted by ``si``. Two passes, as the grid's:

1. per spring (:func:`spring_work`): the Hooke force ``k (|e| - rest) e / |e|``, ``e = x_j - x_i``,
   into ``buf[:, s]`` (a member writes its own ranges of springs: no cache line written by two);
2. per point (:func:`gather`): the forces of its springs, those that start at it (a range of the
   list, ``out``) less those that end at it (read through the table ``into``/``spring``), added
   to what the streams and the other forces left there, then scaled to the point's own mass.

A mesh's points do not all weigh the same (a third of each adjacent triangle's area times the
density), while every integrator divides the forces by one mass, the mean ``m``. So the gather
leaves ``(m / m_p) F_p`` for point p, with ``F_p`` its whole force (gravity ``m_p g`` included):
divided by ``m``, that is ``F_p / m_p``. Every entry is summed in a fixed order, so the result does
not depend on the number of threads.

Provot's limit runs over the structural springs (:func:`stretch_limit`), Gauss-Seidel, in two
phases as the grid's bands and cuts: first the springs with both ends in one of the CHUNKS point
ranges, range by range (ranges share no point, so the members of the thread team take theirs
side by side), then the springs between two ranges, in order, on one member. Which member takes
a range changes nothing, so neither does the number of threads.
"""

from __future__ import annotations

from typing import NamedTuple

import numpy as np
from numba import njit

from ...jit import CHUNKS, KERNEL
from ..team import share


class MeshSprings(NamedTuple):
    """A mesh cloth's listed springs (see the module's notes): ends, stiffness, rest lengths and
    the per-spring force buffer (3, S); the springs that start at point p (``out[p]`` to
    ``out[p + 1]``) and those that end there (``spring[into[p]:into[p + 1]]``); the mass factors
    ``ratio = m / m_p`` and ``extra = m_p - m``; and Provot's springs (all the structural ones,
    streamed or listed: ends and rest lengths), those within point range c from ``pstart[c]`` to
    ``pstart[c + 1]``, those between ranges from ``pstart[CHUNKS]`` on."""

    si: np.ndarray
    sj: np.ndarray
    k: np.ndarray
    rest: np.ndarray
    buf: np.ndarray
    out: np.ndarray
    into: np.ndarray
    spring: np.ndarray
    ratio: np.ndarray
    extra: np.ndarray
    gravity: np.ndarray
    pi: np.ndarray
    pj: np.ndarray
    prest: np.ndarray
    pstart: np.ndarray


#: An offset that at least this share of the points start a spring at makes a stream: a stream
#: costs a vectorised pass over every point, a listed spring several times one stream entry.
STREAM_SHARE = 0.125

#: At most this many streams (each a (3, N) buffer and a pass over every point).
MAX_STREAMS = 16


def mesh_streams(i: np.ndarray, j: np.ndarray, k: np.ndarray, rest: np.ndarray,
                 n: int) -> tuple[tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray], np.ndarray]:
    """The springs ``i``-``j`` (stiffness ``k``, rest lengths ``rest``, on ``n`` points) that go
    into streams, in the layout of :func:`clothsim.cloth.spring_streams` (offsets, k, rest,
    buffer), and a mask of the springs left for the list. A stream holds every spring of its
    offset; the offsets taken are the most common ones, most common first, while each is shared
    by at least ``STREAM_SHARE`` of the points."""
    a = np.minimum(i, j).astype(np.int64)
    b = np.maximum(i, j).astype(np.int64)
    off = b - a
    values, counts = np.unique(off, return_counts=True)
    # most common first, the smaller offset first among equals: a fixed order
    rank = np.lexsort((values, -counts))
    taken = [int(values[r]) for r in rank[:MAX_STREAMS] if counts[r] >= STREAM_SHARE * n]
    offsets = np.array(taken, dtype=np.int64)
    ks = np.zeros((len(taken), n))
    rests = np.zeros((len(taken), n))
    listed = np.ones(i.shape[0], dtype=bool)
    for g, o in enumerate(taken):
        mine = off == o
        ks[g, a[mine]] = k[mine]
        rests[g, a[mine]] = rest[mine]
        listed &= ~mine
    width = n + (int(offsets.max()) if taken else 0)
    return (offsets, ks, rests, np.zeros((len(taken), 3, width))), listed


def pack_mesh_springs(si: np.ndarray, sj: np.ndarray, k: np.ndarray, rest: np.ndarray, structural: np.ndarray,
                      listed: np.ndarray, point_mass: np.ndarray, gravity: np.ndarray) -> MeshSprings:
    """The group for springs ``si``-``sj`` with stiffness ``k`` and rest lengths ``rest`` on points
    of masses ``point_mass``: the ``listed`` ones in the list, every ``structural`` one for Provot."""
    n = point_mass.shape[0]
    a = np.minimum(si, sj)[listed].astype(np.int64)
    b = np.maximum(si, sj)[listed].astype(np.int64)
    order = np.lexsort((b, a))
    a, b = a[order], b[order]
    into = np.lexsort((np.arange(b.shape[0]), b))
    # unsigned indices: a load through one needs no wrap-around check (a signed one is a gather
    # with a test for a negative index)
    out_start = np.zeros(n + 1, dtype=np.uint64)
    np.cumsum(np.bincount(a, minlength=n), out=out_start[1:])
    into_start = np.zeros(n + 1, dtype=np.uint64)
    np.cumsum(np.bincount(b, minlength=n), out=into_start[1:])
    mean = float(point_mass.mean())
    # Provot's springs by the point range of their ends (CHUNKS: those between two ranges), each
    # group in the springs' order
    pi, pj, prest = si[structural], sj[structural], rest[structural]
    bounds = np.array([share(n, c, CHUNKS)[0] for c in range(CHUNKS)] + [n])
    ci = np.searchsorted(bounds, pi, side="right") - 1
    cj = np.searchsorted(bounds, pj, side="right") - 1
    group = np.where(ci == cj, ci, CHUNKS)
    porder = np.argsort(group, kind="stable")
    pstart = np.zeros(CHUNKS + 1, dtype=np.int64)
    np.cumsum(np.bincount(group, minlength=CHUNKS + 1)[:CHUNKS], out=pstart[1:])
    return MeshSprings(np.ascontiguousarray(a, dtype=np.uint64), np.ascontiguousarray(b, dtype=np.uint64),
                       np.ascontiguousarray(k[listed][order], dtype=np.float64),
                       np.ascontiguousarray(rest[listed][order], dtype=np.float64),
                       np.zeros((3, a.shape[0])), out_start, into_start, np.ascontiguousarray(into, dtype=np.uint64),
                       mean / point_mass, point_mass - mean, np.asarray(gravity, dtype=np.float64),
                       np.ascontiguousarray(pi[porder], dtype=np.uint64),
                       np.ascontiguousarray(pj[porder], dtype=np.uint64),
                       np.ascontiguousarray(prest[porder], dtype=np.float64), pstart)


@njit(**KERNEL)
def spring_work(g: MeshSprings, pos: np.ndarray, c0: int, c1: int) -> None:
    """Work items ``c0..c1-1`` (of CHUNKS spring ranges) of the per-spring pass.

    Each range in two loops: the springs' end-to-end vectors gathered into ``buf``, then the forces
    from them in place, a loop over contiguous arrays that the compiler vectorises (the square
    root and the division, several springs at once; docs/performance.md has the figures). A range is the same whatever the number of members, so the same springs take the
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
    bx, by, bz, spring = g.buf[0], g.buf[1], g.buf[2], g.spring
    out, into, extra, ratio = g.out[lo : hi + 1], g.into[lo : hi + 1], g.extra[lo:hi], g.ratio[lo:hi]
    fxs, fys, fzs = forces[0, lo:hi], forces[1, lo:hi], forces[2, lo:hi]
    gx = g.gravity[0]
    gy = g.gravity[1]
    gz = g.gravity[2]
    if out[hi - lo] == out[0] and into[hi - lo] == into[0]:
        # no listed spring touches the range (a mesh whose springs are all in streams): the
        # scaling alone, a loop the compiler vectorises
        for p in range(hi - lo):
            r = ratio[p]
            fxs[p] = (fxs[p] + extra[p] * gx) * r
            fys[p] = (fys[p] + extra[p] * gy) * r
            fzs[p] = (fzs[p] + extra[p] * gz) * r
        return
    for p in range(hi - lo):
        # the springs that start at p and those that end there summed apart: two chains of
        # additions, not one twice as long (the sums' latency, not the loads, set this loop's pace)
        ox = 0.0
        oy = 0.0
        oz = 0.0
        for s in range(out[p], out[p + 1]):
            ox += bx[s]
            oy += by[s]
            oz += bz[s]
        ix = 0.0
        iy = 0.0
        iz = 0.0
        for t in range(into[p], into[p + 1]):
            s = spring[t]
            ix += bx[s]
            iy += by[s]
            iz += bz[s]
        r = ratio[p]
        fxs[p] = (fxs[p] + extra[p] * gx + (ox - ix)) * r
        fys[p] = (fys[p] + extra[p] * gy + (oy - iy)) * r
        fzs[p] = (fzs[p] + extra[p] * gz + (oz - iz)) * r


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
def stretch_limit(pos: np.ndarray, pinned: np.ndarray, g: MeshSprings, limit: float, s0: int, s1: int) -> None:
    """Provot's limit over Provot's springs ``s0..s1-1``, in place, spring after spring: a spring longer
    than ``limit`` x rest is shortened to it, the correction split evenly or given wholly to the
    free end; springs with both ends pinned are left alone (the grid's rule, :mod:`.provot`).

    (The correction of one spring repeats the grid's ``_provot_row``, which the duplicate-code
    scan pairs: the grid's row is slices of a band read at fixed offsets, after a vectorised scan;
    this is one list reached through indices; a shared helper would hand six coordinates back and
    forth, and the grid's compiled row, which keeps its bits, would change.)"""
    lim2 = limit * limit
    pi, pj, prest = g.pi, g.pj, g.prest
    px, py, pz = pos[0], pos[1], pos[2]
    for s in range(s0, s1):
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
def mesh_limit(pos: np.ndarray, pinned: np.ndarray, g: MeshSprings | None, limit: float, c0: int, c1: int,
               between: bool) -> bool:
    """For a mesh cloth, :func:`stretch_limit` over the springs within point ranges ``c0..c1-1``
    and, when ``between``, then over those between ranges (see the module's notes), and True;
    False for a grid (whose caller runs the grid's Provot instead)."""
    if g is None:
        return False
    for c in range(c0, c1):
        stretch_limit(pos, pinned, g, limit, g.pstart[c], g.pstart[c + 1])
    if between:
        stretch_limit(pos, pinned, g, limit, g.pstart[CHUNKS], g.pi.shape[0])
    return True
