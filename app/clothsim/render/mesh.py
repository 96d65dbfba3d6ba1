"""Mesh data: cloth triangles/uvs and per-frame normals/tangents, the UV sphere, the plane quad.

The cloth's vertex stream is one float32 array of shape (N, 9): position, normal, tangent.
It is refilled in place every frame by :func:`update_cloth_vertices` (a grid) or
:func:`update_surface_vertices` (a mesh cloth: one row per render vertex, R >= N where UV seams
split a point) and uploaded as one VBO write. UVs and triangle indices never change, so they
live in static buffers.
"""

from __future__ import annotations

import math

import numpy as np
from numba import njit, types

from ..cloth import cloth_triangles, cloth_uvs  # noqa: F401 - the grid's, drawn here
from ..jit import EXACT
from ..jit.compile import on_warm

CLOTH_FLOATS = 9  # position(3) normal(3) tangent(3)


@njit(inline="always", **EXACT)
def _unit(x: float, y: float, z: float, fx: float, fy: float, fz: float) -> tuple[float, float, float]:
    """(x, y, z) scaled to unit length, or the fallback (fx, fy, fz) for a zero vector."""
    ln = math.sqrt(x * x + y * y + z * z)
    if ln > 0.0:
        return x / ln, y / ln, z / ln
    return fx, fy, fz


