"""Edge-triangle crossings of a triangle mesh: the measure of a cloth passing through itself.

A *crossing* is an edge of the mesh that passes through a triangle it shares no vertex with. The
cloth's mesh is the renderer's (:func:`clothsim.cloth.cloth_triangles`: two triangles per grid
quad, so its edges are the grid's rows, columns and one diagonal per quad). A cloth that never
passes through itself has none at any time; each place where one sheet of it pierces another shows
up as a few crossings (the edges of one sheet that run through the other's triangles).

The rule, exact for every input (no tolerance): edge ``pq`` crosses triangle ``abc`` when ``p`` and
``q`` lie strictly on opposite sides of the triangle's plane and the line ``pq`` passes strictly
inside the triangle (the three orientations of ``pq`` against its sides are non-zero and of one
sign). A contact in a degenerate position counts zero: an endpoint on the plane, the segment
through a side or a corner of the triangle, a segment lying in the plane. So a flat cloth has
none, and a segment through the side two triangles share is counted by neither (a position of
measure zero, which a simulated cloth does not hold for more than an instant).

Each of the five orientation signs is computed in float64 and taken when it exceeds Shewchuk's
error bound for ``orient3d`` (J. R. Shewchuk, "Adaptive Precision Floating-Point Arithmetic and
Fast Robust Geometric Predicates", 1997: ``(7 + 56 eps) eps`` times the permanent); otherwise
the determinant is summed exactly (error-free products and sums of doubles), so the sign is the
exact sign of the exact determinant. That holds while no product of coordinate differences
underflows (differences above about 1e-100 m or exactly 0), which any cloth satisfies.

The broad phase is a uniform spatial hash over the triangles' bounding boxes, with a cell about
one mean edge long: each edge looks only at the triangles that share a cell with its own box, so
the cost grows with the number of edges, not edges times triangles.
"""

from __future__ import annotations

import functools

import numpy as np
from numba import njit

from ..cloth import cloth_triangles
from ..jit import EXACT

#: Shewchuk's orient3d error bound factor, epsilon = 2**-53.
_EPS = 2.0 ** -53
_O3D_BOUND = (7.0 + 56.0 * _EPS) * _EPS
#: Dekker's splitter for float64: 2**27 + 1.
_SPLITTER = 134217729.0
#: Most (triangle, cell) entries the hash may hold per triangle before the cell is made larger (a
#: stretched or exploded mesh would otherwise put one long triangle in millions of cells).
_ENTRIES_PER_TRIANGLE = 16


# ----------------------------------------------------------------------------------------------
# Exact orientation


@njit(inline="always", **EXACT)
def _two_sum(a: float, b: float) -> tuple[float, float]:
    """x + y == a + b exactly, x = fl(a + b) (Knuth)."""
    x = a + b
    bv = x - a
    av = x - bv
    return x, (a - av) + (b - bv)


@njit(inline="always", **EXACT)
def _two_diff(a: float, b: float) -> tuple[float, float]:
    """x + y == a - b exactly, x = fl(a - b)."""
    x = a - b
    bv = a - x
    av = x + bv
    return x, (a - av) + (bv - b)


@njit(inline="always", **EXACT)
def _split(a: float) -> tuple[float, float]:
    c = _SPLITTER * a
    big = c - a
    hi = c - big
    return hi, a - hi


@njit(inline="always", **EXACT)
def _two_product(a: float, b: float) -> tuple[float, float]:
    """x + y == a * b exactly, x = fl(a * b) (Dekker; exact unless it underflows)."""
    x = a * b
    ahi, alo = _split(a)
    bhi, blo = _split(b)
    err = x - ahi * bhi
    err -= alo * bhi
    err -= ahi * blo
    return x, alo * blo - err


@njit(**EXACT)
def _grow(e: np.ndarray, n: int, b: float) -> int:
    """Add ``b`` to the nonoverlapping expansion ``e[:n]`` (increasing magnitude), in place,
    dropping zero components; return the new length (Shewchuk's Grow-Expansion)."""
    q = b
    m = 0
    for i in range(n):
        q, h = _two_sum(q, e[i])
        if h != 0.0:
            e[m] = h
            m += 1
    if q != 0.0:
        e[m] = q
        m += 1
    return m


