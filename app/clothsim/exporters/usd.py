"""A USD stage (``.usd``, ``.usda``, ``.usdc``) through Pixar's ``usd-core`` (the ``usd`` extra).

Layout of the stage (default prim ``/World``, Y up, 1 metre per unit, time code = exported
frame number, ``timeCodesPerSecond`` = ``framesPerSecond`` = the export's frame rate: the scene's
frames_per_sec unless resampled; ``startTimeCode``/``endTimeCode`` the first and last frame)::

    /World                    Xform
    /World/cloth              Mesh: the cloth's triangles over its points; points/normals/extent
                              time-sampled at every exported frame (normals per point); primvars:st
                              per point (``vertex``) where render vertices are the points, else
                              ``faceVarying`` and indexed (values per render vertex, an index per
                              triangle corner)
    /World/colliders/sphere_0 Sphere: radius, xformOp:translate, extent
    /World/colliders/plane_0  Mesh: one large quad
    /World/colliders/capsule_0, box_0, mesh_0   Mesh: triangles
    a moving collider: xformOp:translate time-sampled at every exported frame (a sphere's
    translate is its origin; a mesh's is its offset from the scene pose its points are written in),
    or xformOp:transform for one that turns; a deforming mesh (an OBJ sequence or a USD with time
    samples): its points, normals and extent time-sampled at every exported frame as well

The stage is built in memory and exported once at the end to the atomic output's temporary
file; ``.usd`` is written in the binary crate format, as usd-core does by default.
"""

from __future__ import annotations

from pathlib import Path
from typing import Any

import numpy as np

from ..version import __version__
from ..errors import ClothsimError
from .geometry import ClothGeometry, Collider, MeshData

SUFFIXES = (".usd", ".usda", ".usdc")
INSTALL_HINT = "pip install 'clothsim[usd]'"


def import_pxr(label: str, suffix: str) -> Any:
    """``pxr`` (Usd, UsdGeom, Sdf, Vt, Gf), or one error line naming the extra that provides it."""
    try:
        from pxr import Gf, Sdf, Usd, UsdGeom, Vt
    except ImportError:
        raise ClothsimError(f"{label}: writing {suffix} needs the 'usd' extra (usd-core): {INSTALL_HINT}") from None
    return Usd, UsdGeom, Sdf, Vt, Gf


