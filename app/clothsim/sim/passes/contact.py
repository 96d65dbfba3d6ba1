"""Self-collision by contact (``simulation.self_collision: "contact"``): point-triangle and
edge-edge proximity, repulsion with friction, and a conservative displacement bound that lets no
element pass through another over a substep's whole motion. It is two passes of the substep: the
response in the self-collision slot (before the colliders, so that they have the last word on a
point the response pushed into them) and the bound at the very end (after Provot: no later pass
may move a point past it).

The method is the displacement bound of Vertex Block Descent and Offset Geometric Contact (Chen
et al. 2024, 2025): from a crossing-free reference state, every point gets a ball of radius
``GAMMA`` (< 1/2) times its distance to the nearest element it does not belong to (point-triangle
and edge-edge, both ways, within the query radius), less a floor (``FLOOR``) that keeps every pair
further apart than rounding. A state in which every point lies in its ball is crossing-free, and so
is every state on the straight path from the reference to it (a ball is convex): two elements at
distance d each move less than d/2. In each substep:

1. (self-collision slot) the points whose position after the integrator has left their ball
   (a pin, or a free point whose ball is not tiny: ROOMY) or that the bound held back since
   their reference was set have their references moved to where the substep started, one by
   one (:func:`rereference`); the whole reference is rebuilt from there instead (crossing-free,
   by the same argument) when more than ``LOCAL_SHARE`` of the points call for it, when a
   point's position at the substep's start has left its ball, and when there is none (the first
   substep, a frame whose pins move, after ``reset``: the simulation clears ``meta[VALID]``);
2. (self-collision slot) every stored pair closer than the contact distance is pushed apart along its reference normal
   (inelastically, plus a fraction of the overlap), with Coulomb friction on the pair's relative
   tangential motion; corrections are averaged per point (Jacobi, in pair order), in one sweep,
   or in ``SWEEPS_MOVING`` stronger ones while pins move;
3. (after Provot) every free point is projected into its ball: on the segment from its
   reference, so a point that a convex collider left outside stays outside when its reference
   is outside too. Pinned points are never moved; their balls are
   checked in step 1 like every other point's.

The broad phase is a dense grid of cells over the cloth's extent (:mod:`.celltables`), built at
a rebuild only (:func:`rebuild` has the rule): the triangles' boxes, widened by the query radius,
in every cell they overlap, read by each point in its own cell; each edge's box, widened by half
of it, once in the cell of its lower corner, read by the other edges from the cells where an
overlapping box can start (cells of half the largest box, a column of them one run). A rebuild is
cut into ``PARTS`` parts, ranges of the points and of the edges (:func:`search`), which the thread
team's members search side by side; the first member joins them in order (:func:`join`), so the
pairs and balls are one sweep's whoever searched what. Moving a few points' references finds
what is near them through cells kept up to date as they move (:mod:`.nearby`). Between rebuilds
a substep costs three passes over the points and one over the stored pairs.
"""

from __future__ import annotations

from typing import NamedTuple

import numpy as np
from numba import njit

from ...jit import BORROWED, CHUNKS, EXACT, KERNEL
from ..team import share
from .celltables import box_table, cell_at, corner_table, grid_over, index_of
from .nearby import Cells, Nearby, box_key, element_box, extent, key_of, list_all, listed_in, nearby_index, relist

#: Fraction of the distance to the nearest other element a point may move from its reference.
GAMMA = 0.45
#: No two elements come closer than this fraction of the contact distance: a ball's radius is
#: GAMMA x (d - FLOOR x h), so a pair at d >= FLOOR x h stays at (1 - 2 GAMMA) d + 2 GAMMA FLOOR x h
#: >= FLOOR x h. Without it distances may shrink by 1 - 2 GAMMA at every rebuild, down to below
#: the spacing of floats (1e-16 m near 1 m), where a neighbour's move flips the exact crossing test
#: (seen in the twist: two edges 4e-17 m apart).
FLOOR = 1e-6
#: Fraction of the remaining overlap a contact removes per substep beyond stopping the approach.
PUSH = 0.1
#: While pins move (a pin track, or pins put elsewhere through the API between calls) the response
#: runs SWEEPS_MOVING Jacobi sweeps of PUSH_MOVING each: one sweep averages the pushes a point gets,
#: so cloth wrung between pins turning against each other does not make way for them fast enough,
#: and the pins' balls shrink below their step (the stress set's twist). Four sweeps of 30 % leave
#: 24 % of an isolated pair's overlap, where one of 10 % leaves 90 %.
PUSH_MOVING = 0.3
SWEEPS_MOVING = 4
#: Cloth-on-cloth Coulomb friction coefficient.
FRICTION = 0.3
#: The contact distance is at most this fraction of the shortest rest edge: a flat cloth's own
#: non-adjacent elements lie 0.7 edge apart, and a thicker contact would push the sheet from itself.
MAX_THICKNESS_PER_EDGE = 0.5
#: Query radius over the contact distance.
REACH = 1.5
#: A point about to leave its ball calls for a new reference only if its ball is at least this
#: fraction of the largest (GAMMA x the query radius): a point held a hair from another element
#: would otherwise rebuild every substep and gain nothing; it waits, clamped, for the next rebuild
#: (which another point's leaving, a frame whose pins move or a point found outside its ball at a
#: substep's start calls for).
ROOMY = 0.25
#: Parts a rebuild is cut into, each a contiguous range of points and of edges with its own share
#: of the pair arrays: the thread team's members search as many parts each as costs them alike
#: (the previous rebuild's costs), and the bits do not depend on who searched which.
PARTS = 32

#: A member's flag, an int64 row of FLAG: whether the substep rebuilds the reference, the member's
#: first part and end part, the team's size (the rows of ``dmins`` written), the parts the
#: rebuild is cut into, and whether any point calls for a new reference (so that a substep in
#: which none does skips :func:`rereference`'s own pass over the points).
STALE, FIRST, END, SIZE, CUT, CALLS = range(6)
FLAG = 6

#: A substep whose points about to leave their balls are more than this fraction of the cloth
#: rebuilds the whole reference (one search of the cloth, shared by the team) instead of moving
#: those points' references one by one (:func:`rereference`, run by one member).
LOCAL_SHARE = 1.0 / 128.0

# meta fields (MOVING: 1 in a frame whose pins move, set by the simulation; CLAMPED: 1 when the
# bound has moved a point since its reference was set; REBUILDS counts the whole rebuilds, LOCALS
# the substeps that moved some points' references, MOVED those points)
VALID, N_PT, N_EE, REBUILDS, DROPPED, UNSAFE, MOVING, CLAMPED, LOCALS, MOVED = range(10)
META = 10


class Contact(NamedTuple):
    """The contact pass's arrays: the mesh (triangles (3, T), edges (2, E)), the movable mask, the
    reference state (3, N) and each point's squared ball radius, the stored pairs (point-triangle:
    indices (2, P) and weights + normal (6, P); edge-edge: indices (2, Q) and parameters + normal
    (5, Q)), the Jacobi sums, ``meta`` counters (see VALID ... UNSAFE), a rebuild's work space
    (each member's bounds on the balls, each part's pairs found and cost, see :func:`search`), the
    points by cell and the elements by point (for :func:`rereference`), the contact distance,
    the query radius and the broad phase's cell edge."""

    tris: np.ndarray
    edges: np.ndarray
    movable: np.ndarray
    ref: np.ndarray
    rho2: np.ndarray
    pt: np.ndarray
    ptf: np.ndarray
    ee: np.ndarray
    eef: np.ndarray
    acc: np.ndarray
    cnt: np.ndarray
    meta: np.ndarray
    dmins: np.ndarray
    found: np.ndarray
    cost: np.ndarray
    near: Nearby
    thickness: float
    radius: float
    cell: float


def mesh_edges(tris: np.ndarray) -> np.ndarray:
    """The unique edges (2, E) int64 of triangles (3, T), lower index first, sorted."""
    t = tris.astype(np.int64)
    e = np.concatenate([t[[0, 1]], t[[1, 2]], t[[2, 0]]], axis=1)
    e = np.sort(e, axis=0)
    e = np.unique(e.T, axis=0).T
    return np.ascontiguousarray(e)


def contact_group(pos: np.ndarray, tris: np.ndarray, movable: np.ndarray, thickness: float) -> Contact:
    """The pass's group for a cloth at rest positions ``pos`` (3, N) with triangles ``tris``."""
    tris = np.ascontiguousarray(tris, dtype=np.int64)
    edges = mesh_edges(tris)
    lengths = np.sqrt(((pos[:, edges[0]] - pos[:, edges[1]]) ** 2).sum(axis=0))
    shortest = float(lengths[lengths > 0].min()) if (lengths > 0).any() else thickness
    h = min(thickness, MAX_THICKNESS_PER_EDGE * shortest)
    radius = REACH * h
    n = pos.shape[1]
    cap = 16 * n + 64
    cell = max(radius, 2.0 * float(np.median(lengths)))
    return Contact(tris, edges, np.ascontiguousarray(movable, dtype=np.bool_), np.zeros((3, n)), np.zeros(n),
                   np.zeros((2, cap), dtype=np.int64), np.zeros((6, cap)), np.zeros((2, cap), dtype=np.int64),
                   np.zeros((5, cap)), np.zeros((3, n)), np.zeros(n, dtype=np.int64), np.zeros(META, dtype=np.int64),
                   np.zeros((CHUNKS, n)), np.zeros((PARTS, 2), dtype=np.int64), np.zeros(PARTS, dtype=np.int64),
                   nearby_index(n, tris, edges, cell), h, radius, cell)


# ------------------------------------------------------------------------------------------------
# closest points


