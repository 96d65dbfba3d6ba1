"""The scene's ``mesh`` collider: its rule, the OBJ it names, and the checks on that mesh's shape.

``"mesh": {"path": "shape.obj", "scale": 1.0, "translate": [0, 0, 0], "rotation": [0, 0, 0],
"friction": 0.3, "motion": {...}}`` (one object or a list). The path is relative to the scene
file. A vertex ``v`` of the file is placed at ``R (scale v) + translate`` with ``R = Rz Ry Rx``
(degrees, right-handed, x applied first); ``motion`` moves ``translate`` over time
(:mod:`clothsim.motion`; the velocity form starts from ``translate``).

A mesh may instead deform: ``"sequence": "walk_####.obj", "fps": 30`` (and ``"loop": true``) in
place of ``path`` names a numbered series of OBJ files (:mod:`clothsim.meshsequence`): frame k,
the k-th existing file, is the shape at time k / fps, linear between frames, held after the last
(or, with ``loop``, back to the first over one more frame's time). The placement and ``motion``
apply to the deformed shape as to a fixed one.

What is checked on the triangles, after the OBJ reader's own checks (:mod:`clothsim.objfile`):

* no triangle of zero area (collinear corners);
* edge-manifold: every edge (pair of vertex indices) belongs to one or two triangles; one in
  three or more is refused;
* consistently wound: two triangles sharing an edge run along it in opposite directions (else
  "inside" is undefined);
* the mesh is **closed** when every edge has two triangles, **open** when some have one. A closed
  mesh wound inside out (negative signed volume) is turned the right way out.

Not checked: vertex-manifoldness (two surfaces touching at one vertex), self-intersection, and
several separate closed parts (each keeps points out of itself, which is what a user expects).
"""

from __future__ import annotations

import math
import os
import stat
from dataclasses import dataclass
from pathlib import Path
from typing import Any, Callable, TypeVar

import numpy as np

from . import validate as V
from .meshsequence import MAX_FPS, USD_SUFFIXES, MeshFrames, read_sequence
from .motion import COLLIDER_MOTION, MotionSpec, Track
from .objfile import ObjError, read_obj

#: Largest scale and translation accepted: far beyond any scene, so that positions stay finite.
MAX_EXTENT = 1e6
_T = TypeVar("_T")
_FRICTION = V.number(ge=0.0, le=1.0)

#: Most triangles a cloth point's list of near triangles holds, per mesh (more: that point asks
#: the mesh's grid, every substep; see :mod:`clothsim.sim.passes.colliders.mesh`).
NEAR_ROOM = 64
#: How many of a list's nearest triangles carry a separating plane (a point whose reachable
#: triangles go further down its list is handled by the exact tests; see
#: :mod:`clothsim.sim.passes.colliders.mesh`).
NEAR_PLANES = 16
#: Numbers in a row of a list's distances: one more than the list holds, so that the row is not a
#: power of two bytes long. The pass reads the first entries of one point's rows after another's;
#: rows 512 B apart fall in one eighth of the caches' sets, and where a process's arrays happened to
#: start at the same offset within those sets they evicted each other and the cloth's own arrays
#: (see docs/performance-meshes.md, "The lists' rows").
NEAR_D_WIDTH = NEAR_ROOM + 1
#: Numbers a separating plane takes in its row: unit normal, offset, and its triangle's distance
#: (a copy of the list's, read in the same cache line as the plane it decides about); 40 B, so a
#: row of planes is not a power of two bytes long either.
PLANE_WIDTH = 5
#: Memory each mesh adds per cloth point, for the memory check: counted from the pass's arrays
#: (the list's anchor and reference point, 2 x 3 x 8 B, its length and its first distance, 2 x 8 B,
#: its triangles, 4 B each, its row of distances, NEAR_D_WIDTH x 8 B, and its planes, PLANE_WIDTH
#: x 8 B each), not measured, plus 25 % as for every figure of that check.
MESH_BYTES_PER_POINT = int(1.25 * (2 * 3 * 8 + 2 * 8 + NEAR_ROOM * 4 + NEAR_D_WIDTH * 8
                                   + NEAR_PLANES * PLANE_WIDTH * 8))


