"""The capsule collider kind: the points within ``radius`` of the segment a-b.

Rows (C, 11) float64: ax ay az, bx by bz, radius, friction, carry xyz (how far the capsule moved
during the current substep; zero for a static one). Points inside are pushed to the surface (as on
a sphere) along their path relative to the capsule (:func:`~.shapes.push_out`, or
:func:`~.shapes.push_out_turning` where a capsule turns); a moving capsule moves rigidly (a keyframe
places the segment's midpoint, about which it turns).
"""

from __future__ import annotations


import numpy as np
from numba import njit

from ....jit import KERNEL
from .rows import collide, packer, pose, reach, row_group
from .shapes import ball_surface, overlaps, overlaps_turning, push_out, push_out_turning

__all__ = ["CAPSULE_CARRY", "CAPSULE_COLUMNS", "CARRY_AT", "Capsules", "Group", "POINTS", "TURNS", "capsule_surface",
           "collide", "collide_rows", "pack", "pose", "reach", "reach_rows"]

#: Columns of a row, and where its carry starts.
CAPSULE_COLUMNS = 11
CAPSULE_CARRY = 8


#: The scene's capsules: their rows, reach flags and tracks.
Group = Capsules = row_group("Capsules", __name__, "The scene's capsules (see clothsim.sim.passes.colliders.rows).")
#: A pose moves a capsule's two ends; its carry is the last three columns of its row (see :mod:`.rows`).
POINTS, CARRY_AT = 2, CAPSULE_CARRY
#: A turn turns no direction of a capsule's row: its two ends are points.
TURNS = ()
pack = packer(Capsules, "capsules", lambda c: (*c.a, *c.b, c.radius, c.friction, 0.0, 0.0, 0.0), CAPSULE_COLUMNS,
              lambda c: (*c.a, *c.b))


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
    # the sphere of radius r about the axis point nearest (x, y, z)
    return ball_surface(x, y, z, ax + t * ex, ay + t * ey, az + t * ez, r)


@njit(**KERNEL)
def collide_rows(pos: np.ndarray, last: np.ndarray, free: np.ndarray, capsules: np.ndarray, on: np.ndarray,
                 turn: np.ndarray | None, offset: float) -> None:
    """Push the points inside each reachable capsule to its surface, with friction (see module);
    points land on the surface, so ``offset`` is unused."""
    for o in range(capsules.shape[0]):
        if on[o]:
            row = capsules[o]
            if turn is None:
                push_out(pos, last, free, row, 1.0 - row[7], 0.5 * row[6], row[CAPSULE_CARRY], row[CAPSULE_CARRY + 1],
                         row[CAPSULE_CARRY + 2], capsule_surface, 0.0)
            else:
                push_out_turning(pos, last, free, row, 1.0 - row[7], 0.5 * row[6], turn[o], capsule_surface, 0.0)


@njit(**KERNEL)
def reach_rows(box: np.ndarray, capsules: np.ndarray, on: np.ndarray, turn: np.ndarray | None, offset: float) -> int:
    """Mark the capsules whose bounds meet the cloth's box; returns how many were ruled out."""
    skipped = 0
    for o in range(capsules.shape[0]):
        row = capsules[o]
        r = row[6]
        if turn is None:
            on[o] = overlaps(box, row[CAPSULE_CARRY], row[CAPSULE_CARRY + 1], row[CAPSULE_CARRY + 2],
                             min(row[0], row[3]) - r, min(row[1], row[4]) - r, min(row[2], row[5]) - r,
                             max(row[0], row[3]) + r, max(row[1], row[4]) + r, max(row[2], row[5]) + r)
        else:
            on[o] = overlaps_turning(box, turn[o], min(row[0], row[3]) - r, min(row[1], row[4]) - r,
                                     min(row[2], row[5]) - r, max(row[0], row[3]) + r, max(row[1], row[4]) + r,
                                     max(row[2], row[5]) + r)
        skipped += 0 if on[o] else 1
    return skipped