@njit(inline="always", **EXACT)
def closest_on_triangle(px: float, py: float, pz: float, ax: float, ay: float, az: float, bx: float, by: float,
                        bz: float, cx: float, cy: float, cz: float) -> tuple[float, float, float]:
    """Barycentric weights of the point of triangle abc nearest to p (Ericson, Real-Time
    Collision Detection, 5.1.5)."""
    abx, aby, abz = bx - ax, by - ay, bz - az
    acx, acy, acz = cx - ax, cy - ay, cz - az
    apx, apy, apz = px - ax, py - ay, pz - az
    d1 = abx * apx + aby * apy + abz * apz
    d2 = acx * apx + acy * apy + acz * apz
    if d1 <= 0.0 and d2 <= 0.0:
        return 1.0, 0.0, 0.0
    bpx, bpy, bpz = px - bx, py - by, pz - bz
    d3 = abx * bpx + aby * bpy + abz * bpz
    d4 = acx * bpx + acy * bpy + acz * bpz
    if d3 >= 0.0 and d4 <= d3:
        return 0.0, 1.0, 0.0
    vc = d1 * d4 - d3 * d2
    if vc <= 0.0 and d1 >= 0.0 and d3 <= 0.0:
        v = d1 / (d1 - d3)
        return 1.0 - v, v, 0.0
    cpx, cpy, cpz = px - cx, py - cy, pz - cz
    d5 = abx * cpx + aby * cpy + abz * cpz
    d6 = acx * cpx + acy * cpy + acz * cpz
    if d6 >= 0.0 and d5 <= d6:
        return 0.0, 0.0, 1.0
    vb = d5 * d2 - d1 * d6
    if vb <= 0.0 and d2 >= 0.0 and d6 <= 0.0:
        w = d2 / (d2 - d6)
        return 1.0 - w, 0.0, w
    va = d3 * d6 - d5 * d4
    if va <= 0.0 and d4 - d3 >= 0.0 and d5 - d6 >= 0.0:
        w = (d4 - d3) / ((d4 - d3) + (d5 - d6))
        return 0.0, 1.0 - w, w
    denom = 1.0 / (va + vb + vc)
    v = vb * denom
    w = vc * denom
    return 1.0 - v - w, v, w


#: Squared length below which closest_on_segments takes an edge as a point.
NO_LENGTH = 1e-30


@njit(inline="always", **EXACT)
def _clamp01(x: float) -> float:
    return min(max(x, 0.0), 1.0)


@njit(inline="always", **EXACT)
def closest_on_segments(p1x: float, p1y: float, p1z: float, q1x: float, q1y: float, q1z: float, p2x: float,
                        p2y: float, p2z: float, q2x: float, q2y: float, q2z: float) -> tuple[float, float]:
    """Parameters (s, t) of the closest points p1 + s (q1 - p1), p2 + t (q2 - p2) of two segments
    (Ericson 5.1.9)."""
    d1x, d1y, d1z = q1x - p1x, q1y - p1y, q1z - p1z
    d2x, d2y, d2z = q2x - p2x, q2y - p2y, q2z - p2z
    rx, ry, rz = p1x - p2x, p1y - p2y, p1z - p2z
    a = d1x * d1x + d1y * d1y + d1z * d1z
    e = d2x * d2x + d2y * d2y + d2z * d2z
    f = d2x * rx + d2y * ry + d2z * rz
    eps = NO_LENGTH
    if a <= eps and e <= eps:
        return 0.0, 0.0
    if a <= eps:
        return 0.0, _clamp01(f / e)
    c = d1x * rx + d1y * ry + d1z * rz
    if e <= eps:
        return _clamp01(-c / a), 0.0
    b = d1x * d2x + d1y * d2y + d1z * d2z
    denom = a * e - b * b
    s = 0.0
    if denom > 0.0:
        s = _clamp01((b * f - c * e) / denom)
    t = (b * s + f) / e
    if t < 0.0:
        return _clamp01(-c / a), 0.0
    if t > 1.0:
        return _clamp01((b - c) / a), 1.0
    return s, t


# ------------------------------------------------------------------------------------------------
# broad phase


# ------------------------------------------------------------------------------------------------
# the reference state


@njit(inline="always", **EXACT)
def _keep_pt(c: Contact, p: int, t: int, wa: float, wb: float, wc: float, nx: float, ny: float, nz: float, d: float,
             dmin: np.ndarray, npt: int, end: int) -> int:
    """A point-triangle pair at distance ``d`` (weights, unnormalised normal): the balls of its
    points bounded by it, and stored at column ``npt`` if within the contact distance (written
    only below column ``end``); returns the pairs kept so far, written or not."""
    if d >= c.radius:
        return npt
    tris = c.tris
    a, b, cc = tris[0, t], tris[1, t], tris[2, t]
    dmin[p] = min(dmin[p], d)
    dmin[a] = min(dmin[a], d)
    dmin[b] = min(dmin[b], d)
    dmin[cc] = min(dmin[cc], d)
    # (a pair further than the contact distance only bounds the motion; the response would skip it)
    if 0.0 < d < c.thickness:
        if npt < end:
            c.pt[0, npt] = p
            c.pt[1, npt] = t
            c.ptf[0, npt] = wa
            c.ptf[1, npt] = wb
            c.ptf[2, npt] = wc
            c.ptf[3, npt] = nx / d
            c.ptf[4, npt] = ny / d
            c.ptf[5, npt] = nz / d
        return npt + 1
    return npt


@njit(inline="always", **EXACT)
def _point_triangle(x: np.ndarray, c: Contact, p: int, t: int, dmin: np.ndarray, npt: int, end: int) -> int:
    """Test one point-triangle pair; returns the pairs kept (npt, or npt + 1; see :func:`_keep_pt`).
    (Rebuilds and moves test their pairs in batches, :func:`_triangles_batch`, with the same bits:
    this is the one-pair form the tests hold them to.)"""
    tris = c.tris
    a, b, cc = tris[0, t], tris[1, t], tris[2, t]
    if p == a or p == b or p == cc:
        return npt
    wa, wb, wc = closest_on_triangle(x[0, p], x[1, p], x[2, p], x[0, a], x[1, a], x[2, a], x[0, b],
                                     x[1, b], x[2, b], x[0, cc], x[1, cc], x[2, cc])
    nx = x[0, p] - (wa * x[0, a] + wb * x[0, b] + wc * x[0, cc])
    ny = x[1, p] - (wa * x[1, a] + wb * x[1, b] + wc * x[1, cc])
    nz = x[2, p] - (wa * x[2, a] + wb * x[2, b] + wc * x[2, cc])
    d = np.sqrt(nx * nx + ny * ny + nz * nz)
    return _keep_pt(c, p, t, wa, wb, wc, nx, ny, nz, d, dmin, npt, end)


@njit(inline="always", **EXACT)
def _keep_ee(c: Contact, e1: int, e2: int, u: float, v: float, nx: float, ny: float, nz: float, d: float,
             dmin: np.ndarray, nee: int, end: int) -> int:
    """An edge-edge pair at distance ``d`` (segment parameters, unnormalised normal), as
    :func:`_keep_pt`; returns the pairs kept."""
    # kept apart from _keep_pt, which it mirrors line for line (the duplicate-code scan pairs
    # them): the two pair kinds have their own corners, arrays and counters, and one function
    # over both would branch on the kind in the rebuild's innermost loop
    if d >= c.radius:
        return nee
    edges = c.edges
    p1, q1 = edges[0, e1], edges[1, e1]
    p2, q2 = edges[0, e2], edges[1, e2]
    dmin[p1] = min(dmin[p1], d)
    dmin[q1] = min(dmin[q1], d)
    dmin[p2] = min(dmin[p2], d)
    dmin[q2] = min(dmin[q2], d)
    if 0.0 < d < c.thickness:
        if nee < end:
            c.ee[0, nee] = e1
            c.ee[1, nee] = e2
            c.eef[0, nee] = u
            c.eef[1, nee] = v
            c.eef[2, nee] = nx / d
            c.eef[3, nee] = ny / d
            c.eef[4, nee] = nz / d
        return nee + 1
    return nee


@njit(inline="always", **EXACT)
def _edge_edge(x: np.ndarray, c: Contact, e1: int, e2: int, dmin: np.ndarray, nee: int, end: int) -> int:
    """Test one edge-edge pair; returns the pairs kept (see :func:`_keep_pt`). (Rebuilds and moves
    test their pairs in batches, :func:`_segments_batch`, with the same bits; this one takes the
    pairs with an edge of no length.)"""
    edges = c.edges
    p1, q1 = edges[0, e1], edges[1, e1]
    p2, q2 = edges[0, e2], edges[1, e2]
    if p1 == p2 or p1 == q2 or q1 == p2 or q1 == q2:
        return nee
    u, v = closest_on_segments(x[0, p1], x[1, p1], x[2, p1], x[0, q1], x[1, q1], x[2, q1], x[0, p2],
                               x[1, p2], x[2, p2], x[0, q2], x[1, q2], x[2, q2])
    nx = (x[0, p1] + u * (x[0, q1] - x[0, p1])) - (x[0, p2] + v * (x[0, q2] - x[0, p2]))
    ny = (x[1, p1] + u * (x[1, q1] - x[1, p1])) - (x[1, p2] + v * (x[1, q2] - x[1, p2]))
    nz = (x[2, p1] + u * (x[2, q1] - x[2, p1])) - (x[2, p2] + v * (x[2, q2] - x[2, p2]))
    d = np.sqrt(nx * nx + ny * ny + nz * nz)
    return _keep_ee(c, e1, e2, u, v, nx, ny, nz, d, dmin, nee, end)


