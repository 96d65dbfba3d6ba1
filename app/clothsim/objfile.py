"""A strict reader for the subset of Wavefront OBJ a collider or a cloth needs: vertices, polygon
faces and (for a cloth) texture coordinates.

Read: ``v x y z [w]`` (``w`` ignored) and ``f a b c ...`` with corners written ``v``, ``v/vt``,
``v//vn`` or ``v/vt/vn`` (1-based indices; negative ones count back from the last vertex read so
far). Polygons are split into a fan of triangles from their first corner. Ignored, as they do
not change the shape: ``vt``, ``vn``, ``vp``, ``o``, ``g``, ``s``, ``mtllib``, ``usemtl``,
comments (``#``) and blank lines. Anything else (``l``, ``p``, curves, a misspelt keyword, a
missing or non-finite number, an index out of range) is an error naming the line.

Every problem raises :class:`ObjError` with the 1-based line and what is wrong; the scene loader
prefixes it with the scene file and field.

Two readings of the same text: :func:`parse_obj` (a collider: triangles, ``vt`` ignored) and
:func:`parse_obj_polygons` (a cloth: the polygons as written and their texture coordinates). The
second also reads ``vt u [v [w]]`` (``v`` defaults to 0, ``w`` ignored) and the texture index of
each corner, checked like a vertex index (negative ones count back from the last ``vt`` read), and
leaves a face that repeats a vertex to its caller (a cloth calls that a degenerate face).
"""

from __future__ import annotations

import math
import re
from dataclasses import dataclass
from typing import Iterator

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


@dataclass(frozen=True, eq=False)
class ObjPolygons:
    """An OBJ's faces as written, for a cloth. ``vertices`` (V, 3) float64 and ``uvs`` (U, 2)
    float64 in file order; face ``f``'s corners are ``corners[face_start[f]:face_start[f + 1]]``
    (0-based vertex indices, in the file's order) with ``corner_uv`` beside them (0-based ``vt``
    index, -1 where the corner names none); ``face_line`` (F,) is each face's line."""

    vertices: np.ndarray
    uvs: np.ndarray
    corners: np.ndarray
    corner_uv: np.ndarray
    face_start: np.ndarray
    face_line: np.ndarray


def _index(i: int, line: int, count: int, uv: bool = False) -> int:
    """A corner's 1-based or negative index as 0-based, among the ``count`` vertices (``uv``: the
    ``vt`` lines) read so far."""
    if i > 0 and i <= count:
        return i - 1
    if i < 0 and -i <= count:
        return count + i
    name, what, read = ("face vt index", "vt", "vt lines") if uv else ("face index", "vertex", "vertices")
    if count == 0:
        raise ObjError(line, f"{name} {i} before any {what}")
    raise ObjError(line, f"{name} {i} out of range (1..{count}, or -1..-{count}, {read} read so far)")


def _corner(text: str, line: int, count: int) -> int:
    head = text.split("/", 1)[0]
    try:
        i = int(head)
    except ValueError:
        raise ObjError(line, f"face corner {text[:40]!r}: expected a vertex index") from None
    return _index(i, line, count)


def _corner_uv(text: str, line: int, count: int) -> int:
    parts = text.split("/", 2)
    if len(parts) < 2 or not parts[1]:
        return -1
    try:
        i = int(parts[1])
    except ValueError:
        raise ObjError(line, f"face corner {text[:40]!r}: expected a texture (vt) index after the first /") from None
    return _index(i, line, count, uv=True)


def _statements(text: str, read: tuple[str, ...], ignored: frozenset[str]) -> Iterator[tuple[int, list[str]]]:
    """The line and words of each statement whose keyword is in ``read`` (a face checked for its
    three corners); blank lines, comments and ``ignored`` keywords skipped, anything else refused."""
    for number, raw in enumerate(text.splitlines(), start=1):
        body = raw.split("#", 1)[0].strip()
        if not body:
            continue
        words = body.split()
        key = words[0]
        if key in read:
            if key == "f" and len(words) < 4:
                raise ObjError(number, f"a face needs at least 3 corners, got {len(words) - 1}")
            yield number, words
        elif key not in ignored:
            # Named only when it looks like an OBJ keyword: a file that is not OBJ at all (a
            # mistyped path to some other file) must not have its content quoted back.
            what = f"statement {key!r}" if _KEYWORD.fullmatch(key) else "line: it does not start with an OBJ keyword"
            raise ObjError(number, f"unsupported {what} (read: {', '.join(read)}; ignored: "
                                   f"{', '.join(sorted(ignored))}, comments)")


