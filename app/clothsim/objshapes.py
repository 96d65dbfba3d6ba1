"""Shapes the project makes itself, written as OBJ text: the bundled ``mesh`` scene's torus, a box,
a sphere and a sphere that breathes (a sequence of frames), an open drum with baffles, and cloths to
read as ``cloth.mesh`` (a flat sheet, an open tube), with texture coordinates.

``python -m clothsim.objshapes`` rewrites every OBJ file shipped in ``scenes/`` (:func:`bundled`:
the ``mesh`` scene's torus, the ``skirt``, ``cape`` and ``drum`` scenes' cloths, the ``drum`` scene's
drum, the ``breathing`` scene's frames in ``scenes/breathing/``); the test suite checks that each
shipped file is exactly what this module writes.
"""

from __future__ import annotations

import math
import sys
from pathlib import Path

#: The bundled torus: ring radius, tube radius, segments around the ring and around the tube.
TORUS = (0.25, 0.09, 32, 12)
#: The bundled skirt: an open tube's radius, height, quads round and rows up.
SKIRT = (0.2, 0.45, 48, 16)
#: The bundled cape: a sheet's width, depth and vertices along each (with a texture seam down its middle).
CAPE = (0.9, 0.6, 37, 25)
#: The bundled drum: radius, length, sides round, rows along, baffles, a baffle's height and
#: width at the wall, the gap between a baffle and the wall.
DRUM = (0.35, 0.54, 32, 4, 3, 0.08, 0.08, 0.0015)
#: The bundled towel (the ``drum`` scene's cloth): a sheet's width, depth and vertices along each.
TOWEL = (0.4, 0.4, 25, 25)


def _obj(header: str, vertices: list[tuple[float, float, float]], faces: list[tuple[int, ...]]) -> str:
    lines = [f"# {header}", *(f"v {x:.6f} {y:.6f} {z:.6f}" for x, y, z in vertices),
             *("f " + " ".join(str(i + 1) for i in f) for f in faces)]
    return "\n".join(lines) + "\n"


def _obj_uv(header: str, vertices: list[tuple[float, float, float]], uvs: list[tuple[float, float]],
            faces: list[tuple[int, ...]]) -> str:
    # one vt per v, in the same order, so a corner names both by one number
    lines = [f"# {header}", *(f"v {x:.6f} {y:.6f} {z:.6f}" for x, y, z in vertices),
             *(f"vt {u:.6f} {v:.6f}" for u, v in uvs),
             *("f " + " ".join(f"{i + 1}/{i + 1}" for i in f) for f in faces)]
    return "\n".join(lines) + "\n"


def _cell_faces(corner: list[tuple[int, int, int, int]], quads: bool) -> list[tuple[int, ...]]:
    """Each cell ``(a, b, c, d)`` as a quad, or as the two triangles of its fan from ``a``."""
    if quads:
        return list(corner)
    return [t for a, b, c, d in corner for t in ((a, b, c), (a, c, d))]


def sheet_obj(width: float, height: float, nu: int, nv: int, quads: bool = True, seam: bool = False) -> str:
    """A flat ``width`` x ``height`` rectangle in the xz-plane (y = 0) from the origin, ``nu`` x
    ``nv`` vertices (row by row along x), faces wound counter-clockwise seen from +y, a ``vt`` per
    vertex (u along x, v along z). ``seam`` duplicates the middle column (index ``(nu - 1) // 2``):
    the same positions as new ``v`` lines after the others, with their own ``vt``, used by the
    cells to its right, as an exporter splitting a texture seam writes it."""
    verts = [(width * i / (nu - 1), 0.0, height * j / (nv - 1)) for j in range(nv) for i in range(nu)]
    uvs = [(i / (nu - 1), j / (nv - 1)) for j in range(nv) for i in range(nu)]
    mid = (nu - 1) // 2
    if seam:
        verts += [verts[j * nu + mid] for j in range(nv)]
        uvs += [uvs[j * nu + mid] for j in range(nv)]

    def at(i: int, j: int, right_of: int) -> int:
        return nu * nv + j if seam and i == mid and right_of >= mid else j * nu + i

    cells = [(at(i, j, i), at(i, j + 1, i), at(i + 1, j + 1, i), at(i + 1, j, i))
             for j in range(nv - 1) for i in range(nu - 1)]
    kind = "quads" if quads else "triangles"
    return _obj_uv(f"sheet {width} x {height}, {nu} x {nv} vertices, {kind}{', seam' if seam else ''} "
                   f"(clothsim.objshapes)", verts, uvs, _cell_faces(cells, quads))