class UsdStageWriter:
    """Collects the frames on an in-memory stage and exports it to ``path`` in :meth:`finish`."""

    def __init__(self, path: Path, label: str, cloth: ClothGeometry, colliders: list[Collider], doc: str) -> None:
        self.path = Path(path)
        self.label = label
        self.Usd, self.UsdGeom, self.Sdf, self.Vt, self.Gf = import_pxr(label, self.path.suffix)
        Usd, UsdGeom = self.Usd, self.UsdGeom
        self.stage = Usd.Stage.CreateInMemory()
        self.stage.GetRootLayer().documentation = doc
        world = UsdGeom.Xform.Define(self.stage, "/World")
        self.stage.SetDefaultPrim(world.GetPrim())
        UsdGeom.SetStageUpAxis(self.stage, UsdGeom.Tokens.y)
        UsdGeom.SetStageMetersPerUnit(self.stage, 1.0)
        if cloth.shared:
            self.cloth = self._mesh("/World/cloth", cloth.faces, cloth.uvs)
        else:
            self.cloth = self._mesh("/World/cloth", cloth.faces, cloth.uvs, cloth.uv_faces)
        self.cloth.CreateDoubleSidedAttr(True)  # a cloth is seen from both sides
        self.cloth.SetNormalsInterpolation(UsdGeom.Tokens.vertex)
        if colliders:
            UsdGeom.Scope.Define(self.stage, "/World/colliders")
        #: (collider, its translate op, where the op puts it at offset 0) of the moving colliders
        self._moving: list[tuple[Collider, Any, np.ndarray]] = []
        #: (collider, its Mesh prim) of the deforming meshes
        self._deforming: list[tuple[Collider, Any]] = []
        for collider in colliders:
            self._collider(f"/World/colliders/{collider.name}", collider)

    def _mesh(self, path: str, faces: np.ndarray, uvs: np.ndarray, uv_faces: np.ndarray | None = None) -> Any:
        """A Mesh of ``faces``; ``st`` per vertex, or with ``uv_faces`` (render vertices that are
        not the points) face-varying, indexed: the values ``uvs`` and an index per corner."""
        UsdGeom, Sdf, Vt = self.UsdGeom, self.Sdf, self.Vt
        mesh = UsdGeom.Mesh.Define(self.stage, path)
        mesh.CreateSubdivisionSchemeAttr(UsdGeom.Tokens.none)  # polygons as they are, not a subdivision cage
        n, k = faces.shape
        mesh.CreateFaceVertexCountsAttr(Vt.IntArray.FromNumpy(np.full(n, k, dtype=np.int32)))
        mesh.CreateFaceVertexIndicesAttr(Vt.IntArray.FromNumpy(np.ascontiguousarray(faces.ravel(), dtype=np.int32)))
        st = UsdGeom.PrimvarsAPI(mesh.GetPrim()).CreatePrimvar(
            "st", Sdf.ValueTypeNames.TexCoord2fArray,
            UsdGeom.Tokens.vertex if uv_faces is None else UsdGeom.Tokens.faceVarying)
        st.Set(Vt.Vec2fArray.FromNumpy(np.ascontiguousarray(uvs, dtype=np.float32)))
        if uv_faces is not None:
            st.SetIndices(Vt.IntArray.FromNumpy(np.ascontiguousarray(uv_faces.ravel(), dtype=np.int32)))
        return mesh

    def _collider(self, path: str, collider: Collider) -> None:
        UsdGeom, Gf, Vt = self.UsdGeom, self.Gf, self.Vt
        if collider.sphere is not None:
            (cx, cy, cz), radius = collider.sphere
            sphere = UsdGeom.Sphere.Define(self.stage, path)
            sphere.CreateRadiusAttr(radius)
            sphere.CreateExtentAttr(Vt.Vec3fArray([Gf.Vec3f(-radius, -radius, -radius), Gf.Vec3f(radius, radius, radius)]))
            op = sphere.AddTranslateOp()
            if collider.moving is None:
                op.Set(Gf.Vec3d(cx, cy, cz))
            else:
                self._moving.append((collider, op, np.array([cx, cy, cz])))
            return
        mesh_data: MeshData = collider.mesh
        mesh = self._mesh(path, mesh_data.faces, mesh_data.uvs)
        mesh.CreatePointsAttr(self._vec3f(mesh_data.points))
        mesh.CreateNormalsAttr(self._vec3f(mesh_data.normals))
        mesh.SetNormalsInterpolation(UsdGeom.Tokens.vertex)
        mesh.CreateExtentAttr(self._extent(mesh_data.points))
        if collider.deforming is not None:
            self._deforming.append((collider, mesh))
        if collider.moving is not None:
            # a turning collider: a matrix op of its placement (x -> p + Q (x - anchor))
            self._moving.append((collider, mesh.AddTransformOp() if collider.turns else mesh.AddTranslateOp(),
                                 np.zeros(3)))

    def _vec3f(self, values: np.ndarray) -> Any:
        return self.Vt.Vec3fArray.FromNumpy(np.ascontiguousarray(values, dtype=np.float32))

    def _extent(self, points: np.ndarray) -> Any:
        points = np.asarray(points, dtype=np.float32)
        return self._vec3f(np.stack([points.min(axis=0), points.max(axis=0)]))

    def frame(self, frame: int, points: np.ndarray, normals: np.ndarray, seconds: float = 0.0) -> None:
        """Add the time samples at ``frame`` (``seconds`` into the simulation): the cloth's
        positions and normals (N, 3), float32, the moving colliders' translations (or placements) and
        the deforming meshes' points."""
        time = self.Usd.TimeCode(frame)
        self.cloth.GetPointsAttr().Set(self._vec3f(points), time)
        self.cloth.GetNormalsAttr().Set(self._vec3f(normals), time)
        self.cloth.GetExtentAttr().Set(self._extent(points), time)
        for collider, op, base in self._moving:
            if collider.turns and collider.sphere is None:
                # USD's matrices act on row vectors: the transpose of the placement
                op.Set(self.Gf.Matrix4d(*(float(c) for c in collider.placement(seconds).T.ravel())), time)
            else:
                op.Set(self.Gf.Vec3d(*(float(c) for c in base + collider.offset(seconds))), time)
        for collider, mesh in self._deforming:
            shape = collider.shape(seconds)
            mesh.GetPointsAttr().Set(self._vec3f(shape.points), time)
            mesh.GetNormalsAttr().Set(self._vec3f(shape.normals), time)
            mesh.GetExtentAttr().Set(self._extent(shape.points), time)

    def finish(self, start: int, end: int, fps: float) -> None:
        """Set the time range and rate, and write the stage to the path given at construction."""
        self.stage.SetStartTimeCode(start)
        self.stage.SetEndTimeCode(end)
        self.stage.SetTimeCodesPerSecond(fps)
        self.stage.SetFramesPerSecond(fps)
        if not self.stage.GetRootLayer().Export(str(self.path)):
            raise ClothsimError(f"{self.label}: cannot write: USD could not export the stage")


def stage_doc(scene_name: str) -> str:
    """The stage's documentation string: what wrote it and from which scene (no date, no path)."""
    return f"clothsim {__version__}: cloth simulated from {scene_name}"
