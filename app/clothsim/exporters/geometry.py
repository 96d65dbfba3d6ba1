"""What an exported file holds, independent of the format: the cloth's mesh and the colliders.

The cloth is written from its surface (:func:`clothsim.cloth.cloth_surface`, as
:class:`ClothGeometry`): its triangles over the simulated points, and its texture coordinates over
render vertices (R >= N: a point on a UV seam has one render vertex per side). A grid cloth's
surface is the renderer's (:mod:`clothsim.render.mesh`): two triangles per quad, u along the x index
and v along the y index, one render vertex per point, and its area-weighted normals come from the
renderer's compiled kernel, so its files are what they were before mesh cloths existed. Any other
cloth's normals are area-weighted per point here (:func:`point_normals`). Nothing here loads OpenGL.

Colliders become :class:`Collider` records. Each kind of collider is one function in
:data:`COLLIDER_KINDS` that turns a scene into records; a writer handles every record through its
polygon mesh (world space) and may write a primitive it knows natively instead (a USD sphere).
Another kind of collider is one more function in that tuple. A collider with a ``motion`` keeps
its scene pose in the record and its spec in ``moving``: a writer translates it by
:func:`clothsim.sim.passes.colliders.moving.shift` at each exported frame's time.
"""

from __future__ import annotations

from collections.abc import Callable, Iterator
from dataclasses import dataclass, replace
from typing import Any

import numpy as np

from ..errors import ClothsimError
from ..render import mesh as render_mesh
from ..colliders import KINDS
from ..scene import Scene
from ..sim.passes.colliders.moving import placement, shift

#: Rings and segments of a sphere written as polygons (the renderer's default resolution).
SPHERE_RESOLUTION = (40, 40)
#: Half the side of the square written for a plane, in metres (the renderer draws the same quad).
PLANE_HALF_EXTENT = 2.0


@dataclass(frozen=True)
class MeshData:
    """A polygon mesh whose faces all have the same number of corners.

    ``points`` (V, 3) and ``normals`` (V, 3) float32, ``uvs`` (V, 2) float32, all per vertex;
    ``faces`` (F, k) int64 indices into them, counter-clockwise seen from the front.
    """

    points: np.ndarray
    normals: np.ndarray
    uvs: np.ndarray
    faces: np.ndarray


@dataclass(frozen=True)
class Collider:
    """One collider as exported: a unique ``name`` (``sphere_0``), its polygons, and optionally
    the parameters of a primitive shape (``sphere``: centre and radius) for formats that have it."""

    name: str
    mesh: MeshData
    sphere: tuple[tuple[float, float, float], float] | None = None
    moving: Any = None
    #: a deforming mesh's spec (its ``sequence`` set); ``mesh`` is then its shape at time 0
    deforming: Any = None

    @property
    def animated(self) -> bool:
        """Whether the collider changes from frame to frame: it moves, or its mesh deforms."""
        return self.moving is not None or self.deforming is not None

    def shape(self, t: float) -> MeshData:
        """The polygons at time ``t`` (s) before the motion: a deforming mesh's shape then (at
        its scene pose, its normals its faces'), else :attr:`mesh`."""
        if self.deforming is None:
            return self.mesh
        from ..render.facets import mesh_collider_vertices

        verts, _ = mesh_collider_vertices(self.deforming, t)
        points = (verts[:, 0:3].astype(np.float64) + np.asarray(self.deforming.translate, dtype=np.float64))
        return replace(self.mesh, points=points.astype(np.float32), normals=np.ascontiguousarray(verts[:, 3:6]))

    def offset(self, t: float) -> np.ndarray:
        """How far the collider has moved from the record's pose at time ``t`` (s), (3,)."""
        return np.zeros(3) if self.moving is None else shift(self.moving, t)

    @property
    def turns(self) -> bool:
        """Whether the collider's motion turns it (then :meth:`placement`, not :meth:`offset`)."""
        return self.moving is not None and self.moving.motion.turns

    def placement(self, t: float) -> np.ndarray:
        """(4, 4) the map from the record's pose to the collider's pose at time ``t`` (s)."""
        return np.eye(4) if self.moving is None else placement(self.moving, t)


# -- cloth ---------------------------------------------------------------------------------------
def cloth_faces(nw: int, nh: int) -> np.ndarray:
    """The grid's triangles as (T, 3) int64: the renderer's index buffer, three by three."""
    return render_mesh.cloth_triangles(nw, nh).astype(np.int64).reshape(-1, 3)


def cloth_uvs(nw: int, nh: int) -> np.ndarray:
    """Per-vertex texture coordinates (N, 2) float32, as the renderer uses them."""
    return render_mesh.cloth_uvs(nw, nh)


