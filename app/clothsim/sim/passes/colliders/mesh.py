"""Collisions with triangle meshes (:class:`~clothsim.sim.passes.colliders.meshgrid.MeshGroup`), one point at a time.

Each substep a mesh has a translation before and after it (its motion track at the substep's two
ends), and a turning mesh a turn Q at both ends too; a point is handled in the mesh's own frame,
where its last position ``l`` and its position ``q`` are taken relative to those two poses
(``Q0^T (last - p0)`` and ``Q1^T (pos - p1)``; the corrected point goes back by ``p1 + Q1 x``). Every triangle whose bounding box comes
within ``r`` = thickness + |q - l| of ``q`` gives

* the closest point on it to ``q`` (Ericson, Real-Time Collision Detection, 5.1.5), with the
  feature it lies on (face, edge or vertex) for the pseudo-normal;
* whether the segment ``l -> q`` crosses it (Moller-Trumbore), which sweeps the substep's
  relative motion, so a fast point or a fast mesh cannot pass through a face unseen.

The point is then corrected, in this order:

1. it crossed a face from the side of that face's normal, for a closed mesh, or from either side,
   for an open one: it goes back onto the plane of the face it crossed first, lifted by the
   thickness on the side it came from (like a plane);
2. a closed mesh only: it lies inside (by the pseudo-normal at its closest point, at most ``r``
   away): it goes to the closest point, lifted out by the thickness along the pseudo-normal;
3. it is nearer than the thickness: it is pushed straight away from the closest point to the
   thickness (along the face's normal, on its last position's side, if it lies on the surface).

Friction as for spheres: the point moves from its last position towards the corrected one by
(1 - friction), relative to the mesh, so a mesh of friction 1 carries the points it holds.

Which triangles a point tests (the broad phase): each point keeps, per mesh, a list of the
triangles whose boxes come within the list's reach (1.5 thicknesses, ``INFO_NEAR``) of an anchor,
the point's position when the list was gathered. While the point stays within reach - r of its
anchor (per axis, less a slack far beyond rounding: ``INFO_NEAR_OK``), the list holds every
triangle within r of it; a cloth at rest on a mesh keeps its lists for many substeps, and each
substep reads a few triangles in a row. A point that left its reach gathers its list afresh from
the grid (:mod:`~clothsim.sim.passes.colliders.meshgrid`); one whose r exceeds the reach (a fast
point), or whose list would hold more than ``NEAR_ROOM`` triangles, asks the grid for this
substep's. The lists are a cache of where each point is, not of its history: whichever way a
point's triangles were found, they include every one within r of it.

A list is kept nearest first, each triangle with its distance from a reference point (less the
list's slack): its distance from q is at least that less |q - reference|, so a substep reads the
list only while that bound is within r. The reference is the anchor when the list is gathered,
and where the point is once it has drifted ``REFRESH`` thicknesses from it (the distances are
measured again and the list kept: the drift would otherwise admit ever more of it). A point whose
nearest listed triangle is out of reach by that bound (one hanging clear of the mesh, say) is
passed over before its list is read, as is one further than r from the mesh's box; in that first
test the lengths are bounded from above by their sums of components (no square root). What is
passed over could neither come within r nor be crossed, so no answer changes.

A point whose list is valid is then held by separating planes instead of those tests (the contact
rule of a listed point). When a list is measured, each of its first ``NEAR_PLANES`` triangles gets
the plane through its support point facing the reference point: normal n = (reference - c) /
|reference - c|, c the triangle's closest point to the reference, offset the largest n . v of its
corners (= n . c). The whole triangle lies on the plane's inner side, n . x <= offset, whatever
rounding made of n. A substep takes the triangles the bound above lets through, nearest first,
and for each in turn pushes the point along n until n . q - offset = thickness where it is less
(so no friction where none is violated). As long as the last position is strictly on each such
plane's outer side, and the corrected position is too (checked after the pushes, since one push
can take back part of another where planes face each other), the segment between them stays on
that side (a half-space is convex) and cannot cross the triangle; a point pushed out of a plane
ends at least the thickness from its triangle (unless a later push in a crease takes part of it
back, as the tests, which push from the nearest triangle alone, leave a crease's second face to
the next substep). For a point resting on a face, n is the
face's normal and the push is the tests' push; near an edge or a corner the plane is the tangent
plane of the distance at the reference, a little more cautious than the tests as the point moves
away from it (by the drift, which the remeasuring keeps under ``REFRESH`` thicknesses). The
planes cost a dot product a triangle, the tests a closest point and often a crossing test. The
tests decide instead for a point without a list, a point with a reachable triangle past the
first ``NEAR_PLANES``, a last or corrected position not strictly outside a reachable triangle's
plane, and a closed mesh's list measured from inside it (no planes then).

A deforming mesh (:mod:`.meshdeform`) takes :func:`collide_deforming_points` instead: no lists and
no planes (they assume still triangles), the grid every substep, each point's reach widened by
how far the mesh's vertices move over the substep, and each triangle tested with the point's last
position carried by that triangle's own motion (:func:`_moving_tri_test`), so that the crossing
test and friction see the point's motion relative to the surface.

In the tests, ties between triangles are broken by the lower triangle index, so their answer does
not depend on the order triangles come in, and equals the brute-force one (:func:`mesh_targets`)
bit for bit. Each point's list is written only by the work item that owns the point.
"""

from __future__ import annotations

import math

from typing import Any

import numba
import numpy as np
from numba import njit, types
from numba.extending import overload

from ....jit import BORROWED, CHUNKS, EXACT, KERNEL
from ....jit.internals import call_native, native_address
from ...clock import substep_time
from .meshdeform import Deform, deform_meshes
from .moving import Tracks, Turns, track_ends, turn_ends
from .meshgrid import MeshGroup, mesh_group, DIMS_CELL0, DIMS_CLOSED, DIMS_N, DIMS_TRI0, DIMS_TRI1, INFO_FRICTION, \
    INFO_HI, INFO_INV_H, INFO_LO, INFO_MARGIN, INFO_NEAR, INFO_NEAR_OK, PLANE_D
from ...team import share

#: How far (in thicknesses) a point may drift from where its list's distances and planes were
#: measured before they are measured again from where it is (see the module's docstring).
REFRESH = 0.2
#: How much longer than a sum of absolute components the early test takes a length to be.
_LONGER = 1.0 + 1e-9

# closest-point features
FACE, VERTEX_A, VERTEX_B, VERTEX_C, EDGE_AB, EDGE_BC, EDGE_CA = 0, 1, 2, 3, 4, 5, 6


@njit(inline="always", **EXACT)
def _edge_dots(abx: float, aby: float, abz: float, acx: float, acy: float, acz: float, qx: float, qy: float,
               qz: float) -> tuple[float, float]:
    """(ab . q, ac . q): where q, the point seen from one corner, lies along the triangle's two
    edges from a (Ericson's d1..d6, in the same order of operations)."""
    return abx * qx + aby * qy + abz * qz, acx * qx + acy * qy + acz * qz


