"""Shapes the project makes itself, written as OBJ text: the bundled ``mesh`` scene's torus, a box,
a sphere, and a sphere that breathes (a sequence of frames).

``python -m clothsim.objshapes`` rewrites ``scenes/torus.obj`` (the file shipped with the ``mesh``
scene) and ``python -m clothsim.objshapes breathing`` the frames of the ``breathing`` scene
(``scenes/breathing/breath_##.obj``); the test suite checks that the shipped files are exactly
what this module writes.
"""

from __future__ import annotations

import math
import sys
from pathlib import Path

#: The bundled torus: ring radius, tube radius, segments around the ring and around the tube.
TORUS = (0.25, 0.09, 32, 12)


def _obj(header: str, vertices: list[tuple[float, float, float]], faces: list[tuple[int, ...]]) -> str:
    lines = [f"# {header}", *(f"v {x:.6f} {y:.6f} {z:.6f}" for x, y, z in vertices),
             *("f " + " ".join(str(i + 1) for i in f) for f in faces)]
    return "\n".join(lines) + "\n"


def torus_obj(ring: float, tube: float, around: int, sides: int) -> str:
    """A closed torus around the y axis, centred at the origin, as quads wound outwards."""
    verts = []
    for i in range(around):
        a = 2.0 * math.pi * i / around
        for j in range(sides):
            b = 2.0 * math.pi * j / sides
            rr = ring + tube * math.cos(b)
            verts.append((rr * math.cos(a), tube * math.sin(b), rr * math.sin(a)))
    faces = []
    for i in range(around):
        for j in range(sides):
            i1, j1 = (i + 1) % around, (j + 1) % sides
            faces.append((i * sides + j, i * sides + j1, i1 * sides + j1, i1 * sides + j))
    return _obj(f"torus: ring radius {ring}, tube radius {tube}, {around} x {sides} quads (clothsim.objshapes)",
                verts, faces)


def box_obj(hx: float = 0.5, hy: float = 0.5, hz: float = 0.5, *, drop_top: bool = False) -> str:
    """An axis-aligned box centred at the origin (half extents hx, hy, hz), six quads wound
    outwards; ``drop_top`` leaves out the +y face (an open mesh)."""
    verts = [(sx * hx, sy * hy, sz * hz) for sz in (-1, 1) for sy in (-1, 1) for sx in (-1, 1)]
    # vertex index = x + 2 y + 4 z with 0 for the minus side
    faces = [(0, 2, 3, 1), (4, 5, 7, 6), (0, 1, 5, 4), (0, 4, 6, 2), (1, 3, 7, 5)]
    if not drop_top:
        faces.append((2, 6, 7, 3))
    return _obj(f"box {2 * hx} x {2 * hy} x {2 * hz}{' without its top' if drop_top else ''} (clothsim.objshapes)",
                verts, faces)


#: The bundled breathing body: rest radius, how far the radius swings either way, frames in one
#: breath (the sequence loops), rings and segments of the sphere.
BREATHING = (0.22, 0.05, 24, 12, 24)


def sphere_obj(radius: float, rings: int, segments: int, *, squash: float = 1.0) -> str:
    """A closed UV sphere centred at the origin, wound outwards: a vertex at each pole, ``rings``
    - 1 rings of ``segments`` vertices between them; ``squash`` scales its height (y)."""
    verts = [(0.0, -radius * squash, 0.0)]
    for i in range(1, rings):
        a = math.pi * i / rings - 0.5 * math.pi
        for j in range(segments):
            b = 2.0 * math.pi * j / segments
            verts.append((radius * math.cos(a) * math.cos(b), radius * math.sin(a) * squash,
                          radius * math.cos(a) * math.sin(b)))
    verts.append((0.0, radius * squash, 0.0))
    top = len(verts) - 1

    def ring(i: int, j: int) -> int:
        return 1 + (i - 1) * segments + j % segments

    faces: list[tuple[int, ...]] = [(0, ring(1, j), ring(1, j + 1)) for j in range(segments)]
    for i in range(1, rings - 1):
        faces += [(ring(i, j), ring(i + 1, j), ring(i + 1, j + 1), ring(i, j + 1)) for j in range(segments)]
    faces += [(ring(rings - 1, j), top, ring(rings - 1, j + 1)) for j in range(segments)]
    return _obj(f"sphere: radius {radius:g}, height x {squash:g}, {rings} rings x {segments} segments "
                f"(clothsim.objshapes)", verts, faces)


def breathing_frames(radius: float, swing: float, frames: int, rings: int, segments: int) -> list[str]:
    """One breath of a body: ``frames`` spheres whose radius goes ``radius`` + ``swing`` sin(2 pi k /
    frames) and whose height swells a little more than their width, the same faces in every frame."""
    out = []
    for k in range(frames):
        phase = math.sin(2.0 * math.pi * k / frames)
        out.append(sphere_obj(radius + swing * phase, rings, segments, squash=1.0 + 0.15 * phase))
    return out


def write_breathing(folder: Path) -> list[Path]:
    """The breathing scene's frames, ``breath_00.obj`` ..., into ``folder`` (made if missing)."""
    folder.mkdir(parents=True, exist_ok=True)
    paths = []
    for k, text in enumerate(breathing_frames(*BREATHING)):
        path = folder / f"breath_{k:02d}.obj"
        path.write_text(text, encoding="ascii")
        paths.append(path)
    return paths


def main(argv: list[str]) -> int:
    """Write the bundled torus to ``argv[0]`` (default: scenes/torus.obj of this checkout), or with
    ``breathing [FOLDER]`` the breathing scene's frames (default: scenes/breathing/)."""
    scenes = Path(__file__).resolve().parents[2] / "scenes"
    if argv[:1] == ["breathing"]:
        paths = write_breathing(Path(argv[1]) if len(argv) > 1 else scenes / "breathing")
        print(f"wrote {len(paths)} frames into {paths[0].parent}")
        return 0
    out = Path(argv[0]) if argv else scenes / "torus.obj"
    out.write_text(torus_obj(*TORUS), encoding="ascii")
    print(f"wrote {out}")
    return 0


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))