@njit(**EXACT)
def _exact_orient_sign(a: np.ndarray, b: np.ndarray, c: np.ndarray, d: np.ndarray) -> int:
    """Sign of det[a-d; b-d; c-d], summed exactly from the coordinates."""
    # each difference exactly as (head, tail); then every product of three differences expanded
    # into products of doubles, each made exact by two error-free products, and all summed.
    diff = np.empty((3, 3, 2))
    for k in range(3):
        diff[0, k, 0], diff[0, k, 1] = _two_diff(a[k], d[k])
        diff[1, k, 0], diff[1, k, 1] = _two_diff(b[k], d[k])
        diff[2, k, 0], diff[2, k, 1] = _two_diff(c[k], d[k])
    acc = np.empty(6 * 8 * 4 + 1)
    n = 0
    # det = sum over permutations (i, j, k) of rows for columns x, y, z, with the permutation's sign
    for perm in range(6):
        if perm == 0:
            r0, r1, r2, sign = 0, 1, 2, 1.0
        elif perm == 1:
            r0, r1, r2, sign = 1, 2, 0, 1.0
        elif perm == 2:
            r0, r1, r2, sign = 2, 0, 1, 1.0
        elif perm == 3:
            r0, r1, r2, sign = 0, 2, 1, -1.0
        elif perm == 4:
            r0, r1, r2, sign = 2, 1, 0, -1.0
        else:
            r0, r1, r2, sign = 1, 0, 2, -1.0
        for i in range(2):
            x = diff[r0, 0, i]
            if x == 0.0:
                continue
            for j in range(2):
                y = diff[r1, 1, j]
                if y == 0.0:
                    continue
                p, pe = _two_product(x, y)
                for k in range(2):
                    z = sign * diff[r2, 2, k]
                    if z == 0.0:
                        continue
                    h, t = _two_product(p, z)
                    n = _grow(acc, n, h)
                    n = _grow(acc, n, t)
                    h, t = _two_product(pe, z)
                    n = _grow(acc, n, h)
                    n = _grow(acc, n, t)
    if n == 0:
        return 0
    # the largest component of a nonoverlapping expansion carries its sign
    return 1 if acc[n - 1] > 0.0 else -1


@njit(inline="always", **EXACT)
def _orient(ax: float, ay: float, az: float, bx: float, by: float, bz: float, cx: float, cy: float, cz: float,
            dx: float, dy: float, dz: float) -> int:
    """:func:`orient3d_sign` of points given by their coordinates (no arrays on the hot path)."""
    adx = ax - dx
    ady = ay - dy
    adz = az - dz
    bdx = bx - dx
    bdy = by - dy
    bdz = bz - dz
    cdx = cx - dx
    cdy = cy - dy
    cdz = cz - dz
    bdxcdy = bdx * cdy
    cdxbdy = cdx * bdy
    cdxady = cdx * ady
    adxcdy = adx * cdy
    adxbdy = adx * bdy
    bdxady = bdx * ady
    det = adz * (bdxcdy - cdxbdy) + bdz * (cdxady - adxcdy) + cdz * (adxbdy - bdxady)
    permanent = ((abs(bdxcdy) + abs(cdxbdy)) * abs(adz) + (abs(cdxady) + abs(adxcdy)) * abs(bdz)
                 + (abs(adxbdy) + abs(bdxady)) * abs(cdz))
    if permanent == 0.0:
        # every product holds a zero difference (a rounded difference is 0 only when the
        # coordinates are equal, and no product underflows): the exact determinant is 0 too. A
        # flat cloth takes this way for every pair.
        return 0
    bound = _O3D_BOUND * permanent
    if det > bound:
        return 1
    if -det > bound:
        return -1
    return _exact_orient_sign(np.array([ax, ay, az]), np.array([bx, by, bz]), np.array([cx, cy, cz]),
                              np.array([dx, dy, dz]))


@njit(**EXACT)
def orient3d_sign(a: np.ndarray, b: np.ndarray, c: np.ndarray, d: np.ndarray) -> int:
    """Exact sign of det[a-d; b-d; c-d]: +1 when ``d`` lies below the plane of ``a, b, c`` (seen
    with ``a, b, c`` counter-clockwise from above), -1 above, 0 on it.

    A float64 determinant whose magnitude exceeds Shewchuk's bound is taken as it is; otherwise the
    sign is computed exactly.
    """
    return _orient(a[0], a[1], a[2], b[0], b[1], b[2], c[0], c[1], c[2], d[0], d[1], d[2])