@njit(**EXACT)
def closest_on_triangle(px: float, py: float, pz: float, ax: float, ay: float, az: float, bx: float, by: float,
                        bz: float, cx: float, cy: float, cz: float) -> tuple[float, float, float, int]:
    """The point of triangle abc closest to p and the feature it lies on (Ericson 5.1.5)."""
    # The corners' and the edges' regions are tested alike, one after another in the book's
    # order (the duplicate-code scan sees the edges' three tests as near-copies): each edge's
    # test has its own weight and its own early return, and folding them into a loop over the
    # edges would only hide that order.
    abx, aby, abz = bx - ax, by - ay, bz - az
    acx, acy, acz = cx - ax, cy - ay, cz - az
    d1, d2 = _edge_dots(abx, aby, abz, acx, acy, acz, px - ax, py - ay, pz - az)
    if d1 <= 0.0 and d2 <= 0.0:
        return ax, ay, az, VERTEX_A
    d3, d4 = _edge_dots(abx, aby, abz, acx, acy, acz, px - bx, py - by, pz - bz)
    if d3 >= 0.0 and d4 <= d3:
        return bx, by, bz, VERTEX_B
    vc = d1 * d4 - d3 * d2
    if vc <= 0.0 and d1 >= 0.0 and d3 <= 0.0:
        v = d1 / (d1 - d3)
        return ax + v * abx, ay + v * aby, az + v * abz, EDGE_AB
    d5, d6 = _edge_dots(abx, aby, abz, acx, acy, acz, px - cx, py - cy, pz - cz)
    if d6 >= 0.0 and d5 <= d6:
        return cx, cy, cz, VERTEX_C
    vb = d5 * d2 - d1 * d6
    if vb <= 0.0 and d2 >= 0.0 and d6 <= 0.0:
        w = d2 / (d2 - d6)
        return ax + w * acx, ay + w * acy, az + w * acz, EDGE_CA
    va = d3 * d6 - d5 * d4
    if va <= 0.0 and (d4 - d3) >= 0.0 and (d5 - d6) >= 0.0:
        w = (d4 - d3) / ((d4 - d3) + (d5 - d6))
        return bx + w * (cx - bx), by + w * (cy - by), bz + w * (cz - bz), EDGE_BC
    denom = 1.0 / (va + vb + vc)
    v = vb * denom
    w = vc * denom
    return ax + abx * v + acx * w, ay + aby * v + acy * w, az + abz * v + acz * w, FACE


@njit(**EXACT)
def segment_hits(lx: float, ly: float, lz: float, qx: float, qy: float, qz: float, ax: float, ay: float,
                 az: float, bx: float, by: float, bz: float, cx: float, cy: float, cz: float) -> float:
    """Parameter s in [0, 1] where the segment l -> q meets triangle abc (Moller-Trumbore), or -1."""
    dx, dy, dz = qx - lx, qy - ly, qz - lz
    e1x, e1y, e1z = bx - ax, by - ay, bz - az
    e2x, e2y, e2z = cx - ax, cy - ay, cz - az
    hx = dy * e2z - dz * e2y
    hy = dz * e2x - dx * e2z
    hz = dx * e2y - dy * e2x
    det = e1x * hx + e1y * hy + e1z * hz
    if det == 0.0:
        return -1.0
    inv = 1.0 / det
    sx, sy, sz = lx - ax, ly - ay, lz - az
    u = (sx * hx + sy * hy + sz * hz) * inv
    if u < 0.0 or u > 1.0:
        return -1.0
    kx = sy * e1z - sz * e1y
    ky = sz * e1x - sx * e1z
    kz = sx * e1y - sy * e1x
    v = (dx * kx + dy * ky + dz * kz) * inv
    if v < 0.0 or u + v > 1.0:
        return -1.0
    s = (e2x * kx + e2y * ky + e2z * kz) * inv
    if s < 0.0 or s > 1.0:
        return -1.0
    return s


@njit(inline="always", **EXACT)
def pseudo_normal(mesh: tuple, t: int, feature: int) -> tuple[float, float, float]:
    """The pseudo-normal of triangle ``t``'s ``feature`` (face, edge or vertex)."""
    if feature == FACE:
        return mesh.fnorm[t, 0], mesh.fnorm[t, 1], mesh.fnorm[t, 2]
    if feature >= EDGE_AB:
        k = feature - EDGE_AB
        return mesh.enorm[t, k, 0], mesh.enorm[t, k, 1], mesh.enorm[t, k, 2]
    v = mesh.tris[t, feature - VERTEX_A]
    return mesh.vnorm[v, 0], mesh.vnorm[v, 1], mesh.vnorm[v, 2]


@njit(inline="always", **EXACT)
def resolve(mesh: tuple, m: int, lx: float, ly: float, lz: float, qx: float, qy: float, qz: float, d2: float,
            cx: float, cy: float, cz: float, t: int, feature: int, h: int) -> tuple[bool, float, float, float]:
    """(contact?, corrected position in the mesh frame before friction) from the closest point c
    (distance^2 ``d2``, triangle ``t``, ``feature``; t = -1: none within reach) and the first
    crossed triangle ``h`` (-1: none)."""
    th = mesh.thickness
    closed = mesh.dims[m, DIMS_CLOSED] != 0
    if h >= 0:
        nx, ny, nz = mesh.fnorm[h, 0], mesh.fnorm[h, 1], mesh.fnorm[h, 2]
        v = mesh.tris[h, 0]
        x0, y0, z0 = mesh.verts[v, 0], mesh.verts[v, 1], mesh.verts[v, 2]
        before = (lx - x0) * nx + (ly - y0) * ny + (lz - z0) * nz
        side = 1.0 if before >= 0.0 else -1.0
        if not closed or side > 0.0:
            shift = side * th - ((qx - x0) * nx + (qy - y0) * ny + (qz - z0) * nz)
            return True, qx + nx * shift, qy + ny * shift, qz + nz * shift
    if t < 0:
        return False, qx, qy, qz
    dx, dy, dz = qx - cx, qy - cy, qz - cz
    if closed:
        nx, ny, nz = pseudo_normal(mesh, t, feature)
        if dx * nx + dy * ny + dz * nz < 0.0:
            return True, cx + nx * th, cy + ny * th, cz + nz * th
    if d2 >= th * th:
        return False, qx, qy, qz
    if d2 > 0.0:
        s = th / math.sqrt(d2)
        return True, cx + dx * s, cy + dy * s, cz + dz * s
    nx, ny, nz = mesh.fnorm[t, 0], mesh.fnorm[t, 1], mesh.fnorm[t, 2]
    side = th if (lx - cx) * nx + (ly - cy) * ny + (lz - cz) * nz >= 0.0 else -th
    return True, cx + nx * side, cy + ny * side, cz + nz * side