@dataclass(frozen=True, eq=False)
class MeshSpec:
    """A triangle-mesh collider: the file and placement as written, and the checked triangles.

    ``vertices`` (V, 3) float64 as in the file; ``triangles`` (T, 3) int64, wound so that their
    normals (right-hand rule) face out of a closed mesh; ``closed`` tells which kind it is.
    """

    path: str
    file: str
    scale: float
    translate: tuple[float, float, float]
    rotation: tuple[float, float, float]
    friction: float
    motion: MotionSpec | None
    vertices: np.ndarray
    triangles: np.ndarray
    closed: bool
    #: a deforming mesh's frames (None: a fixed shape); ``vertices`` is then its first frame
    sequence: MeshFrames | None = None

    def rotation_matrix(self) -> np.ndarray:
        """R = Rz . Ry . Rx for the ``rotation`` angles (degrees)."""
        return rotation_matrix(self.rotation)

    def local_vertices(self) -> np.ndarray:
        """Vertices scaled and rotated, before the translation: (V, 3) float64."""
        return (self.vertices * self.scale) @ self.rotation_matrix().T

    def local_vertices_at(self, t: float) -> np.ndarray:
        """Vertices scaled and rotated at time ``t`` (s): the sequence's frames interpolated as the
        simulator does (:meth:`MeshFrames.at` of the placed frames); the fixed shape without one."""
        if self.sequence is None:
            return self.local_vertices()
        return self.sequence.at(self.local_frames(), t)

    def local_frames(self) -> np.ndarray:
        """Every frame's vertices scaled and rotated, before the translation: (F, V, 3) float64."""
        assert self.sequence is not None
        return (self.sequence.frames * self.scale) @ self.rotation_matrix().T

    def surface_speed(self) -> float:
        """The fastest a vertex of the placed shape moves by its deformation alone (m/s; 0 for a
        fixed shape): the largest step between consecutive frames times the rate."""
        if self.sequence is None:
            return 0.0
        frames = self.local_frames()
        if self.sequence.loop:
            frames = np.concatenate([frames, frames[:1]])
        if frames.shape[0] < 2:
            return 0.0
        return float(np.linalg.norm(np.diff(frames, axis=0), axis=2).max()) * self.sequence.fps

    @property
    def anchor(self) -> tuple[float, float, float]:
        """The position a ``motion`` keyframe gives: the translation."""
        return self.translate

    def track(self) -> Track:
        """The translation over time (a held keyframe at ``translate`` when the mesh does not move)."""
        if self.motion is None:
            return MotionSpec(keyframes=((0.0, self.translate),)).track()
        return self.motion.track(start=self.translate)

    def as_json(self) -> dict[str, Any]:
        """The object as a scene file writes it (the path resolved, so it loads from anywhere)."""
        where: dict[str, Any] = {"path": os.path.abspath(self.file)}
        if self.sequence is not None:
            where = {"sequence": os.path.abspath(self.file), "fps": self.sequence.fps}
            if self.sequence.loop:
                where["loop"] = True
        out: dict[str, Any] = {**where, "scale": self.scale,
                               "translate": list(self.translate), "rotation": list(self.rotation),
                               "friction": self.friction}
        if self.motion is not None:
            out["motion"] = self.motion.as_json()
        return out


def rotation_matrix(degrees: tuple[float, float, float]) -> np.ndarray:
    """R = Rz . Ry . Rx (right-handed, angles in degrees, x applied first)."""
    ax, ay, az = (math.radians(a) for a in degrees)
    cx, sx, cy, sy, cz, sz = math.cos(ax), math.sin(ax), math.cos(ay), math.sin(ay), math.cos(az), math.sin(az)
    rx = np.array([[1, 0, 0], [0, cx, -sx], [0, sx, cx]])
    ry = np.array([[cy, 0, sy], [0, 1, 0], [-sy, 0, cy]])
    rz = np.array([[cz, -sz, 0], [sz, cz, 0], [0, 0, 1]])
    return rz @ ry @ rx


