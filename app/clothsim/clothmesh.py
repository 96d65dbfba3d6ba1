"""A cloth read from an OBJ (``cloth.mesh``): its points, triangles, springs, areas and UVs.

``"cloth": {"mesh": {"path": "skirt.obj", "scale": 1, "translate": [x, y, z], "rotation":
[rx, ry, rz]}, ...}``: the keys and the placement are the mesh collider's
(:mod:`clothsim.meshcollider`): a vertex ``v`` is placed at ``R (scale v) + translate`` with
``R = Rz Ry Rx`` in degrees. The topology is built once, at load, with NumPy.

Rules:

* **Welding.** OBJ vertices whose coordinates are equal as numbers, as parsed (before placement),
  are one simulated point: exporters split a vertex where a texture seam runs through it, and the
  cloth must not tear there. Points are numbered in the order in which their position first
  appears among the ``v`` lines. The seam stays for texturing: a render vertex is a (point,
  ``vt``) pair (``uv_point``, ``uvs``, ``uv_triangles``), sorted by point then ``vt`` index.
* **Unused vertices** (no face names them, and none at the same position is named) are dropped
  from the points: ``vertex_point`` is -1 for them, and pinning one is an error.
* **Triangles**: each face as written, a polygon split as a fan from its first corner, the OBJ's
  winding kept. Neighbouring faces may be wound either way (cloth has two sides).
* **Structural springs**: one per edge of the triangulation (a quad's or polygon's fan diagonals
  included). **Shearing**: for each quad face ``(a, b, c, d)``, split into ``(a, b, c)`` and
  ``(a, c, d)``, one spring ``b``-``d`` unless that pair is a spring already. **Bending**: for
  each edge shared by exactly two triangles, one spring between the two corners opposite it,
  unless that pair is a structural, shearing or (already) bending spring. Springs are listed
  structural, then shearing, then bending, each family sorted by its ends ``(i, j)``, ``i < j``.
  Rest lengths (from ``points``) and the bending factor 0.2 are the simulator's.
* **Areas**: ``point_area`` is a third of the area of each triangle at the point, summed (placed,
  m^2): the point's mass is that times the density.
* **UVs**: the ``vt`` of each corner when every corner of every face names one; otherwise
  (``has_uvs`` False) every point gets a planar projection: onto the plane of the points' two
  largest principal axes (SVD of the centred points; each axis' largest component made positive;
  when the two largest extents are equal within 1e-9, the in-plane axes follow the world axes
  instead, so that a square sheet does not take an arbitrary direction), shifted to start at 0
  and scaled alike on both axes so that the larger extent spans [0, 1].

Refused, each with one line naming the OBJ line or vertices (the scene loader adds the scene file
and ``cloth.mesh.path``): the OBJ reader's errors (:mod:`clothsim.objfile`: no faces, an index out
of range, ...); a face that names a vertex twice, or whose corners weld into one point; a triangle
of area at most 1e-12 x the squared diagonal of the points' bounding box; an edge shared by more
than two triangles. The memory check is the scene's (:func:`clothsim.scene.check_memory`).
"""

from __future__ import annotations

import os
from dataclasses import dataclass
from typing import Any

import numpy as np

from . import validate as V
from .meshcollider import PLACEMENT, obj_file, read_checked, rotation_matrix
from .objfile import ObjError, ObjPolygons, read_obj_polygons

# The families' numbers: the same as clothsim.cloth's (that module sits above this one).
STRUCTURAL, SHEARING, BENDING = 0, 1, 2
#: A triangle of area at most this times the squared bounding-box diagonal is degenerate.
DEGENERATE_AREA = 1e-12
# Two principal extents closer than this (relative) are a tie: the in-plane axes follow the world's.
_TIE = 1e-9


