"""Triangle-mesh colliders packed for the kernels, with the uniform grid built once over their triangles.

Every mesh of a scene goes into one :class:`MeshGroup` of flat arrays: its scaled and rotated
vertices (the translation, which may move, is applied to the cloth's points instead), triangles,
the pseudo-normals that tell inside from outside (face normals, edge normals = the normalised sum
of the two faces' normals, and angle-weighted vertex normals: Baerentzen and Aanaes, "Signed
distance computation using the angle weighted pseudonormal", IEEE TVCG 2005), its pose (the
translation at the substep's start and end, and for a turning mesh its turn Q at both: put there
each substep for a moving mesh by :func:`clothsim.sim.passes.colliders.mesh.pose` from its
:class:`~.moving.Tracks` and :class:`~.moving.Turns`), and a
uniform grid of its triangles.

The grid: cubic cells of edge ``h`` over the mesh's bounding box; a triangle is listed in every
cell that its bounding box, grown by the grid's margin (the cloth's thickness), overlaps, with a
copy of its box beside it. A point's query box is ``q +- r``, ``r`` = thickness + |q - l|: a
triangle whose box overlaps it has its grown box overlap ``q +- (r - margin)``, which is ``q``
itself for a point that has not moved, so a point usually visits one cell, and finds there only
the triangles near it, their boxes in a row. ``h`` is the mean of the triangles' largest
bounding-box sides plus the margin (grown until there are at most 8 cells per triangle, so a flat
or long mesh cannot make the grid huge). Cell indices are ``floor((x - lo) * inv_h)`` clipped to
the grid, the same expression here and in the kernel; clipping keeps the order of coordinates, so
the overlap of a grown box and a query box survives it, and the listing's margin is wider than
the query's by far more than the rounding of either (the grid finds every triangle the
brute-force test does).
"""

from __future__ import annotations

import dataclasses
import math
from typing import NamedTuple

import numpy as np

from ....meshcollider import NEAR_D_WIDTH, NEAR_PLANES, NEAR_ROOM, PLANE_WIDTH
from ....motion import MotionSpec
from ....scene import Scene
from ...clock import track_at
from .meshdeform import ROW_WIDTH, Deform, edge_mates
from .moving import Tracks, Turns, pack_tracks, pack_turns

#: Columns of ``MeshGroup.info`` (float64) and ``MeshGroup.dims`` (int64), one row per mesh.
INFO_LO, INFO_HI, INFO_INV_H, INFO_FRICTION, INFO_MARGIN, INFO_NEAR, INFO_NEAR_OK = 0, 3, 6, 7, 8, 9, 10
DIMS_TRI0, DIMS_TRI1, DIMS_CELL0, DIMS_N, DIMS_CLOSED = 0, 1, 2, 3, 6
#: Where a plane of ``MeshGroup.near_pl`` keeps its triangle's distance (after its normal and offset).
PLANE_D = 4
#: Most cells per triangle the grid may have (see the module's docstring).
MAX_CELLS_PER_TRIANGLE = 8
#: How much wider (relative to the margin plus the mesh's size) a triangle's listing is than the
#: query assumes: far beyond the rounding of either side's sums, far below a cell.
LISTING_SLACK = 1e-9
#: A point's list reaches this many thicknesses from its anchor: the wider, the longer a moving
#: point keeps its list, the more triangles in it.
NEAR_REACH = 1.5


