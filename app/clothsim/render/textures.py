"""Images the looks sample: a colour texture, a height map and a six-face environment cubemap.

The defaults are generated here (no image files ship with the package); users can pass their
own files, read with Pillow. Arrays are uint8, rows ordered the way OpenGL uploads them (first
row = v 0 for 2D textures, t 0 for cube faces).
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from ..errors import ClothsimError

COLOR_SIZE = 512
HEIGHT_SIZE = 64
CUBE_SIZE = 256
# GL_TEXTURE_CUBE_MAP face order: +x, -x, +y, -y, +z, -z.
CUBE_FACES = ("+x", "-x", "+y", "-y", "+z", "-z")


def default_color_texture(size: int = COLOR_SIZE) -> np.ndarray:
    """A tartan-like woven pattern, (size, size, 4) sRGB uint8: bands that read at any distance."""
    t = (np.arange(size) + 0.5) / size
    u, v = np.meshgrid(t, t)
    base = np.array([150, 32, 40], dtype=np.float64)
    navy = np.array([24, 38, 92], dtype=np.float64)
    green = np.array([22, 84, 52], dtype=np.float64)
    gold = np.array([226, 182, 60], dtype=np.float64)

    def bands(x: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        f = (x * 4.0) % 1.0
        wide = (np.abs(f - 0.5) < 0.17).astype(np.float64)
        mid = (np.abs(f - 0.12) < 0.05).astype(np.float64)
        line = (np.abs(f - 0.85) < 0.012).astype(np.float64)
        return wide, mid, line

    img = np.broadcast_to(base, (size, size, 3)).copy()
    for coord, weight in ((u, 0.55), (v, 0.45)):
        wide, mid, line = bands(coord)
        img += weight * (wide[..., None] * (navy - img) + mid[..., None] * (green - img))
        img += line[..., None] * (gold - img)
    # A 2x2 twill: threads alternate over/under, a small brightness ripple like woven cloth.
    ix, iy = np.meshgrid(np.arange(size), np.arange(size))
    twill = ((ix // 2 + iy // 2) % 2) * 2 - 1
    img *= 1.0 + 0.06 * twill[..., None]
    return _rgba(img)


def default_height_map(size: int = HEIGHT_SIZE, cells: int = 8, seed: int = 7) -> np.ndarray:
    """A quilt: rounded pillows between narrow stitched seams, plus a fine weave, (size, size) uint8.

    Two scales on purpose: displacement moves vertices a cloth grid can resolve, so the pillows
    are smooth and wide; bump mapping differentiates over single texels, so the seams and the
    weave are sharp enough to tilt the normal at the course's k_h * k_n = 0.2. The map is
    small (64 texels) for the same reason: a one-texel difference spans more of the pattern.
    """
    c = (np.arange(size) + 0.5) / size * cells
    fy, fx = np.meshgrid(c % 1.0, c % 1.0, indexing="ij")
    pillow = np.sqrt(np.sin(np.pi * fx) * np.sin(np.pi * fy))
    cell_texels = size / cells
    d = np.minimum(np.minimum(fx, 1 - fx), np.minimum(fy, 1 - fy)) * cell_texels  # texels to a seam
    seam = np.clip(d - 0.5, 0.0, 1.0)
    ix, iy = np.meshgrid(np.arange(size), np.arange(size))
    weave = ((ix // 2 + iy // 2) % 2).astype(np.float64)
    rng = np.random.default_rng(seed)
    h = seam * (0.15 + 0.7 * pillow + 0.08 * weave + 0.07 * rng.random((size, size)))
    return np.clip(h * 255.0 + 0.5, 0, 255).astype(np.uint8)


def _face_directions(face: int, size: int) -> np.ndarray:
    """Unit view directions of every texel of one cube face (size, size, 3), GL conventions."""
    c = (np.arange(size) + 0.5) / size * 2.0 - 1.0
    tc, sc = np.meshgrid(c, c, indexing="ij")  # row = t, column = s
    one = np.ones_like(sc)
    d = {
        0: (one, -tc, -sc),
        1: (-one, -tc, sc),
        2: (sc, one, tc),
        3: (sc, -one, -tc),
        4: (sc, -tc, one),
        5: (-sc, -tc, -one),
    }[face]
    v = np.stack(d, axis=-1)
    return v / np.linalg.norm(v, axis=-1, keepdims=True)


def environment_color(d: np.ndarray) -> np.ndarray:
    """Linear RGB of the default environment seen along unit directions ``d`` (..., 3).

    A blue sky with a sun towards the default light and a checkered ground: structure that a
    mirror reflection makes easy to recognise.
    """
    y = d[..., 1:2]
    zenith = np.array([0.05, 0.16, 0.55])
    horizon = np.array([0.75, 0.80, 0.88])
    sky = horizon + (zenith - horizon) * np.sqrt(np.clip(y, 0.0, 1.0))
    sun_dir = np.array([0.5, 2.0, 2.0]) / np.linalg.norm([0.5, 2.0, 2.0])
    sun = np.clip((d @ sun_dir - 0.985) / 0.01, 0.0, 1.0)[..., None]
    sky = sky + sun * np.array([4.0, 3.6, 2.8])
    # Ground: project the ray onto a plane one unit below and checker it.
    t = 1.0 / np.maximum(-y, 1e-3)
    gx = d[..., 0:1] * t
    gz = d[..., 2:3] * t
    checker = ((np.floor(gx * 2.0) + np.floor(gz * 2.0)) % 2.0)
    ground = np.array([0.10, 0.22, 0.06]) + checker * np.array([0.25, 0.20, 0.10])
    haze = np.exp(-0.08 * t)  # fades the checker into the horizon colour far away
    ground = horizon * 0.6 + (ground - horizon * 0.6) * haze
    return np.where(y >= 0.0, sky, ground)


def default_cubemap(size: int = CUBE_SIZE) -> list[np.ndarray]:
    """Six (size, size, 4) sRGB uint8 faces of the default environment, in GL face order."""
    faces = []
    for face in range(6):
        lin = environment_color(_face_directions(face, size))
        faces.append(_rgba(_linear_to_srgb(lin) * 255.0))
    return faces


def load_image(path: str | Path, *, gray: bool = False, flip: bool = True) -> np.ndarray:
    """Read an image file with Pillow as uint8 RGBA (or one channel when ``gray``).

    ``flip`` puts the image's bottom row first, so that uv (0, 0) is its lower-left corner.
    """
    import struct

    from PIL import Image

    try:
        with Image.open(path) as im:
            im = im.convert("L" if gray else "RGBA")
            arr = np.asarray(im, dtype=np.uint8)
    # What Pillow raises for a file it cannot decode: a truncated or malformed file surfaces as any
    # of these depending on the format, and an image of more than twice MAX_IMAGE_PIXELS (a
    # "decompression bomb") as DecompressionBombError, which derives from none of them.
    except (OSError, ValueError, SyntaxError, EOFError, struct.error, Image.DecompressionBombError) as exc:
        raise ClothsimError(f"{path}: cannot read image: {' '.join(str(exc).split())}") from None
    return np.ascontiguousarray(arr[::-1] if flip else arr)


def load_cubemap(paths: tuple[str, ...]) -> list[np.ndarray]:
    """Six face images (+x, -x, +y, -y, +z, -z), square and of one size, as RGBA uint8."""
    faces = [load_image(p, flip=False) for p in paths]
    shape = faces[0].shape
    for p, f in zip(paths, faces):
        if f.shape != shape or f.shape[0] != f.shape[1]:
            raise ClothsimError(f"{p}: cubemap faces must be square and all the same size "
                                f"(first face is {shape[1]}x{shape[0]}, this one {f.shape[1]}x{f.shape[0]})")
    return faces


def _linear_to_srgb(c: np.ndarray) -> np.ndarray:
    c = np.clip(c, 0.0, 1.0)
    return np.where(c <= 0.0031308, c * 12.92, 1.055 * np.power(c, 1.0 / 2.4) - 0.055)


def _rgba(rgb: np.ndarray) -> np.ndarray:
    out = np.empty(rgb.shape[:2] + (4,), dtype=np.uint8)
    out[..., :3] = np.clip(rgb + 0.5, 0, 255).astype(np.uint8)
    out[..., 3] = 255
    return out