#: Pairs a rebuild collects before testing them together (see :func:`rebuild`).
BATCH = 256
#: What a pair's test costs a rebuild, in entries of a cell read (for sharing the parts out).
TEST_COST = 4
#: A rebuild's grids have at most this many cells per element (plus 64), their cells made larger
#: where the cloth spreads wider (:func:`~.celltables.grid_over`).
GRID_CELLS = 8
#: The edges' cells are this fraction of the largest edge box: finer cells read fewer entries an
#: edge but more columns of cells.
EDGE_SPLIT = 2.0
# (the member and team size the serial path calls with, typed int64: a literal argument would have
# the callees compiled once more for its literal type)
_ZERO, _ONE = np.int64(0), np.int64(1)


@njit(inline="always", **EXACT)
def _get3(rows: np.ndarray, row: int, k: int) -> tuple[float, float, float]:
    # column k of rows row .. row + 2 of a batch (flat, BATCH long rows: a constant stride, so the
    # loop over a batch needs no run-time test that its rows do not overlap, and is vectorised)
    return rows[row * BATCH + k], rows[(row + 1) * BATCH + k], rows[(row + 2) * BATCH + k]


@njit(inline="always", **EXACT)
def _four_points(rows: np.ndarray, k: int) -> tuple:
    # the four points (rows 0-2, 3-5, 6-8, 9-11) of a batch's pair k
    return (*_get3(rows, 0, k), *_get3(rows, 3, k), *_get3(rows, 6, k), *_get3(rows, 9, k))


@njit(inline="always", **EXACT)
def _add_pair(rows: np.ndarray, pairs: np.ndarray, k: int, x: np.ndarray, i0: int, i1: int, i2: int, i3: int,
              first: int, second: int) -> int:
    """Put the pair (``first``, ``second``) of points ``i0 .. i3`` of ``x`` at column ``k`` of a
    batch; returns the batch's new length."""
    for j, i in enumerate((i0, i1, i2, i3)):
        rows[(3 * j) * BATCH + k] = x[0, i]
        rows[(3 * j + 1) * BATCH + k] = x[1, i]
        rows[(3 * j + 2) * BATCH + k] = x[2, i]
    pairs[k] = first
    pairs[BATCH + k] = second
    return k + 1


# A batch is 12 flat rows, BATCH long: a pair's four points (an edge's ends and the other's, or a
# point and a triangle's corners), x y z each. Rows of an edge-edge batch's results: the segment
# parameters s, t, the normal (unnormalised), the distance, 1.0 where an edge has no length
_S, _T, _N, _D, _DEG = 0, 1, 2, 5, 6


class Batch(NamedTuple):
    """Pairs tested together: ``rows`` (12 flat rows, ``BATCH`` long) their four points,
    ``results`` (7 such rows) what the tests give, ``pairs`` (2 rows) the two elements of each."""

    rows: np.ndarray
    results: np.ndarray
    pairs: np.ndarray


@njit(**EXACT)
def new_batch() -> Batch:
    """An empty :class:`Batch`."""
    return Batch(np.empty(12 * BATCH), np.empty(7 * BATCH), np.empty(2 * BATCH, dtype=np.int64))


@njit(**BORROWED)
def _segments_batch(xin: np.ndarray, out: np.ndarray, n: int) -> None:
    """:func:`closest_on_segments` and the distance of each of the first ``n`` pairs of a batch,
    without branches (every case computed, the one that applies kept): the loop runs over several
    pairs at once. A pair with an edge of no length is marked, for the scalar test."""
    for k in range(n):
        p1x, p1y, p1z, q1x, q1y, q1z, p2x, p2y, p2z, q2x, q2y, q2z = _four_points(xin, k)
        d1x, d1y, d1z = q1x - p1x, q1y - p1y, q1z - p1z
        d2x, d2y, d2z = q2x - p2x, q2y - p2y, q2z - p2z
        rx, ry, rz = p1x - p2x, p1y - p2y, p1z - p2z
        a = d1x * d1x + d1y * d1y + d1z * d1z
        e = d2x * d2x + d2y * d2y + d2z * d2z
        f = d2x * rx + d2y * ry + d2z * rz
        c = d1x * rx + d1y * ry + d1z * rz
        b = d1x * d2x + d1y * d2y + d1z * d2z
        denom = a * e - b * b
        s = min(max((b * f - c * e) / denom, 0.0), 1.0)
        s = s if denom > 0.0 else 0.0
        t = (b * s + f) / e
        low = min(max(-c / a, 0.0), 1.0)
        high = min(max((b - c) / a, 0.0), 1.0)
        u = low if t < 0.0 else (high if t > 1.0 else s)
        v = 0.0 if t < 0.0 else (1.0 if t > 1.0 else t)
        nx = (p1x + u * (q1x - p1x)) - (p2x + v * (q2x - p2x))
        ny = (p1y + u * (q1y - p1y)) - (p2y + v * (q2y - p2y))
        nz = (p1z + u * (q1z - p1z)) - (p2z + v * (q2z - p2z))
        out[_S * BATCH + k] = u
        out[_T * BATCH + k] = v
        out[_N * BATCH + k] = nx
        out[(_N + 1) * BATCH + k] = ny
        out[(_N + 2) * BATCH + k] = nz
        out[_D * BATCH + k] = np.sqrt(nx * nx + ny * ny + nz * nz)
        out[_DEG * BATCH + k] = 1.0 if (a <= NO_LENGTH) | (e <= NO_LENGTH) else 0.0


@njit(**BORROWED)
def _settle_ee(x: np.ndarray, c: Contact, pairs: np.ndarray, out: np.ndarray, n: int, dmin: np.ndarray,
               nee: int, end: int) -> int:
    """The batch's pairs, in order, as :func:`_edge_edge` takes them one by one; returns the pairs
    kept."""
    for k in range(n):
        e1 = pairs[k]
        e2 = pairs[BATCH + k]
        if out[_DEG * BATCH + k] != 0.0:
            nee = _edge_edge(x, c, e1, e2, dmin, nee, end)
        else:
            nx, ny, nz = _get3(out, _N, k)
            nee = _keep_ee(c, e1, e2, out[_S * BATCH + k], out[_T * BATCH + k], nx, ny, nz, out[_D * BATCH + k],
                           dmin, nee, end)
    return nee


# rows of a point-triangle batch's results: the weights, the normal (unnormalised), the distance
_W, _PN, _PD = 0, 3, 6


@njit(**BORROWED)
def _triangles_batch(xin: np.ndarray, out: np.ndarray, n: int) -> None:
    """:func:`closest_on_triangle` and the distance of each of the first ``n`` pairs of a batch,
    without branches (every region's weights computed, the one the scalar test would return
    kept): the loop runs over several pairs at once, with the same bits."""
    for k in range(n):
        px, py, pz, ax, ay, az, bx, by, bz, cx, cy, cz = _four_points(xin, k)
        abx, aby, abz = bx - ax, by - ay, bz - az
        acx, acy, acz = cx - ax, cy - ay, cz - az
        apx, apy, apz = px - ax, py - ay, pz - az
        d1 = abx * apx + aby * apy + abz * apz
        d2 = acx * apx + acy * apy + acz * apz
        bpx, bpy, bpz = px - bx, py - by, pz - bz
        d3 = abx * bpx + aby * bpy + abz * bpz
        d4 = acx * bpx + acy * bpy + acz * bpz
        vc = d1 * d4 - d3 * d2
        cpx, cpy, cpz = px - cx, py - cy, pz - cz
        d5 = abx * cpx + aby * cpy + abz * cpz
        d6 = acx * cpx + acy * cpy + acz * cpz
        vb = d5 * d2 - d1 * d6
        va = d3 * d6 - d5 * d4
        # the regions from last to first, each taking over where closest_on_triangle would stop at it
        denom = 1.0 / (va + vb + vc)
        v = vb * denom
        w = vc * denom
        wa, wb, wc = 1.0 - v - w, v, w
        here = va <= 0.0 and d4 - d3 >= 0.0 and d5 - d6 >= 0.0
        w = (d4 - d3) / ((d4 - d3) + (d5 - d6))
        wa = 0.0 if here else wa
        wb = 1.0 - w if here else wb
        wc = w if here else wc
        here = vb <= 0.0 and d2 >= 0.0 and d6 <= 0.0
        w = d2 / (d2 - d6)
        wa = 1.0 - w if here else wa
        wb = 0.0 if here else wb
        wc = w if here else wc
        here = d6 >= 0.0 and d5 <= d6
        wa = 0.0 if here else wa
        wb = 0.0 if here else wb
        wc = 1.0 if here else wc
        here = vc <= 0.0 and d1 >= 0.0 and d3 <= 0.0
        v = d1 / (d1 - d3)
        wa = 1.0 - v if here else wa
        wb = v if here else wb
        wc = 0.0 if here else wc
        here = d3 >= 0.0 and d4 <= d3
        wa = 0.0 if here else wa
        wb = 1.0 if here else wb
        wc = 0.0 if here else wc
        here = d1 <= 0.0 and d2 <= 0.0
        wa = 1.0 if here else wa
        wb = 0.0 if here else wb
        wc = 0.0 if here else wc
        nx = px - (wa * ax + wb * bx + wc * cx)
        ny = py - (wa * ay + wb * by + wc * cy)
        nz = pz - (wa * az + wb * bz + wc * cz)
        out[_W * BATCH + k] = wa
        out[(_W + 1) * BATCH + k] = wb
        out[(_W + 2) * BATCH + k] = wc
        out[_PN * BATCH + k] = nx
        out[(_PN + 1) * BATCH + k] = ny
        out[(_PN + 2) * BATCH + k] = nz
        out[_PD * BATCH + k] = np.sqrt(nx * nx + ny * ny + nz * nz)