def tube_obj(radius: float, height: float, around: int, rows: int) -> str:
    """An open cylinder about the y axis from y = 0 up to ``height`` (a skirt): ``around`` quads
    round and ``rows`` up, wound outwards. The ``vt`` u wraps from 0 to 1, so the seam column is
    written twice in ``v`` (the same positions, u = 1), as exporters do."""
    verts, uvs = [], []
    for j in range(rows + 1):
        for i in range(around + 1):
            a = 2.0 * math.pi * (i % around) / around
            verts.append((radius * math.cos(a), height * j / rows, radius * math.sin(a)))
            uvs.append((i / around, j / rows))
    w = around + 1
    cells = [(j * w + i, (j + 1) * w + i, (j + 1) * w + i + 1, j * w + i + 1) for j in range(rows) for i in range(around)]
    return _obj_uv(f"open tube: radius {radius}, height {height}, {around} x {rows} quads (clothsim.objshapes)",
                   verts, uvs, cells)


def drum_obj(radius: float, length: float, around: int, rows: int, baffles: int, height: float, width: float,
             gap: float) -> str:
    """An open drum about the z axis, centred at the origin: a polygonal tube of ``around`` sides
    (its corners at ``radius``) and ``rows`` rows from z = -``length``/2 to +``length``/2, no ends,
    and ``baffles`` ridges along its inside, evenly spaced from the +x side. A baffle is a tent of two
    strips meeting in a ridge ``height`` in from the wall, its two feet ``width`` apart and ``gap``
    from the wall; it shares no vertex with the tube (an edge of three triangles is refused), and a
    gap thinner than a cloth keeps the cloth from slipping under it. Every part is wound with its
    normals facing the drum's axis."""
    verts: list[tuple[float, float, float]] = []
    faces: list[tuple[int, ...]] = []
    zs = [length * (j / rows - 0.5) for j in range(rows + 1)]

    def strip(lines: list[tuple[float, float]]) -> None:
        # a surface swept along z through the cross-section points ``lines``, in the order given
        first = len(verts)
        verts.extend((x, y, z) for z in zs for x, y in lines)
        w = len(lines)
        faces.extend((first + j * w + i, first + j * w + i + 1, first + (j + 1) * w + i + 1, first + (j + 1) * w + i)
                     for j in range(rows) for i in range(w - 1))

    step = 2.0 * math.pi / around
    # the tube: corners going clockwise seen from +z, so each quad faces the axis
    first = len(verts)
    verts.extend((radius * math.cos(-i * step), radius * math.sin(-i * step), z) for z in zs for i in range(around))
    faces.extend((first + j * around + i, first + j * around + (i + 1) % around,
                  first + (j + 1) * around + (i + 1) % around, first + (j + 1) * around + i)
                 for j in range(rows) for i in range(around))
    apothem = radius * math.cos(0.5 * step)

    def wall(a: float) -> float:
        """Distance from the axis to the tube's wall in the direction of angle ``a``."""
        return apothem / math.cos((a % step) - 0.5 * step)

    ridge = apothem - height
    for k in range(baffles):
        a = 2.0 * math.pi * k / baffles
        feet = []
        for side in (1.0, -1.0):  # the foot at the larger angle first: the same turn as the tube's corners
            b = a + side * math.asin(0.5 * width / radius)
            r = wall(b) - gap
            feet.append((r * math.cos(b), r * math.sin(b)))
        strip([feet[0], (ridge * math.cos(a), ridge * math.sin(a)), feet[1]])
    return _obj(f"open drum: radius {radius}, length {length}, {around} x {rows} quads, {baffles} baffles "
                f"{height} high, {width} wide, {gap} from the wall (clothsim.objshapes)", verts, faces)


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


def bundled() -> dict[str, str]:
    """Every OBJ shipped in ``scenes/``, by path under it: the ``mesh`` scene's torus, the
    ``skirt``, ``cape`` and ``drum`` scenes' cloths, the ``drum`` scene's drum and the ``breathing``
    scene's frames (the ``cape`` scene's body too)."""
    files = {"torus.obj": torus_obj(*TORUS), "skirt.obj": tube_obj(*SKIRT), "cape.obj": sheet_obj(*CAPE, seam=True),
             "drum.obj": drum_obj(*DRUM), "towel.obj": sheet_obj(*TOWEL)}
    files.update({f"breathing/breath_{k:02d}.obj": text for k, text in enumerate(breathing_frames(*BREATHING))})
    return files


def main(argv: list[str]) -> int:
    """Write the bundled OBJ files under the folder ``argv[0]`` (default: scenes/ of this checkout)."""
    folder = Path(argv[0]) if argv else Path(__file__).resolve().parents[2] / "scenes"
    for name, text in bundled().items():
        (folder / name).parent.mkdir(parents=True, exist_ok=True)
        (folder / name).write_text(text, encoding="ascii")
    print(f"wrote {len(bundled())} OBJ files under {folder}")
    return 0


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))
