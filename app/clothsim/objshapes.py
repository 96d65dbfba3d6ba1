"""Shapes the project makes itself, written as OBJ text: the bundled ``mesh`` scene's torus, and a box.

``python -m clothsim.objshapes`` rewrites ``scenes/torus.obj`` (the file shipped with the ``mesh``
scene); the test suite checks that the shipped file is exactly what this module writes.
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


def main(argv: list[str]) -> int:
    """Write the bundled torus to ``argv[0]`` (default: scenes/torus.obj of this checkout)."""
    out = Path(argv[0]) if argv else Path(__file__).resolve().parents[2] / "scenes" / "torus.obj"
    out.write_text(torus_obj(*TORUS), encoding="ascii")
    print(f"wrote {out}")
    return 0


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))