@dataclass(frozen=True)
class ClothGeometry:
    """The cloth as written, whatever its kind.

    ``faces`` (T, 3) int64 point indices; ``uvs`` (R, 2) float32 per render vertex, ``uv_faces``
    (T, 3) int64 the same triangles over render vertices and ``uv_point`` (R,) int64 each render
    vertex's point. ``shared`` is true when render vertices are the points (R = N, the same
    triangles): then texture coordinates are written per point, as a grid's always were.
    ``nw``/``nh`` are the grid's size (0 for a mesh cloth).
    """

    faces: np.ndarray
    uvs: np.ndarray
    uv_faces: np.ndarray
    uv_point: np.ndarray
    points: int
    nw: int = 0
    nh: int = 0

    @property
    def shared(self) -> bool:
        return (len(self.uv_point) == self.points and np.array_equal(self.uv_point, np.arange(self.points))
                and np.array_equal(self.uv_faces, self.faces))

    @property
    def grid(self) -> bool:
        """Whether this is an nw x nh grid's own surface (its normals come from the renderer's kernel)."""
        return self.nw > 0 and self.nh > 0 and self.points == self.nw * self.nh


def grid_geometry(nw: int, nh: int) -> ClothGeometry:
    """The surface of an nw x nh grid cloth."""
    faces = cloth_faces(nw, nh)
    return ClothGeometry(faces=faces, uvs=cloth_uvs(nw, nh), uv_faces=faces, uv_point=np.arange(nw * nh, dtype=np.int64),
                         points=nw * nh, nw=nw, nh=nh)


def cloth_geometry(sim: Any) -> ClothGeometry:
    """The geometry a :class:`~clothsim.Simulation`'s cloth is written with.

    It comes from the cloth's ``Surface`` (``sim.surface``); a grid's surface holds exactly the
    arrays of :func:`grid_geometry`, written as before mesh cloths existed.
    """
    nw, nh = int(sim.nw), int(sim.nh)
    n = int(sim.positions.shape[0])
    is_grid = nw > 0 and nh > 0 and nw * nh == n
    surface = getattr(sim, "surface", None)
    if surface is None and is_grid:  # a simulation without a surface of its own: the grid's
        return grid_geometry(nw, nh)
    geometry = surface_geometry(surface, n)
    return replace(geometry, nw=nw, nh=nh) if is_grid else geometry


def surface_geometry(surface: Any, points: int) -> ClothGeometry:
    """A :class:`ClothGeometry` from a ``Surface`` (:func:`clothsim.cloth.cloth_surface`) of
    ``points`` simulated points; one line naming what is wrong if its arrays do not fit."""
    faces = np.ascontiguousarray(surface.triangles, dtype=np.int64).reshape(-1, 3)
    uv_faces = np.ascontiguousarray(surface.uv_triangles, dtype=np.int64).reshape(-1, 3)
    uv_point = np.ascontiguousarray(surface.uv_point, dtype=np.int64).ravel()
    uvs = np.ascontiguousarray(surface.uvs, dtype=np.float32).reshape(-1, 2)
    if faces.size and (faces.min() < 0 or faces.max() >= points):
        raise ClothsimError(f"cloth surface: a triangle names a point outside 0..{points - 1}")
    if uv_faces.shape != faces.shape:
        raise ClothsimError(f"cloth surface: {len(uv_faces)} UV triangles for {len(faces)} triangles")
    if len(uv_point) != len(uvs) or (uv_point.size and (uv_point.min() < 0 or uv_point.max() >= points)):
        raise ClothsimError("cloth surface: uv_point does not map each render vertex to a point")
    if uv_faces.size and (uv_faces.min() < 0 or uv_faces.max() >= len(uvs)):
        raise ClothsimError(f"cloth surface: a UV triangle names a render vertex outside 0..{len(uvs) - 1}")
    if not np.array_equal(uv_point[uv_faces], faces):
        raise ClothsimError("cloth surface: a UV triangle's corners are not its triangle's points")
    return ClothGeometry(faces=faces, uvs=uvs, uv_faces=uv_faces, uv_point=uv_point, points=points)


def point_normals(positions: np.ndarray, faces: np.ndarray) -> np.ndarray:
    """Unit normals (N, 3) float32 per point, area-weighted as the renderer's kernel does:
    each triangle adds its unnormalised cross product to its three corners; a point with a zero
    sum (no triangle, or only degenerate ones) gets +y."""
    p = np.asarray(positions, dtype=np.float64)
    a, b, c = p[faces[:, 0]], p[faces[:, 1]], p[faces[:, 2]]
    cross = np.cross(b - a, c - a)
    n = len(p)
    acc = np.zeros((n, 3))
    for k in range(3):  # three columns of corners, each one scatter over every triangle
        idx = faces[:, k]
        for axis in range(3):
            acc[:, axis] += np.bincount(idx, weights=cross[:, axis], minlength=n)
    length = np.sqrt(np.einsum("ij,ij->i", acc, acc))
    out = np.zeros((n, 3))
    out[:, 1] = 1.0
    ok = length > 0.0
    out[ok] = acc[ok] / length[ok, None]
    return out.astype(np.float32)