@dataclass(frozen=True, eq=False)
class ClothMesh:
    """A mesh cloth's file, placement and topology (see the module's rules for each array)."""

    path: str
    file: str
    scale: float
    translate: tuple[float, float, float]
    rotation: tuple[float, float, float]
    points: np.ndarray  # (N, 3) float64 rest positions, placed
    triangles: np.ndarray  # (T, 3) int64 point indices
    spring_i: np.ndarray  # (S,) int32, spring_i < spring_j
    spring_j: np.ndarray  # (S,) int32
    spring_kind: np.ndarray  # (S,) int8
    point_area: np.ndarray  # (N,) float64, m^2
    vertex_point: np.ndarray  # (V,) int64: OBJ vertex -> point, -1 when unused
    uv_point: np.ndarray  # (R,) int64: render vertex -> point
    uvs: np.ndarray  # (R, 2) float32
    uv_triangles: np.ndarray  # (T, 3) int64 render-vertex indices
    has_uvs: bool
    lines: np.ndarray  # (T,) int64: OBJ line of each triangle's face

    def as_json(self) -> dict[str, Any]:
        """The object as a scene file writes it (the path resolved, so it loads from anywhere)."""
        return {"path": os.path.abspath(self.file), "scale": self.scale, "translate": list(self.translate),
                "rotation": list(self.rotation)}


def place(vertices: np.ndarray, scale: float, translate: tuple[float, float, float],
          rotation: tuple[float, float, float]) -> np.ndarray:
    """``(v * scale) @ R.T + translate``, the mesh collider's placement: (V, 3) float64."""
    return (vertices * scale) @ rotation_matrix(rotation).T + np.asarray(translate, dtype=np.float64)


def _fan(obj: ObjPolygons) -> tuple[np.ndarray, np.ndarray]:
    """Each triangle's face and its three corner slots (indices into ``obj.corners``)."""
    per_face = np.diff(obj.face_start) - 2
    face = np.repeat(np.arange(per_face.size, dtype=np.int64), per_face)
    first = obj.face_start[:-1][face]
    step = np.arange(face.size, dtype=np.int64) - np.repeat(np.cumsum(per_face) - per_face, per_face) + 1
    return face, np.stack([first, first + step, first + step + 1], axis=1)