@njit(inline="always", **EXACT)
def tri_test(verts: np.ndarray, tris: np.ndarray, fnorm: np.ndarray, t: int, lx: float, ly: float, lz: float,
             qx: float, qy: float, qz: float, r: float) -> tuple[float, float, float, float, int, float]:
    """Triangle ``t`` against a point: (distance^2 from q, closest point, its feature, the
    parameter where l -> q crosses the triangle or -1); distance^2 is inf for a triangle whose
    plane is further than ``r`` from q (then nothing within r, and no crossing, since |q - l| < r)."""
    a, b, c = tris[t, 0], tris[t, 1], tris[t, 2]
    ax, ay, az = verts[a, 0], verts[a, 1], verts[a, 2]
    nx, ny, nz = fnorm[t, 0], fnorm[t, 1], fnorm[t, 2]
    dq = (qx - ax) * nx + (qy - ay) * ny + (qz - az) * nz
    if dq > r or dq < -r:
        return np.inf, 0.0, 0.0, 0.0, -1, -1.0
    bx, by, bz = verts[b, 0], verts[b, 1], verts[b, 2]
    cx, cy, cz = verts[c, 0], verts[c, 1], verts[c, 2]
    px, py, pz, feature = closest_on_triangle(qx, qy, qz, ax, ay, az, bx, by, bz, cx, cy, cz)
    d2 = (qx - px) ** 2 + (qy - py) ** 2 + (qz - pz) ** 2
    dl = (lx - ax) * nx + (ly - ay) * ny + (lz - az) * nz
    if (dq > 0.0 and dl > 0.0) or (dq < 0.0 and dl < 0.0):
        return d2, px, py, pz, feature, -1.0  # both ends strictly on one side: no crossing
    return d2, px, py, pz, feature, segment_hits(lx, ly, lz, qx, qy, qz, ax, ay, az, bx, by, bz, cx, cy, cz)


@njit(inline="always", **EXACT)
def _far(tbox: np.ndarray, t: int, qx: float, qy: float, qz: float, r: float) -> bool:
    # A triangle whose bounding box is further than r from q in some axis can neither be within r
    # (too far) nor be crossed (the segment lies within |q - l| < r of q): passed over untested.
    return (qx + r < tbox[t, 0] or qx - r > tbox[t, 3] or qy + r < tbox[t, 1] or qy - r > tbox[t, 4]
            or qz + r < tbox[t, 2] or qz - r > tbox[t, 5])


@njit(inline="always", **EXACT)
def _fold(t: int, d2: float, px: float, py: float, pz: float, feature: int, s: float, r2: float, bd2: float,
          bpx: float, bpy: float, bpz: float, bt: int, bf: int, bs: float, bh: int
          ) -> tuple[float, float, float, float, int, int, float, int]:
    """The running answer after triangle ``t``: closest within sqrt(r2) (distance^2, point,
    triangle, feature) and first crossing (parameter, triangle); -1 = none. Ties go to the lower
    triangle index, so the order triangles come in does not matter."""
    if d2 <= r2 and (bt < 0 or d2 < bd2 or (d2 == bd2 and t < bt)):
        bd2, bpx, bpy, bpz, bt, bf = d2, px, py, pz, t, feature
    if s >= 0.0 and (bh < 0 or s < bs or (s == bs and t < bh)):
        bs, bh = s, t
    return bd2, bpx, bpy, bpz, bt, bf, bs, bh


@njit(inline="always", **EXACT)
def _cell(x: float, lo: float, inv_h: float, n: int) -> int:
    c = int(math.floor((x - lo) * inv_h))
    return 0 if c < 0 else (n - 1 if c > n - 1 else c)


@njit(inline="always", **EXACT)
def _grid_range(mesh: tuple, m: int, qx: float, qy: float, qz: float, reach: float
                ) -> tuple[int, int, int, int, int, int]:
    """The cells (x0, x1, y0, y1, z0, z1) that list every triangle whose box comes within
    ``reach`` of q: the triangles are listed with their boxes grown by the margin, so only a reach
    beyond the margin looks past q's own cell."""
    info = mesh.info
    dims = mesh.dims
    e = reach - info[m, INFO_MARGIN]
    e = e if e > 0.0 else 0.0
    inv_h = info[m, INFO_INV_H]
    nx, ny, nz = dims[m, DIMS_N], dims[m, DIMS_N + 1], dims[m, DIMS_N + 2]
    return (_cell(qx - e, info[m, INFO_LO], inv_h, nx), _cell(qx + e, info[m, INFO_LO], inv_h, nx),
            _cell(qy - e, info[m, INFO_LO + 1], inv_h, ny), _cell(qy + e, info[m, INFO_LO + 1], inv_h, ny),
            _cell(qz - e, info[m, INFO_LO + 2], inv_h, nz), _cell(qz + e, info[m, INFO_LO + 2], inv_h, nz))


@njit(**BORROWED)
def gather_near(mesh: tuple, m: int, p: int, qx: float, qy: float, qz: float) -> int:
    """Point ``p``'s list of mesh ``m``: every triangle whose box comes within the list's reach
    (``INFO_NEAR``) of q, each once, into ``near_tris[m, p]``, nearest first, with its distance
    from q less the listing's slack in ``near_d[m, p]``; returns their number, or -1 when there
    are more than a list holds (the point then asks the grid every substep)."""
    info = mesh.info
    reach = info[m, INFO_NEAR]
    x0, x1, y0, y1, z0, z1 = _grid_range(mesh, m, qx, qy, qz, reach)
    nx, ny = mesh.dims[m, DIMS_N], mesh.dims[m, DIMS_N + 1]
    base = mesh.dims[m, DIMS_CELL0]
    cell_start = mesh.cell_start
    cell_tris = mesh.cell_tris
    cell_box = mesh.cell_box
    near = mesh.near_tris
    room = near.shape[2]
    count = 0
    # The walk over the cells in reach is the fold's too (:func:`_grid_fold`, a point without a
    # list): Numba cannot pass a loop's body, and the two bodies differ (a list kept without
    # duplicates, and the nearest triangle folded), so each spells the walk out.
    for cz in range(z0, z1 + 1):
        for cy in range(y0, y1 + 1):
            for cx in range(x0, x1 + 1):
                cell = base + (cz * ny + cy) * nx + cx
                for k in range(cell_start[cell], cell_start[cell + 1]):
                    if not _far(cell_box, k, qx, qy, qz, reach):
                        t = cell_tris[k]
                        seen = False
                        for j in range(count):  # a triangle may be listed in several of the cells
                            if near[m, p, j] == t:
                                seen = True
                                break
                        if not seen:
                            if count == room:
                                return -1
                            near[m, p, count] = t
                            count += 1
    measure_list(mesh, m, p, count, qx, qy, qz)
    return count


@njit(inline="always", **EXACT)
def _separating(verts: np.ndarray, a: int, b: int, c: int, dx: float, dy: float, dz: float, length: float
                ) -> tuple[float, float, float, float]:
    """The plane (unit normal, offset) with triangle abc on its inner side, facing along (dx, dy,
    dz) (reference - closest point, of ``length``): the offset is the largest n . v of the corners,
    so it holds the whole triangle whatever the rounding of n. No plane (offset +inf) for a
    reference on the triangle."""
    if length == 0.0:
        return 0.0, 0.0, 0.0, np.inf
    nx, ny, nz = dx / length, dy / length, dz / length
    off = nx * verts[a, 0] + ny * verts[a, 1] + nz * verts[a, 2]
    off = max(off, nx * verts[b, 0] + ny * verts[b, 1] + nz * verts[b, 2])
    off = max(off, nx * verts[c, 0] + ny * verts[c, 1] + nz * verts[c, 2])
    return nx, ny, nz, off


