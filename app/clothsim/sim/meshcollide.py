"""Collisions with triangle meshes (:class:`~clothsim.sim.meshgrid.MeshGroup`), one point at a time.

Each substep a mesh has a translation before and after it (its motion track at the substep's two
ends); a point is handled in the mesh's own frame, where its last position ``l`` and its position
``q`` are taken relative to those two translations. Every candidate triangle (from the grid cells
overlapping ``q +- r``, ``r`` = thickness + |q - l|) gives

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
Ties between triangles are broken by the lower triangle index, so the grid's answer does not
depend on the order it visits cells, and equals the brute-force one (:func:`mesh_targets`).
"""

from __future__ import annotations

import math

import numpy as np
from numba import njit

from ..motion import position_at
from .jit import CHUNKS, EXACT
from .meshgrid import DIMS_CELL0, DIMS_CLOSED, DIMS_K0, DIMS_K1, DIMS_N, DIMS_TRI0, DIMS_TRI1, INFO_FRICTION, \
    INFO_HI, INFO_INV_H, INFO_LO
from .team import share

_position_at = njit(**EXACT)(position_at)

# closest-point features
FACE, VERTEX_A, VERTEX_B, VERTEX_C, EDGE_AB, EDGE_BC, EDGE_CA = 0, 1, 2, 3, 4, 5, 6


@njit(**EXACT)
def closest_on_triangle(px: float, py: float, pz: float, ax: float, ay: float, az: float, bx: float, by: float,
                        bz: float, cx: float, cy: float, cz: float) -> tuple[float, float, float, int]:
    """The point of triangle abc closest to p and the feature it lies on (Ericson 5.1.5)."""
    abx, aby, abz = bx - ax, by - ay, bz - az
    acx, acy, acz = cx - ax, cy - ay, cz - az
    apx, apy, apz = px - ax, py - ay, pz - az
    d1 = abx * apx + aby * apy + abz * apz
    d2 = acx * apx + acy * apy + acz * apz
    if d1 <= 0.0 and d2 <= 0.0:
        return ax, ay, az, VERTEX_A
    bpx, bpy, bpz = px - bx, py - by, pz - bz
    d3 = abx * bpx + aby * bpy + abz * bpz
    d4 = acx * bpx + acy * bpy + acz * bpz
    if d3 >= 0.0 and d4 <= d3:
        return bx, by, bz, VERTEX_B
    vc = d1 * d4 - d3 * d2
    if vc <= 0.0 and d1 >= 0.0 and d3 <= 0.0:
        v = d1 / (d1 - d3)
        return ax + v * abx, ay + v * aby, az + v * abz, EDGE_AB
    cpx, cpy, cpz = px - cx, py - cy, pz - cz
    d5 = abx * cpx + aby * cpy + abz * cpz
    d6 = acx * cpx + acy * cpy + acz * cpz
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


@njit(**EXACT)
def consider(mesh: tuple, t: int, l: np.ndarray, q: np.ndarray, r2: float, best: np.ndarray, ids: np.ndarray) -> None:
    """Fold triangle ``t`` into the point's running answer.

    ``best`` = [closest distance^2, closest x y z, first crossing parameter]; ``ids`` = [closest
    triangle, its feature, crossed triangle] (-1 = none yet). Only closest points within
    sqrt(r2) count. Ties go to the lower triangle index.
    """
    tri = mesh.tris[t]
    v = mesh.verts
    a, b, c = tri[0], tri[1], tri[2]
    cx, cy, cz, feature = closest_on_triangle(q[0], q[1], q[2], v[a, 0], v[a, 1], v[a, 2], v[b, 0], v[b, 1],
                                              v[b, 2], v[c, 0], v[c, 1], v[c, 2])
    d2 = (q[0] - cx) ** 2 + (q[1] - cy) ** 2 + (q[2] - cz) ** 2
    if d2 <= r2 and (ids[0] < 0 or d2 < best[0] or (d2 == best[0] and t < ids[0])):
        best[0] = d2
        best[1] = cx
        best[2] = cy
        best[3] = cz
        ids[0] = t
        ids[1] = feature
    s = segment_hits(l[0], l[1], l[2], q[0], q[1], q[2], v[a, 0], v[a, 1], v[a, 2], v[b, 0], v[b, 1], v[b, 2],
                     v[c, 0], v[c, 1], v[c, 2])
    if s >= 0.0 and (ids[2] < 0 or s < best[4] or (s == best[4] and t < ids[2])):
        best[4] = s
        ids[2] = t


@njit(**EXACT)
def pseudo_normal(mesh: tuple, t: int, feature: int) -> tuple[float, float, float]:
    """The pseudo-normal of triangle ``t``'s ``feature`` (face, edge or vertex)."""
    if feature == FACE:
        n = mesh.fnorm[t]
    elif feature >= EDGE_AB:
        n = mesh.enorm[t, feature - EDGE_AB]
    else:
        n = mesh.vnorm[mesh.tris[t, feature - VERTEX_A]]
    return n[0], n[1], n[2]


