"""What an exported file holds, independent of the format: the cloth's mesh and the colliders.

The cloth's topology, texture coordinates and per-vertex normals are the renderer's
(:mod:`clothsim.render.mesh`): the grid's two triangles per quad, u along the x index and v along
the y index, and area-weighted normals from the same compiled kernel. Nothing here loads OpenGL.

Colliders become :class:`Collider` records. Each kind of collider is one function in
:data:`COLLIDER_KINDS` that turns a scene into records; a writer handles every record through its
polygon mesh (world space) and may write a primitive it knows natively instead (a USD sphere).
Another kind of collider is one more function in that tuple. A collider with a ``motion`` keeps
its scene pose in the record and its spec in ``moving``: a writer translates it by
:func:`clothsim.sim.passes.colliders.moving.shift` at each exported frame's time.
"""

from __future__ import annotations

from collections.abc import Callable, Iterator
from dataclasses import dataclass
from typing import Any

import numpy as np

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


class ClothNormals:
    """Per-vertex unit normals of the cloth, computed by the renderer's kernel (area-weighted)."""

    def __init__(self, nw: int, nh: int) -> None:
        self.nw = nw
        self.nh = nh
        self._vertices = np.zeros((nw * nh, render_mesh.CLOTH_FLOATS), dtype=np.float32)

    def __call__(self, positions: np.ndarray) -> np.ndarray:
        """Normals (N, 3) float32 for positions (N, 3): a new array."""
        render_mesh.update_cloth_vertices(np.ascontiguousarray(positions, dtype=np.float64),
                                          self.nw, self.nh, False, self._vertices)
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
        yield Collider(f"mesh_{k}", mesh, moving=spec if spec.motion is not None else None)


#: The exported geometry of each kind of collider (:data:`clothsim.colliders.KINDS`), by its key.
COLLIDER_KINDS: dict[str, Callable[[Scene], Iterator[Collider]]] = {
    "sphere": _spheres, "plane": _planes, "capsule": _capsules, "box": _boxes, "mesh": _meshes}


def colliders(scene: Scene) -> list[Collider]:
    """Every collider of ``scene``, kind by kind in the registry's order."""
    return [c for kind in KINDS for c in COLLIDER_KINDS[kind.key](scene)]