@njit(**BORROWED)
def measure_list(mesh: tuple, m: int, p: int, count: int, qx: float, qy: float, qz: float) -> None:
    """Point ``p``'s list of mesh ``m`` (``count`` triangles) sorted nearest first from q, each
    triangle's distance from q, less the list's slack, in ``near_d[m, p]``, and the first
    ``NEAR_PLANES`` triangles' separating planes from q, each with that distance again, in
    ``near_pl[m, p]`` (none when q is inside a closed mesh); q becomes the list's reference,
    ``near_ref[m, p]``, and the first distance ``near_first[m, p]``."""
    # A triangle's distance from the reference bounds its distance from any later q from below
    # (less |q - reference|), so a substep reads the list only as far as that bound is within r.
    # The slack (the list's own, far beyond the rounding of either distance) keeps the bound
    # below the distance the tests would compute.
    info = mesh.info
    slack = info[m, INFO_NEAR] - info[m, INFO_NEAR_OK]
    near = mesh.near_tris
    dist = mesh.near_d
    planes = mesh.near_pl
    room = planes.shape[2]
    verts = mesh.verts
    tris = mesh.tris
    bd, bt, bf, bcx, bcy, bcz = np.inf, -1, FACE, 0.0, 0.0, 0.0
    for j in range(count):
        t = near[m, p, j]
        a, b, c = tris[t, 0], tris[t, 1], tris[t, 2]
        px, py, pz, f = closest_on_triangle(qx, qy, qz, verts[a, 0], verts[a, 1], verts[a, 2], verts[b, 0],
                                            verts[b, 1], verts[b, 2], verts[c, 0], verts[c, 1], verts[c, 2])
        length = math.sqrt((qx - px) ** 2 + (qy - py) ** 2 + (qz - pz) ** 2)
        if length < bd or (length == bd and t < bt):
            bd, bt, bf, bcx, bcy, bcz = length, t, f, px, py, pz
        nx, ny, nz, off = _separating(verts, a, b, c, qx - px, qy - py, qz - pz, length)
        d = length - slack
        i = j
        while i > 0 and dist[m, p, i - 1] > d:  # insertion sort: a list holds a few triangles
            dist[m, p, i] = dist[m, p, i - 1]
            near[m, p, i] = near[m, p, i - 1]
            if i < room:
                for k in range(planes.shape[3]):
                    planes[m, p, i, k] = planes[m, p, i - 1, k]
            i -= 1
        dist[m, p, i] = d
        near[m, p, i] = t
        if i < room:
            planes[m, p, i, 0], planes[m, p, i, 1], planes[m, p, i, 2], planes[m, p, i, 3] = nx, ny, nz, off
            planes[m, p, i, PLANE_D] = d
    if bt >= 0 and mesh.dims[m, DIMS_CLOSED] != 0:
        # inside a closed mesh the planes would face inwards and hold the point there
        nx, ny, nz = pseudo_normal(mesh, bt, bf)
        if (qx - bcx) * nx + (qy - bcy) * ny + (qz - bcz) * nz < 0.0:
            for j in range(min(count, room)):
                planes[m, p, j, 3] = np.inf
    ref = mesh.near_ref
    ref[m, p, 0], ref[m, p, 1], ref[m, p, 2] = qx, qy, qz
    mesh.near_first[m, p] = dist[m, p, 0] if count > 0 else np.inf


@njit(inline="always", **EXACT)
def _against_planes(mesh: tuple, m: int, p: int, count: int, within: float, lx: float, ly: float, lz: float,
                    qx: float, qy: float, qz: float) -> tuple[int, float, float, float]:
    """Point ``p`` (last ``l``, now ``q``) against the separating planes of the triangles of its list
    whose bound is within ``within``, nearest first (see the module's docstring): (1 contact or 0
    none, the corrected position before friction); -1 when one of those triangles has no plane, or
    its plane does not have ``l`` strictly on its outer side (the tests decide then)."""
    planes = mesh.near_pl
    dist = mesh.near_d
    th = mesh.thickness
    hit = 0
    ox, oy, oz = qx, qy, qz
    read = 0
    for j in range(count):
        if j == planes.shape[2]:
            if dist[m, p, j] > within:
                break
            return -1, qx, qy, qz
        # the triangle's bound is read from its plane's row, in the same cache line
        if planes[m, p, j, PLANE_D] > within:
            break
        nx, ny, nz, off = planes[m, p, j, 0], planes[m, p, j, 1], planes[m, p, j, 2], planes[m, p, j, 3]
        if not nx * lx + ny * ly + nz * lz - off > 0.0:  # also no plane: offset +inf
            return -1, qx, qy, qz
        s = nx * ox + ny * oy + nz * oz - off
        if s < th:
            push = th - s
            ox, oy, oz = ox + nx * push, oy + ny * push, oz + nz * push
            hit = 1
        read = j + 1
    if hit:
        # a push can take a point back over a plane read before it (planes facing each other, as
        # across a thin part of the mesh): the point must end strictly outside every one
        for j in range(read):
            nx, ny, nz, off = planes[m, p, j, 0], planes[m, p, j, 1], planes[m, p, j, 2], planes[m, p, j, 3]
            if not nx * ox + ny * oy + nz * oz - off > 0.0:
                return -1, qx, qy, qz
    return hit, ox, oy, oz


@njit(**BORROWED)
def _brute_fold(mesh: tuple, m: int, lx: float, ly: float, lz: float, qx: float, qy: float, qz: float, r: float
                ) -> tuple[float, float, float, float, int, int, float, int]:
    """The fold (:func:`_fold`) over every triangle of mesh ``m``: the reference the tests hold the
    lists and the grid to (compiled apart, so the pass does not carry a third copy of the tests)."""
    tbox = mesh.tbox
    r2 = r * r
    bd2, bpx, bpy, bpz, bt, bf, bs, bh = 0.0, 0.0, 0.0, 0.0, -1, -1, 0.0, -1
    for t in range(mesh.dims[m, DIMS_TRI0], mesh.dims[m, DIMS_TRI1]):
        if not _far(tbox, t, qx, qy, qz, r):
            d2, px, py, pz, f, s = tri_test(mesh.verts, mesh.tris, mesh.fnorm, t, lx, ly, lz, qx, qy, qz, r)
            bd2, bpx, bpy, bpz, bt, bf, bs, bh = _fold(t, d2, px, py, pz, f, s, r2, bd2, bpx, bpy, bpz, bt, bf,
                                                       bs, bh)
    return bd2, bpx, bpy, bpz, bt, bf, bs, bh