class ClothNormals:
    """Per-point unit normals of the cloth (area-weighted): a grid's from the renderer's kernel,
    any other cloth's from :func:`point_normals`."""

    def __init__(self, geometry: ClothGeometry) -> None:
        self.geometry = geometry
        if geometry.grid:
            self._vertices = np.zeros((geometry.points, render_mesh.CLOTH_FLOATS), dtype=np.float32)

    def __call__(self, positions: np.ndarray) -> np.ndarray:
        """Normals (N, 3) float32 for positions (N, 3): a new array."""
        g = self.geometry
        if not g.grid:
            return point_normals(positions, g.faces)
        render_mesh.update_cloth_vertices(np.ascontiguousarray(positions, dtype=np.float64),
                                          g.nw, g.nh, False, self._vertices)
        return self._vertices[:, 3:6].copy()


# -- colliders -----------------------------------------------------------------------------------
def _spheres(scene: Scene) -> Iterator[Collider]:
    verts, idx = render_mesh.sphere_mesh(*SPHERE_RESOLUTION)  # a unit sphere
    for k, sphere in enumerate(scene.spheres):
        centre = np.asarray(sphere.origin, dtype=np.float64)
        points = (verts[:, 0:3].astype(np.float64) * sphere.radius + centre).astype(np.float32)
        mesh = MeshData(points=points, normals=np.ascontiguousarray(verts[:, 3:6]),
                        uvs=np.ascontiguousarray(verts[:, 9:11]), faces=idx.astype(np.int64).reshape(-1, 3))
        yield Collider(f"sphere_{k}", mesh, sphere=(tuple(float(c) for c in sphere.origin), float(sphere.radius)),
                       moving=sphere if sphere.motion is not None else None)


def _planes(scene: Scene) -> Iterator[Collider]:
    for k, plane in enumerate(scene.planes):
        verts, _ = render_mesh.plane_mesh(plane.point, plane.normal, half_extent=PLANE_HALF_EXTENT)
        # plane_mesh's corners go round the square counter-clockwise seen from the normal's side.
        mesh = MeshData(points=np.ascontiguousarray(verts[:, 0:3]), normals=np.ascontiguousarray(verts[:, 3:6]),
                        uvs=np.ascontiguousarray(verts[:, 9:11]), faces=np.array([[0, 1, 2, 3]], dtype=np.int64))
        yield Collider(f"plane_{k}", mesh, moving=plane if plane.motion is not None else None)


def _triangles(verts: np.ndarray, idx: np.ndarray) -> MeshData:
    return MeshData(points=np.ascontiguousarray(verts[:, 0:3]), normals=np.ascontiguousarray(verts[:, 3:6]),
                    uvs=np.ascontiguousarray(verts[:, 9:11]), faces=idx.astype(np.int64).reshape(-1, 3))


def _capsules(scene: Scene) -> Iterator[Collider]:
    for k, capsule in enumerate(scene.capsules):
        verts, idx = render_mesh.capsule_mesh(capsule.a, capsule.b, capsule.radius, *SPHERE_RESOLUTION)
        yield Collider(f"capsule_{k}", _triangles(verts, idx), moving=capsule if capsule.motion is not None else None)


def _boxes(scene: Scene) -> Iterator[Collider]:
    for k, box in enumerate(scene.boxes):
        verts, idx = render_mesh.box_mesh(box.center, box.half_extents, box.matrix())
        yield Collider(f"box_{k}", _triangles(verts, idx), moving=box if box.motion is not None else None)


def _meshes(scene: Scene) -> Iterator[Collider]:
    from ..render.facets import mesh_collider_vertices

    for k, spec in enumerate(scene.meshes):
        verts, idx = mesh_collider_vertices(spec)
        # At its scene pose (``translate``), like every other collider; a moving one is shifted
        # from there by its track at each exported frame.
        points = (verts[:, 0:3].astype(np.float64) + np.asarray(spec.translate, dtype=np.float64)).astype(np.float32)
        mesh = MeshData(points=points, normals=np.ascontiguousarray(verts[:, 3:6]),
                        uvs=np.ascontiguousarray(verts[:, 9:11]), faces=idx.astype(np.int64).reshape(-1, 3))
        yield Collider(f"mesh_{k}", mesh, moving=spec if spec.motion is not None else None,
                       deforming=spec if spec.sequence is not None else None)


#: The exported geometry of each kind of collider (:data:`clothsim.colliders.KINDS`), by its key.
COLLIDER_KINDS: dict[str, Callable[[Scene], Iterator[Collider]]] = {
    "sphere": _spheres, "plane": _planes, "capsule": _capsules, "box": _boxes, "mesh": _meshes}


def colliders(scene: Scene) -> list[Collider]:
    """Every collider of ``scene``, kind by kind in the registry's order."""
    return [c for kind in KINDS for c in COLLIDER_KINDS[kind.key](scene)]