class MeshGroup(NamedTuple):
    """Every mesh collider of a scene as flat arrays (see the module's docstring)."""

    verts: np.ndarray  # (V, 3) scaled and rotated, before the translation
    tris: np.ndarray  # (T, 3) int64, outward-wound for a closed mesh
    tbox: np.ndarray  # (T, 6) each triangle's bounding box: lo xyz, hi xyz
    fnorm: np.ndarray  # (T, 3) unit face normals
    enorm: np.ndarray  # (T, 3, 3) unit edge pseudo-normals, edge k = corner k -> corner k+1
    vnorm: np.ndarray  # (V, 3) unit angle-weighted vertex pseudo-normals
    info: np.ndarray  # (M, 11) bounding box lo, hi (local), 1/cell edge, friction, grid margin, list reach and
    # the reach a query may have within it
    dims: np.ndarray  # (M, 7) first and end triangle, first cell, cells along x y z, closed
    cell_start: np.ndarray  # (C + 1,) int64
    cell_tris: np.ndarray  # (E,) int64 triangle ids, cell by cell
    cell_box: np.ndarray  # (E, 6) those triangles' bounding boxes (= tbox rows), in the same order
    near_at: np.ndarray  # (M, N, 3) each point's anchor, where its list of each mesh was gathered (mesh frame)
    near_n: np.ndarray  # (M, N) int64 triangles in that list; -1: none (too many, or never gathered)
    near_tris: np.ndarray  # (M, N, NEAR_ROOM) int32 the list: every triangle whose box comes within reach
    near_d: np.ndarray  # (M, N, NEAR_D_WIDTH) each listed triangle's distance from near_ref, less a slack; ascending
    near_ref: np.ndarray  # (M, N, 3) where those distances were measured (mesh frame)
    near_first: np.ndarray  # (M, N) the first of each list's distances (+inf: none), which most points read
    # every substep, side by side
    near_pl: np.ndarray  # (M, N, NEAR_PLANES, PLANE_WIDTH) the first listed triangles' separating planes from
    # near_ref: unit normal, offset (+inf: none), and the triangle's near_d (read with the plane)
    pose: np.ndarray  # (M, 6) translation at the substep's start and at its end
    thickness: float
    on: np.ndarray  # (M,) bool: the reach flags
    tracks: Tracks | None  # the moving meshes' translations (None when none moves)
    turns: Turns | None  # their turns, motion (M, 18): Q at the substep's start and end (None when none turns)
    deform: Deform | None  # the deforming meshes' frames and their pose (None when none deforms)
    #: address of the mesh pass compiled for this group (see :func:`clothsim.sim.solvers.frame.kernel_addresses`); 0 until known
    collide: int = 0


def _unit_rows(v: np.ndarray) -> np.ndarray:
    n = np.linalg.norm(v, axis=-1, keepdims=True)
    return np.where(n > 0.0, v / np.where(n > 0.0, n, 1.0), 0.0)