@njit(**BORROWED)
def _grid_fold(mesh: tuple, m: int, lx: float, ly: float, lz: float, qx: float, qy: float, qz: float, r: float
               ) -> tuple[float, float, float, float, int, int, float, int]:
    """The fold (:func:`_fold`) over the triangles the grid lists near q: for a point without a
    list (one that moves fast, or has too many triangles near it; compiled apart, as it is rare)."""
    x0, x1, y0, y1, z0, z1 = _grid_range(mesh, m, qx, qy, qz, r)
    dims = mesh.dims
    nx, ny = dims[m, DIMS_N], dims[m, DIMS_N + 1]
    base = dims[m, DIMS_CELL0]
    cell_start = mesh.cell_start
    cell_tris = mesh.cell_tris
    cell_box = mesh.cell_box
    r2 = r * r
    bd2, bpx, bpy, bpz, bt, bf, bs, bh = 0.0, 0.0, 0.0, 0.0, -1, -1, 0.0, -1
    for cz in range(z0, z1 + 1):
        for cy in range(y0, y1 + 1):
            for cx in range(x0, x1 + 1):
                cell = base + (cz * ny + cy) * nx + cx
                # the boxes in a row, read in order; the triangle's own data only for the near ones
                for k in range(cell_start[cell], cell_start[cell + 1]):
                    if not _far(cell_box, k, qx, qy, qz, r):
                        t = cell_tris[k]
                        d2, px, py, pz, f, s = tri_test(mesh.verts, mesh.tris, mesh.fnorm, t, lx, ly, lz, qx, qy,
                                                        qz, r)
                        bd2, bpx, bpy, bpz, bt, bf, bs, bh = _fold(t, d2, px, py, pz, f, s, r2, bd2, bpx, bpy,
                                                                   bpz, bt, bf, bs, bh)
    return bd2, bpx, bpy, bpz, bt, bf, bs, bh


@njit(inline="always", **EXACT)
def point_contact(mesh: tuple, m: int, p: int, lx: float, ly: float, lz: float, qx: float, qy: float, qz: float,
                  brute: bool) -> tuple[bool, float, float, float]:
    """Collide point ``p`` (mesh frame: last ``l``, now ``q``) with mesh ``m``: (contact?, the
    corrected position before friction). ``brute`` tests every triangle instead of the point's
    list or the grid's cells, and holds no point by its list's planes (the tests' answer)."""
    info = mesh.info
    r = mesh.thickness + math.sqrt((qx - lx) ** 2 + (qy - ly) ** 2 + (qz - lz) ** 2)
    if (qx + r < info[m, INFO_LO] or qx - r > info[m, INFO_HI] or qy + r < info[m, INFO_LO + 1]
            or qy - r > info[m, INFO_HI + 1] or qz + r < info[m, INFO_LO + 2] or qz - r > info[m, INFO_HI + 2]):
        return False, qx, qy, qz
    # The point's own list (see the module's docstring) holds every triangle within the list's
    # reach of its anchor, so it holds every one within r of q while q has moved less than
    # reach - r (per axis) from the anchor; else it is gathered afresh at q, if r leaves room.
    # Read in order of distance from the list's reference point, it is read only while a
    # triangle's distance from the reference, less the point's from it, can be within r.
    count = -1
    moved = 0.0
    near_n = mesh.near_n
    if p < near_n.shape[1] and not brute:
        limit = info[m, INFO_NEAR_OK]
        if r <= limit:
            at = mesh.near_at
            ex, ey, ez = qx - at[m, p, 0], qy - at[m, p, 1], qz - at[m, p, 2]
            count = near_n[m, p]
            if max(abs(ex), abs(ey), abs(ez)) + r <= limit:
                ref = mesh.near_ref
                fx, fy, fz = qx - ref[m, p, 0], qy - ref[m, p, 1], qz - ref[m, p, 2]
                moved = math.sqrt(fx * fx + fy * fy + fz * fz)
                if moved > REFRESH * mesh.thickness:
                    # the bound's drift term admits ever more of the list: measured again from here
                    measure_list(mesh, m, p, count, qx, qy, qz)
                    moved = 0.0
            else:
                count = gather_near(mesh, m, p, qx, qy, qz)
                near_n[m, p] = count
                at[m, p, 0], at[m, p, 1], at[m, p, 2] = qx, qy, qz
    if count >= 0:
        within = r + moved
        held, ox, oy, oz = _against_planes(mesh, m, p, count, within, lx, ly, lz, qx, qy, qz)
        if held >= 0:
            return held == 1, ox, oy, oz
        tbox = mesh.tbox
        near = mesh.near_tris
        dist = mesh.near_d
        r2 = r * r
        bd2, bpx, bpy, bpz, bt, bf, bs, bh = 0.0, 0.0, 0.0, 0.0, -1, -1, 0.0, -1
        for j in range(count):
            if dist[m, p, j] > within:
                break
            t = np.int64(near[m, p, j])
            if not _far(tbox, t, qx, qy, qz, r):
                d2, px, py, pz, f, s = tri_test(mesh.verts, mesh.tris, mesh.fnorm, t, lx, ly, lz, qx, qy, qz, r)
                bd2, bpx, bpy, bpz, bt, bf, bs, bh = _fold(t, d2, px, py, pz, f, s, r2, bd2, bpx, bpy, bpz, bt,
                                                           bf, bs, bh)
    elif brute:
        bd2, bpx, bpy, bpz, bt, bf, bs, bh = _brute_fold(mesh, m, lx, ly, lz, qx, qy, qz, r)
    else:
        bd2, bpx, bpy, bpz, bt, bf, bs, bh = _grid_fold(mesh, m, lx, ly, lz, qx, qy, qz, r)
    return resolve(mesh, m, lx, ly, lz, qx, qy, qz, bd2, bpx, bpy, bpz, bt, bf, bh)


