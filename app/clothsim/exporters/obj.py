"""An OBJ sequence: one ``cloth_NNNNN.obj`` per exported frame and ``colliders.obj``.

Every file holds ``v``, ``vt``, ``vn`` and ``f v/vt/vn`` lines (1-based indices). Where the
cloth's render vertices are its points (a grid, a mesh without UV seams) there is one texture
coordinate and one normal per vertex, so the three indices are equal; otherwise ``vt`` and ``vn``
are per render vertex (a point on a seam has one per side, its normal the point's) and ``f``
names a point and a render vertex at each corner. Coordinates are the
float32 values written with 9 significant digits, which parse back to exactly the same float32.
The text is built with one string format over whole arrays (no loop per point), and holds no
date or path, so the same scene and seed give the same bytes.
"""

from __future__ import annotations

import re
from dataclasses import replace
from pathlib import Path

import numpy as np

from ..version import __version__
from .geometry import ClothGeometry, Collider, MeshData

COLLIDERS_NAME = "colliders.obj"
_CLOTH = re.compile(r"cloth_(\d{5,})\.obj")


def cloth_name(frame: int) -> str:
    """The file name of the cloth at ``frame``: ``cloth_00012.obj``."""
    return f"cloth_{frame:05d}.obj"


def is_sequence_name(name: str) -> bool:
    """True for exactly the names an OBJ sequence is made of (:func:`cloth_name`, colliders.obj)."""
    if name == COLLIDERS_NAME:
        return True
    m = _CLOTH.fullmatch(name)
    return m is not None and name == cloth_name(int(m[1]))


def _rows(prefix: str, values: np.ndarray) -> str:
    """``PREFIX a b c`` lines for a (n, k) float32 array, each value in round-trip precision."""
    values = np.asarray(values, dtype=np.float32)
    n, k = values.shape
    line = prefix + " %.9g" * k + "\n"
    return (line * n) % tuple(values.astype(np.float64).ravel().tolist())


def _faces(faces: np.ndarray, offset: int, uv_faces: np.ndarray | None = None, uv_offset: int | None = None) -> str:
    """``f a/a/a b/b/b c/c/c`` lines (1-based, shifted by ``offset`` vertices); with ``uv_faces``,
    ``f a/s/s ...``: the point of each corner, then its render vertex (shifted by ``uv_offset``)
    for both the texture coordinate and the normal."""
    n, k = faces.shape
    line = "f" + " %d/%d/%d" * k + "\n"
    if uv_faces is None and (uv_offset is None or uv_offset == offset):
        idx = np.repeat(faces.astype(np.int64) + offset + 1, 3, axis=1)
    else:
        uv = (faces if uv_faces is None else uv_faces).astype(np.int64) + (offset if uv_offset is None else uv_offset) + 1
        idx = np.stack([faces.astype(np.int64) + offset + 1, uv, uv], axis=2).reshape(n, 3 * k)
    return (line * n) % tuple(idx.ravel().tolist())


class ObjSequenceWriter:
    """Writes the sequence into ``folder`` (the temporary folder of an atomic output)."""

    def __init__(self, folder: Path, cloth: ClothGeometry, colliders: list[Collider]) -> None:
        self.folder = Path(folder)
        self.cloth = cloth
        self._shared = cloth.shared
        self._size = (f"{cloth.nw} x {cloth.nh} points" if cloth.grid
                      else f"{cloth.points} points, {len(cloth.uvs)} render vertices")
        # The same in every frame: formatted once.
        self._uv_text = _rows("vt", cloth.uvs)
        self._face_text = "s off\n" + (_faces(cloth.faces, 0) if self._shared else _faces(cloth.faces, 0, cloth.uv_faces, 0))
        self._colliders = [c for c in colliders if not c.animated]
        self._moving = [c for c in colliders if c.animated]

    def frame(self, frame: int, points: np.ndarray, normals: np.ndarray, seconds: float = 0.0) -> None:
        """Write the cloth at ``frame`` (``seconds`` into the simulation): positions and normals
        (N, 3), float32; the moving colliders follow it in the same file, where they are then."""
        if not self._shared:
            normals = normals[self.cloth.uv_point]  # a render vertex has its point's normal
        parts = [f"# clothsim {__version__}: cloth at frame {frame} ({self._size})\n",
                 "o cloth\n", _rows("v", points), self._uv_text, _rows("vn", normals), self._face_text]
        offset = len(points)
        uv_offset = len(self.cloth.uvs)
        for collider in self._moving:
            shape = collider.shape(seconds)
            if collider.turns:
                place = collider.placement(seconds)
                moved = (shape.points.astype(np.float64) @ place[:3, :3].T + place[:3, 3]).astype(np.float32)
                turned = (shape.normals.astype(np.float64) @ place[:3, :3].T).astype(np.float32)
                parts.append(_mesh_text(collider.name, replace(shape, points=moved, normals=turned), offset,
                                        uv_offset))
            else:
                moved = (shape.points + collider.offset(seconds)).astype(np.float32)
                parts.append(_mesh_text(collider.name, replace(shape, points=moved), offset, uv_offset))
            offset += len(moved)
            uv_offset += len(moved)
        (self.folder / cloth_name(frame)).write_text("".join(parts), encoding="ascii", newline="\n")

    def finish(self, start: int, end: int, fps: float) -> None:
        """Write ``colliders.obj`` when the scene has static colliders."""
        if not self._colliders:
            return
        parts = [f"# clothsim {__version__}: static colliders\n"]
        offset = 0
        for collider in self._colliders:
            parts.append(_mesh_text(collider.name, collider.mesh, offset))
            offset += len(collider.mesh.points)
        (self.folder / COLLIDERS_NAME).write_text("".join(parts), encoding="ascii", newline="\n")


def _mesh_text(name: str, mesh: MeshData, offset: int, uv_offset: int | None = None) -> str:
    """An object's lines; its ``vt``/``vn`` are numbered from ``uv_offset`` (after the cloth's
    render vertices) and its ``v`` from ``offset`` (after the cloth's points)."""
    return (f"o {name}\n" + _rows("v", mesh.points) + _rows("vt", mesh.uvs) + _rows("vn", mesh.normals)
            + "s off\n" + _faces(mesh.faces, offset, None, uv_offset))