def pseudo_normals(verts: np.ndarray, tris: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Face normals (T, 3), edge pseudo-normals (T, 3, 3) and vertex pseudo-normals (V, 3).

    A boundary edge (one face) gets that face's normal."""
    a, b, c = (verts[tris[:, k]] for k in range(3))
    fn = _unit_rows(np.cross(b - a, c - a))
    t = tris.shape[0]
    heads = tris.reshape(-1)
    tails = tris[:, [1, 2, 0]].reshape(-1)
    key = np.minimum(heads, tails) * (verts.shape[0] + 1) + np.maximum(heads, tails)
    _, inverse = np.unique(key, return_inverse=True)
    summed = np.zeros((inverse.max() + 1, 3))
    np.add.at(summed, inverse, np.repeat(fn, 3, axis=0))
    en = _unit_rows(summed[inverse]).reshape(t, 3, 3)
    vn = np.zeros_like(verts)
    corners = (a, b, c)
    for k in range(3):
        p, q, r = corners[k], corners[(k + 1) % 3], corners[(k + 2) % 3]
        u = _unit_rows(q - p)
        w = _unit_rows(r - p)
        angle = np.arccos(np.clip(np.einsum("ij,ij->i", u, w), -1.0, 1.0))
        np.add.at(vn, tris[:, k], fn * angle[:, None])
    return fn, en, _unit_rows(vn)


def build_grid(verts: np.ndarray, tris: np.ndarray, margin: float, frames: np.ndarray | None = None
               ) -> tuple[np.ndarray, np.ndarray, float, tuple[int, int, int], np.ndarray, np.ndarray]:
    """The uniform grid of one mesh, its triangles listed with their boxes grown by ``margin``
    (see the module's docstring): (lo, hi, inv_h, cells along x y z, cell_start, cell_tris);
    triangle ids in ``cell_tris`` are local to ``tris``. With ``frames`` (F, V, 3), a deforming
    mesh's, each triangle's box and the grid hold it in every frame."""
    if frames is not None:
        corners = frames[:, tris]  # (F, T, 3 corners, 3)
        tlo = corners.min(axis=(0, 2))
        thi = corners.max(axis=(0, 2))
        verts = frames.reshape(-1, 3)
        lo = verts.min(axis=0)
        hi = verts.max(axis=0)
    else:
        lo = verts.min(axis=0)
        hi = verts.max(axis=0)
        tlo = np.minimum(np.minimum(verts[tris[:, 0]], verts[tris[:, 1]]), verts[tris[:, 2]])
        thi = np.maximum(np.maximum(verts[tris[:, 0]], verts[tris[:, 1]]), verts[tris[:, 2]])
    extent = np.maximum(hi - lo, 0.0)
    h = float(np.mean((thi - tlo).max(axis=1))) + margin
    if not h > 0.0:
        h = max(float(extent.max()), 1e-9)
    limit = MAX_CELLS_PER_TRIANGLE * tris.shape[0] + 64
    while True:
        n = np.maximum(np.ceil(extent / h).astype(np.int64), 1)
        if int(np.prod(n)) <= limit:
            break
        h *= 1.25
    inv_h = 1.0 / h
    grow = margin + LISTING_SLACK * (margin + float(np.abs(verts).max()))

    def cell(x: np.ndarray) -> np.ndarray:
        return np.clip(np.floor((x - lo) * inv_h).astype(np.int64), 0, n - 1)

    c0 = cell(tlo - grow)
    c1 = cell(thi + grow)
    span = c1 - c0 + 1
    count = np.prod(span, axis=1)
    ids = np.repeat(np.arange(tris.shape[0], dtype=np.int64), count)
    # the k-th cell of a triangle's block, k = 0..count-1, as offsets along x, y, z
    k = np.arange(ids.size, dtype=np.int64) - np.repeat(np.cumsum(count) - count, count)
    sx = span[ids, 0]
    sy = span[ids, 1]
    ox = k % sx
    oy = (k // sx) % sy
    oz = k // (sx * sy)
    flat = ((c0[ids, 2] + oz) * n[1] + (c0[ids, 1] + oy)) * n[0] + (c0[ids, 0] + ox)
    order = np.argsort(flat, kind="stable")
    cell_tris = ids[order]
    start = np.zeros(int(np.prod(n)) + 1, dtype=np.int64)
    np.add.at(start, flat + 1, 1)
    return lo, hi, inv_h, (int(n[0]), int(n[1]), int(n[2])), np.cumsum(start), cell_tris


def mesh_group(scene: Scene, clock: np.ndarray | None = None, dt: float = 0.0) -> MeshGroup | None:
    """The scene's meshes packed for the kernels, or None when it has none; ``clock`` and ``dt``
    are the simulation's clock and substep length (none: a group whose meshes never move)."""
    if not scene.meshes:
        return None
    verts, tris, fnorm, enorm, vnorm, starts, cells = ([] for _ in range(7))
    info = np.zeros((len(scene.meshes), 11))
    n_points = scene.cloth.num_points
    thickness = scene.cloth.thickness
    dims = np.zeros((len(scene.meshes), 7), dtype=np.int64)
    pose = np.zeros((len(scene.meshes), 6))
    here = np.empty(3)
    nv = nt = nc = 0
    deforming: list[tuple] = []  # mesh, placed frames, first vertex, triangle, grid entry, fps, loop
    for m, spec in enumerate(scene.meshes):
        v = spec.local_vertices()
        t = spec.triangles
        fn, en, vn = pseudo_normals(v, t)
        frames = None
        if spec.sequence is not None:
            frames = spec.local_frames()
            v = spec.sequence.at(frames, 0.0)
            fn, en, vn = pseudo_normals(v, t)
            deforming.append((m, frames, nv, nt, sum(c.size for c in cells), spec.sequence.fps, spec.sequence.loop))
        lo, hi, inv_h, n, start, cell_tris = build_grid(v, t, thickness, frames)
        track = spec.track()
        info[m, INFO_LO:INFO_LO + 3] = lo
        info[m, INFO_HI:INFO_HI + 3] = hi
        info[m, INFO_INV_H] = inv_h
        info[m, INFO_FRICTION] = spec.friction
        info[m, INFO_MARGIN] = thickness
        info[m, INFO_NEAR] = NEAR_REACH * thickness
        # the list is used only where the rounding of both sides' sums cannot matter
        info[m, INFO_NEAR_OK] = info[m, INFO_NEAR] - LISTING_SLACK * (info[m, INFO_NEAR] + float(np.abs(v).max()))
        dims[m] = (nt, nt + t.shape[0], nc, *n, int(spec.closed))
        # where it stands at time 0 (a static mesh stays there), by the kernels' own evaluation
        track_at(track.times, track.points, track.velocity, 0.0, here)
        pose[m, :3] = here
        pose[m, 3:] = here
        verts.append(v)
        tris.append(t + nv)
        fnorm.append(fn)
        enorm.append(en)
        vnorm.append(vn)
        starts.append(start[:-1] + sum(c.size for c in cells))
        cells.append(cell_tris + nt)
        nv += v.shape[0]
        nt += t.shape[0]
        nc += start.size - 1
    cell_start = np.concatenate([*starts, [sum(c.size for c in cells)]]).astype(np.int64)
    all_verts = np.ascontiguousarray(np.concatenate(verts))
    all_tris = np.ascontiguousarray(np.concatenate(tris))
    corners = all_verts[all_tris]  # (T, 3, 3)
    tbox = np.ascontiguousarray(np.concatenate([corners.min(axis=1), corners.max(axis=1)], axis=1))
    cell_tris = np.ascontiguousarray(np.concatenate(cells))
    all_fnorm = np.ascontiguousarray(np.concatenate(fnorm))
    deform = None
    moving = scene.meshes
    if deforming and clock is not None:
        deform = _pack_deform(deforming, dims, all_verts, all_tris, cell_start, len(scene.meshes))
        # a deforming mesh is posed every substep: one that does not move gets a track held at its
        # translation, so that the group's tracks (its clock and substep length) exist
        moving = tuple(spec if spec.motion is not None or spec.sequence is None
                       else dataclasses.replace(spec, motion=MotionSpec(keyframes=((0.0, spec.translate),)))
                       for spec in scene.meshes)
    return MeshGroup(all_verts, all_tris, tbox,
                     all_fnorm, np.ascontiguousarray(np.concatenate(enorm)),
                     np.ascontiguousarray(np.concatenate(vnorm)), info, dims, cell_start,
                     cell_tris, np.ascontiguousarray(tbox[cell_tris]), np.full((len(scene.meshes), n_points, 3), np.inf),
                     np.full((len(scene.meshes), n_points), -1, dtype=np.int64),
                     np.zeros((len(scene.meshes), n_points, NEAR_ROOM), dtype=np.int32),
                     np.zeros((len(scene.meshes), n_points, NEAR_D_WIDTH)), np.zeros((len(scene.meshes), n_points, 3)),
                     np.full((len(scene.meshes), n_points), np.inf),
                     np.zeros((len(scene.meshes), n_points, NEAR_PLANES, PLANE_WIDTH)),
                     pose, float(thickness),
                     np.zeros(len(scene.meshes), dtype=np.bool_),
                     None if clock is None else pack_tracks(moving, clock, dt),
                     None if clock is None else pack_turns(moving, width=18), deform)


def _pack_deform(deforming: list, dims: np.ndarray, verts: np.ndarray, tris: np.ndarray, cell_start: np.ndarray,
                 meshes: int) -> Deform:
    """The :class:`~.meshdeform.Deform` of the deforming meshes (mesh row, placed frames, first
    vertex, first triangle, first entry of its cells in the grid, fps, loop)."""
    table = np.zeros((len(deforming), ROW_WIDTH), dtype=np.int64)
    rate = np.zeros((len(deforming), 2))
    which = np.full(meshes, -1, dtype=np.int64)
    rows = 0
    for r, (m, frames, v0, t0, e0, fps, loop) in enumerate(deforming):
        rate[r] = (fps, 1.0 if loop else 0.0)
        count, n = frames.shape[0], frames.shape[1]
        cells = int(np.prod(dims[m, DIMS_N:DIMS_N + 3]))
        e1 = int(cell_start[dims[m, DIMS_CELL0] + cells])
        table[r] = (m, v0, v0 + n, rows, count, t0, dims[m, DIMS_TRI1], e0, e1)
        rows += count * n
        which[m] = r
    seq = [spec_frames for _, spec_frames, *_ in deforming]
    return Deform(np.ascontiguousarray(np.concatenate([f.reshape(-1, 3) for f in seq])), table, rate, which,
                  verts.copy(), edge_mates(tris), np.zeros(meshes))


def cells_per_mesh(group: MeshGroup) -> list[int]:
    """Number of grid cells of each mesh (for reports)."""
    return [int(math.prod(int(x) for x in row[DIMS_N:DIMS_N + 3])) for row in group.dims]