@njit(**BORROWED)
def _settle_pt(c: Contact, pairs: np.ndarray, out: np.ndarray, n: int, dmin: np.ndarray, npt: int, end: int) -> int:
    """The batch's pairs, in order, as :func:`_point_triangle` takes them one by one; returns the
    pairs kept."""
    for k in range(n):
        wa, wb, wc = _get3(out, _W, k)
        nx, ny, nz = _get3(out, _PN, k)
        npt = _keep_pt(c, pairs[k], pairs[BATCH + k], wa, wb, wc, nx, ny, nz, out[_PD * BATCH + k], dmin, npt, end)
    return npt


@njit(**BORROWED)
def _tested_pt(c: Contact, batch: Batch, n: int, dmin: np.ndarray, npt: int, end: int) -> int:
    # a batch of point-triangle pairs tested and taken in order (as rebuilds and moves test them)
    _triangles_batch(batch.rows, batch.results, n)
    return _settle_pt(c, batch.pairs, batch.results, n, dmin, npt, end)


@njit(**BORROWED)
def _tested_ee(x: np.ndarray, c: Contact, batch: Batch, n: int, dmin: np.ndarray, nee: int, end: int) -> int:
    # (as _tested_pt, for edge-edge pairs)
    _segments_batch(batch.rows, batch.results, n)
    return _settle_ee(x, c, batch.pairs, batch.results, n, dmin, nee, end)


@njit(**KERNEL)
def _element_boxes(x: np.ndarray, ids: np.ndarray, pad: float) -> np.ndarray:
    """(6, K) boxes (lo, hi) of the elements whose corners are the columns of ``ids`` (k, K),
    widened by ``pad``."""
    box = np.empty((6, ids.shape[1]))
    for e in range(ids.shape[1]):
        element_box(x, ids, e, pad, box)
    return box


@njit(**EXACT)
def search(x: np.ndarray, c: Contact, lo: int, hi: int, parts: int, row: int) -> None:
    """Parts ``lo`` to ``hi`` (of ``parts``) of a rebuild from ``x`` (3, N): every point-triangle
    and edge-edge pair closer than the query radius among each part's points and edges, stored in
    the part's share of the pair arrays (columns ``share(capacity, part, parts)``), its pair
    counts in its row of ``found`` and its cost (entries read, pairs tested) in ``cost``; the
    balls' bounds in row ``row`` of ``dmins`` (:func:`join` puts the parts together).

    Point-triangle: the triangles' boxes, widened by the radius, go into every cell they overlap;
    each point reads its own cell (a triangle is listed once per cell: no pair twice). Edge-edge:
    each edge's box, widened by half the radius, goes once into the cell of its lower corner
    (cells ``1 / EDGE_SPLIT`` of the largest box); each edge reads the cells where an overlapping
    box can have its lower corner (from its own lower corner less the largest box to its upper
    corner) and tests the edges found there that come after it in the table (each pair once,
    stored lower edge first). The pairs found are tested ``BATCH`` at a time
    (:func:`_triangles_batch`, :func:`_segments_batch`), with the bits of :func:`_point_triangle`
    and :func:`_edge_edge`, and taken in the order found. A part's points and edges are a
    contiguous range, so the parts' pairs, one part after another, are the pairs one sweep over
    all of them finds, in its order (which :func:`join` then sorts by edge for the edge-edge
    pairs).
    """
    n = x.shape[1]
    radius = c.radius
    tris = c.tris
    edges = c.edges
    batch = new_batch()
    hit = np.empty(max(c.tris.shape[1], c.edges.shape[1]), dtype=np.int64)
    # the tables, once for the parts this call runs
    tbox = _element_boxes(x, c.tris, radius)
    grid, tcell = grid_over(tbox, c.cell, GRID_CELLS * tbox.shape[1] + 64)
    start, ids = box_table(tbox, grid, tcell)
    inv = 1.0 / tcell
    ebox = _element_boxes(x, c.edges, 0.5 * radius)
    ne = ebox.shape[1]
    eext = 0.0
    for e in range(ne):
        eext = max(eext, extent(ebox, e))
    egrid, ecell = grid_over(ebox, max(eext / EDGE_SPLIT, 1e-300), GRID_CELLS * ne + 64)
    estart, eids = corner_table(ebox, egrid, ecell)
    einv = 1.0 / ecell
    # (each entry's box beside it, in the table's order: a run's boxes read as one stream, where
    # the boxes by edge cost six scattered reads an entry)
    sbox = np.empty((ne, 6))
    epos = np.empty(ne, dtype=np.int64)
    for i in range(ne):
        epos[eids[i]] = i
        for k in range(6):
            sbox[i, k] = ebox[k, eids[i]]
    # (the same for the triangles' boxes, by triangle: one line of memory a box)
    tb = np.empty((tbox.shape[1], 6))
    for t in range(tbox.shape[1]):
        for k in range(6):
            tb[t, k] = tbox[k, t]
    dmin = c.dmins[row]
    for p in range(n):
        dmin[p] = radius
    for part in range(lo, hi):
        # (counters typed int64 from the start, as share's are: a literal 0 has the callees below
        # compiled a second time for the literal's type)
        pt_first, pt_end = share(c.pt.shape[1], part, parts)
        npt = pt_first
        nb = np.int64(0)
        p0, p1 = share(n, part, parts)
        cost = np.int64(0)
        for p in range(p0, p1):
            s = index_of(grid, cell_at(grid, 0, x[0, p], inv), cell_at(grid, 1, x[1, p], inv),
                         cell_at(grid, 2, x[2, p], inv))
            cost += start[s + 1] - start[s]
            px, py, pz = x[0, p], x[1, p], x[2, p]
            m = np.int64(0)
            for i in range(start[s], start[s + 1]):  # (as the edges' below)
                t = ids[i]
                hit[m] = t
                m += ((px >= tb[t, 0]) & (px <= tb[t, 3]) & (py >= tb[t, 1]) & (py <= tb[t, 4]) & (pz >= tb[t, 2])
                      & (pz <= tb[t, 5]))
            for j in range(m):
                t = hit[j]
                a, b, cc = tris[0, t], tris[1, t], tris[2, t]
                if p == a or p == b or p == cc:
                    continue
                nb = _add_pair(batch.rows, batch.pairs, nb, x, p, a, b, cc, p, t)
                cost += TEST_COST
                if nb == BATCH:
                    npt = _tested_pt(c, batch, nb, dmin, npt, pt_end)
                    nb = 0
        if nb > 0:
            npt = _tested_pt(c, batch, nb, dmin, npt, pt_end)
        # edge-edge: each edge once, in its lower corner's cell (cells as large as the largest box);
        # the cells an overlapping box can start in read column by column, each one run
        ee_first, ee_end = share(c.ee.shape[1], part, parts)
        nee = ee_first
        nb = np.int64(0)
        f0, f1 = share(ne, part, parts)
        for e1 in range(f0, f1):
            x1 = cell_at(egrid, 0, ebox[3, e1], einv)
            y0, y1 = cell_at(egrid, 1, ebox[1, e1] - eext, einv), cell_at(egrid, 1, ebox[4, e1], einv)
            z0, z1 = cell_at(egrid, 2, ebox[2, e1] - eext, einv), cell_at(egrid, 2, ebox[5, e1], einv)
            lx, ly, lz, hx, hy, hz = ebox[0, e1], ebox[1, e1], ebox[2, e1], ebox[3, e1], ebox[4, e1], ebox[5, e1]
            # each pair once, from the edge that comes first in the table: the columns of cells
            # before this edge's own skipped, its own read from past its entry (half the entries
            # read, where a test on the index read every pair from both sides)
            cx, cy = cell_at(egrid, 0, lx, einv), cell_at(egrid, 1, ly, einv)
            m = np.int64(0)
            for ix in range(cx, x1 + 1):
                for iy in range(y0 if ix > cx else cy, y1 + 1):
                    r0 = estart[index_of(egrid, ix, iy, z0)]
                    r1 = estart[index_of(egrid, ix, iy, z1) + 1]
                    if ix == cx and iy == cy:
                        r0 = max(r0, epos[e1] + 1)
                    cost += r1 - r0 + 1
                    # (the entries tested without branches and the ones that pass gathered in
                    # order: a test that one entry in seven passes is a branch the processor
                    # guesses wrong)
                    for i in range(r0, r1):
                        hit[m] = eids[i]
                        m += ((sbox[i, 0] <= hx) & (sbox[i, 3] >= lx) & (sbox[i, 1] <= hy) & (sbox[i, 4] >= ly)
                              & (sbox[i, 2] <= hz) & (sbox[i, 5] >= lz))
            for j in range(m):
                # (a pair stored lower edge first, as the moves store it)
                a, b = min(e1, hit[j]), max(e1, hit[j])
                p1, q1 = edges[0, a], edges[1, a]
                p2, q2 = edges[0, b], edges[1, b]
                if p1 == p2 or p1 == q2 or q1 == p2 or q1 == q2:
                    continue
                nb = _add_pair(batch.rows, batch.pairs, nb, x, p1, q1, p2, q2, a, b)
                cost += TEST_COST
                if nb == BATCH:
                    nee = _tested_ee(x, c, batch, nb, dmin, nee, ee_end)
                    nb = 0
        if nb > 0:
            nee = _tested_ee(x, c, batch, nb, dmin, nee, ee_end)
        c.found[part, 0] = npt - pt_first
        c.found[part, 1] = nee - ee_first
        c.cost[part] = cost


@njit(inline="always", **EXACT)
def _room(ids: np.ndarray, part: int, parts: int) -> int:
    """Columns of the pair array ``ids`` that part ``part`` of ``parts`` stores its pairs in."""
    first, end = share(ids.shape[1], part, parts)
    return end - first


