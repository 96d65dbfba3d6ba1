"""The capsule collider kind: the points within ``radius`` of the segment a-b.

Rows (C, 11) float64: ax ay az, bx by bz, radius, friction, carry xyz (how far the capsule moved
during the current substep; zero for a static one). Points inside are pushed to the surface (as on
a sphere) along their path relative to the capsule (:func:`~.shapes.push_out`); a moving capsule
moves rigidly (a keyframe places the segment's midpoint).
"""

from __future__ import annotations

from typing import Any, NamedTuple

import numpy as np
from numba import njit

from ....jit import KERNEL
from ...team import chunk_of
from .moving import Tracks, pack_tracks, pose_rows
from .shapes import overlaps, push_out

#: Columns of a row, and where its carry starts.
CAPSULE_COLUMNS = 11
CAPSULE_CARRY = 8


class Capsules(NamedTuple):
    """The scene's capsules: their rows, reach flags and the tracks of the moving ones (None when
    none moves)."""

    rows: np.ndarray
    on: np.ndarray
    tracks: Tracks | None


Group = Capsules


def pack(scene: Any, clock: np.ndarray, dt: float, swept: bool) -> Capsules:
    """The group of ``scene``'s capsules."""
    rows = np.array([[*c.a, *c.b, c.radius, c.friction, 0.0, 0.0, 0.0] for c in scene.capsules], dtype=np.float64)
    return Capsules(rows, np.zeros(len(rows), dtype=np.bool_),
                    pack_tracks(scene.capsules, clock, dt, lambda c: (*c.a, *c.b)))


@njit(inline="always", **KERNEL)
def capsule_surface(x: float, y: float, z: float, row: np.ndarray, offset: float) -> tuple[bool, float, float, float]:
    """(inside, surface point): the point of the capsule's surface nearest (x, y, z) when it is
    inside (a point exactly on the axis has no direction and is left alone, as at a sphere's
    centre). ``offset`` is unused: points land on a capsule's surface, as on a sphere's."""
    ax = row[0]
    ay = row[1]
    az = row[2]
    ex = row[3] - ax
    ey = row[4] - ay
    ez = row[5] - az
    r = row[6]
    ee = ex * ex + ey * ey + ez * ez
    t = 0.0
    if ee > 0.0:
        t = ((x - ax) * ex + (y - ay) * ey + (z - az) * ez) / ee
        t = min(max(t, 0.0), 1.0)
    cx = ax + t * ex
    cy = ay + t * ey
    cz = az + t * ez
    dx = x - cx
    dy = y - cy
    dz = z - cz
    d2 = dx * dx + dy * dy + dz * dz
    if d2 <= r * r and d2 > 0.0:
        s = r / np.sqrt(d2)
        return True, cx + dx * s, cy + dy * s, cz + dz * s
    return False, x, y, z


@njit(**KERNEL)
def collide_capsules(pos: np.ndarray, last: np.ndarray, free: np.ndarray, capsules: np.ndarray,
                     on: np.ndarray) -> None:
    """Push the points inside each reachable capsule to its surface, with friction (see module)."""
    for o in range(capsules.shape[0]):
        if on[o]:
            row = capsules[o]
            push_out(pos, last, free, row, 1.0 - row[7], 0.5 * row[6], CAPSULE_CARRY, capsule_surface, 0.0)


@njit(**KERNEL)
def reach_capsules(box: np.ndarray, capsules: np.ndarray, on: np.ndarray) -> int:
    """Mark the capsules whose bounds meet the cloth's box; returns how many were ruled out."""
    skipped = 0
    for o in range(capsules.shape[0]):
        row = capsules[o]
        r = row[6]
        on[o] = overlaps(box, row[CAPSULE_CARRY], row[CAPSULE_CARRY + 1], row[CAPSULE_CARRY + 2],
                         min(row[0], row[3]) - r, min(row[1], row[4]) - r, min(row[2], row[5]) - r,
                         max(row[0], row[3]) + r, max(row[1], row[4]) + r, max(row[2], row[5]) + r)
        skipped += 0 if on[o] else 1
    return skipped


# -- the kind's passes (see clothsim.sim.passes.colliders) -----------------------------------------

@njit(**KERNEL)
def pose(g: Capsules, substep: int) -> None:
    """Put the moving capsules at their pose at the end of substep ``substep``."""
    pose_rows(g.tracks, g.rows, 2, g.rows, CAPSULE_CARRY, substep)


@njit(**KERNEL)
def reach(g: Capsules, box: np.ndarray, on: np.ndarray, offset: float) -> int:
    """Mark the capsules the cloth's box reaches in ``on``; returns how many were ruled out."""
    return reach_capsules(box, g.rows, on)


@njit(**KERNEL)
def collide(g: Capsules, pos: np.ndarray, last: np.ndarray, free: np.ndarray, c: int, on: np.ndarray,
            offset: float) -> None:
    """Work item ``c`` (of CHUNKS) of the free points against the reachable capsules."""
    collide_capsules(pos, last, chunk_of(free, c), g.rows, on)
