"""What the renderer draws a cloth from: the grid's render mesh, or a mesh cloth's surface.

A grid cloth (``nw`` x ``nh`` points) is drawn as it always was: one render vertex per point,
:func:`~.mesh.update_cloth_vertices` over the grid. A mesh cloth (``nw = nh = 0``) is drawn from
its :class:`~clothsim.cloth.Surface`: one render vertex per (point, uv) pair, so a UV seam splits a
point into several render vertices that share its position and normal but keep their own uvs
and tangents (:func:`~.mesh.update_surface_vertices`). This module turns either into the static
arrays the GL buffers hold (uvs, triangle indices) and fills the per-frame vertex stream.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

import numpy as np

from ..errors import ClothsimError
from . import mesh

__all__ = ["ClothGeometry", "drawn_surface", "grid_geometry", "surface_geometry", "surface_name"]


def drawn_surface(state: Any) -> Any:
    """The :class:`~clothsim.cloth.Surface` to draw ``state``'s cloth from, or None for a grid.

    A mesh cloth has no grid (``nw = nh = 0``); its surface is the state's ``surface`` (a
    ``Simulation`` computes it once), else the scene's cloth's."""
    if state.nw > 0 and state.nh > 0:
        return None
    surface = getattr(state, "surface", None)
    if surface is None:
        from ..cloth import cloth_surface

        surface = cloth_surface(state.scene.cloth)
    return surface


def surface_name(cloth: Any) -> str:
    """How a warning names a mesh cloth: its OBJ file where the spec knows it."""
    obj = getattr(cloth, "mesh", None)
    for attr in ("path", "file"):
        where = getattr(obj, attr, None)
        if where:
            return str(where)
    return "the cloth mesh"


@dataclass(frozen=True)
class ClothGeometry:
    """The cloth's render mesh: ``uvs`` (R, 2) float32 and ``triangles`` (3T,) uint32 over R render
    vertices; ``surface`` None for a grid. ``point_vertex`` (N,) int64 is one render vertex of
    each simulated point (-1: none), through which the wireframe draws springs between points;
    None where render vertex k is point k (a grid)."""

    nw: int
    nh: int
    surface: Any
    uvs: np.ndarray
    triangles: np.ndarray
    point_vertex: np.ndarray | None
    # the surface kernel's arguments, converted once
    _tris: np.ndarray | None = None
    _uv_point: np.ndarray | None = None
    _uvs: np.ndarray | None = None
    _uv_tris: np.ndarray | None = None

    @property
    def vertex_count(self) -> int:
        """R: rows of the vertex stream."""
        return int(self.uvs.shape[0])

    def fits(self, nw: int, nh: int, surface: Any) -> bool:
        """Whether this is the geometry of a grid of ``nw`` x ``nh`` or of ``surface`` (the object)."""
        if surface is None:
            return self.surface is None and (self.nw, self.nh) == (nw, nh)
        return self.surface is surface

    def fill(self, positions: np.ndarray, with_tangents: bool, out: np.ndarray) -> None:
        """Write the frame's positions, normals and (``with_tangents``) tangents into ``out``
        (R, 9) float32 from the points' ``positions`` (N, 3) float64, C-contiguous."""
        if self.surface is None:
            mesh.update_cloth_vertices(positions, self.nw, self.nh, with_tangents, out)
        else:
            mesh.update_surface_vertices(positions, self._tris, self._uv_point, self._uvs, self._uv_tris,
                                         with_tangents, out)

    def per_vertex(self, values: np.ndarray) -> np.ndarray:
        """Per-point ``values`` (N, k) as per-render-vertex rows (R, k) (the same array for a grid)."""
        return values if self._uv_point is None else values[self._uv_point]


def grid_geometry(nw: int, nh: int) -> ClothGeometry:
    """The render mesh of an ``nw`` x ``nh`` grid (its points are its render vertices)."""
    return ClothGeometry(nw=nw, nh=nh, surface=None, uvs=mesh.cloth_uvs(nw, nh),
                         triangles=mesh.cloth_triangles(nw, nh), point_vertex=None)


def surface_geometry(surface: Any, points: int) -> ClothGeometry:
    """The render mesh of a mesh cloth's ``surface`` over ``points`` simulated points; a surface
    whose arrays disagree (they index out of range, or their shapes differ) is refused with one
    line naming the field, before a kernel could read outside them."""
    tris = _index_array(surface.triangles, "triangles", 2)
    uv_point = _index_array(surface.uv_point, "uv_point", 1)
    uv_tris = _index_array(surface.uv_triangles, "uv_triangles", 2)
    uvs = np.asarray(surface.uvs)
    vertices = uv_point.shape[0]
    if uvs.ndim != 2 or uvs.shape != (vertices, 2):
        raise ClothsimError(f"cloth surface: uvs has shape {uvs.shape}, expected ({vertices}, 2) "
                            "(one per render vertex)")
    if tris.shape[1:] != (3,) or uv_tris.shape != tris.shape:
        raise ClothsimError(f"cloth surface: triangles {tris.shape} and uv_triangles {uv_tris.shape} must both be "
                            "(T, 3), the same triangles")
    _in_range(tris, points, "triangles", "points")
    _in_range(uv_point, points, "uv_point", "points")
    _in_range(uv_tris, vertices, "uv_triangles", "render vertices")
    if not np.array_equal(uv_point[uv_tris], tris):
        raise ClothsimError("cloth surface: uv_triangles do not map to triangles through uv_point")
    point_vertex = np.full(points, -1, dtype=np.int64)
    order = np.arange(vertices, dtype=np.int64)
    point_vertex[uv_point[::-1]] = order[::-1]  # the first render vertex of each point
    return ClothGeometry(nw=0, nh=0, surface=surface, uvs=np.ascontiguousarray(uvs, dtype=np.float32),
                         triangles=np.ascontiguousarray(uv_tris.ravel().astype(np.uint32)),
                         point_vertex=point_vertex, _tris=tris, _uv_point=uv_point,
                         _uvs=np.ascontiguousarray(uvs, dtype=np.float64), _uv_tris=uv_tris)


def _index_array(values: Any, field: str, ndim: int) -> np.ndarray:
    a = np.asarray(values)
    if a.ndim != ndim or (a.size and a.dtype.kind not in "iu"):
        raise ClothsimError(f"cloth surface: {field} must be a {ndim}-D integer array, got {a.dtype} "
                            f"of shape {a.shape}")
    return np.ascontiguousarray(a, dtype=np.int64)


def _in_range(a: np.ndarray, size: int, field: str, what: str) -> None:
    if a.size and (int(a.min()) < 0 or int(a.max()) >= size):
        bad = int(a.min()) if int(a.min()) < 0 else int(a.max())
        raise ClothsimError(f"cloth surface: {field} holds {bad}, outside the {size} {what}")