@njit(inline="always", **EXACT)
def _gather_pairs(ids: np.ndarray, data: np.ndarray, found: np.ndarray, k: int, parts: int) -> tuple[int, int]:
    """Move the ``parts`` parts' pairs of kind ``k`` (0 point-triangle, 1 edge-edge) from their
    shares of ``ids`` / ``data`` to one run from column 0, in part order; returns (pairs kept,
    pairs beyond the arrays' room)."""
    room = ids.shape[1]
    kept = 0
    beyond = 0
    for part in range(parts):
        first, end = share(room, part, parts)
        want = found[part, k]
        take = min(want, end - first)
        beyond += want - take
        if first != kept:
            # (kept <= first: each part's share starts at or after the pairs before it)
            for j in range(take):
                for r in range(ids.shape[0]):
                    ids[r, kept + j] = ids[r, first + j]
                for r in range(data.shape[0]):
                    data[r, kept + j] = data[r, first + j]
        kept += take
    return kept, beyond


@njit(inline="always", **EXACT)
def overflowed(c: Contact, parts: int) -> bool:
    """Whether a part of a rebuild cut into ``parts`` found more pairs than its share of the pair
    arrays holds. The rebuild is then searched again as one part (see :func:`fall_back`), which
    stores what fits in the whole arrays, in the order found, and counts the rest as dropped."""
    for part in range(parts):
        if c.found[part, 0] > _room(c.pt, part, parts) or c.found[part, 1] > _room(c.ee, part, parts):
            return True
    return False


@njit(inline="always", **EXACT)
def fall_back(flag: np.ndarray) -> None:
    """``flag`` (see :data:`FLAG`) made the whole rebuild as one part, searched by one member."""
    flag[FIRST], flag[END], flag[SIZE], flag[CUT] = 0, 1, 1, 1


@njit(**EXACT)
def join(x: np.ndarray, c: Contact, parts: int, rows: int) -> None:
    """Make ``x`` (3, N) the reference from a rebuild's ``parts`` parts (:func:`search`, the
    balls' bounds in the first ``rows`` rows of ``dmins``), none of them :func:`overflowed`: their
    pairs in one run, in part order, and each point's ball from the nearest of its bounds."""
    npt, lost_pt = _gather_pairs(c.pt, c.ptf, c.found, 0, parts)
    nee, lost_ee = _gather_pairs(c.ee, c.eef, c.found, 1, parts)
    # (the point-triangle pairs come in order, by point then triangle; the edge-edge ones in the
    # order of the broad phase's cells, so they are put in order of their edges: the response's
    # sums, and so the bits, then depend on which pairs there are, not on how they were found)
    _in_order(c.ee, c.eef, nee, c.edges.shape[1])
    n = x.shape[1]
    # (element by element: an array assigned to a slice compiles Numba's error-message string
    # code, about 3 s of a cold start)
    for ax in range(3):
        for p in range(n):
            c.ref[ax, p] = x[ax, p]
    floor = FLOOR * c.thickness
    dmins = c.dmins
    for p in range(n):
        d = dmins[0, p]
        for k in range(1, rows):
            d = min(d, dmins[k, p])
        r = GAMMA * max(d - floor, 0.0)
        c.rho2[p] = r * r
    _index_reference(c)
    c.meta[VALID] = 1
    c.meta[N_PT] = npt
    c.meta[N_EE] = nee
    c.meta[DROPPED] += lost_pt + lost_ee
    c.meta[REBUILDS] += 1
    c.meta[CLAMPED] = 0


@njit(**EXACT)
def _in_order(ids: np.ndarray, data: np.ndarray, n: int, width: int) -> None:
    """The first ``n`` columns of ``ids`` (2, M) (values below ``width``) and ``data`` sorted by
    ``ids[0]``, then ``ids[1]``: two stable counting sorts, the second key first."""
    if n < 2:
        return
    tid = np.empty((2, n), dtype=np.int64)
    tdata = np.empty((data.shape[0], n))
    count = np.empty(width + 1, dtype=np.int64)
    for key in (1, 0):
        for k in range(width + 1):
            count[k] = 0
        for j in range(n):
            count[ids[key, j] + 1] += 1
        for k in range(width):
            count[k + 1] += count[k]
        for j in range(n):
            to = count[ids[key, j]]
            count[ids[key, j]] += 1
            tid[0, to] = ids[0, j]
            tid[1, to] = ids[1, j]
            for r in range(data.shape[0]):
                tdata[r, to] = data[r, j]
        for j in range(n):
            ids[0, j] = tid[0, j]
            ids[1, j] = tid[1, j]
            for r in range(data.shape[0]):
                data[r, j] = tdata[r, j]


@njit(**BORROWED)
def _index_reference(c: Contact) -> None:
    # a new reference: every point, triangle and edge in its cell, no point held
    nb = c.near
    inv = 1.0 / nb.cell
    x = c.ref
    keys = nb.hits
    for p in range(x.shape[1]):
        keys[p] = key_of(x[0, p], x[1, p], x[2, p], inv)
        nb.held[p] = False
    list_all(nb.points, keys, x.shape[1])
    nb.ext[0] = _index_elements(x, c.tris, nb.tri_box, c.radius, nb.tris, keys, inv)
    nb.ext[1] = _index_elements(x, c.edges, nb.edge_box, 0.5 * c.radius, nb.edges, keys, inv)


@njit(**BORROWED)
def _index_elements(x: np.ndarray, ids: np.ndarray, box: np.ndarray, pad: float, cells: Cells, keys: np.ndarray,
                    inv: float) -> float:
    # the elements' boxes (widened by pad) and cells; returns the largest extent
    most = 0.0
    for e in range(ids.shape[1]):
        element_box(x, ids, e, pad, box)
        keys[e] = box_key(box, e, inv)
        most = max(most, extent(box, e))
    list_all(cells, keys, ids.shape[1])
    return most


@njit(**EXACT)
def rebuild(x: np.ndarray, c: Contact) -> None:
    """Make ``x`` (3, N) the reference: find every point-triangle and edge-edge pair closer than
    the query radius, store them, and give each point its ball (:func:`search` over every part,
    then :func:`join`; the thread team runs the parts side by side)."""
    flag = np.empty(FLAG, dtype=np.int64)
    flag[STALE], flag[FIRST], flag[END], flag[SIZE], flag[CUT] = 1, 0, PARTS, 1, PARTS
    _search_alone(x, c, flag)
    join(x, c, flag[CUT], flag[SIZE])


@njit(inline="always", **KERNEL)
def _leaves(x: np.ndarray, c: Contact, p: int, roomy: float) -> bool:
    """True when point ``p`` of ``x`` lies outside its ball and calls for a new reference: a
    pinned point (it cannot wait clamped: its motion is prescribed), or a free point whose squared
    radius is at least ``roomy`` (see ROOMY)."""
    if c.rho2[p] < roomy and c.movable[p]:
        return False
    dx = x[0, p] - c.ref[0, p]
    dy = x[1, p] - c.ref[1, p]
    dz = x[2, p] - c.ref[2, p]
    return dx * dx + dy * dy + dz * dz > c.rho2[p]


@njit(**KERNEL)
def _leaving(x: np.ndarray, c: Contact, most: int) -> int:
    """How many points of ``x`` call for a new reference (they are :func:`_leaves`, or the bound has
    held them back since their reference was set), counted up to ``most`` + 1."""
    roomy = (ROOMY * GAMMA * c.radius) ** 2
    count = 0
    for p in range(x.shape[1]):
        if c.near.held[p] or _leaves(x, c, p, roomy):
            count += 1
            if count > most:
                break
    return count


#: A point is outside its ball when its squared distance from its reference passes the squared
#: radius x (1 + OUTSIDE_REL) + OUTSIDE_ABS: by more than rounding (a ball of a few nanometres,
#: next to an element the cloth was given crossing, is placed to 1e-16 m).
OUTSIDE_REL = 1e-6
OUTSIDE_ABS = 1e-28


@njit(**KERNEL)
def _outside(x: np.ndarray, c: Contact) -> bool:
    """True when a point of ``x`` lies outside its ball (see OUTSIDE_REL)."""
    ref = c.ref
    rho2 = c.rho2
    for p in range(x.shape[1]):
        dx = x[0, p] - ref[0, p]
        dy = x[1, p] - ref[1, p]
        dz = x[2, p] - ref[2, p]
        if dx * dx + dy * dy + dz * dz > rho2[p] * (1.0 + OUTSIDE_REL) + OUTSIDE_ABS:
            return True
    return False


def any_outside(x: np.ndarray, c: Contact, points: np.ndarray) -> bool:
    """Whether one of ``points`` of ``x`` (3, N) lies outside its ball, by :func:`_outside`'s rule
    (for the simulation's few pins between frames, in NumPy)."""
    if not c.meta[VALID] or points.shape[0] == 0:
        return False
    d2 = ((x[:, points] - c.ref[:, points]) ** 2).sum(axis=0)
    return bool(np.any(d2 > c.rho2[points] * (1.0 + OUTSIDE_REL) + OUTSIDE_ABS))


# ------------------------------------------------------------------------------------------------
# a few points' references moved


@njit(**EXACT)
def rereference(pos: np.ndarray, last: np.ndarray, c: Contact) -> bool:
    """Move the reference of each point about to leave its ball (:func:`_leaves`, in ``pos``) or
    held back by the bound since its reference was set to where it started the substep
    (``last``), find again every pair those points belong to, and give them new balls; the
    other points' balls shrink where a new pair is nearer, and a point whose ball shrank so
    that its starting position lies outside it is moved in a further round. Returns whether any
    point was moved.

    Why this keeps the guarantee: every point's starting position lies in its ball, so the
    state ``last`` is joined to the reference by straight paths that keep every pair apart. Once
    the rounds end, every pair closer than the query radius in the new reference (every such
    pair that has a moved point is searched again, and the others kept their distances) bounds
    the balls of its points, and every point's starting position lies in its ball: the new
    reference is joined to ``last``, which has no crossing, by paths that keep every pair apart,
    so it has none either, and the argument of the module's docstring holds from it.
    """
    return _rereference(pos, last, c, c.dmins[0], new_batch())


