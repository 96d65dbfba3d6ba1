"""A deforming mesh collider's frames: a numbered series of OBJ files, and its shape at any time.

A ``sequence`` pattern such as ``walk_####.obj`` names frame n by writing n, zero-padded to the
width of each run of ``#``, in place of the run (a number wider than its run is written whole).
The frames are numbered from the first file that exists, frame 0 or else frame 1, and run on while
the next number's file exists: the first missing number ends the sequence. Every frame must have
the first frame's faces (the same vertex indices, face by face, after polygons are split into
triangles) and as many vertices; only the vertices' positions change.

With the ``usd`` extra (usd-core), a sequence may instead name one USD stage (``.usd``, ``.usda``,
``.usdc``, no ``#``): its first mesh prim (``UsdGeom.Mesh``, in stage order) is read, and each
time sample of its ``points`` is a frame, in time order (their time codes are not used: ``fps``
sets the rate, as for OBJ frames); its faces must not be time-sampled. Messages name the stage and
the face's number (1-based) instead of a line.

Time: frame k (counted from the first, whatever its number) is the shape at time k / fps; between
two frames each vertex moves on the straight line between them; after the last frame the shape
holds it, or with ``loop`` it goes back to the first frame over one more frame's time and repeats
(a period of F / fps for F frames). :meth:`MeshFrames.at` is the rule, and
:mod:`clothsim.sim.passes.colliders.meshdeform` compiles the same function for the kernels.
"""

from __future__ import annotations

import math
import os
import re
from dataclasses import dataclass

import numpy as np

from .objfile import ObjError, read_obj

#: Most frames one sequence may hold (each is a whole OBJ read and kept in memory).
MAX_FRAMES = 10_000
#: Highest frame rate accepted (frames a second): a frame per course substep is 2700.
MAX_FPS = 1e5
_RUN = re.compile(r"#+")


@dataclass(frozen=True, eq=False)
class MeshFrames:
    """A read sequence: ``frames`` (F, V, 3) float64 as in the files, the first frame's
    ``triangles`` (T, 3) int64 and their faces' ``lines``, the ``files`` read, the number of the
    first, the rate ``fps`` and whether it ``loop``s."""

    pattern: str
    files: tuple[str, ...]
    first: int
    frames: np.ndarray
    triangles: np.ndarray
    lines: np.ndarray
    fps: float
    loop: bool

    def at(self, frames: np.ndarray, t: float) -> np.ndarray:
        """The shape at time ``t`` from ``frames`` (F, V, 3): these frames, or the same placed
        (scaled and rotated, which commutes with the interpolation up to rounding)."""
        i, j, f = frame_pair(t, self.fps, frames.shape[0], self.loop)
        a = frames[i]
        return a + (frames[j] - a) * f


def frame_pair(t: float, fps: float, count: int, loop: bool) -> tuple[int, int, float]:
    """(frame i, frame j, weight f): the shape at ``t`` is frame i + (frame j - frame i) f. The
    kernels compile this function itself (:func:`clothsim.sim.passes.colliders.meshdeform.frame_pair`)."""
    x = t * fps
    if not x > 0.0:
        return 0, 0, 0.0
    k = math.floor(x)
    f = x - k
    if loop:
        i = int(k % count)
        return i, (i + 1) % count, f
    if k >= count - 1:
        return count - 1, count - 1, 0.0
    return int(k), int(k) + 1, f


def frame_name(pattern: str, number: int) -> str:
    """The file of frame ``number``: each run of ``#`` in the file name (not in its folders)
    replaced by the number, zero-padded to the run's width."""
    folder, name = os.path.split(pattern)
    return os.path.join(folder, _RUN.sub(lambda run: f"{number:0{len(run.group())}d}", name))


#: A stage's suffixes (a USD source instead of numbered OBJ files).
USD_SUFFIXES = (".usd", ".usda", ".usdc")


def read_sequence(pattern: str, fps: float, loop: bool) -> MeshFrames:
    """Every frame of ``pattern`` read and checked against the first; raises ``ValueError`` with
    one line naming the file (and the face's line) that is wrong."""
    if "#" not in os.path.basename(pattern) and pattern.lower().endswith(USD_SUFFIXES):
        return read_usd(pattern, fps, loop)
    if "#" not in os.path.basename(pattern):
        raise ValueError(f"{pattern}: the pattern has no '#' in its file name (each run of '#' is the "
                         f"frame number, zero-padded: e.g. walk_####.obj)")
    if not fps > 0.0:
        raise ValueError(f"fps must be > 0, got {fps:g}")
    first = next((n for n in (0, 1) if os.path.isfile(frame_name(pattern, n))), None)
    if first is None:
        raise ValueError(f"no first frame: neither {frame_name(pattern, 0)} nor {frame_name(pattern, 1)} is a file")
    files: list[str] = []
    shapes: list[np.ndarray] = []
    triangles = lines = None
    number = first
    while os.path.isfile(frame_name(pattern, number)):
        name = frame_name(pattern, number)
        if len(files) == MAX_FRAMES:
            raise ValueError(f"{name}: more than {MAX_FRAMES} frames")
        try:
            obj = read_obj(name)
        except ObjError as exc:
            raise ValueError(f"{name}: {exc}") from None
        except OSError as exc:
            raise ValueError(f"{name}: cannot read OBJ file: {exc.strerror or exc}") from None
        if triangles is None:
            triangles, lines = obj.triangles, obj.lines
        else:
            _same_faces(name, files[0], obj, triangles, lines, shapes[0].shape[0])
        files.append(name)
        shapes.append(obj.vertices)
        number += 1
    assert triangles is not None and lines is not None
    return MeshFrames(pattern, tuple(files), first, np.ascontiguousarray(np.stack(shapes)), triangles, lines,
                      float(fps), bool(loop))


