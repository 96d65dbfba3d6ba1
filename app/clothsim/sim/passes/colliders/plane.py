"""The plane collider kind: rows (px, py, pz, nx, ny, nz, friction) with unit normals.

A point that crossed a plane during the substep (its signed distance changed sign between its
last position and now) goes back onto the plane, lifted by ``SURFACE_OFFSET`` on the side it came
from, moving from its last position towards there by (1 - friction). A point whose last position
lies exactly on the plane counts as being on the normal's side, so a cloth row that starts on the
floor does not fall through it. In a scene where any collider moves, the test is made in the
plane's moving frame (the last position carried along by the plane's displacement): exact at any
speed of the plane.
"""

from __future__ import annotations

from typing import Any, NamedTuple

import numpy as np
from numba import njit

from ....jit import KERNEL
from ...team import chunk_of
from .moving import Tracks, pack_tracks, pose_rows

#: The spec's SURFACE_OFFSET: how far above a plane (or outside a box) a corrected point is put.
SURFACE_OFFSET = 0.0001


class Planes(NamedTuple):
    """The scene's planes: their rows, reach flags, carries (None where nothing in the scene
    moves) and the tracks of the moving ones (None when none moves)."""

    rows: np.ndarray
    on: np.ndarray
    carry: np.ndarray | None
    tracks: Tracks | None


Group = Planes
#: In every plan with colliders, empty when the scene has no planes: the course's kinds, so that the
#: course's scenes (a sphere, a plane, both) share one compiled plan, as they always have.
ALWAYS = True


def pack(scene: Any, clock: np.ndarray, dt: float, swept: bool) -> Planes:
    """The group of ``scene``'s planes; ``swept``: something in the scene moves. Always a group,
    empty for a scene without planes (see :data:`ALWAYS`)."""
    rows = np.array([[*p.point, *p.normal, p.friction] for p in scene.planes], dtype=np.float64).reshape(-1, 7)
    return Planes(rows, np.zeros(len(rows), dtype=np.bool_), np.zeros((len(rows), 3)) if swept else None,
                  pack_tracks(scene.planes, clock, dt, lambda p: p.point))


@njit(**KERNEL)
def collide_planes(pos: np.ndarray, last: np.ndarray, free: np.ndarray, planes: np.ndarray,
                   offset: float) -> None:
    """Bounce back points that crossed a plane during the last step (see the module's notes)."""
    for o in range(planes.shape[0]):
        px = planes[o, 0]
        py = planes[o, 1]
        pz = planes[o, 2]
        nx = planes[o, 3]
        ny = planes[o, 4]
        nz = planes[o, 5]
        keep = 1.0 - planes[o, 6]
        for k in range(free.shape[0]):
            p = free[k]
            now = (pos[0, p] - px) * nx + (pos[1, p] - py) * ny + (pos[2, p] - pz) * nz
            before = (last[0, p] - px) * nx + (last[1, p] - py) * ny + (last[2, p] - pz) * nz
            if (before >= 0.0) != (now >= 0.0):
                side = offset if before >= 0.0 else -offset
                # target = projection of pos onto the plane, lifted to the side it came from
                shift = side - now
                pos[0, p] = last[0, p] + (pos[0, p] + nx * shift - last[0, p]) * keep
                pos[1, p] = last[1, p] + (pos[1, p] + ny * shift - last[1, p]) * keep
                pos[2, p] = last[2, p] + (pos[2, p] + nz * shift - last[2, p]) * keep