@njit(**BORROWED)
def _rereference(pos: np.ndarray, last: np.ndarray, c: Contact, dmin: np.ndarray, batch: Batch) -> bool:
    nb = c.near
    roomy = (ROOMY * GAMMA * c.radius) ** 2
    nb.count[0] += 1
    moving = nb.count[0]
    k = 0
    for p in range(pos.shape[1]):
        if nb.held[p] or _leaves(pos, c, p, roomy):
            nb.todo[k] = p
            nb.mark[0, p] = moving
            k += 1
    if k == 0:
        return False
    npt = c.meta[N_PT]
    nee = c.meta[N_EE]
    cap_pt = c.pt.shape[1]
    cap_ee = c.ee.shape[1]
    done = 0
    while done < k:
        nb.count[0] += 1
        now = nb.count[0]
        _move_round(last, c, done, k, now)
        npt = _drop_pt(c, npt, now)
        nee = _drop_ee(c, nee, now)
        for p in range(dmin.shape[0]):
            dmin[p] = c.radius
        npt, nee = _round_pairs(c, done, k, now, dmin, npt, nee, batch)
        # (pairs beyond the arrays' room are counted, as a rebuild counts them)
        c.meta[DROPPED] += max(npt - cap_pt, 0) + max(nee - cap_ee, 0)
        npt = min(npt, cap_pt)
        nee = min(nee, cap_ee)
        more = _round_balls(last, c, done, k, now, moving, dmin)
        done = k
        k = more
    c.meta[N_PT] = npt
    c.meta[N_EE] = nee
    c.meta[LOCALS] += 1
    c.meta[MOVED] += k
    c.meta[CLAMPED] = 0
    return True


@njit(**BORROWED)
def _move_round(last: np.ndarray, c: Contact, lo: int, hi: int, now: int) -> None:
    # the round's points (todo[lo:hi]) to their starting positions, marked and listed in their
    # cells; the elements they belong to marked, their boxes and cells made the new reference's
    nb = c.near
    ref = c.ref
    inv = 1.0 / nb.cell
    for i in range(lo, hi):
        p = nb.todo[i]
        nb.mark[1, p] = now
        nb.held[p] = False
        for ax in range(3):
            ref[ax, p] = last[ax, p]
        relist(nb.points, p, key_of(ref[0, p], ref[1, p], ref[2, p], inv))
    for i in range(lo, hi):
        p = nb.todo[i]
        for j in range(nb.tri_at[p], nb.tri_at[p + 1]):
            t = nb.tri_ids[j]
            if nb.tri_mark[t] != now:
                nb.tri_mark[t] = now
                element_box(ref, c.tris, t, c.radius, nb.tri_box)
                relist(nb.tris, t, box_key(nb.tri_box, t, inv))
                nb.ext[0] = max(nb.ext[0], extent(nb.tri_box, t))
        for j in range(nb.edge_at[p], nb.edge_at[p + 1]):
            e = nb.edge_ids[j]
            if nb.edge_mark[e] != now:
                nb.edge_mark[e] = now
                element_box(ref, c.edges, e, 0.5 * c.radius, nb.edge_box)
                relist(nb.edges, e, box_key(nb.edge_box, e, inv))
                nb.ext[1] = max(nb.ext[1], extent(nb.edge_box, e))


@njit(**BORROWED)
def _drop_pt(c: Contact, npt: int, now: int) -> int:
    # the stored point-triangle pairs the round's points belong to taken out, the others kept in order
    nb = c.near
    kept = 0
    for k in range(npt):
        if nb.mark[1, c.pt[0, k]] != now and nb.tri_mark[c.pt[1, k]] != now:
            kept = _keep(c.pt, c.ptf, k, kept)
    return kept


@njit(**BORROWED)
def _drop_ee(c: Contact, nee: int, now: int) -> int:
    # (as _drop_pt, for the edge-edge pairs)
    nb = c.near
    kept = 0
    for k in range(nee):
        if nb.edge_mark[c.ee[0, k]] != now and nb.edge_mark[c.ee[1, k]] != now:
            kept = _keep(c.ee, c.eef, k, kept)
    return kept


@njit(inline="always", **EXACT)
def _keep(ids: np.ndarray, data: np.ndarray, k: int, kept: int) -> int:
    # stored pair k moved to column kept (the pairs before it that stay); returns kept + 1
    if kept != k:
        for r in range(ids.shape[0]):
            ids[r, kept] = ids[r, k]
        for r in range(data.shape[0]):
            data[r, kept] = data[r, k]
    return kept + 1


@njit(inline="always", **EXACT)
def _holds(lx: float, ly: float, lz: float, hx: float, hy: float, hz: float, x: float, y: float, z: float) -> bool:
    """Whether the box (lower, upper corner) holds the point (x, y, z), edges included; without
    branches, so that a loop that counts with it is vectorised."""
    return (x >= lx) & (x <= hx) & (y >= ly) & (y <= hy) & (z >= lz) & (z <= hz)


@njit(inline="always", **EXACT)
def _meets(box: np.ndarray, e: int, lx: float, ly: float, lz: float, hx: float, hy: float, hz: float) -> bool:
    """Whether box ``e`` of ``box`` (6, M) overlaps the box (lower, upper corner), without branches."""
    return ~((box[0, e] > hx) | (box[3, e] < lx) | (box[1, e] > hy) | (box[4, e] < ly) | (box[2, e] > hz)
             | (box[5, e] < lz))


@njit(inline="always", **EXACT)
def _union(box: np.ndarray, ids: np.ndarray, first: int, end: int, mark: np.ndarray, now: int) -> tuple:
    """The union (lower, then upper corner) of the boxes of the elements ``ids[first:end]`` marked
    ``now``; its lower corner is +inf when none is."""
    lox = loy = loz = np.inf
    hix = hiy = hiz = -np.inf
    for j in range(first, end):
        e = ids[j]
        if mark[e] == now:
            lox, loy, loz = min(lox, box[0, e]), min(loy, box[1, e]), min(loz, box[2, e])
            hix, hiy, hiz = max(hix, box[3, e]), max(hiy, box[4, e]), max(hiz, box[5, e])
    return lox, loy, loz, hix, hiy, hiz


@njit(**BORROWED)
def _round_pairs(c: Contact, lo: int, hi: int, now: int, dmin: np.ndarray, npt: int, nee: int,
                 batch: Batch) -> tuple[int, int]:
    # every pair the round's points (todo[lo:hi]) belong to, with the boxes and the exact tests
    # of a rebuild: each moved point against the triangles whose box holds it; each triangle a
    # moved point belongs to against the points in its box that did not move; each edge a moved
    # point belongs to against the edges whose boxes overlap its own (a pair of two such edges
    # once). The elements are found by their boxes' lower corners (see nearby.py), each once. The
    # pairs are tested BATCH at a time, in the order found, as a rebuild tests them.
    nb = c.near
    x = c.ref
    tris = c.tris
    edges = c.edges
    hits = nb.hits
    cell = nb.cell
    end_pt = c.pt.shape[1]
    end_ee = c.ee.shape[1]
    tbox = nb.tri_box
    ebox = nb.edge_box
    text = nb.ext[0]
    eext = nb.ext[1]
    k = np.int64(0)
    for i in range(lo, hi):
        p = nb.todo[i]
        px, py, pz = x[0, p], x[1, p], x[2, p]
        found = listed_in(nb.tris, hits, cell, px - text, py - text, pz - text, px, py, pz)
        kept = np.int64(0)
        for j in range(found):
            t = hits[j]
            hits[kept] = t
            kept += ((tris[0, t] != p) & (tris[1, t] != p) & (tris[2, t] != p)
                     & _holds(tbox[0, t], tbox[1, t], tbox[2, t], tbox[3, t], tbox[4, t], tbox[5, t], px, py, pz))
        for j in range(kept):
            t = hits[j]
            k = _add_pair(batch.rows, batch.pairs, k, x, p, tris[0, t], tris[1, t], tris[2, t], p, t)
            if k == BATCH:
                npt = _tested_pt(c, batch, k, dmin, npt, end_pt)
                k = 0
    # A moved point's triangles (and edges) are read against what one query of the union of their
    # boxes lists, kept where it is inside (overlaps) that union: an item inside (overlapping) one
    # element's box lies in that element's own query cells, which the union's query reads in the
    # same order (cell by cell, each cell's list in its order), so each element meets its items in
    # the order its own query gives. Each element then picks its own from the few kept, without
    # branches (as a rebuild reads its cells).
    picked = nb.picked
    for i in range(lo, hi):
        p = nb.todo[i]
        ulx, uly, ulz, uhx, uhy, uhz = _union(tbox, nb.tri_ids, nb.tri_at[p], nb.tri_at[p + 1], nb.tri_mark, now)
        if ulx > uhx:
            continue
        found = listed_in(nb.points, hits, cell, ulx, uly, ulz, uhx, uhy, uhz)
        m = np.int64(0)
        for j in range(found):
            q = hits[j]
            hits[m] = q
            m += _holds(ulx, uly, ulz, uhx, uhy, uhz, x[0, q], x[1, q], x[2, q])
        for j in range(nb.tri_at[p], nb.tri_at[p + 1]):
            t = nb.tri_ids[j]
            if nb.tri_mark[t] != now:
                continue
            nb.tri_mark[t] = -now  # (tested once)
            a, b, cc = tris[0, t], tris[1, t], tris[2, t]
            lx, ly, lz, hx, hy, hz = tbox[0, t], tbox[1, t], tbox[2, t], tbox[3, t], tbox[4, t], tbox[5, t]
            kept = np.int64(0)
            for jj in range(m):
                q = hits[jj]
                picked[kept] = q
                kept += ((nb.mark[1, q] != now) & (q != a) & (q != b) & (q != cc)
                         & _holds(lx, ly, lz, hx, hy, hz, x[0, q], x[1, q], x[2, q]))
            for jj in range(kept):
                k = _add_pair(batch.rows, batch.pairs, k, x, picked[jj], a, b, cc, picked[jj], t)
                if k == BATCH:
                    npt = _tested_pt(c, batch, k, dmin, npt, end_pt)
                    k = 0
    if k > 0:
        npt = _tested_pt(c, batch, k, dmin, npt, end_pt)
        k = 0
    for i in range(lo, hi):
        p = nb.todo[i]
        ulx, uly, ulz, uhx, uhy, uhz = _union(ebox, nb.edge_ids, nb.edge_at[p], nb.edge_at[p + 1], nb.edge_mark, now)
        if ulx > uhx:
            continue
        found = listed_in(nb.edges, hits, cell, ulx - eext, uly - eext, ulz - eext, uhx, uhy, uhz)
        m = np.int64(0)
        for j in range(found):
            e2 = hits[j]
            hits[m] = e2
            m += _meets(ebox, e2, ulx, uly, ulz, uhx, uhy, uhz)
        for j in range(nb.edge_at[p], nb.edge_at[p + 1]):
            e = nb.edge_ids[j]
            if nb.edge_mark[e] != now:
                continue
            nb.edge_mark[e] = -now  # (tested once)
            lx, ly, lz, hx, hy, hz = ebox[0, e], ebox[1, e], ebox[2, e], ebox[3, e], ebox[4, e], ebox[5, e]
            kept = np.int64(0)
            for jj in range(m):
                e2 = hits[jj]
                picked[kept] = e2
                # (a pair of two edges of the round's points once, from the lower)
                kept += ((e2 != e) & ((abs(nb.edge_mark[e2]) != now) | (e2 > e))
                         & _meets(ebox, e2, lx, ly, lz, hx, hy, hz))
            for jj in range(kept):
                f1, f2 = min(e, picked[jj]), max(e, picked[jj])  # (a pair stored lower edge first)
                p1, q1 = edges[0, f1], edges[1, f1]
                p2, q2 = edges[0, f2], edges[1, f2]
                if p1 == p2 or p1 == q2 or q1 == p2 or q1 == q2:
                    continue
                k = _add_pair(batch.rows, batch.pairs, k, x, p1, q1, p2, q2, f1, f2)
                if k == BATCH:
                    nee = _tested_ee(x, c, batch, k, dmin, nee, end_ee)
                    k = 0
    if k > 0:
        nee = _tested_ee(x, c, batch, k, dmin, nee, end_ee)
    return npt, nee