@njit(**EXACT)
def resolve(mesh: tuple, m: int, l: np.ndarray, q: np.ndarray, best: np.ndarray, ids: np.ndarray,
            out: np.ndarray) -> bool:
    """Write the corrected position (mesh frame, before friction) into ``out``; False = no contact."""
    th = mesh.thickness
    closed = mesh.dims[m, DIMS_CLOSED] != 0
    h = ids[2]
    if h >= 0:
        n = mesh.fnorm[h]
        x0 = mesh.verts[mesh.tris[h, 0]]
        before = (l[0] - x0[0]) * n[0] + (l[1] - x0[1]) * n[1] + (l[2] - x0[2]) * n[2]
        side = 1.0 if before >= 0.0 else -1.0
        if not closed or side > 0.0:
            now = (q[0] - x0[0]) * n[0] + (q[1] - x0[1]) * n[1] + (q[2] - x0[2]) * n[2]
            shift = side * th - now
            for k in range(3):
                out[k] = q[k] + n[k] * shift
            return True
    t = ids[0]
    if t < 0:
        return False
    dx, dy, dz = q[0] - best[1], q[1] - best[2], q[2] - best[3]
    if closed:
        nx, ny, nz = pseudo_normal(mesh, t, ids[1])
        if dx * nx + dy * ny + dz * nz < 0.0:
            out[0] = best[1] + nx * th
            out[1] = best[2] + ny * th
            out[2] = best[3] + nz * th
            return True
    d2 = best[0]
    if d2 >= th * th:
        return False
    if d2 > 0.0:
        s = th / math.sqrt(d2)
        out[0] = best[1] + dx * s
        out[1] = best[2] + dy * s
        out[2] = best[3] + dz * s
        return True
    n = mesh.fnorm[t]
    before = (l[0] - best[1]) * n[0] + (l[1] - best[2]) * n[1] + (l[2] - best[3]) * n[2]
    side = th if before >= 0.0 else -th
    for k in range(3):
        out[k] = best[1 + k] + n[k] * side
    return True


@njit(**EXACT)
def _cell(x: float, lo: float, inv_h: float, n: int) -> int:
    c = int(math.floor((x - lo) * inv_h))
    return 0 if c < 0 else (n - 1 if c > n - 1 else c)


@njit(**EXACT)
def point_contact(mesh: tuple, m: int, l: np.ndarray, q: np.ndarray, brute: bool, best: np.ndarray,
                  ids: np.ndarray, out: np.ndarray) -> bool:
    """Collide one point (mesh frame: last ``l``, now ``q``) with mesh ``m``; the corrected
    position, before friction, goes into ``out``. ``brute`` tests every triangle instead of the
    grid's (same answer)."""
    info = mesh.info[m]
    dims = mesh.dims[m]
    move2 = (q[0] - l[0]) ** 2 + (q[1] - l[1]) ** 2 + (q[2] - l[2]) ** 2
    r = mesh.thickness + math.sqrt(move2)
    for k in range(3):
        if q[k] + r < info[INFO_LO + k] or q[k] - r > info[INFO_HI + k]:
            return False
    ids[0] = -1
    ids[1] = -1
    ids[2] = -1
    best[0] = 0.0
    best[4] = 0.0
    r2 = r * r
    if brute:
        for t in range(dims[DIMS_TRI0], dims[DIMS_TRI1]):
            consider(mesh, t, l, q, r2, best, ids)
    else:
        inv_h = info[INFO_INV_H]
        nx, ny, nz = dims[DIMS_N], dims[DIMS_N + 1], dims[DIMS_N + 2]
        x0 = _cell(q[0] - r, info[INFO_LO], inv_h, nx)
        x1 = _cell(q[0] + r, info[INFO_LO], inv_h, nx)
        y0 = _cell(q[1] - r, info[INFO_LO + 1], inv_h, ny)
        y1 = _cell(q[1] + r, info[INFO_LO + 1], inv_h, ny)
        z0 = _cell(q[2] - r, info[INFO_LO + 2], inv_h, nz)
        z1 = _cell(q[2] + r, info[INFO_LO + 2], inv_h, nz)
        base = dims[DIMS_CELL0]
        for cz in range(z0, z1 + 1):
            for cy in range(y0, y1 + 1):
                for cx in range(x0, x1 + 1):
                    cell = base + (cz * ny + cy) * nx + cx
                    for e in range(mesh.cell_start[cell], mesh.cell_start[cell + 1]):
                        consider(mesh, mesh.cell_tris[e], l, q, r2, best, ids)
    return resolve(mesh, m, l, q, best, ids, out)


@njit(**EXACT)
def mesh_shift(mesh: tuple, m: int, t: float, out: np.ndarray) -> None:
    """Mesh ``m``'s translation at time ``t`` into ``out`` (3,)."""
    k0, k1 = mesh.dims[m, DIMS_K0], mesh.dims[m, DIMS_K1]
    _position_at(mesh.times[k0:k1], mesh.points[k0:k1], mesh.velocity[m], t, out)