@njit(inline="always", **EXACT)
def _crosses(pts: np.ndarray, i: int, j: int, a: int, b: int, c: int) -> bool:
    """:func:`segment_crosses_triangle` of points ``i``, ``j`` and ``a``, ``b``, ``c`` of ``pts``."""
    px, py, pz = pts[i, 0], pts[i, 1], pts[i, 2]
    qx, qy, qz = pts[j, 0], pts[j, 1], pts[j, 2]
    ax, ay, az = pts[a, 0], pts[a, 1], pts[a, 2]
    bx, by, bz = pts[b, 0], pts[b, 1], pts[b, 2]
    cx, cy, cz = pts[c, 0], pts[c, 1], pts[c, 2]
    sp = _orient(ax, ay, az, bx, by, bz, cx, cy, cz, px, py, pz)
    if sp == 0:
        return False
    sq = _orient(ax, ay, az, bx, by, bz, cx, cy, cz, qx, qy, qz)
    if sq == 0 or sq == sp:
        return False
    s1 = _orient(px, py, pz, qx, qy, qz, ax, ay, az, bx, by, bz)
    if s1 == 0:
        return False
    if _orient(px, py, pz, qx, qy, qz, bx, by, bz, cx, cy, cz) != s1:
        return False
    return _orient(px, py, pz, qx, qy, qz, cx, cy, cz, ax, ay, az) == s1


@njit(**EXACT)
def segment_crosses_triangle(p: np.ndarray, q: np.ndarray, a: np.ndarray, b: np.ndarray, c: np.ndarray) -> bool:
    """True when segment ``pq`` passes through the interior of triangle ``abc`` transversally
    (the module's rule: every touching or coplanar contact is False)."""
    pts = np.empty((5, 3))
    pts[0] = p
    pts[1] = q
    pts[2] = a
    pts[3] = b
    pts[4] = c
    return _crosses(pts, 0, 1, 2, 3, 4)


# ----------------------------------------------------------------------------------------------
# Broad phase and count


@njit(inline="always", **EXACT)
def _bucket(ix: int, iy: int, iz: int, mask: int) -> int:
    return ((ix * 73856093) ^ (iy * 19349663) ^ (iz * 83492791)) & mask


@njit(**EXACT)
def _triangle_boxes(points: np.ndarray, tris: np.ndarray, h: float) -> tuple[np.ndarray, np.ndarray, float]:
    """Each triangle's box (T, 6) and cell range (T, 6), and the number of (triangle, cell) entries
    (a float: it only decides whether the cell is large enough, and may exceed an int64)."""
    n_tris = tris.shape[0]
    boxes = np.empty((n_tris, 6))
    cells = np.empty((n_tris, 6), dtype=np.int64)
    entries = 0.0
    for t in range(n_tris):
        for k in range(3):
            lo = min(points[tris[t, 0], k], points[tris[t, 1], k], points[tris[t, 2], k])
            hi = max(points[tris[t, 0], k], points[tris[t, 1], k], points[tris[t, 2], k])
            boxes[t, k] = lo
            boxes[t, 3 + k] = hi
            cells[t, k] = np.int64(np.floor(lo / h))
            cells[t, 3 + k] = np.int64(np.floor(hi / h))
        entries += (float(cells[t, 3] - cells[t, 0] + 1) * float(cells[t, 4] - cells[t, 1] + 1)
                    * float(cells[t, 5] - cells[t, 2] + 1))
    return boxes, cells, entries