def _vertex(words: list[str], number: int) -> tuple[float, ...]:
    if len(words) not in (4, 5):
        raise ObjError(number, f"a vertex needs 3 coordinates (x y z [w]), got {len(words) - 1}")
    xyz = tuple(_number(w, number, f"vertex {'xyzw'[k]}") for k, w in enumerate(words[1:4]))
    if len(words) == 5:
        _number(words[4], number, "vertex w")
    return xyz


def parse_obj_polygons(text: str) -> ObjPolygons:
    """Parse OBJ text into vertices, texture coordinates and polygons as written (see
    :class:`ObjPolygons`); raises :class:`ObjError`."""
    vertices: list[tuple[float, ...]] = []
    uvs: list[tuple[float, float]] = []
    corners: list[int] = []
    corner_uv: list[int] = []
    starts: list[int] = [0]
    face_line: list[int] = []
    for number, words in _statements(text, ("v", "vt", "f"), _IGNORED - {"vt"}):
        key = words[0]
        if key == "v":
            vertices.append(_vertex(words, number))
        elif key == "vt":
            if len(words) not in (2, 3, 4):
                raise ObjError(number, f"a texture coordinate needs 1 to 3 numbers (u [v [w]]), got {len(words) - 1}")
            u = _number(words[1], number, "texture u")
            v = _number(words[2], number, "texture v") if len(words) > 2 else 0.0
            if len(words) == 4:
                _number(words[3], number, "texture w")
            uvs.append((u, v))
        else:
            for w in words[1:]:
                corners.append(_corner(w, number, len(vertices)))
                corner_uv.append(_corner_uv(w, number, len(uvs)))
            starts.append(len(corners))
            face_line.append(number)
    if not face_line:
        raise ObjError(0, f"empty mesh: no faces ({len(vertices)} vertices)")
    return ObjPolygons(np.array(vertices, dtype=np.float64).reshape(-1, 3),
                       np.array(uvs, dtype=np.float64).reshape(-1, 2), np.array(corners, dtype=np.int64),
                       np.array(corner_uv, dtype=np.int64), np.array(starts, dtype=np.int64),
                       np.array(face_line, dtype=np.int64))


def parse_obj(text: str) -> ObjMesh:
    """Parse OBJ text into vertices and triangles; raises :class:`ObjError`."""
    vertices: list[tuple[float, ...]] = []
    tris: list[tuple[int, int, int]] = []
    lines: list[int] = []
    for number, words in _statements(text, ("v", "f"), _IGNORED):
        if words[0] == "v":
            vertices.append(_vertex(words, number))
        else:
            corners = [_corner(w, number, len(vertices)) for w in words[1:]]
            if len(set(corners)) != len(corners):
                raise ObjError(number, "face uses the same vertex twice")
            for k in range(1, len(corners) - 1):
                tris.append((corners[0], corners[k], corners[k + 1]))
                lines.append(number)
    if not tris:
        raise ObjError(0, f"empty mesh: no faces ({len(vertices)} vertices)")
    return ObjMesh(np.array(vertices, dtype=np.float64).reshape(-1, 3), np.array(tris, dtype=np.int64),
                   np.array(lines, dtype=np.int64))


def read_obj(path: str) -> ObjMesh:
    """Read and parse an OBJ file; OSError for a file that cannot be read, :class:`ObjError` else."""
    return parse_obj(_read_text(path))


def read_obj_polygons(path: str) -> ObjPolygons:
    """Read and parse an OBJ file as :func:`parse_obj_polygons` does; errors as :func:`read_obj`."""
    return parse_obj_polygons(_read_text(path))


def _read_text(path: str) -> str:
    with open(path, "rb") as fh:
        data = fh.read(MAX_BYTES + 1)
    if len(data) > MAX_BYTES:
        raise ObjError(0, f"file is larger than {MAX_BYTES // 2**20} MiB")
    try:
        text = data.decode("utf-8")
    except UnicodeDecodeError as exc:
        raise ObjError(data.count(b"\n", 0, exc.start) + 1, f"not UTF-8 text ({exc.reason})") from None
    return text