@njit(**BORROWED)
def collide_mesh_points(pos: np.ndarray, last: np.ndarray, free: np.ndarray, mesh: tuple, m: int,
                        before: np.ndarray, after: np.ndarray, turns: Turns | None, brute: bool) -> None:
    """Collide the points ``free`` with mesh ``m`` translated by ``before`` at the substep's start
    and ``after`` at its end (and turned by its Q at both, ``turns.motion[m]``, when ``turns`` is
    not None: a scene where a mesh turns), in place."""
    keep = 1.0 - mesh.info[m, INFO_FRICTION]
    bx, by, bz = before[0], before[1], before[2]
    ax, ay, az = after[0], after[1], after[2]
    th = mesh.thickness
    limit = mesh.info[m, INFO_NEAR_OK]
    near_n = mesh.near_n
    at = mesh.near_at
    ref = mesh.near_ref
    first = mesh.near_first
    listed = 0 if brute else near_n.shape[1]
    info = mesh.info
    x0, y0, z0 = info[m, INFO_LO], info[m, INFO_LO + 1], info[m, INFO_LO + 2]
    x1, y1, z1 = info[m, INFO_HI], info[m, INFO_HI + 1], info[m, INFO_HI + 2]
    for k in range(free.shape[0]):
        p = free[k]
        lx, ly, lz = last[0, p] - bx, last[1, p] - by, last[2, p] - bz
        qx, qy, qz = pos[0, p] - ax, pos[1, p] - ay, pos[2, p] - az
        if turns is not None:  # into the mesh's frame: Q0^T and Q1^T
            u = turns.motion[m]
            lx, ly, lz = (u[0] * lx + u[3] * ly + u[6] * lz, u[1] * lx + u[4] * ly + u[7] * lz,
                          u[2] * lx + u[5] * ly + u[8] * lz)
            qx, qy, qz = (u[9] * qx + u[12] * qy + u[15] * qz, u[10] * qx + u[13] * qy + u[16] * qz,
                          u[11] * qx + u[14] * qy + u[17] * qz)
        # Most points have nothing within r: they lie beyond r of the mesh's box, or their list
        # is still valid and its nearest triangle, less how far the point is from the list's
        # reference point, is beyond r. Lengths bounded from above here by their sums of
        # components, made a little longer so that no rounding can bring them under the Euclidean
        # ones (no square roots); what this does not rule out, point_contact works out exactly.
        r1 = th + (abs(qx - lx) + abs(qy - ly) + abs(qz - lz)) * _LONGER
        if (qx + r1 < x0 or qx - r1 > x1 or qy + r1 < y0 or qy - r1 > y1 or qz + r1 < z0 or qz - r1 > z1):
            continue
        if p < listed and near_n[m, p] >= 0:
            ex, ey, ez = qx - at[m, p, 0], qy - at[m, p, 1], qz - at[m, p, 2]
            if max(abs(ex), abs(ey), abs(ez)) + r1 <= limit:
                if near_n[m, p] == 0:
                    continue
                fx, fy, fz = qx - ref[m, p, 0], qy - ref[m, p, 1], qz - ref[m, p, 2]
                if first[m, p] > r1 + (abs(fx) + abs(fy) + abs(fz)) * _LONGER:
                    continue
        hit, ox, oy, oz = point_contact(mesh, m, p, lx, ly, lz, qx, qy, qz, brute)
        if hit:
            if turns is None:
                pos[0, p] = ax + lx + (ox - lx) * keep
                pos[1, p] = ay + ly + (oy - ly) * keep
                pos[2, p] = az + lz + (oz - lz) * keep
            else:  # back from the mesh's frame at the substep's end: p1 + Q1 x
                u = turns.motion[m]
                x, y, z = lx + (ox - lx) * keep, ly + (oy - ly) * keep, lz + (oz - lz) * keep
                pos[0, p] = ax + u[9] * x + u[10] * y + u[11] * z
                pos[1, p] = ay + u[12] * x + u[13] * y + u[14] * z
                pos[2, p] = az + u[15] * x + u[16] * y + u[17] * z


@njit(inline="always", **EXACT)
def _moving_tri_test(verts: np.ndarray, verts0: np.ndarray, tris: np.ndarray, fnorm: np.ndarray, t: int,
                     lx: float, ly: float, lz: float, qx: float, qy: float, qz: float, r: float
                     ) -> tuple[float, float, float, float, int, float, float, float, float]:
    """:func:`tri_test` against a triangle that moved over the substep (from ``verts0`` to
    ``verts``): the point's last position is first carried by the motion of the triangle's point
    closest to q (its corners' displacements weighted as that point is by them), so the crossing
    is tested on the point's motion relative to the surface there. Returns tri_test's answer and
    the carried last position."""
    a, b, c = tris[t, 0], tris[t, 1], tris[t, 2]
    ax, ay, az = verts[a, 0], verts[a, 1], verts[a, 2]
    nx, ny, nz = fnorm[t, 0], fnorm[t, 1], fnorm[t, 2]
    dq = (qx - ax) * nx + (qy - ay) * ny + (qz - az) * nz
    if dq > r or dq < -r:
        return np.inf, 0.0, 0.0, 0.0, -1, -1.0, lx, ly, lz
    bx, by, bz = verts[b, 0], verts[b, 1], verts[b, 2]
    cx, cy, cz = verts[c, 0], verts[c, 1], verts[c, 2]
    px, py, pz, feature = closest_on_triangle(qx, qy, qz, ax, ay, az, bx, by, bz, cx, cy, cz)
    d2 = (qx - px) ** 2 + (qy - py) ** 2 + (qz - pz) ** 2
    # the closest point's weights on the corners (barycentric coordinates; the duplicate-code scan
    # pairs these dot products, by shape alone, with contactdistance.py's closest points of two segments)
    e0x, e0y, e0z = bx - ax, by - ay, bz - az
    e1x, e1y, e1z = cx - ax, cy - ay, cz - az
    e2x, e2y, e2z = px - ax, py - ay, pz - az
    d00 = e0x * e0x + e0y * e0y + e0z * e0z
    d01 = e0x * e1x + e0y * e1y + e0z * e1z
    d11 = e1x * e1x + e1y * e1y + e1z * e1z
    d20 = e2x * e0x + e2y * e0y + e2z * e0z
    d21 = e2x * e1x + e2y * e1y + e2z * e1z
    den = d00 * d11 - d01 * d01
    wb = (d11 * d20 - d01 * d21) / den if den > 0.0 else 0.0
    wc = (d00 * d21 - d01 * d20) / den if den > 0.0 else 0.0
    wa = 1.0 - wb - wc
    clx = lx + wa * (ax - verts0[a, 0]) + wb * (bx - verts0[b, 0]) + wc * (cx - verts0[c, 0])
    cly = ly + wa * (ay - verts0[a, 1]) + wb * (by - verts0[b, 1]) + wc * (cy - verts0[c, 1])
    clz = lz + wa * (az - verts0[a, 2]) + wb * (bz - verts0[b, 2]) + wc * (cz - verts0[c, 2])
    dl = (clx - ax) * nx + (cly - ay) * ny + (clz - az) * nz
    if (dq > 0.0 and dl > 0.0) or (dq < 0.0 and dl < 0.0):
        return d2, px, py, pz, feature, -1.0, clx, cly, clz
    s = segment_hits(clx, cly, clz, qx, qy, qz, ax, ay, az, bx, by, bz, cx, cy, cz)
    return d2, px, py, pz, feature, s, clx, cly, clz