@njit(**KERNEL)
def collide_moving_planes(pos: np.ndarray, last: np.ndarray, free: np.ndarray, planes: np.ndarray,
                          on: np.ndarray, carry: np.ndarray, offset: float) -> None:
    """Planes tested in their moving frame: a point crossed a plane when its distance from it
    changed sign between its carried last position and now (exact for any speed of the plane)."""
    for o in range(planes.shape[0]):
        if not on[o]:
            continue
        px = planes[o, 0]
        py = planes[o, 1]
        pz = planes[o, 2]
        nx = planes[o, 3]
        ny = planes[o, 4]
        nz = planes[o, 5]
        keep = 1.0 - planes[o, 6]
        for k in range(free.shape[0]):
            p = free[k]
            lx = last[0, p] + carry[o, 0]
            ly = last[1, p] + carry[o, 1]
            lz = last[2, p] + carry[o, 2]
            now = (pos[0, p] - px) * nx + (pos[1, p] - py) * ny + (pos[2, p] - pz) * nz
            before = (lx - px) * nx + (ly - py) * ny + (lz - pz) * nz
            if (before >= 0.0) != (now >= 0.0):
                side = offset if before >= 0.0 else -offset
                shift = side - now
                pos[0, p] = lx + (pos[0, p] + nx * shift - lx) * keep
                pos[1, p] = ly + (pos[1, p] + ny * shift - ly) * keep
                pos[2, p] = lz + (pos[2, p] + nz * shift - lz) * keep


@njit(**KERNEL)
def reach_planes(box: np.ndarray, planes: np.ndarray, on: np.ndarray) -> int:
    """Mark the planes the cloth's box (of current and last positions) is not wholly on one side
    of; returns how many were ruled out."""
    skipped = 0
    for o in range(planes.shape[0]):
        lo = 0.0
        hi = 0.0
        for c in range(3):
            n = planes[o, 3 + c]
            a = (box[c] - planes[o, c]) * n
            b = (box[3 + c] - planes[o, c]) * n
            lo += a if a < b else b
            hi += a if a > b else b
        # every point strictly on the normal's side, or strictly behind: nothing can cross
        on[o] = not (lo > 0.0 or hi < 0.0)
        skipped += 0 if on[o] else 1
    return skipped


@njit(**KERNEL)
def reach_moving_planes(box: np.ndarray, planes: np.ndarray, on: np.ndarray, carry: np.ndarray) -> int:
    """:func:`reach_planes` with the cloth's box stretched by each plane's carry."""
    skipped = 0
    for o in range(planes.shape[0]):
        lo = 0.0
        hi = 0.0
        for c in range(3):
            n = planes[o, 3 + c]
            a = (box[c] + min(carry[o, c], 0.0) - planes[o, c]) * n
            b = (box[3 + c] + max(carry[o, c], 0.0) - planes[o, c]) * n
            lo += a if a < b else b
            hi += a if a > b else b
        on[o] = not (lo > 0.0 or hi < 0.0)
        skipped += 0 if on[o] else 1
    return skipped


# -- the kind's passes (see clothsim.sim.passes.colliders) -----------------------------------------

@njit(**KERNEL)
def pose(g: Planes, substep: int) -> None:
    """Put the moving planes at their pose at the end of substep ``substep``."""
    pose_rows(g.tracks, g.rows, 1, g.carry, 0, substep)


@njit(**KERNEL)
def reach(g: Planes, box: np.ndarray, on: np.ndarray, offset: float) -> int:
    """Mark the planes the cloth's box reaches in ``on``; returns how many were ruled out."""
    return _reach(box, g.rows, on, g.carry)


@njit(**KERNEL)
def _reach(box: np.ndarray, rows: np.ndarray, on: np.ndarray, carry: np.ndarray | None) -> int:
    # (the carry passed on its own: Numba prunes a branch on an argument that is None)
    if carry is None:
        return reach_planes(box, rows, on)
    return reach_moving_planes(box, rows, on, carry)


@njit(**KERNEL)
def collide(g: Planes, pos: np.ndarray, last: np.ndarray, free: np.ndarray, c: int, on: np.ndarray,
            offset: float) -> None:
    """Work item ``c`` (of CHUNKS) of the free points against the reachable planes."""
    _collide(pos, last, chunk_of(free, c), g.rows, on, g.carry, offset)


@njit(**KERNEL)
def _collide(pos: np.ndarray, last: np.ndarray, part: np.ndarray, rows: np.ndarray, on: np.ndarray,
             carry: np.ndarray | None, offset: float) -> None:
    if carry is None:
        for o in range(rows.shape[0]):
            if on[o]:
                collide_planes(pos, last, part, rows[o : o + 1], offset)
    else:
        collide_moving_planes(pos, last, part, rows, on, carry, offset)
