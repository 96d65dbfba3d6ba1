"""``clothsim check-intersections FILE.npz``: the cloth's edge-triangle crossings, frame by frame.

Reads a ``clothsim simulate`` output (one frame: ``positions`` (N, 3) and the grid's
``num_width_points`` x ``num_height_points``) or a sweep dataset's ``runs/<id>.npz`` (``positions``
(T, N, 3) sampled at ``frames``, its mesh in ``faces``). Any .npz with ``positions`` (N, 3) or
(T, N, 3) and either ``faces`` or the two grid sizes will do.
"""

from __future__ import annotations

import argparse
import zipfile
from typing import Any

import numpy as np

from ..errors import ClothsimError


def add_parser(sub: argparse._SubParsersAction) -> None:
    """Register ``clothsim check-intersections``."""
    p = sub.add_parser("check-intersections", help="count the cloth's edge-triangle crossings in a .npz, per frame",
                       description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("file", metavar="FILE.npz", help="a clothsim simulate output or a sweep run's .npz")
    p.add_argument("--fail-on-crossings", action="store_true",
                   help="exit with code 1 when any frame has a crossing (for scripts and CI)")
    p.set_defaults(func=run)


def _load(path: str) -> dict[str, np.ndarray]:
    try:
        with np.load(path, allow_pickle=False) as data:
            if not hasattr(data, "files"):
                raise ClothsimError(f"{path}: not a .npz archive (a single .npy array)")
            return {k: data[k] for k in data.files}
    except FileNotFoundError:
        raise ClothsimError(f"{path}: no such file") from None
    except IsADirectoryError:
        raise ClothsimError(f"{path}: is a folder, not a .npz file") from None
    except (OSError, EOFError, zipfile.BadZipFile) as exc:
        raise ClothsimError(f"{path}: cannot read: {exc}") from None
    except ValueError:  # not an archive (NumPy then tries pickle, refused), or object arrays in it
        raise ClothsimError(f"{path}: not a NumPy .npz file of numeric arrays") from None


def _scalar_int(path: str, arrays: dict[str, np.ndarray], name: str) -> int:
    v = arrays[name]
    if v.shape != () or v.dtype.kind not in "iu" or int(v) < 2:
        raise ClothsimError(f"{path}: {name}: expected an integer >= 2, got {v.dtype} {v.shape} {v!r}")
    return int(v)


def read_frames(path: str) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(frame numbers (T,), positions (T, N, 3) float64, triangles (F, 3) int64) of a .npz, or a
    ClothsimError naming the file and the field."""
    arrays = _load(path)
    if "positions" not in arrays:
        raise ClothsimError(f"{path}: positions: missing (expected a clothsim simulate output or a sweep run's .npz)")
    pos = arrays["positions"]
    if pos.dtype.kind != "f" or pos.ndim not in (2, 3) or pos.shape[-1] != 3 or pos.shape[-2] < 4:
        raise ClothsimError(f"{path}: positions: expected floats of shape (N, 3) or (T, N, 3), "
                            f"got {pos.dtype} {pos.shape}")
    frames_3d = pos if pos.ndim == 3 else pos[None]
    n = frames_3d.shape[1]
    if "faces" in arrays:
        tris = arrays["faces"]
        if tris.dtype.kind not in "iu" or tris.ndim != 2 or tris.shape[1] != 3 or len(tris) == 0:
            raise ClothsimError(f"{path}: faces: expected integers of shape (F, 3), got {tris.dtype} {tris.shape}")
        if tris.min() < 0 or tris.max() >= n:
            raise ClothsimError(f"{path}: faces: point indices must be in 0..{n - 1}, got {tris.min()}..{tris.max()}")
        tris = tris.astype(np.int64)
    elif "num_width_points" in arrays and "num_height_points" in arrays:
        from ..sim.crossings import grid_triangles

        nw = _scalar_int(path, arrays, "num_width_points")
        nh = _scalar_int(path, arrays, "num_height_points")
        if nw * nh != n:
            raise ClothsimError(f"{path}: positions: {n} points, but num_width_points x num_height_points is "
                                f"{nw} x {nh} = {nw * nh}")
        tris = grid_triangles(nw, nh)
    else:
        raise ClothsimError(f"{path}: faces: missing, and no num_width_points/num_height_points to build the grid's")
    numbers: Any = arrays.get("frames")
    if numbers is None:
        numbers = np.arange(len(frames_3d))
    elif pos.ndim == 2 and numbers.shape == () and numbers.dtype.kind in "iu":
        numbers = numbers.reshape(1)
    elif numbers.dtype.kind not in "iu" or numbers.shape != (len(frames_3d),):
        raise ClothsimError(f"{path}: frames: expected {len(frames_3d)} integer frame numbers, "
                            f"got {numbers.dtype} {numbers.shape}")
    bad = np.flatnonzero(~np.isfinite(frames_3d).all(axis=(1, 2)))
    if len(bad):
        raise ClothsimError(f"{path}: positions: not every coordinate is finite (frame {int(numbers[bad[0]])})")
    return numbers.astype(np.int64), frames_3d.astype(np.float64), tris


def run(args: argparse.Namespace) -> int:
    """Print one line per frame, then the largest count and the last."""
    from ..sim.crossings import mesh_crossings, mesh_edges

    numbers, frames, tris = read_frames(args.file)
    edges = mesh_edges(tris)
    print(f"{args.file}: {frames.shape[1]} points, {len(tris)} triangles, {len(edges)} edges, {len(frames)} "
          f"frame{'s' if len(frames) != 1 else ''}")
    print(f"{'frame':>8}{'crossings':>11}")
    counts = []
    for number, pts in zip(numbers, frames):
        counts.append(int(mesh_crossings(pts, tris, edges=edges)))
        print(f"{int(number):>8}{counts[-1]:>11}", flush=True)
    worst = int(np.argmax(counts))
    print(f"max {counts[worst]} (frame {int(numbers[worst])}), final {counts[-1]}; a crossing is an edge passing "
          "through a triangle it shares no point with")
    return 1 if args.fail_on_crossings and max(counts) > 0 else 0