@njit(**EXACT)
def collide_mesh_points(pos: np.ndarray, last: np.ndarray, free: np.ndarray, mesh: tuple, m: int,
                        before: np.ndarray, after: np.ndarray, brute: bool) -> None:
    """Collide the points ``free`` with mesh ``m`` translated by ``before`` at the substep's start
    and ``after`` at its end, in place."""
    keep = 1.0 - mesh.info[m, INFO_FRICTION]
    l = np.empty(3)
    q = np.empty(3)
    out = np.empty(3)
    best = np.empty(5)
    ids = np.empty(3, dtype=np.int64)
    for k in range(free.shape[0]):
        p = free[k]
        for c in range(3):
            l[c] = last[c, p] - before[c]
            q[c] = pos[c, p] - after[c]
        if point_contact(mesh, m, l, q, brute, best, ids, out):
            for c in range(3):
                pos[c, p] = after[c] + l[c] + (out[c] - l[c]) * keep


@njit(**EXACT)
def mesh_flags(mesh: tuple | None) -> np.ndarray:
    """Work space: one reachability flag per mesh (none without meshes)."""
    if mesh is None:
        return np.zeros(0, dtype=np.bool_)
    return np.zeros(mesh.dims.shape[0], dtype=np.bool_)


@njit(**EXACT)
def reachable_meshes(mesh: tuple | None, box: np.ndarray, step: int, on: np.ndarray) -> int:
    """Mark the meshes the cloth's bounding box (current and last positions) may touch during
    substep ``step`` of this call; returns how many were ruled out. A mesh's box, over both
    translations of the substep and widened by the thickness, that misses the cloth's box can
    neither be crossed nor come within the thickness of a point, so skipping it is exact."""
    if mesh is None:
        return 0
    skipped = 0
    t1 = mesh.clock[0] + (step + 1) * mesh.clock[1]
    before = np.empty(3)
    after = np.empty(3)
    for m in range(mesh.dims.shape[0]):
        mesh_shift(mesh, m, t1 - mesh.clock[1], before)
        mesh_shift(mesh, m, t1, after)
        hit = True
        for c in range(3):
            lo = mesh.info[m, INFO_LO + c] + min(before[c], after[c]) - mesh.thickness
            hi = mesh.info[m, INFO_HI + c] + max(before[c], after[c]) + mesh.thickness
            if hi < box[c] or lo > box[3 + c]:
                hit = False
        on[m] = hit
        skipped += 0 if hit else 1
    return skipped


@njit(**EXACT)
def collide_meshes_chunk(pos: np.ndarray, last: np.ndarray, free: np.ndarray, mesh: tuple | None, on: np.ndarray,
                         step: int, c: int) -> None:
    """Work item ``c`` (of CHUNKS) of the mesh pass in substep ``step`` of this call: the c-th part
    of the free points against every reachable mesh, in scene order."""
    if mesh is None:
        return
    n = free.shape[0]
    f0, f1 = share(n, c, CHUNKS)
    part = free[f0:f1]
    t1 = mesh.clock[0] + (step + 1) * mesh.clock[1]
    before = np.empty(3)
    after = np.empty(3)
    for m in range(mesh.dims.shape[0]):
        if on[m]:
            mesh_shift(mesh, m, t1 - mesh.clock[1], before)
            mesh_shift(mesh, m, t1, after)
            collide_mesh_points(pos, last, part, mesh, m, before, after, False)


@njit(**EXACT)
def mesh_targets(pos: np.ndarray, last: np.ndarray, mesh: tuple, brute: bool) -> np.ndarray:
    """Every point of (3, N) ``pos`` collided with every mesh (static, at time 0), on a copy: the
    grid's answer, or the brute-force one (for tests)."""
    out = pos.copy()
    free = np.arange(pos.shape[1])
    shift = np.empty(3)
    for m in range(mesh.dims.shape[0]):
        mesh_shift(mesh, m, 0.0, shift)
        collide_mesh_points(out, last, free, mesh, m, shift, shift, brute)
    return out


@njit(**EXACT)
def mesh_corrections(pos: np.ndarray, last: np.ndarray, free: np.ndarray, mesh: tuple | None) -> int:
    """The mesh pass of the integrators other than the spec's Verlet, one substep per call
    (``mesh.clock[2]`` counts the substeps of the current call); returns the meshes skipped."""
    if mesh is None:
        return 0
    step = int(mesh.clock[2])
    mesh.clock[2] += 1.0
    box = np.empty(6)
    for c in range(3):
        box[c] = min(pos[c].min(), last[c].min())
        box[3 + c] = max(pos[c].max(), last[c].max())
    on = mesh_flags(mesh)
    skipped = reachable_meshes(mesh, box, step, on)
    for c in range(CHUNKS):
        collide_meshes_chunk(pos, last, free, mesh, on, step, c)
    return skipped
