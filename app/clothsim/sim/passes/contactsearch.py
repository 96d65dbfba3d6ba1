"""The contact pass's search (:mod:`.contact`): every point-triangle and edge-edge pair within
the query radius of a reference state, in parts the thread team searches side by side, joined in
order into the stored pairs and each point's ball."""

from __future__ import annotations

from typing import NamedTuple

import numpy as np
from numba import njit

from ...jit import BORROWED, EXACT, INNER, KERNEL
from ..team import share
from .celltables import box_table, cell_at, corner_table, grid_over, index_of
from .contactdistance import NO_LENGTH, closest_on_segments, closest_on_triangle
from .contactgroup import CLAMPED, CUT, DROPPED, END, FIRST, FLAG, FLOOR, GAMMA, N_EE, N_PT, PARTS, REBUILDS, SIZE, \
    STALE, VALID, Contact
from .nearby import Cells, box_key, element_box, extent, key_of, list_all


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


@njit(**EXACT, **INNER)
def new_batch() -> Batch:
    """An empty :class:`Batch`."""
    return Batch(np.empty(12 * BATCH), np.empty(7 * BATCH), np.empty(2 * BATCH, dtype=np.int64))


@njit(**BORROWED, **INNER)
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


@njit(**BORROWED, **INNER)
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


@njit(**BORROWED, **INNER)
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


@njit(**BORROWED, **INNER)
def _settle_pt(c: Contact, pairs: np.ndarray, out: np.ndarray, n: int, dmin: np.ndarray, npt: int, end: int) -> int:
    """The batch's pairs, in order, as :func:`_point_triangle` takes them one by one; returns the
    pairs kept."""
    for k in range(n):
        wa, wb, wc = _get3(out, _W, k)
        nx, ny, nz = _get3(out, _PN, k)
        npt = _keep_pt(c, pairs[k], pairs[BATCH + k], wa, wb, wc, nx, ny, nz, out[_PD * BATCH + k], dmin, npt, end)
    return npt


@njit(**BORROWED, **INNER)
def _tested_pt(c: Contact, batch: Batch, n: int, dmin: np.ndarray, npt: int, end: int) -> int:
    # a batch of point-triangle pairs tested and taken in order (as rebuilds and moves test them)
    _triangles_batch(batch.rows, batch.results, n)
    return _settle_pt(c, batch.pairs, batch.results, n, dmin, npt, end)


@njit(**BORROWED, **INNER)
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


@njit(**EXACT, **INNER)
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


@njit(**BORROWED, **INNER)
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


@njit(**BORROWED, **INNER)
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