def _same_faces(name: str, first_name: str, obj: object, triangles: np.ndarray, lines: np.ndarray,
                vertices: int) -> None:
    tris = obj.triangles  # type: ignore[attr-defined]
    here = obj.lines  # type: ignore[attr-defined]
    n = min(tris.shape[0], triangles.shape[0])
    differ = np.flatnonzero((tris[:n] != triangles[:n]).any(axis=1))
    if differ.size:
        i = int(differ[0])
        raise ValueError(f"{name}: line {int(here[i])}: face differs from the first frame's ({first_name} line "
                         f"{int(lines[i])}); every frame needs the first frame's faces")
    if tris.shape[0] != triangles.shape[0]:
        line = int(here[n]) if tris.shape[0] > n else int(here[-1])
        raise ValueError(f"{name}: line {line}: {tris.shape[0]} triangles, the first frame ({first_name}) has "
                         f"{triangles.shape[0]}; every frame needs the first frame's faces")
    if obj.vertices.shape[0] != vertices:  # type: ignore[attr-defined]
        raise ValueError(f"{name}: {obj.vertices.shape[0]} vertices, the first frame ({first_name}) has "  # type: ignore[attr-defined]
                         f"{vertices}; every frame needs as many")


def read_usd(path: str, fps: float, loop: bool) -> MeshFrames:
    """The frames of a USD stage's first mesh (see the module's docstring); ``ValueError`` naming
    the stage (and the extra, when usd-core is missing)."""
    try:
        from pxr import Usd, UsdGeom
    except ImportError:
        raise ValueError(f"{path}: reading a USD stage needs the 'usd' extra (pip install 'clothsim[usd]')") from None
    if not os.path.isfile(path):
        raise ValueError(f"{path}: no such USD stage")
    try:
        stage = Usd.Stage.Open(path)
    except Exception as exc:  # noqa: BLE001 - usd-core raises its own Tf.ErrorException
        raise ValueError(f"{path}: cannot open USD stage: {str(exc).strip().splitlines()[-1][:200]}") from None
    prim = next((p for p in stage.Traverse() if p.IsA(UsdGeom.Mesh)), None)
    if prim is None:
        raise ValueError(f"{path}: no mesh (UsdGeom.Mesh) in the stage")
    mesh = UsdGeom.Mesh(prim)
    where = f"{path}: {prim.GetPath()}"
    if mesh.GetFaceVertexIndicesAttr().GetNumTimeSamples() > 0 or mesh.GetFaceVertexCountsAttr().GetNumTimeSamples() > 0:
        raise ValueError(f"{where}: faceVertexIndices or faceVertexCounts has time samples; every frame needs the "
                         f"same faces")
    counts = np.asarray(mesh.GetFaceVertexCountsAttr().Get() or [], dtype=np.int64)
    indices = np.asarray(mesh.GetFaceVertexIndicesAttr().Get() or [], dtype=np.int64)
    points = mesh.GetPointsAttr()
    times = points.GetTimeSamples()
    shapes = [np.asarray(points.Get(t), dtype=np.float64).reshape(-1, 3) for t in times] or \
        [np.asarray(points.Get() or [], dtype=np.float64).reshape(-1, 3)]
    if counts.size == 0 or counts.sum() != indices.size or (counts < 3).any():
        raise ValueError(f"{where}: faceVertexCounts and faceVertexIndices do not describe faces of 3 or more corners")
    n = shapes[0].shape[0]
    if indices.min() < 0 or indices.max() >= n:
        raise ValueError(f"{where}: a face index is out of range (0..{n - 1})")
    for k, shape in enumerate(shapes):
        if shape.shape[0] != n:
            raise ValueError(f"{where}: time sample {times[k]:g} has {shape.shape[0]} points, the first has {n}")
        if not np.isfinite(shape).all():
            raise ValueError(f"{where}: time sample {times[k]:g} has a non-finite point")
    starts = np.cumsum(counts) - counts
    # each polygon split into a fan from its first corner, as the OBJ reader does
    face = np.repeat(np.arange(counts.size), counts - 2)
    k = np.arange(face.size) - np.repeat(np.cumsum(counts - 2) - (counts - 2), counts - 2)
    tris = np.stack([indices[starts[face]], indices[starts[face] + k + 1], indices[starts[face] + k + 2]], axis=1)
    twice = np.flatnonzero((tris[:, 0] == tris[:, 1]) | (tris[:, 1] == tris[:, 2]) | (tris[:, 0] == tris[:, 2]))
    if twice.size:
        raise ValueError(f"{where}: face {int(face[twice[0]]) + 1} uses the same point twice")
    if len(shapes) > MAX_FRAMES:
        raise ValueError(f"{where}: more than {MAX_FRAMES} time samples")
    return MeshFrames(path, (path,) * len(shapes), 0, np.ascontiguousarray(np.stack(shapes)),
                      np.ascontiguousarray(tris), face + 1, float(fps), bool(loop))