def check_topology(vertices: np.ndarray, triangles: np.ndarray, lines: np.ndarray, areas_only: bool = False
                   ) -> tuple[np.ndarray, bool]:
    """The triangles (outward-wound when closed) and whether the mesh is closed; raises
    :class:`~clothsim.objfile.ObjError` naming the face's line for a degenerate triangle, an edge
    in more than two triangles, or two neighbours wound against each other. ``areas_only`` checks
    the areas alone (a later frame of a sequence, whose edges are the first frame's)."""
    a, b, c = (vertices[triangles[:, k]] for k in range(3))
    area2 = np.linalg.norm(np.cross(b - a, c - a), axis=1)
    bad = np.flatnonzero(~(area2 > 0.0))
    if bad.size:
        raise ObjError(int(lines[bad[0]]), "face has zero area (its corners are collinear)")
    if areas_only:
        return triangles, False
    heads = triangles.reshape(-1)
    tails = triangles[:, [1, 2, 0]].reshape(-1)
    lo = np.minimum(heads, tails)
    hi = np.maximum(heads, tails)
    key = lo * (int(vertices.shape[0]) + 1) + hi
    order = np.argsort(key, kind="stable")
    sk = key[order]
    starts = np.flatnonzero(np.r_[True, sk[1:] != sk[:-1]])
    counts = np.diff(np.r_[starts, sk.size])
    face_line = np.repeat(lines, 3)[order]
    over = np.flatnonzero(counts > 2)
    if over.size:
        s = starts[over[0]]
        n = int(counts[over[0]])
        e = order[s]
        shown = ", ".join(str(int(x)) for x in face_line[s : s + min(n, 4)])
        raise ObjError(int(face_line[s]), f"non-manifold: the edge between vertices {int(lo[e]) + 1} and "
                                          f"{int(hi[e]) + 1} is shared by {n} faces (lines {shown}); "
                                          f"an edge may belong to at most 2")
    pairs = starts[counts == 2]
    same = heads[order[pairs]] == heads[order[pairs + 1]]
    if same.any():
        s = pairs[np.flatnonzero(same)[0]]
        e = order[s]
        raise ObjError(int(face_line[s + 1]), f"faces on lines {int(face_line[s])} and {int(face_line[s + 1])} "
                                              f"are wound the same way along their shared edge (vertices "
                                              f"{int(lo[e]) + 1} and {int(hi[e]) + 1}); a collider needs "
                                              f"consistently oriented faces")
    closed = bool((counts == 2).all())
    out = triangles
    if closed:
        volume = float(np.einsum("ij,ij->i", a, np.cross(b, c)).sum())
        if volume < 0.0:
            out = triangles[:, [0, 2, 1]]
    return np.ascontiguousarray(out, dtype=np.int64), closed


# ----------------------------------------------------------------------------------------------
# The scene rule


def _path(value: Any, at: V.At) -> str:
    if not isinstance(value, str) or not value.strip():
        raise at.fail(f"expected the path of an OBJ file, got {V.shown(value)}")
    return value


def _fps(value: Any, at: V.At) -> float:
    return V.number(gt=0.0, le=MAX_FPS)(value, at)


def _loop(value: Any, at: V.At) -> bool:
    if not isinstance(value, bool):
        raise at.fail(f"expected true or false, got {V.shown(value)}")
    return value


#: The keys that name and place an OBJ (also those of a cloth read from one, :mod:`clothsim.clothmesh`).
PLACEMENT = {
    "path": V.required(_path),
    "scale": V.default(V.number(gt=0.0, le=MAX_EXTENT), 1.0),
    "translate": V.default(V.vec3(V.number(ge=-MAX_EXTENT, le=MAX_EXTENT)), (0.0, 0.0, 0.0)),
    "rotation": V.default(V.vec3(), (0.0, 0.0, 0.0)),
}
_FIELDS = V.record({
    **PLACEMENT,
    # a collider's path is optional: a deforming mesh names its frames' pattern instead
    "path": V.optional(_path),
    "sequence": V.optional(_path),
    "fps": V.optional(_fps),
    "loop": V.default(_loop, False),
    "friction": V.required(_FRICTION),
    "motion": V.default(COLLIDER_MOTION, None),
})


def _base_dir(source: str | None) -> Path:
    if source is None or source.startswith("<"):
        return Path(".")
    return Path(source).parent


def obj_file(here: V.At, path: str) -> Path:
    """Where the OBJ ``path`` of the field ``here`` is: beside the scene file, or through an
    uploaded scene's files."""
    return _base_dir(here.source) / path if here.files is None else here.files.locate(path, here, "OBJ")