@njit(**EXACT)
def _count(points: np.ndarray, tris: np.ndarray, edges: np.ndarray, boxes: np.ndarray, cells: np.ndarray,
           entries: int, h: float, pairs: np.ndarray) -> int:
    """Crossings of every edge with every triangle it shares no vertex with; the first ones found
    (edge index, triangle index), up to ``pairs``' length, go into ``pairs``."""
    n_tris = tris.shape[0]
    size = 1
    while size < 2 * entries:
        size *= 2
    mask = size - 1
    start = np.zeros(size + 1, dtype=np.int64)
    for t in range(n_tris):
        for ix in range(cells[t, 0], cells[t, 3] + 1):
            for iy in range(cells[t, 1], cells[t, 4] + 1):
                for iz in range(cells[t, 2], cells[t, 5] + 1):
                    start[_bucket(ix, iy, iz, mask) + 1] += 1
    for s in range(size):
        start[s + 1] += start[s]
    fill = start[:-1].copy()
    items = np.empty(entries, dtype=np.int64)
    for t in range(n_tris):
        for ix in range(cells[t, 0], cells[t, 3] + 1):
            for iy in range(cells[t, 1], cells[t, 4] + 1):
                for iz in range(cells[t, 2], cells[t, 5] + 1):
                    s = _bucket(ix, iy, iz, mask)
                    items[fill[s]] = t
                    fill[s] += 1
    # seen[t] == e: triangle t already tested against edge e (it shares several cells with it)
    seen = np.full(n_tris, -1, dtype=np.int64)
    lo = np.empty(3)
    hi = np.empty(3)
    found = 0
    for e in range(edges.shape[0]):
        i = edges[e, 0]
        j = edges[e, 1]
        for k in range(3):
            lo[k] = min(points[i, k], points[j, k])
            hi[k] = max(points[i, k], points[j, k])
        c0 = np.int64(np.floor(lo[0] / h))
        c1 = np.int64(np.floor(lo[1] / h))
        c2 = np.int64(np.floor(lo[2] / h))
        d0 = np.int64(np.floor(hi[0] / h))
        d1 = np.int64(np.floor(hi[1] / h))
        d2 = np.int64(np.floor(hi[2] / h))
        for ix in range(c0, d0 + 1):
            for iy in range(c1, d1 + 1):
                for iz in range(c2, d2 + 1):
                    s = _bucket(ix, iy, iz, mask)
                    for m in range(start[s], start[s + 1]):
                        t = items[m]
                        if seen[t] == e:
                            continue
                        seen[t] = e
                        a = tris[t, 0]
                        b = tris[t, 1]
                        c = tris[t, 2]
                        if i == a or i == b or i == c or j == a or j == b or j == c:
                            continue
                        if (hi[0] < boxes[t, 0] or lo[0] > boxes[t, 3] or hi[1] < boxes[t, 1]
                                or lo[1] > boxes[t, 4] or hi[2] < boxes[t, 2] or lo[2] > boxes[t, 5]):
                            continue
                        if _crosses(points, i, j, a, b, c):
                            if found < pairs.shape[0]:
                                pairs[found, 0] = e
                                pairs[found, 1] = t
                            found += 1
    return found


# ----------------------------------------------------------------------------------------------
# Python side


