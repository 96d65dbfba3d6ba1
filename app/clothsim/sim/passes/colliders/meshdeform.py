"""Deforming mesh colliders (a ``sequence`` of OBJ frames): their shape put in place every substep.

A deforming mesh keeps the fixed mesh's arrays (:class:`~.meshgrid.MeshGroup`) and adds a
:class:`Deform` (None when no mesh of the scene deforms, so that a scene without one compiles and
runs the code it had). Each substep, before any point meets the mesh, :func:`deform_meshes` puts
every deforming mesh's vertices at the substep's start (``Deform.verts0``) and end (the group's
``verts``), both by the rule of :mod:`clothsim.meshsequence` (:func:`frame_pair`), and recomputes
from the end pose what the tests read: face normals, the edge and vertex pseudo-normals (a closed
mesh keeps telling inside from outside as it deforms), each triangle's bounding box, and the grid's
copies of those boxes. The grid's cells are not rebuilt: each triangle is listed in every cell that
any frame's box of it (grown by the margin) overlaps (:func:`~.meshgrid.mesh_group`), and an
interpolated vertex lies between two frames' positions, so the cells hold it at every time; only
the boxes beside the cells, which let a query pass a triangle over, are refit to the current pose.

``Deform.moved`` holds, per mesh, the largest distance a vertex moves over the substep: the pass
widens a point's reach by it (:func:`~.mesh.collide_deforming_points`), so that a surface which
moves onto a point that stands still is found, as a point moving onto a still surface is.
"""

from __future__ import annotations

import math
from typing import NamedTuple

import numpy as np
from numba import njit

from ....jit import EXACT
from ....meshsequence import frame_pair as sequence_frame_pair
from ...clock import substep_time

#: Columns of ``Deform.table``, one row per deforming mesh.
ROW_MESH, ROW_V0, ROW_V1, ROW_FRAME0, ROW_FRAMES, ROW_T0, ROW_T1, ROW_E0, ROW_E1 = range(9)
ROW_WIDTH = 9


class Deform(NamedTuple):
    """The deforming meshes of a group (see the module's docstring)."""

    frames: np.ndarray  # (R, 3) every deforming mesh's placed frames (scaled and rotated), frame after frame
    table: np.ndarray  # (D, ROW_WIDTH) int64: mesh row, vertex range, first frame row and frames, triangle
    # range, range of the grid's entries (cell_tris) of its cells
    rate: np.ndarray  # (D, 2) fps, and 1.0 for a sequence that loops
    which: np.ndarray  # (M,) int64 each mesh's row of ``table``, -1 for a fixed shape
    verts0: np.ndarray  # (V, 3) the vertices at the substep's start (a fixed mesh's rows unused)
    mate: np.ndarray  # (T, 3) int64 the triangle across edge k (corner k -> k+1), -1 on a boundary
    moved: np.ndarray  # (M,) the farthest a vertex of each mesh moves over the substep (0 for a fixed one)


def edge_mates(tris: np.ndarray) -> np.ndarray:
    """(T, 3) int64: for each triangle's edge k (corner k -> corner k+1), the other triangle on it,
    or -1 (a boundary edge); triangles indices as in ``tris``, whose edges have at most two."""
    t = tris.shape[0]
    heads = tris.reshape(-1)
    tails = tris[:, [1, 2, 0]].reshape(-1)
    key = np.minimum(heads, tails) * (int(tris.max()) + 1) + np.maximum(heads, tails)
    order = np.argsort(key, kind="stable")
    sk = key[order]
    mate = np.full(3 * t, -1, dtype=np.int64)
    pair = np.flatnonzero(sk[1:] == sk[:-1])
    mate[order[pair]] = order[pair + 1] // 3
    mate[order[pair + 1]] = order[pair] // 3
    return mate.reshape(t, 3)


#: :func:`clothsim.meshsequence.frame_pair` compiled: the renderer and the kernels pose a deforming
#: mesh by the one expression.
frame_pair = njit(inline="always", **EXACT)(sequence_frame_pair)


@njit(inline="always", **EXACT)
def _shape_at(d: Deform, r: int, t: float, out: np.ndarray) -> None:
    v0, v1 = d.table[r, ROW_V0], d.table[r, ROW_V1]
    n = v1 - v0
    i, j, f = frame_pair(t, d.rate[r, 0], d.table[r, ROW_FRAMES], d.rate[r, 1] != 0.0)
    a0 = d.table[r, ROW_FRAME0] + i * n
    b0 = d.table[r, ROW_FRAME0] + j * n
    for v in range(n):
        for c in range(3):
            a = d.frames[a0 + v, c]
            out[v0 + v, c] = a + (d.frames[b0 + v, c] - a) * f