@njit(**EXACT)
def update_cloth_vertices(positions, nw, nh, with_tangents, out):  # pragma: no cover - compiled
    """Fill ``out`` (N, 9) float32 with positions, unit normals and (optionally) unit tangents.

    Normals are area-weighted: each triangle adds its unnormalised cross product (twice its
    area times its unit normal) to its three corners. Tangents follow +u (the x_index
    direction): each triangle adds dP/du weighted the same way, then Gram-Schmidt against n.
    """
    n_points = nw * nh
    acc_n = np.zeros((n_points, 3))
    acc_t = np.zeros((n_points, 3))
    du = 1.0 / (nw - 1)
    dv = 1.0 / (nh - 1)
    tri = np.empty(3, dtype=np.int64)
    for y in range(nh - 1):
        for x in range(nw - 1):
            a = y * nw + x
            b = a + 1
            c = a + nw
            d = c + 1
            for half in range(2):
                if half == 0:
                    tri[0] = a
                    tri[1] = c
                    tri[2] = b
                else:
                    tri[0] = b
                    tri[1] = c
                    tri[2] = d
                i0, i1, i2 = tri[0], tri[1], tri[2]
                e1x = positions[i1, 0] - positions[i0, 0]
                e1y = positions[i1, 1] - positions[i0, 1]
                e1z = positions[i1, 2] - positions[i0, 2]
                e2x = positions[i2, 0] - positions[i0, 0]
                e2y = positions[i2, 1] - positions[i0, 1]
                e2z = positions[i2, 2] - positions[i0, 2]
                nx = e1y * e2z - e1z * e2y
                ny = e1z * e2x - e1x * e2z
                nz = e1x * e2y - e1y * e2x
                for k in range(3):
                    v = tri[k]
                    acc_n[v, 0] += nx
                    acc_n[v, 1] += ny
                    acc_n[v, 2] += nz
                if with_tangents:
                    # uv deltas of the edges: grid steps, so the inverse is closed-form.
                    u0 = (i0 % nw) * du
                    v0 = (i0 // nw) * dv
                    s1 = (i1 % nw) * du - u0
                    t1 = (i1 // nw) * dv - v0
                    s2 = (i2 % nw) * du - u0
                    t2 = (i2 // nw) * dv - v0
                    det = s1 * t2 - s2 * t1
                    if det != 0.0:
                        # dP/du scaled by |det| (the uv area) so larger triangles weigh more.
                        sgn = 1.0 if det > 0.0 else -1.0
                        tx = (e1x * t2 - e2x * t1) * sgn
                        ty = (e1y * t2 - e2y * t1) * sgn
                        tz = (e1z * t2 - e2z * t1) * sgn
                        for k in range(3):
                            v = tri[k]
                            acc_t[v, 0] += tx
                            acc_t[v, 1] += ty
                            acc_t[v, 2] += tz
    for p in range(n_points):
        out[p, 0] = positions[p, 0]
        out[p, 1] = positions[p, 1]
        out[p, 2] = positions[p, 2]
        nx, ny, nz = _unit(acc_n[p, 0], acc_n[p, 1], acc_n[p, 2], 0.0, 1.0, 0.0)
        out[p, 3] = nx
        out[p, 4] = ny
        out[p, 5] = nz
        if with_tangents:
            tx = acc_t[p, 0]
            ty = acc_t[p, 1]
            tz = acc_t[p, 2]
            dot = tx * nx + ty * ny + tz * nz
            tx, ty, tz = _unit(tx - dot * nx, ty - dot * ny, tz - dot * nz, 1.0, 0.0, 0.0)
            out[p, 6] = tx
            out[p, 7] = ty
            out[p, 8] = tz
        else:
            out[p, 6] = 0.0
            out[p, 7] = 0.0
            out[p, 8] = 0.0


@njit(**EXACT)
def update_surface_vertices(positions, triangles, uv_point, uvs, uv_triangles, with_tangents,
                            out):  # pragma: no cover - compiled
    """Fill ``out`` (R, 9) float32, one row per render vertex of a cloth surface, with its point's
    position, unit normal and (optionally) unit tangent.

    ``triangles`` (T, 3) index the simulated points ``positions`` (N, 3); ``uv_triangles`` (T, 3)
    the same triangles over the render vertices, which ``uv_point`` (R,) maps to points and
    ``uvs`` (R, 2) float64 place in texture space. Normals are area-weighted per simulated point,
    as the grid's are, and gathered per render vertex: the copies of a point split by a UV seam
    get one normal, so the seam shows no crease. Tangents follow +u of each render vertex's own
    uvs (a seam may turn u): each triangle adds dP/du times its uv area to its render corners,
    then Gram-Schmidt against the normal. Triangles are taken in order, so a grid given as a
    surface sums the same terms in the same order as :func:`update_cloth_vertices`.

    (Its tangent sums and normalisations repeat the grid kernel's, which the duplicate-code scan
    pairs: the grid's kernel is left exactly as it was, so that the grid's pixels, and the goldens,
    do not change; this one reads triangles and uvs through indices where the grid's computes them.)
    """
    n_points = positions.shape[0]
    n_vertices = uv_point.shape[0]
    acc_n = np.zeros((n_points, 3))
    acc_t = np.zeros((n_vertices, 3))
    for f in range(triangles.shape[0]):
        i0, i1, i2 = triangles[f, 0], triangles[f, 1], triangles[f, 2]
        e1x = positions[i1, 0] - positions[i0, 0]
        e1y = positions[i1, 1] - positions[i0, 1]
        e1z = positions[i1, 2] - positions[i0, 2]
        e2x = positions[i2, 0] - positions[i0, 0]
        e2y = positions[i2, 1] - positions[i0, 1]
        e2z = positions[i2, 2] - positions[i0, 2]
        nx = e1y * e2z - e1z * e2y
        ny = e1z * e2x - e1x * e2z
        nz = e1x * e2y - e1y * e2x
        for k in range(3):
            v = triangles[f, k]
            acc_n[v, 0] += nx
            acc_n[v, 1] += ny
            acc_n[v, 2] += nz
        if with_tangents:
            r0, r1, r2 = uv_triangles[f, 0], uv_triangles[f, 1], uv_triangles[f, 2]
            s1 = uvs[r1, 0] - uvs[r0, 0]
            t1 = uvs[r1, 1] - uvs[r0, 1]
            s2 = uvs[r2, 0] - uvs[r0, 0]
            t2 = uvs[r2, 1] - uvs[r0, 1]
            det = s1 * t2 - s2 * t1
            if det != 0.0:
                # dP/du scaled by |det| (the uv area), as the grid's kernel weighs it
                sgn = 1.0 if det > 0.0 else -1.0
                tx = (e1x * t2 - e2x * t1) * sgn
                ty = (e1y * t2 - e2y * t1) * sgn
                tz = (e1z * t2 - e2z * t1) * sgn
                for k in range(3):
                    v = uv_triangles[f, k]
                    acc_t[v, 0] += tx
                    acc_t[v, 1] += ty
                    acc_t[v, 2] += tz
    for r in range(n_vertices):
        p = uv_point[r]
        out[r, 0] = positions[p, 0]
        out[r, 1] = positions[p, 1]
        out[r, 2] = positions[p, 2]
        nx, ny, nz = _unit(acc_n[p, 0], acc_n[p, 1], acc_n[p, 2], 0.0, 1.0, 0.0)
        out[r, 3] = nx
        out[r, 4] = ny
        out[r, 5] = nz
        if with_tangents:
            tx = acc_t[r, 0]
            ty = acc_t[r, 1]
            tz = acc_t[r, 2]
            dot = tx * nx + ty * ny + tz * nz
            tx, ty, tz = _unit(tx - dot * nx, ty - dot * ny, tz - dot * nz, 1.0, 0.0, 0.0)
            out[r, 6] = tx
            out[r, 7] = ty
            out[r, 8] = tz
        else:
            out[r, 6] = 0.0
            out[r, 7] = 0.0
            out[r, 8] = 0.0


def sphere_mesh(lat: int, lon: int) -> tuple[np.ndarray, np.ndarray]:
    """A unit UV sphere: vertices (V, 11) float32 (position, normal, tangent, uv) and indices.

    ``lat`` rings from pole to pole and ``lon`` segments around; the seam column is duplicated
    so u runs 0..1 without wrapping. Front faces point outwards.
    """
    if lat < 2 or lon < 3:
        raise ValueError("sphere resolution must be at least 2 x 3")
    theta = np.linspace(0.0, math.pi, lat + 1)  # from +y (north) to -y
    phi = np.linspace(0.0, 2.0 * math.pi, lon + 1)
    th, ph = np.meshgrid(theta, phi, indexing="ij")  # (lat+1, lon+1)
    st, ct, sp, cp = np.sin(th), np.cos(th), np.sin(ph), np.cos(ph)
    pos = np.stack([st * sp, ct, st * cp], axis=-1)
    # dP/dphi direction; at the poles use the limit so the tangent never vanishes.
    tan = np.stack([cp, np.zeros_like(cp), -sp], axis=-1)
    uv = np.stack([ph / (2.0 * math.pi), 1.0 - th / math.pi], axis=-1)
    verts = np.concatenate([pos, pos, tan, uv], axis=-1).reshape(-1, 11).astype(np.float32)
    idx = np.arange((lat + 1) * (lon + 1), dtype=np.uint32).reshape(lat + 1, lon + 1)
    a = idx[:-1, :-1].ravel()
    b = idx[:-1, 1:].ravel()
    c = idx[1:, :-1].ravel()
    d = idx[1:, 1:].ravel()
    # Going down a ring increases theta and going right increases phi; (a, c, b) is CCW seen
    # from outside.
    tris = np.stack([a, c, b, b, c, d], axis=1).ravel()
    return np.ascontiguousarray(verts), np.ascontiguousarray(tris.astype(np.uint32))


def plane_mesh(point: tuple[float, float, float], normal: tuple[float, float, float],
               half_extent: float = 2.0, uv_tiles: float = 4.0) -> tuple[np.ndarray, np.ndarray]:
    """A square quad centred at ``point`` facing ``normal``: vertices (4, 11) float32, indices (6,).

    The quad is large (the course draws its planes the same way) and its uv repeats
    ``uv_tiles`` times so that textures keep a sensible scale.
    """
    n = np.asarray(normal, dtype=np.float64)
    n = n / np.linalg.norm(n)
    helper = np.array([1.0, 0.0, 0.0]) if abs(n[0]) < 0.9 else np.array([0.0, 0.0, 1.0])
    t = np.cross(helper, n)
    t /= np.linalg.norm(t)
    b = np.cross(n, t)
    p = np.asarray(point, dtype=np.float64)
    corners = []
    for su, sv in ((-1, -1), (1, -1), (1, 1), (-1, 1)):
        q = p + half_extent * (su * t + sv * b)
        uv = ((su + 1) * 0.5 * uv_tiles, (sv + 1) * 0.5 * uv_tiles)
        corners.append([*q, *n, *t, *uv])
    verts = np.asarray(corners, dtype=np.float32)
    # t x b = n, so (0, 1, 2) is counter-clockwise seen from the normal's side.
    idx = np.array([0, 1, 2, 0, 2, 3], dtype=np.uint32)
    return verts, idx


def _frame_of(axis: np.ndarray) -> np.ndarray:
    """A rotation (3, 3) whose second column is the unit vector ``axis`` (x and z columns any
    right-handed completion)."""
    across = np.array([1.0, 0.0, 0.0]) if abs(axis[0]) < 0.9 else np.array([0.0, 0.0, 1.0])
    x = np.cross(axis, across)
    x /= np.linalg.norm(x)
    z = np.cross(x, axis)
    return np.stack([x, axis, z], axis=1)


def capsule_mesh(a: tuple[float, float, float], b: tuple[float, float, float], radius: float, lat: int,
                 lon: int) -> tuple[np.ndarray, np.ndarray]:
    """A capsule around the segment a-b in world space: vertices (V, 11) float32 (position,
    normal, tangent, uv) and indices, front faces outwards.

    Built like :func:`sphere_mesh` with its two hemispheres pulled apart along the axis: ``lat``
    rings from pole to pole (at least 2) and ``lon`` segments around; the equator ring is doubled
    so that the two copies bound the cylinder between the caps.
    """
    if lat < 2 or lon < 3:
        raise ValueError("capsule resolution must be at least 2 x 3")
    pa = np.asarray(a, dtype=np.float64)
    pb = np.asarray(b, dtype=np.float64)
    length = float(np.linalg.norm(pb - pa))
    axis = (pb - pa) / length if length > 0.0 else np.array([0.0, 1.0, 0.0])
    half = lat // 2 + 1
    theta = np.concatenate([np.linspace(0.0, math.pi / 2, half), np.linspace(math.pi / 2, math.pi, half)])
    lift = np.concatenate([np.full(half, 0.5 * length), np.full(half, -0.5 * length)])
    phi = np.linspace(0.0, 2.0 * math.pi, lon + 1)
    th, ph = np.meshgrid(theta, phi, indexing="ij")
    st, ct, sp, cp = np.sin(th), np.cos(th), np.sin(ph), np.cos(ph)
    normal = np.stack([st * sp, ct, st * cp], axis=-1)
    local = normal * radius
    local[..., 1] += lift[:, None]
    tan = np.stack([cp, np.zeros_like(cp), -sp], axis=-1)
    span = 2.0 * radius + length
    uv = np.stack([ph / (2.0 * math.pi), np.broadcast_to(((local[..., 1] + 0.5 * span) / span), ph.shape)], axis=-1)
    rot = _frame_of(axis)
    mid = 0.5 * (pa + pb)
    pos = local @ rot.T + mid
    verts = np.concatenate([pos, normal @ rot.T, tan @ rot.T, uv], axis=-1).reshape(-1, 11).astype(np.float32)
    rows = theta.shape[0]
    idx = np.arange(rows * (lon + 1), dtype=np.uint32).reshape(rows, lon + 1)
    q = idx[:-1, :-1].ravel(), idx[:-1, 1:].ravel(), idx[1:, :-1].ravel(), idx[1:, 1:].ravel()
    tris = np.stack([q[0], q[2], q[1], q[1], q[2], q[3]], axis=1).ravel()
    return np.ascontiguousarray(verts), np.ascontiguousarray(tris.astype(np.uint32))


def box_mesh(center: tuple[float, float, float], half_extents: tuple[float, float, float],
             rotation: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """An oriented box in world space: 24 vertices (V, 11) float32 (four per face, so each face
    has its own normal) and 36 indices, front faces outwards. ``rotation`` (3, 3) maps the box's
    axes to world space (column k is its k-th axis)."""
    rot = np.asarray(rotation, dtype=np.float64)
    h = np.asarray(half_extents, dtype=np.float64)
    c = np.asarray(center, dtype=np.float64)
    verts = []
    for k in range(3):
        for sign in (1.0, -1.0):
            n = np.zeros(3)
            n[k] = sign
            # u, v span the face with u x v = n (counter-clockwise seen from outside)
            u = np.zeros(3)
            u[(k + 1) % 3] = 1.0
            v = np.cross(n, u)
            for su, sv in ((-1, -1), (1, -1), (1, 1), (-1, 1)):
                local = (n + su * u + sv * v) * h
                verts.append([*(rot @ local + c), *(rot @ n), *(rot @ u), (su + 1) * 0.5, (sv + 1) * 0.5])
    idx = np.array([[4 * f, 4 * f + 1, 4 * f + 2, 4 * f, 4 * f + 2, 4 * f + 3] for f in range(6)], dtype=np.uint32)
    return np.asarray(verts, dtype=np.float32), idx.ravel()


def _warm() -> None:
    update_cloth_vertices(np.zeros((4, 3)), 2, 2, True, np.zeros((4, CLOTH_FLOATS), dtype=np.float32))


on_warm("3 render mesh", _warm)


def _warm_surface() -> None:
    tri = np.array([[0, 2, 1], [1, 2, 3]], dtype=np.int64)
    update_surface_vertices(np.zeros((4, 3)), tri, np.arange(4, dtype=np.int64), np.zeros((4, 2)), tri, True,
                            np.zeros((4, CLOTH_FLOATS), dtype=np.float32))


# The renderer's call: positions, point triangles, vertex -> point, uvs, vertex triangles, tangents, out.
_INDEX = types.Array(types.int64, 1, "C")
_TRIS = types.Array(types.int64, 2, "C")
_SURFACE_SIGNATURE = (types.Array(types.float64, 2, "C"), _TRIS, _INDEX, types.Array(types.float64, 2, "C"), _TRIS,
                      types.boolean, types.Array(types.float32, 2, "C"))


def register_surface_warm() -> None:
    """Have :func:`~clothsim.jit.compile.warm_side_kernels` compile (or load) the surface kernel;
    done for mesh cloths only (:meth:`Renderer.prepare <clothsim.render.renderer.Renderer.prepare>`,
    :func:`~clothsim.render.pipeline.clip_frames`), so that a grid's cold start does not pay for it."""
    on_warm("3 render surface", _warm_surface, beside=((update_surface_vertices, _SURFACE_SIGNATURE),))