def read_checked(here: V.At, path: str, file: Path, read: Callable[[str], _T]) -> _T:
    """``read(file)`` (an OBJ reader and the checks on its result); a missing or unreadable file
    and every :class:`~clothsim.objfile.ObjError` become one line naming ``here`` and ``path``."""
    try:
        if not stat.S_ISREG(os.stat(file).st_mode):  # a FIFO or a device would block the read or never end
            raise here.fail(f"{path}: not a regular file")
        return read(str(file))
    except FileNotFoundError:
        raise here.fail(f"{path}: no such OBJ file (looked for {file})") from None
    except IsADirectoryError:
        raise here.fail(f"{path}: is a directory, not an OBJ file") from None
    except OSError as exc:
        raise here.fail(f"{path}: cannot read OBJ file: {exc.strerror or exc}") from None
    except ObjError as exc:
        raise here.fail(f"{path}: {exc}") from None


def _collider_obj(file: str) -> tuple[np.ndarray, np.ndarray, bool]:
    obj = read_obj(file)
    triangles, closed = check_topology(obj.vertices, obj.triangles, obj.lines)
    return obj.vertices, triangles, closed


def MESH(value: Any, at: V.At) -> MeshSpec:  # noqa: N802 - a rule, named like the scene's records
    """The rule for one ``mesh`` object: its fields, then the OBJ file read and checked."""
    fields = _FIELDS(value, at)
    if "path" not in fields and "sequence" not in fields:
        raise at.key("path").fail("missing required field (or sequence, for numbered OBJ frames)")
    if "path" in fields and "sequence" in fields:
        raise at.key("sequence").fail("give either path (one OBJ file) or sequence (numbered OBJ frames), not both")
    if "sequence" in fields:
        return _sequence_mesh(fields, at)
    if "fps" in fields or fields["loop"]:
        raise at.key("fps" if "fps" in fields else "loop").fail("applies only to a sequence, not to a path")
    here = at.key("path")
    path = fields["path"]
    file = obj_file(here, path)
    vertices, triangles, closed = read_checked(here, path, file, _collider_obj)
    spec = MeshSpec(path=path, file=str(file), scale=fields["scale"], translate=fields["translate"],
                    rotation=fields["rotation"], friction=fields["friction"], motion=fields["motion"],
                    vertices=vertices, triangles=triangles, closed=closed)
    return _placed(spec, spec.local_vertices(), at)


def _placed(spec: MeshSpec, local: np.ndarray, at: V.At) -> MeshSpec:
    if not np.isfinite(local * 2.0).all():
        raise at.key("scale").fail(f"places the mesh's vertices beyond the float range (scale {spec.scale:g})")
    return spec


def _sequence_mesh(fields: dict[str, Any], at: V.At) -> MeshSpec:
    """A deforming mesh: its frames read (:func:`~clothsim.meshsequence.read_sequence`), the
    first frame's triangles checked as a fixed mesh's, the others' areas."""
    here = at.key("sequence")
    pattern = fields["sequence"]
    if "fps" not in fields:
        raise at.key("fps").fail("missing required field (the frames' rate, for a sequence)")
    if here.files is not None:  # the server opens only the files uploaded by name
        raise here.fail("a sequence of OBJ files is not available for an uploaded scene; use path")
    base = _base_dir(at.source) / pattern
    try:
        frames = read_sequence(str(base), fields["fps"], fields["loop"])
    except ValueError as exc:
        raise here.fail(str(exc)) from None
    name = frames.files[0]
    try:
        triangles, closed = check_topology(frames.frames[0], frames.triangles, frames.lines)
        for name, shape in zip(frames.files[1:], frames.frames[1:]):
            check_topology(shape, frames.triangles, frames.lines, areas_only=True)
    except ObjError as exc:
        if frames.files[0].lower().endswith(USD_SUFFIXES):  # a stage's faces are numbered, not lines
            raise here.fail(f"{name}: face {exc.line}: {exc.problem}") from None
        raise here.fail(f"{name}: {exc}") from None
    spec = MeshSpec(path=pattern, file=str(base), scale=fields["scale"], translate=fields["translate"],
                    rotation=fields["rotation"], friction=fields["friction"], motion=fields["motion"],
                    vertices=frames.frames[0], triangles=triangles, closed=closed, sequence=frames)
    return _placed(spec, spec.local_frames(), at)