@njit(**BORROWED)
def _deforming_contact(mesh: tuple, d: Deform, m: int, lx: float, ly: float, lz: float, qx: float, qy: float,
                       qz: float, r: float) -> tuple[bool, float, float, float, float, float, float]:
    """A point (mesh frame: last ``l``, now ``q``) against deforming mesh ``m``, every triangle the
    grid lists near q tested with the point's last position carried by that triangle's motion:
    (contact?, the corrected position before friction, the carried last position the correction
    and friction start from)."""
    # The walk over the cells is _grid_fold's (as gather_near's is): Numba cannot pass a loop's
    # body, and this one folds a carried last position per triangle besides the answer.
    x0, x1, y0, y1, z0, z1 = _grid_range(mesh, m, qx, qy, qz, r)
    dims = mesh.dims
    nx, ny = dims[m, DIMS_N], dims[m, DIMS_N + 1]
    base = dims[m, DIMS_CELL0]
    cell_start = mesh.cell_start
    cell_tris = mesh.cell_tris
    cell_box = mesh.cell_box
    r2 = r * r
    bd2, bpx, bpy, bpz, bt, bf, bs, bh = 0.0, 0.0, 0.0, 0.0, -1, -1, 0.0, -1
    tx, ty, tz, hx, hy, hz = lx, ly, lz, lx, ly, lz
    for cz in range(z0, z1 + 1):
        for cy in range(y0, y1 + 1):
            for cx in range(x0, x1 + 1):
                cell = base + (cz * ny + cy) * nx + cx
                for k in range(cell_start[cell], cell_start[cell + 1]):
                    if not _far(cell_box, k, qx, qy, qz, r):
                        t = cell_tris[k]
                        d2, px, py, pz, f, s, clx, cly, clz = _moving_tri_test(mesh.verts, d.verts0, mesh.tris,
                                                                               mesh.fnorm, t, lx, ly, lz, qx, qy,
                                                                               qz, r)
                        was_t, was_h = bt, bh
                        bd2, bpx, bpy, bpz, bt, bf, bs, bh = _fold(t, d2, px, py, pz, f, s, r2, bd2, bpx, bpy,
                                                                   bpz, bt, bf, bs, bh)
                        if bt != was_t:
                            tx, ty, tz = clx, cly, clz
                        if bh != was_h:
                            hx, hy, hz = clx, cly, clz
    # the crossing decides first (see resolve), so its carried position is the one it starts from
    if bh >= 0:
        tx, ty, tz = hx, hy, hz
    hit, ox, oy, oz = resolve(mesh, m, tx, ty, tz, qx, qy, qz, bd2, bpx, bpy, bpz, bt, bf, bh)
    return hit, ox, oy, oz, tx, ty, tz


@njit(**BORROWED)
def collide_deforming_points(pos: np.ndarray, last: np.ndarray, free: np.ndarray, mesh: tuple, m: int,
                             before: np.ndarray, after: np.ndarray, turns: Turns | None, d: Deform) -> None:
    """:func:`collide_mesh_points` for a deforming mesh ``m`` (:mod:`.meshdeform`): no lists, the
    grid every substep, each point's reach widened by how far the mesh's vertices move over the
    substep (``d.moved``), and friction relative to the surface: the point moves from its last
    position carried by the surface, not from where it was."""
    # The way into the mesh's frame and back, and the first test against its box, are
    # collide_mesh_points' (the duplicate-code scan pairs them): that pass is left exactly as it
    # was, so that a fixed mesh's bits and compiled code do not change, and this one differs in
    # its reach, its lists (none) and the last position friction starts from.
    keep = 1.0 - mesh.info[m, INFO_FRICTION]
    bx, by, bz = before[0], before[1], before[2]
    ax, ay, az = after[0], after[1], after[2]
    near = mesh.thickness + d.moved[m]
    info = mesh.info
    x0, y0, z0 = info[m, INFO_LO], info[m, INFO_LO + 1], info[m, INFO_LO + 2]
    x1, y1, z1 = info[m, INFO_HI], info[m, INFO_HI + 1], info[m, INFO_HI + 2]
    for k in range(free.shape[0]):
        p = free[k]
        lx, ly, lz = last[0, p] - bx, last[1, p] - by, last[2, p] - bz
        qx, qy, qz = pos[0, p] - ax, pos[1, p] - ay, pos[2, p] - az
        if turns is not None:  # into the mesh's frame: Q0^T and Q1^T
            u = turns.motion[m]
            lx, ly, lz = (u[0] * lx + u[3] * ly + u[6] * lz, u[1] * lx + u[4] * ly + u[7] * lz,
                          u[2] * lx + u[5] * ly + u[8] * lz)
            qx, qy, qz = (u[9] * qx + u[12] * qy + u[15] * qz, u[10] * qx + u[13] * qy + u[16] * qz,
                          u[11] * qx + u[14] * qy + u[17] * qz)
        # the mesh's box holds it in every frame (see meshgrid)
        r1 = near + (abs(qx - lx) + abs(qy - ly) + abs(qz - lz)) * _LONGER
        if (qx + r1 < x0 or qx - r1 > x1 or qy + r1 < y0 or qy - r1 > y1 or qz + r1 < z0 or qz - r1 > z1):
            continue
        r = near + math.sqrt((qx - lx) ** 2 + (qy - ly) ** 2 + (qz - lz) ** 2)
        hit, ox, oy, oz, lx, ly, lz = _deforming_contact(mesh, d, m, lx, ly, lz, qx, qy, qz, r)
        if hit:
            x, y, z = lx + (ox - lx) * keep, ly + (oy - ly) * keep, lz + (oz - lz) * keep
            if turns is None:
                pos[0, p], pos[1, p], pos[2, p] = ax + x, ay + y, az + z
            else:  # back from the mesh's frame at the substep's end: p1 + Q1 x
                u = turns.motion[m]
                pos[0, p] = ax + u[9] * x + u[10] * y + u[11] * z
                pos[1, p] = ay + u[12] * x + u[13] * y + u[14] * z
                pos[2, p] = az + u[15] * x + u[16] * y + u[17] * z


@njit(**BORROWED)
def collide_meshes_chunk(pos: np.ndarray, last: np.ndarray, free: np.ndarray, mesh: tuple, on: np.ndarray,
                         c: int) -> None:
    """Work item ``c`` (of CHUNKS) of the mesh pass: the c-th part of the free points against
    every reachable mesh at its pose, in scene order."""
    n = free.shape[0]
    f0, f1 = share(n, c, CHUNKS)
    part = free[f0:f1]
    for m in range(mesh.dims.shape[0]):
        if on[m]:
            collide_one(pos, last, part, mesh, m, mesh.deform)


def collide_one(pos: np.ndarray, last: np.ndarray, part: np.ndarray, mesh: tuple, m: int, d: Deform | None) -> None:
    """The points ``part`` against mesh ``m`` at its pose: :func:`collide_deforming_points` for a
    deforming mesh, else :func:`collide_mesh_points` (compiled code only)."""
    raise NotImplementedError("compiled code only")


@overload(collide_one, inline="always", jit_options=BORROWED)
def _collide_one(pos, last, part, mesh, m, d):  # noqa: ANN001, ANN202
    # inlined, and without a deforming mesh (d None) only the fixed meshes' pass: the code it had
    if isinstance(d, types.NoneType):
        def fixed(pos, last, part, mesh, m, d):  # noqa: ANN001, ANN202
            collide_mesh_points(pos, last, part, mesh, m, mesh.pose[m, :3], mesh.pose[m, 3:], mesh.turns, False)

        return fixed

    def impl(pos, last, part, mesh, m, d):  # noqa: ANN001, ANN202
        if d.which[m] >= 0:
            collide_deforming_points(pos, last, part, mesh, m, mesh.pose[m, :3], mesh.pose[m, 3:], mesh.turns, d)
        else:
            collide_mesh_points(pos, last, part, mesh, m, mesh.pose[m, :3], mesh.pose[m, 3:], mesh.turns, False)

    return impl


@njit(**EXACT)
def mesh_targets(pos: np.ndarray, last: np.ndarray, mesh: tuple, brute: bool) -> np.ndarray:
    """Every point of (3, N) ``pos`` collided with every mesh (held at the start of its current
    pose), on a copy: the pass's answer (lists, their planes, the grid), or that of the tests on
    every triangle (``brute``, for tests)."""
    out = pos.copy()
    free = np.arange(pos.shape[1])
    for m in range(mesh.dims.shape[0]):
        shift = mesh.pose[m, :3]
        collide_mesh_points(out, last, free, mesh, m, shift, shift, None, brute)
    return out