@njit(**BORROWED)
def _round_balls(last: np.ndarray, c: Contact, lo: int, hi: int, now: int, moving: int, dmin: np.ndarray) -> int:
    # the round's points' new balls; every other point's ball shrunk to a nearer new pair, and a
    # point not yet moved whose start is then outside its ball put on the list for the next round
    # (one that only its position after the integrator has left is clamped by the bound, and
    # moved in the next substep: moving it now too moved many more points, at twice the cost on
    # the folding 100 x 100 cloth); returns the list's new length
    nb = c.near
    floor = FLOOR * c.thickness
    for i in range(lo, hi):
        p = nb.todo[i]
        r = GAMMA * max(dmin[p] - floor, 0.0)
        c.rho2[p] = r * r
    k = hi
    for q in range(dmin.shape[0]):
        if nb.mark[1, q] == now:
            continue
        r = GAMMA * max(dmin[q] - floor, 0.0)
        if r * r < c.rho2[q]:
            c.rho2[q] = r * r
            if nb.mark[0, q] != moving and _leaves(last, c, q, 0.0):
                nb.todo[k] = q
                nb.mark[0, q] = moving
                k += 1
    return k


# ------------------------------------------------------------------------------------------------
# contact response


@njit(inline="always", **KERNEL)
def _respond(pos: np.ndarray, last: np.ndarray, c: Contact, ids: np.ndarray, coef: np.ndarray, nx: float, ny: float,
             nz: float, h: float, push: float) -> None:
    """One pair's response: ``ids`` its four points, ``coef`` their signed weights (the pair's
    separation is sum coef_k x_k along n); pushes the pair apart towards ``h`` (``push`` of the
    overlap left) with friction."""
    s_now = 0.0
    for k in range(4):
        q = ids[k]
        s_now += coef[k] * (pos[0, q] * nx + pos[1, q] * ny + pos[2, q] * nz)
    if s_now >= h:
        return
    # (the start's separation only for a pair in contact: most stored pairs are not)
    s_last = 0.0
    for k in range(4):
        q = ids[k]
        s_last += coef[k] * (last[0, q] * nx + last[1, q] * ny + last[2, q] * nz)
    # inelastic: no closer than at the substep's start (or the contact distance), then part of
    # what overlap is left
    base = max(s_now, min(s_last, h))
    delta = base + push * (h - base) - s_now
    den = 0.0
    for k in range(4):
        if c.movable[ids[k]]:
            den += coef[k] * coef[k]
    if den <= 0.0 or delta <= 0.0:
        return
    imp = delta / den
    # relative tangential motion over the substep, reduced by up to friction x the normal push
    ux = 0.0
    uy = 0.0
    uz = 0.0
    for k in range(4):
        q = ids[k]
        ux += coef[k] * (pos[0, q] - last[0, q])
        uy += coef[k] * (pos[1, q] - last[1, q])
        uz += coef[k] * (pos[2, q] - last[2, q])
    un = ux * nx + uy * ny + uz * nz
    ux -= un * nx
    uy -= un * ny
    uz -= un * nz
    ut = np.sqrt(ux * ux + uy * uy + uz * uz)
    fx = 0.0
    fy = 0.0
    fz = 0.0
    if ut > 0.0:
        j = min(ut, FRICTION * delta) / (den * ut)
        fx, fy, fz = ux * j, uy * j, uz * j
    for k in range(4):
        q = ids[k]
        if c.movable[q] and coef[k] != 0.0:
            c.acc[0, q] += coef[k] * (imp * nx - fx)
            c.acc[1, q] += coef[k] * (imp * ny - fy)
            c.acc[2, q] += coef[k] * (imp * nz - fz)
            c.cnt[q] += 1


@njit(**KERNEL)
def respond(pos: np.ndarray, last: np.ndarray, c: Contact) -> None:
    """The response: one :func:`sweep` of ``PUSH``, or ``SWEEPS_MOVING`` of ``PUSH_MOVING`` in a
    frame whose pins move (``meta[MOVING]``)."""
    _sweeps(pos, last, c, np.empty(4, dtype=np.int64), np.empty(4))


@njit(**BORROWED)
def _sweeps(pos: np.ndarray, last: np.ndarray, c: Contact, ids: np.ndarray, coef: np.ndarray) -> None:
    # Apart from respond, which makes the scratch: compiled without reference counting, since
    # handing the group to the inlined per-pair response counted every one of its arrays up and
    # down, pair by pair (about 200 ns a pair, most of a substep between rebuilds); and in IEEE
    # order, so that its bits are the source's, not whatever the optimiser makes of the loop.
    sweeps, push = (SWEEPS_MOVING, PUSH_MOVING) if c.meta[MOVING] else (1, PUSH)
    for _ in range(sweeps):
        sweep(pos, last, c, ids, coef, push)


@njit(inline="always", **KERNEL)
def sweep(pos: np.ndarray, last: np.ndarray, c: Contact, ids: np.ndarray, coef: np.ndarray, push: float) -> None:
    """Every stored pair's response, averaged per point and applied (Jacobi); ``ids`` and
    ``coef`` are (4,) scratch."""
    h = c.thickness
    tris = c.tris
    edges = c.edges
    for k in range(c.meta[N_PT]):
        t = c.pt[1, k]
        ids[0] = c.pt[0, k]
        ids[1] = tris[0, t]
        ids[2] = tris[1, t]
        ids[3] = tris[2, t]
        coef[0] = 1.0
        coef[1] = -c.ptf[0, k]
        coef[2] = -c.ptf[1, k]
        coef[3] = -c.ptf[2, k]
        _respond(pos, last, c, ids, coef, c.ptf[3, k], c.ptf[4, k], c.ptf[5, k], h, push)
    for k in range(c.meta[N_EE]):
        e1 = c.ee[0, k]
        e2 = c.ee[1, k]
        u = c.eef[0, k]
        v = c.eef[1, k]
        ids[0] = edges[0, e1]
        ids[1] = edges[1, e1]
        ids[2] = edges[0, e2]
        ids[3] = edges[1, e2]
        coef[0] = 1.0 - u
        coef[1] = u
        coef[2] = v - 1.0
        coef[3] = -v
        _respond(pos, last, c, ids, coef, c.eef[2, k], c.eef[3, k], c.eef[4, k], h, push)
    for p in range(pos.shape[1]):
        m = c.cnt[p]
        if m > 0:
            inv = 1.0 / m
            pos[0, p] += c.acc[0, p] * inv
            pos[1, p] += c.acc[1, p] * inv
            pos[2, p] += c.acc[2, p] * inv
            c.acc[0, p] = 0.0
            c.acc[1, p] = 0.0
            c.acc[2, p] = 0.0
            c.cnt[p] = 0


