"""A strict reader for the subset of Wavefront OBJ a collider needs: vertices and polygon faces.

Read: ``v x y z [w]`` (``w`` ignored) and ``f a b c ...`` with corners written ``v``, ``v/vt``,
``v//vn`` or ``v/vt/vn`` (1-based indices; negative ones count back from the last vertex read so
far). Polygons are split into a fan of triangles from their first corner. Ignored, as they do
not change the shape: ``vt``, ``vn``, ``vp``, ``o``, ``g``, ``s``, ``mtllib``, ``usemtl``,
comments (``#``) and blank lines. Anything else (``l``, ``p``, curves, a misspelt keyword, a
missing or non-finite number, an index out of range) is an error naming the line.

Every problem raises :class:`ObjError` with the 1-based line and what is wrong; the scene loader
prefixes it with the scene file and field.
"""

from __future__ import annotations

import math
import re
from dataclasses import dataclass

import numpy as np

_IGNORED = frozenset(("vt", "vn", "vp", "o", "g", "s", "mtllib", "usemtl"))
#: Largest OBJ read (bytes): a collider, not a scanned statue; the grid and the checks are O(T).
MAX_BYTES = 64 * 2**20
_KEYWORD = re.compile(r"[a-z_]{1,12}")


class ObjError(ValueError):
    """A problem in an OBJ file: ``line`` (1-based, 0 for the whole file) and ``problem``."""

    def __init__(self, line: int, problem: str) -> None:
        self.line = line
        self.problem = problem
        super().__init__(f"line {line}: {problem}" if line else problem)


@dataclass(frozen=True, eq=False)
class ObjMesh:
    """``vertices`` (V, 3) float64, ``triangles`` (T, 3) int64 0-based, and ``lines`` (T,) int64:
    the line of the face each triangle came from (for messages)."""

    vertices: np.ndarray
    triangles: np.ndarray
    lines: np.ndarray


def _number(text: str, line: int, what: str) -> float:
    try:
        x = float(text)
    except ValueError:
        raise ObjError(line, f"{what}: expected a number, got {text[:40]!r}") from None
    if not math.isfinite(x):
        raise ObjError(line, f"{what}: must be finite, got {text[:40]}")
    return x


def _corner(text: str, line: int, count: int) -> int:
    head = text.split("/", 1)[0]
    try:
        i = int(head)
    except ValueError:
        raise ObjError(line, f"face corner {text[:40]!r}: expected a vertex index") from None
    if i > 0 and i <= count:
        return i - 1
    if i < 0 and -i <= count:
        return count + i
    if count == 0:
        raise ObjError(line, f"face index {i} before any vertex")
    raise ObjError(line, f"face index {i} out of range (1..{count}, or -1..-{count}, vertices read so far)")


def parse_obj(text: str) -> ObjMesh:
    """Parse OBJ text into vertices and triangles; raises :class:`ObjError`."""
    vertices: list[tuple[float, float, float]] = []
    tris: list[tuple[int, int, int]] = []
    lines: list[int] = []
    for number, raw in enumerate(text.splitlines(), start=1):
        body = raw.split("#", 1)[0].strip()
        if not body:
            continue
        words = body.split()
        key = words[0]
        if key == "v":
            if len(words) not in (4, 5):
                raise ObjError(number, f"a vertex needs 3 coordinates (x y z [w]), got {len(words) - 1}")
            vertices.append(tuple(_number(w, number, f"vertex {'xyzw'[k]}") for k, w in enumerate(words[1:4])))
            if len(words) == 5:
                _number(words[4], number, "vertex w")
        elif key == "f":
            if len(words) < 4:
                raise ObjError(number, f"a face needs at least 3 corners, got {len(words) - 1}")
            corners = [_corner(w, number, len(vertices)) for w in words[1:]]
            if len(set(corners)) != len(corners):
                raise ObjError(number, "face uses the same vertex twice")
            for k in range(1, len(corners) - 1):
                tris.append((corners[0], corners[k], corners[k + 1]))
                lines.append(number)
        elif key in _IGNORED:
            continue
        else:
            # Named only when it looks like an OBJ keyword: a file that is not OBJ at all (a
            # mistyped path to some other file) must not have its content quoted back.
            what = f"statement {key!r}" if _KEYWORD.fullmatch(key) else "line: it does not start with an OBJ keyword"
            raise ObjError(number, f"unsupported {what} (read: v, f; ignored: "
                                   f"{', '.join(sorted(_IGNORED))}, comments)")
    if not tris:
        raise ObjError(0, f"empty mesh: no faces ({len(vertices)} vertices)")
    return ObjMesh(np.array(vertices, dtype=np.float64).reshape(-1, 3), np.array(tris, dtype=np.int64),
                   np.array(lines, dtype=np.int64))


def read_obj(path: str) -> ObjMesh:
    """Read and parse an OBJ file; OSError for a file that cannot be read, :class:`ObjError` else."""
    with open(path, "rb") as fh:
        data = fh.read(MAX_BYTES + 1)
    if len(data) > MAX_BYTES:
        raise ObjError(0, f"file is larger than {MAX_BYTES // 2**20} MiB")
    try:
        text = data.decode("utf-8")
    except UnicodeDecodeError as exc:
        raise ObjError(data.count(b"\n", 0, exc.start) + 1, f"not UTF-8 text ({exc.reason})") from None
    return parse_obj(text)