def _repeated_vertex(obj: ObjPolygons) -> None:
    face = np.repeat(np.arange(obj.face_line.size, dtype=np.int64), np.diff(obj.face_start))
    key = face * (obj.vertices.shape[0] + 1) + obj.corners
    sk = np.sort(key)
    dup = np.flatnonzero(sk[1:] == sk[:-1])
    if dup.size:
        k = sk[dup[0]]
        f = int(k // (obj.vertices.shape[0] + 1))
        raise ObjError(int(obj.face_line[f]), f"degenerate face: it names vertex {int(k - f * (obj.vertices.shape[0] + 1)) + 1} twice")


def _weld(vertices: np.ndarray, used: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """``vertex_point`` (V,) and each point's first vertex (N,)."""
    count = vertices.shape[0]
    order = np.lexsort((vertices[:, 2], vertices[:, 1], vertices[:, 0]))
    sv = vertices[order]
    new = np.r_[True, np.any(sv[1:] != sv[:-1], axis=1)]
    group = np.empty(count, dtype=np.int64)
    group[order] = np.cumsum(new) - 1
    groups = int(new.sum())
    first = np.full(groups, count, dtype=np.int64)
    np.minimum.at(first, group, np.arange(count, dtype=np.int64))
    live = np.zeros(groups, dtype=np.bool_)
    live[group[used]] = True
    kept = np.flatnonzero(live)
    kept = kept[np.argsort(first[kept], kind="stable")]
    point_of = np.full(groups, -1, dtype=np.int64)
    point_of[kept] = np.arange(kept.size, dtype=np.int64)
    return point_of[group], first[kept]


def _check_triangles(tri_v: np.ndarray, triangles: np.ndarray, points: np.ndarray,
                     lines: np.ndarray) -> np.ndarray:
    """Each triangle's area; raises for a face whose corners weld together or a degenerate one."""
    same = ((triangles[:, 0] == triangles[:, 1]) | (triangles[:, 1] == triangles[:, 2])
            | (triangles[:, 0] == triangles[:, 2]))
    if same.any():
        t = int(np.flatnonzero(same)[0])
        a, b = next((tri_v[t, k], tri_v[t, m]) for k, m in ((0, 1), (1, 2), (0, 2))
                    if triangles[t, k] == triangles[t, m])
        raise ObjError(int(lines[t]), f"degenerate face: vertices {int(a) + 1} and {int(b) + 1} are at the same "
                                      f"position (welded into one point)")
    a, b, c = (points[triangles[:, k]] for k in range(3))
    area = 0.5 * np.linalg.norm(np.cross(b - a, c - a), axis=1)
    diag2 = float(np.sum((points.max(axis=0) - points.min(axis=0)) ** 2))
    bad = np.flatnonzero(~(area > DEGENERATE_AREA * diag2))
    if bad.size:
        t = int(bad[0])
        raise ObjError(int(lines[t]), f"degenerate face: a triangle of area {area[t]:.3g} m^2 (at most "
                                      f"{DEGENERATE_AREA:g} x the squared bounding-box diagonal, {diag2:.3g} m^2)")
    return area


def _edges(tri_v: np.ndarray, triangles: np.ndarray, lines: np.ndarray, n: int) -> tuple[np.ndarray, ...]:
    """The unique edges' keys (``i * n + j``, sorted) and, for each edge in exactly two triangles,
    the two corners opposite it; raises for an edge in more than two."""
    heads = triangles.reshape(-1)
    tails = triangles[:, [1, 2, 0]].reshape(-1)
    key = np.minimum(heads, tails) * n + np.maximum(heads, tails)
    order = np.argsort(key, kind="stable")
    sk = key[order]
    starts = np.flatnonzero(np.r_[True, sk[1:] != sk[:-1]])
    counts = np.diff(np.r_[starts, sk.size])
    over = np.flatnonzero(counts > 2)
    if over.size:
        s, m = starts[over[0]], int(counts[over[0]])
        t, k = divmod(int(order[s]), 3)
        shown = ", ".join(str(int(x)) for x in dict.fromkeys(lines[order[s : s + m] // 3]))
        raise ObjError(int(lines[t]), f"non-manifold: the edge between vertices {int(tri_v[t, k]) + 1} and "
                                      f"{int(tri_v[t, (k + 1) % 3]) + 1} is shared by {m} triangles (faces on "
                                      f"lines {shown}); an edge of a cloth may belong to at most 2")
    two = starts[counts == 2]
    first, second = order[two], order[two + 1]
    p = triangles[first // 3, (first % 3 + 2) % 3]
    q = triangles[second // 3, (second % 3 + 2) % 3]
    return sk[starts], p, q


def _unique(keys: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Sorted unique values and each value's index among them: by one sort (NumPy's own unique
    hashes integers first, several times slower on a mesh of 10^5 points)."""
    order = np.argsort(keys, kind="stable")
    sk = keys[order]
    new = np.ones(sk.size, dtype=np.bool_)
    new[1:] = sk[1:] != sk[:-1]
    inverse = np.empty(keys.size, dtype=np.int64)
    inverse[order] = np.cumsum(new) - 1
    return sk[new], inverse


def _pairs(a: np.ndarray, b: np.ndarray, n: int, taken: np.ndarray) -> np.ndarray:
    """Sorted unique keys ``min * n + max`` of the pairs a-b that join two different points and
    are not in ``taken`` (sorted keys)."""
    keep = a != b
    keys = _unique(np.minimum(a, b)[keep] * n + np.maximum(a, b)[keep])[0]
    if taken.size:
        at = np.minimum(np.searchsorted(taken, keys), taken.size - 1)
        keys = keys[taken[at] != keys]
    return keys


def planar_uvs(points: np.ndarray) -> np.ndarray:
    """The planar projection of the module's rules: (N, 2) float32 in [0, 1]."""
    centred = points - points.mean(axis=0)
    _, s, vt = np.linalg.svd(centred, full_matrices=False)
    axes = vt[:2].copy()
    if s[0] - s[1] <= _TIE * s[0]:
        normal = vt[2]
        # the first (x, y, z order) of the two world axes that lie most in the plane
        first = np.eye(3)[int(np.sort(np.argsort(np.abs(normal), kind="stable")[:2])[0])]
        u = first - normal * (first @ normal)
        u /= np.linalg.norm(u)
        axes = np.stack([u, np.cross(normal, u)])
    for a in axes:
        if a[np.argmax(np.abs(a))] < 0.0:
            a *= -1.0
    uv = centred @ axes.T
    uv -= uv.min(axis=0)
    return (uv / uv.max()).astype(np.float32)


def build_cloth_mesh(obj: ObjPolygons, *, path: str, file: str, scale: float,
                     translate: tuple[float, float, float], rotation: tuple[float, float, float]) -> ClothMesh:
    """The mesh cloth from an OBJ's polygons and its placement; raises :class:`~clothsim.objfile.ObjError`."""
    _repeated_vertex(obj)
    face, slot = _fan(obj)
    lines = obj.face_line[face]
    tri_v = obj.corners[slot]
    used = np.zeros(obj.vertices.shape[0], dtype=np.bool_)
    used[obj.corners] = True
    vertex_point, rep = _weld(obj.vertices, used)
    points = place(obj.vertices[rep], scale, translate, rotation)
    n = points.shape[0]
    triangles = vertex_point[tri_v]
    area = _check_triangles(tri_v, triangles, points, lines)
    structural, p, q = _edges(tri_v, triangles, lines, n)
    quad = np.flatnonzero(np.diff(obj.face_start) == 4)
    b = vertex_point[obj.corners[obj.face_start[quad] + 1]]
    d = vertex_point[obj.corners[obj.face_start[quad] + 3]]
    shearing = _pairs(b, d, n, structural)
    bending = _pairs(p, q, n, np.sort(np.concatenate([structural, shearing])))
    keys = np.concatenate([structural, shearing, bending])
    kind = np.repeat(np.array([STRUCTURAL, SHEARING, BENDING], dtype=np.int8),
                     [structural.size, shearing.size, bending.size])
    point_area = np.bincount(triangles.reshape(-1), weights=np.repeat(area / 3.0, 3), minlength=n)
    tri_uv = obj.corner_uv[slot]
    has_uvs = bool(tri_uv.size) and bool((tri_uv >= 0).all())
    if has_uvs:
        count = obj.uvs.shape[0]
        render, inverse = _unique(triangles.reshape(-1) * count + tri_uv.reshape(-1))
        uv_point, uvs = render // count, obj.uvs[render % count].astype(np.float32)
        uv_triangles = inverse.reshape(-1, 3).astype(np.int64)
    else:
        uv_point, uvs, uv_triangles = np.arange(n, dtype=np.int64), planar_uvs(points), triangles
    return ClothMesh(path=path, file=file, scale=scale, translate=translate, rotation=rotation, points=points,
                     triangles=np.ascontiguousarray(triangles, dtype=np.int64),
                     spring_i=(keys // n).astype(np.int32), spring_j=(keys % n).astype(np.int32),
                     spring_kind=kind, point_area=point_area, vertex_point=vertex_point,
                     uv_point=np.ascontiguousarray(uv_point, dtype=np.int64), uvs=np.ascontiguousarray(uvs),
                     uv_triangles=np.ascontiguousarray(uv_triangles, dtype=np.int64), has_uvs=has_uvs,
                     lines=lines)


_FIELDS = V.record(PLACEMENT)


def CLOTH_MESH(value: Any, at: V.At) -> ClothMesh:  # noqa: N802 - a rule, named like the scene's records
    """The rule for ``cloth.mesh``: the mesh collider's keys less friction and motion, then the OBJ
    read and the cloth built from it."""
    fields = _FIELDS(value, at)
    here = at.key("path")
    path = fields["path"]
    file = obj_file(here, path)
    obj = read_checked(here, path, file, read_obj_polygons)
    scale, translate, rotation = fields["scale"], fields["translate"], fields["rotation"]
    if not np.isfinite(place(obj.vertices, scale, (0.0, 0.0, 0.0), rotation) * 2.0).all():
        raise at.key("scale").fail(f"places the mesh's vertices beyond the float range (scale {scale:g})")
    try:
        return build_cloth_mesh(obj, path=path, file=str(file), scale=scale, translate=translate, rotation=rotation)
    except ObjError as exc:
        raise here.fail(f"{path}: {exc}") from None