def mesh_edges(triangles: np.ndarray) -> np.ndarray:
    """The unique edges (E, 2) int64 of a triangle list (T, 3), each as (low, high) point index,
    sorted."""
    tris = np.asarray(triangles, dtype=np.int64).reshape(-1, 3)
    if len(tris) == 0:
        return np.zeros((0, 2), dtype=np.int64)
    first = np.concatenate([tris[:, 0], tris[:, 1], tris[:, 2]])
    second = np.concatenate([tris[:, 1], tris[:, 2], tris[:, 0]])
    # one int64 key per edge, (low, high), sorted and deduplicated (np.unique, rows or not, took
    # 20x longer than the sort on NumPy 2.4)
    base = int(tris.max()) + 1
    keys = np.sort(np.minimum(first, second) * base + np.maximum(first, second))
    keys = keys[np.r_[True, keys[1:] != keys[:-1]]]
    return np.column_stack([keys // base, keys % base])


def grid_triangles(nw: int, nh: int) -> np.ndarray:
    """The cloth's render triangles (T, 3) int64 for an ``nw`` x ``nh`` grid."""
    return cloth_triangles(nw, nh).astype(np.int64).reshape(-1, 3)


@functools.lru_cache(maxsize=8)
def _grid_mesh(nw: int, nh: int) -> tuple[np.ndarray, np.ndarray]:
    """(triangles, edges) of a grid, built once per size (a run counts every frame), read-only."""
    tris = grid_triangles(nw, nh)
    edges = mesh_edges(tris)
    tris.flags.writeable = False
    edges.flags.writeable = False
    return tris, edges


def _cell_size(points: np.ndarray, tris: np.ndarray, edges: np.ndarray) -> float:
    if len(edges) == 0:
        return 1.0
    d = points[edges[:, 1]] - points[edges[:, 0]]
    h = float(np.sqrt(np.einsum("ij,ij->i", d, d)).mean())
    extent = float(np.max(np.abs(points))) if points.size else 0.0
    # a cell far below the coordinates' size would make floor(x / h) overflow
    return max(h, extent * 1e-12, 1e-300) if h > 0.0 else max(extent, 1.0)


def _check(points: np.ndarray, triangles: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    pts = np.ascontiguousarray(points, dtype=np.float64)
    if pts.ndim != 2 or pts.shape[1] != 3:
        raise ValueError(f"positions: expected shape (N, 3), got {np.shape(points)}")
    if not np.all(np.isfinite(pts)):
        raise ValueError("positions: not every coordinate is finite")
    tris = np.ascontiguousarray(triangles, dtype=np.int64)
    if tris.ndim != 2 or tris.shape[1] != 3:
        raise ValueError(f"triangles: expected shape (T, 3), got {np.shape(triangles)}")
    if tris.size and (tris.min() < 0 or tris.max() >= len(pts)):
        raise ValueError(f"triangles: indices must be in 0..{len(pts) - 1}")
    return pts, tris


def mesh_crossings(points: np.ndarray, triangles: np.ndarray, *, pairs: bool = False,
                   edges: np.ndarray | None = None) -> int | np.ndarray:
    """Crossings of a triangle mesh: edges through triangles they share no point with.

    ``points`` (N, 3), ``triangles`` (T, 3) point indices; ``edges`` (E, 2), default every edge
    of the triangles. Returns the count, or with ``pairs=True`` the crossings as an (K, 2) int64
    array of (edge index into ``edges``, triangle index), in a fixed order. Raises ValueError for
    arrays of the wrong shape, indices out of range or non-finite positions.
    """
    pts, tris = _check(points, triangles)
    edges = mesh_edges(tris) if edges is None else np.ascontiguousarray(edges, dtype=np.int64)
    h = _cell_size(pts, tris, edges)
    while True:
        boxes, cells, entries = _triangle_boxes(pts, tris, h)
        if entries <= _ENTRIES_PER_TRIANGLE * len(tris) + 1024:
            break
        h *= 2.0
    out = np.zeros((0, 2), dtype=np.int64)
    found = _count(pts, tris, edges, boxes, cells, int(entries), h, out)
    if not pairs:
        return int(found)
    out = np.zeros((found, 2), dtype=np.int64)
    _count(pts, tris, edges, boxes, cells, int(entries), h, out)
    return out


def count_crossings(positions: np.ndarray, nw: int, nh: int) -> int:
    """Edge-triangle crossings of a cloth's render mesh: the number of (edge, triangle) pairs,
    sharing no point, where the edge passes through the triangle (exact; see the module's rule).

    ``positions`` (nw * nh, 3), row-major as :attr:`Simulation.positions`. Raises ValueError when
    the shape does not match the grid or a coordinate is not finite.
    """
    pts = np.asarray(positions)
    if pts.ndim != 2 or pts.shape != (nw * nh, 3):
        raise ValueError(f"positions: expected shape ({nw * nh}, 3) for a {nw}x{nh} grid, got {pts.shape}")
    tris, edges = _grid_mesh(nw, nh)
    return int(mesh_crossings(pts, tris, edges=edges))


def crossing_pairs(positions: np.ndarray, nw: int, nh: int) -> np.ndarray:
    """The crossings of :func:`count_crossings` as (K, 3) int64 rows: the edge's two points and the
    triangle's index in :func:`clothsim.cloth.cloth_triangles` order (triangle t has points
    ``cloth_triangles(nw, nh)[3 * t : 3 * t + 3]``)."""
    pts = np.asarray(positions)
    if pts.ndim != 2 or pts.shape != (nw * nh, 3):
        raise ValueError(f"positions: expected shape ({nw * nh}, 3) for a {nw}x{nh} grid, got {pts.shape}")
    tris, edges = _grid_mesh(nw, nh)
    found = mesh_crossings(pts, tris, pairs=True, edges=edges)
    return np.column_stack([edges[found[:, 0]], found[:, 1]]).astype(np.int64)