@njit(**KERNEL)
def bound(pos: np.ndarray, c: Contact) -> None:
    """Project every free point into its ball (pinned points are never moved)."""
    ref = c.ref
    rho2 = c.rho2
    for p in range(pos.shape[1]):
        if not c.movable[p]:
            continue
        dx = pos[0, p] - ref[0, p]
        dy = pos[1, p] - ref[1, p]
        dz = pos[2, p] - ref[2, p]
        r2 = dx * dx + dy * dy + dz * dz
        if r2 > rho2[p]:
            # (a hair inside, so rounding does not leave it outside and force a rebuild)
            f = np.sqrt(rho2[p] / r2) * (1.0 - 1e-9)
            pos[0, p] = ref[0, p] + dx * f
            pos[1, p] = ref[1, p] + dy * f
            pos[2, p] = ref[2, p] + dz * f
            c.near.held[p] = True
            c.meta[CLAMPED] = 1


@njit(**KERNEL)
def _stale(pos: np.ndarray, last: np.ndarray, c: Contact, flag: np.ndarray) -> bool:
    """True when the substep that started at ``last`` needs a whole new reference: there is none,
    a point has left its ball, or more than ``LOCAL_SHARE`` of the points are about to (fewer have
    their references moved one by one: :func:`rereference`; how many call for one goes in
    ``flag[CALLS]``)."""
    if c.meta[VALID] == 0 or _outside(last, c):
        return True
    most = np.int64(LOCAL_SHARE * pos.shape[1])
    flag[CALLS] = _leaving(pos, c, most)
    return flag[CALLS] > most


@njit(**KERNEL)
def _rebuilt(pos: np.ndarray, c: Contact) -> None:
    # a pinned point that moved further than its ball in this one substep: the bound cannot hold
    # for its pairs (the pin's motion is prescribed); counted, not hidden
    for p in range(pos.shape[1]):
        if not c.movable[p]:
            dx = pos[0, p] - c.ref[0, p]
            dy = pos[1, p] - c.ref[1, p]
            dz = pos[2, p] - c.ref[2, p]
            if dx * dx + dy * dy + dz * dz > c.rho2[p]:
                c.meta[UNSAFE] += 1
                break


# The first half of the pass as the thread team runs it (solvers/frame.py): each member asks
# whether the reference is stale and, if so, which parts of the rebuild are its own (the same
# answers from the same arrays, so no member waits for another's, and the question costs the team
# no time: the others would wait for the first member meanwhile); if it is stale each searches
# its parts; after a barrier the first member joins them and responds. The parts' pairs, joined
# in order, are the pairs of one sweep in its order, and a ball's bound is a minimum, so the bits
# do not depend on the team's size. Before joining, the first member has a rebuild whose part
# overflowed its share searched again as one part (by the member's search called once more, not
# from inside the join, which would carry a second compiled copy of the search).


@njit(inline="always", **EXACT)
def _first_part(cost: np.ndarray, member: int, size: int) -> int:
    """The first part of member ``member`` of ``size``: parts cut where the running sum of
    ``cost`` reaches member / size of the whole (equal counts of parts before any cost is known)."""
    total = np.int64(0)
    for k in range(cost.shape[0]):
        total += cost[k]
    if total == 0:
        return share(cost.shape[0], member, size)[0]
    run = np.int64(0)
    for k in range(cost.shape[0]):
        if run * size >= total * member:
            return k
        run += cost[k]
    return cost.shape[0]


@njit(**EXACT)
def contact_stale(pos: np.ndarray, last: np.ndarray, c: Contact, flag: np.ndarray, member: int, size: int) -> None:
    """Member ``member``'s ``flag``: whether the substep that started at ``last`` rebuilds the
    reference, and if so its parts of the rebuild."""
    flag[CALLS] = 0
    flag[STALE] = 1 if _stale(pos, last, c, flag) else 0
    if flag[STALE] != 0:
        flag[FIRST] = _first_part(c.cost, member, size)
        flag[END] = _first_part(c.cost, member + 1, size) if member + 1 < size else PARTS
        flag[SIZE] = size
        flag[CUT] = PARTS


@njit(**EXACT)
def contact_search(last: np.ndarray, c: Contact, flag: np.ndarray, member: int) -> None:
    """Member ``member``'s parts (``flag``) of the rebuild from ``last``."""
    search(last, c, flag[FIRST], flag[END], flag[CUT], member)


@njit(inline="always", **EXACT)
def _search_alone(x: np.ndarray, c: Contact, flag: np.ndarray) -> None:
    """The parts of a rebuild that ``flag`` gives, searched by one member alone, and the whole
    rebuild again as one part if a part :func:`overflowed` (the team's first member does the same
    after the others' searches: solvers/frame.py)."""
    contact_search(x, c, flag, _ZERO)
    if overflowed(c, flag[CUT]):
        fall_back(flag)
        contact_search(x, c, flag, _ZERO)


@njit(**EXACT)
def contact_joined(pos: np.ndarray, last: np.ndarray, c: Contact, flag: np.ndarray) -> None:
    """The first member's end of the first half: the rebuild's parts joined (when ``flag`` says
    it is stale), or else the references of the points about to leave their balls moved, then
    the response."""
    if flag[STALE] != 0:
        join(last, c, flag[CUT], flag[SIZE])
        _rebuilt(pos, c)
    elif flag[CALLS] != 0 and rereference(pos, last, c):
        _rebuilt(pos, c)
    respond(pos, last, c)


@njit(**EXACT)
def contact_respond(pos: np.ndarray, last: np.ndarray, c: Contact) -> None:
    """The first half of the pass, in the self-collision slot of a substep that started at
    ``last``: rebuild the reference if a point has left its ball, then push the pairs apart (the
    team's three steps run by a team of one: the other integrators' substep)."""
    flag = np.empty(FLAG, dtype=np.int64)
    contact_stale(pos, last, c, flag, _ZERO, _ONE)
    if flag[STALE] != 0:
        _search_alone(last, c, flag)
    contact_joined(pos, last, c, flag)


@njit(**EXACT)
def contact_bound(pos: np.ndarray, c: Contact) -> None:
    """The second half, last in the substep: every free point into its ball."""
    bound(pos, c)


def snapshot_reference(c: Contact) -> tuple:
    """A copy of what the pass carries from one substep to the next (the reference, the balls,
    the stored pairs, the counters, the points' cells, the points held), for
    :func:`restore_reference`."""
    npt, nee = int(c.meta[N_PT]), int(c.meta[N_EE])
    nb = c.near
    kept = (nb.tri_box, nb.edge_box, nb.ext, nb.held, *(a for cells in (nb.points, nb.tris, nb.edges) for a in cells[:3]))
    return (c.ref.copy(), c.rho2.copy(), c.pt[:, :npt].copy(), c.ptf[:, :npt].copy(), c.ee[:, :nee].copy(),
            c.eef[:, :nee].copy(), c.meta.copy(), tuple(a.copy() for a in kept))


def restore_reference(c: Contact, saved: tuple) -> None:
    """Put back a :func:`snapshot_reference` (a frame replayed from its start)."""
    ref, rho2, pt, ptf, ee, eef, meta, kept = saved
    nb = c.near
    for a, b in zip((nb.tri_box, nb.edge_box, nb.ext, nb.held,
                     *(a for cells in (nb.points, nb.tris, nb.edges) for a in cells[:3])), kept):
        a[...] = b
    c.ref[...] = ref
    c.rho2[...] = rho2
    c.pt[:, :pt.shape[1]] = pt
    c.ptf[:, :ptf.shape[1]] = ptf
    c.ee[:, :ee.shape[1]] = ee
    c.eef[:, :eef.shape[1]] = eef
    c.meta[...] = meta


#: The pair arrays grow while frames drop pairs (see :func:`with_more_room`), up to this many
#: bytes in all.
MOST_PAIR_BYTES = 1 << 30


def with_more_room(c: Contact) -> Contact | None:
    """``c`` with pair arrays twice as long (what they hold copied over), or None when they would
    pass ``MOST_PAIR_BYTES``. A frame whose rebuilds or moves found more pairs than the arrays
    hold (``meta[DROPPED]`` grew) is run again from its start with them (the simulation does
    it): a pair left out is one the response does not push, and cloth wrung between moving pins
    then closes on them faster than their balls allow (the stress set's twist crossed itself)."""
    cap = 2 * c.pt.shape[1]
    if cap * 8 * (c.pt.shape[0] + c.ptf.shape[0] + c.ee.shape[0] + c.eef.shape[0]) > MOST_PAIR_BYTES:
        return None

    def grown(a: np.ndarray) -> np.ndarray:
        b = np.zeros((a.shape[0], cap), dtype=a.dtype)
        b[:, : a.shape[1]] = a
        return b

    return c._replace(pt=grown(c.pt), ptf=grown(c.ptf), ee=grown(c.ee), eef=grown(c.eef))


def response_reach(c: Contact) -> float:
    """The furthest the response moves a point in one substep: an average of pushes of at most
    the contact distance (plus friction), over a weight sum of at least 1/2."""
    return 2.0 * (1.0 + FRICTION) * c.thickness


# ------------------------------------------------------------------------------------------------
# crossings (for the warning about a cloth that starts crossed)


@njit(inline="always", **KERNEL)
def _volume(a: int, b: int, c: int, d: int, x: np.ndarray) -> float:
    ux, uy, uz = x[0, b] - x[0, a], x[1, b] - x[1, a], x[2, b] - x[2, a]
    vx, vy, vz = x[0, c] - x[0, a], x[1, c] - x[1, a], x[2, c] - x[2, a]
    wx, wy, wz = x[0, d] - x[0, a], x[1, d] - x[1, a], x[2, d] - x[2, a]
    return (uy * vz - uz * vy) * wx + (uz * vx - ux * vz) * wy + (ux * vy - uy * vx) * wz