@njit(inline="always", **EXACT)
def _unit(x: float, y: float, z: float) -> tuple[float, float, float]:
    n = math.sqrt(x * x + y * y + z * z)
    if n > 0.0:
        return x / n, y / n, z / n
    return 0.0, 0.0, 0.0


@njit(**EXACT)
def deform_meshes(d: Deform | None, verts: np.ndarray, tris: np.ndarray, tbox: np.ndarray, fnorm: np.ndarray,
                  enorm: np.ndarray, vnorm: np.ndarray, cell_tris: np.ndarray, cell_box: np.ndarray,
                  clock: np.ndarray, dt: float, substep: int) -> None:
    """Every deforming mesh at its pose for substep ``substep`` of the call (nothing when ``d`` is
    None): the vertices at both ends, the normals and boxes at the end (see the module's docstring)."""
    if d is None:
        return
    s0 = substep_time(clock, substep, dt)
    s1 = substep_time(clock, substep + 1, dt)
    for r in range(d.table.shape[0]):
        _shape_at(d, r, s0, d.verts0)
        _shape_at(d, r, s1, verts)
        v0, v1 = d.table[r, ROW_V0], d.table[r, ROW_V1]
        far = 0.0
        for v in range(v0, v1):
            e = ((verts[v, 0] - d.verts0[v, 0]) ** 2 + (verts[v, 1] - d.verts0[v, 1]) ** 2
                 + (verts[v, 2] - d.verts0[v, 2]) ** 2)
            far = max(far, e)
        d.moved[d.table[r, ROW_MESH]] = math.sqrt(far)
        t0, t1 = d.table[r, ROW_T0], d.table[r, ROW_T1]
        for t in range(t0, t1):
            a, b, c = tris[t, 0], tris[t, 1], tris[t, 2]
            for k in range(3):
                lo = min(verts[a, k], verts[b, k], verts[c, k])
                hi = max(verts[a, k], verts[b, k], verts[c, k])
                tbox[t, k] = lo
                tbox[t, 3 + k] = hi
            ux, uy, uz = verts[b, 0] - verts[a, 0], verts[b, 1] - verts[a, 1], verts[b, 2] - verts[a, 2]
            wx, wy, wz = verts[c, 0] - verts[a, 0], verts[c, 1] - verts[a, 1], verts[c, 2] - verts[a, 2]
            fnorm[t, 0], fnorm[t, 1], fnorm[t, 2] = _unit(uy * wz - uz * wy, uz * wx - ux * wz, ux * wy - uy * wx)
        for v in range(v0, v1):
            vnorm[v, 0] = vnorm[v, 1] = vnorm[v, 2] = 0.0
        for t in range(t0, t1):
            for k in range(3):
                o = d.mate[t, k]
                if o < 0:
                    enorm[t, k, 0], enorm[t, k, 1], enorm[t, k, 2] = fnorm[t, 0], fnorm[t, 1], fnorm[t, 2]
                else:
                    enorm[t, k, 0], enorm[t, k, 1], enorm[t, k, 2] = _unit(
                        fnorm[t, 0] + fnorm[o, 0], fnorm[t, 1] + fnorm[o, 1], fnorm[t, 2] + fnorm[o, 2])
                # the corner's angle weights the face's normal in the vertex's pseudo-normal
                p, q, s = tris[t, k], tris[t, (k + 1) % 3], tris[t, (k + 2) % 3]
                ux, uy, uz = _unit(verts[q, 0] - verts[p, 0], verts[q, 1] - verts[p, 1], verts[q, 2] - verts[p, 2])
                wx, wy, wz = _unit(verts[s, 0] - verts[p, 0], verts[s, 1] - verts[p, 1], verts[s, 2] - verts[p, 2])
                angle = math.acos(min(1.0, max(-1.0, ux * wx + uy * wy + uz * wz)))
                for c in range(3):
                    vnorm[p, c] += fnorm[t, c] * angle
        for v in range(v0, v1):
            vnorm[v, 0], vnorm[v, 1], vnorm[v, 2] = _unit(vnorm[v, 0], vnorm[v, 1], vnorm[v, 2])
        for e in range(d.table[r, ROW_E0], d.table[r, ROW_E1]):
            t = cell_tris[e]
            for k in range(6):
                cell_box[e, k] = tbox[t, k]