# -- the kind's passes (see clothsim.sim.passes.colliders) -----------------------------------------

Group = MeshGroup


def pack(scene: Any, clock: np.ndarray, dt: float, swept: bool) -> MeshGroup:
    """The group of ``scene``'s meshes, their grids built."""
    return mesh_group(scene, clock, dt)


@njit(**KERNEL)
def pose_meshes(tr: Tracks | None, tu: Turns | None, pose: np.ndarray, substep: int) -> None:
    """Each moving mesh's translation at the start and end of substep ``substep`` of the call into
    its row of ``pose`` (nothing when none moves: ``tr`` is None), and with ``tu`` (a mesh turns) its
    turn Q at both into its row of ``tu.motion``. Times count from the clock's base (see
    :mod:`clothsim.sim.clock`)."""
    if tr is None:
        return
    s0 = substep_time(tr.clock, substep, tr.dt)
    s1 = substep_time(tr.clock, substep + 1, tr.dt)
    for m in range(tr.row.shape[0]):
        track_ends(tr, m, s0, s1)
        r = tr.row[m]
        for c in range(3):
            pose[r, c] = tr.scratch[0, c]
            pose[r, 3 + c] = tr.scratch[1, c]
        if tu is not None:
            turn_ends(tu, m, s0, s1)
            for i in range(3):
                for j in range(3):
                    tu.motion[r, 3 * i + j] = tu.q[0, i, j]
                    tu.motion[r, 9 + 3 * i + j] = tu.q[1, i, j]


@njit(**KERNEL)
def pose(g: MeshGroup, substep: int) -> None:
    """Put the moving meshes at their pose for substep ``substep``, and the deforming ones' vertices."""
    pose_meshes(g.tracks, g.turns, g.pose, substep)
    deform_pose(g.deform, g, substep)


def deform_pose(d: Deform | None, g: MeshGroup, substep: int) -> None:
    """The deforming meshes' vertices, normals and boxes for substep ``substep``
    (:func:`~.meshdeform.deform_meshes`); nothing, and no code, when ``d`` is None (compiled code only)."""
    raise NotImplementedError("compiled code only")


@overload(deform_pose, inline="always", jit_options=KERNEL)
def _deform_pose(d, g, substep):  # noqa: ANN001, ANN202
    # inlined, so that a group without a deforming mesh compiles no function for it
    if isinstance(d, types.NoneType):
        return lambda d, g, substep: None

    def impl(d, g, substep):  # noqa: ANN001, ANN202
        deform_meshes(d, g.verts, g.tris, g.tbox, g.fnorm, g.enorm, g.vnorm, g.cell_tris, g.cell_box, g.tracks.clock,
                      g.tracks.dt, substep)

    return impl


@njit(**EXACT)
def reach(g: MeshGroup, box: np.ndarray, on: np.ndarray, offset: float) -> int:
    """Mark the meshes the cloth's bounding box (current and last positions) may touch during
    this substep (at their poses); returns how many were ruled out. A mesh's box, over both
    translations of the substep (and both turns, for a turning mesh) and widened by the thickness,
    that misses the cloth's box can neither be crossed nor come within the thickness of a point, so
    skipping it is exact."""
    return reach_meshes(g.info, g.pose, g.thickness, g.turns, box, on)


@njit(**EXACT)
def reach_meshes(info: np.ndarray, poses: np.ndarray, thickness: float, turns: Turns | None, box: np.ndarray,
                 on: np.ndarray) -> int:
    """:func:`reach` over the meshes' boxes ``info`` and ``poses`` (and ``turns`` where a mesh turns:
    a local box turned by Q is held by the world-axis box of half size |Q| h about Q c)."""
    skipped = 0
    for m in range(poses.shape[0]):
        before = poses[m, :3]
        after = poses[m, 3:]
        hit = True
        if turns is None:
            for c in range(3):
                lo = info[m, INFO_LO + c] + min(before[c], after[c]) - thickness
                hi = info[m, INFO_HI + c] + max(before[c], after[c]) + thickness
                if hi < box[c] or lo > box[3 + c]:
                    hit = False
        else:
            u = turns.motion[m]
            for c in range(3):
                lo = np.inf
                hi = -np.inf
                for end in range(2):
                    centre = before[c] if end == 0 else after[c]
                    extent = 0.0
                    for k in range(3):
                        q = u[9 * end + 3 * c + k]
                        centre += q * 0.5 * (info[m, INFO_LO + k] + info[m, INFO_HI + k])
                        extent += abs(q) * 0.5 * (info[m, INFO_HI + k] - info[m, INFO_LO + k])
                    lo = min(lo, centre - extent)
                    hi = max(hi, centre + extent)
                if hi + thickness < box[c] or lo - thickness > box[3 + c]:
                    hit = False
        on[m] = hit
        skipped += 0 if hit else 1
    return skipped


@njit(inline="always", **EXACT)
def _untracked(g: MeshGroup) -> MeshGroup:
    # the mesh pass reads the poses, never the tracks: without them its type is the same for a
    # moving mesh and a fixed one, so both run one compiled pass
    return MeshGroup(g.verts, g.tris, g.tbox, g.fnorm, g.enorm, g.vnorm, g.info, g.dims, g.cell_start, g.cell_tris,
                     g.cell_box, g.near_at, g.near_n, g.near_tris, g.near_d, g.near_ref, g.near_first,
                     g.near_pl, g.pose,
                     g.thickness, g.on, None, g.turns, g.deform, g.collide)


@njit(**EXACT)
def collide(g: MeshGroup, pos: np.ndarray, last: np.ndarray, free: np.ndarray, c: int, on: np.ndarray,
            offset: float) -> None:
    """Work item ``c`` of the free points against the reachable meshes: :func:`collide_meshes_chunk`
    called by its address (``g.collide``, see :func:`collide_address`), so that it is compiled on
    its own, once for every group of meshes, moving or not, and not again inside every kernel
    that runs the pass."""
    call_native(g.collide, (pos, last, free, _untracked(g), on, np.int64(c)))


def collide_types(pos: types.Type, last: types.Type, free: types.Type, group: types.Type) -> tuple:
    """The argument types :func:`collide_meshes_chunk` is compiled for, given those of the state
    and of the mesh group (whose tracks it does not get)."""
    untracked = types.NamedTuple([types.none if name == "tracks" else t for name, t in zip(group.fields, group.types)],
                                 MeshGroup)
    return (pos, last, free, untracked, types.Array(types.bool_, 1, "C"), types.int64)


def collide_address(g: MeshGroup, pos: np.ndarray, last: np.ndarray, free: np.ndarray) -> int:
    """The address of :func:`collide_meshes_chunk` compiled (or loaded) for these arrays."""
    return native_address(collide_meshes_chunk, collide_types(*(numba.typeof(x) for x in (pos, last, free, g))))
