"""The oriented box collider kind: ``center``, half extents along its own axes and a rotation.

Rows (B, 19) float64: cx cy cz, hx hy hz (half extents), R (9, row-major; column k is the box's
k-th axis in world space), friction, carry xyz (how far the box moved during the current substep;
zero for a static one). Points inside are pushed ``SURFACE_OFFSET`` outside the nearest face (as
on a plane) along their path relative to the box (:func:`~.shapes.push_out`); a moving box does
not turn.
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
CUBOID_COLUMNS = 19
CUBOID_CARRY = 16


class Boxes(NamedTuple):
    """The scene's boxes: their rows, reach flags and the tracks of the moving ones (None when
    none moves)."""

    rows: np.ndarray
    on: np.ndarray
    tracks: Tracks | None


Group = Boxes


def pack(scene: Any, clock: np.ndarray, dt: float, swept: bool) -> Boxes:
    """The group of ``scene``'s boxes."""
    rows = np.array([[*b.center, *b.half_extents, *(x for r in b.matrix() for x in r), b.friction, 0.0, 0.0, 0.0]
                     for b in scene.boxes], dtype=np.float64)
    return Boxes(rows, np.zeros(len(rows), dtype=np.bool_), pack_tracks(scene.boxes, clock, dt, lambda b: b.center))


@njit(**KERNEL)
def cuboid_surface(x: float, y: float, z: float, row: np.ndarray, offset: float) -> tuple[bool, float, float, float]:
    """(inside, surface point): a point inside the box (or on it) goes ``offset`` outside its
    nearest face, along that face's normal."""
    px = x - row[0]
    py = y - row[1]
    pz = z - row[2]
    # q = R^T p: the point in the box's own axes
    q0 = row[6] * px + row[9] * py + row[12] * pz
    q1 = row[7] * px + row[10] * py + row[13] * pz
    q2 = row[8] * px + row[11] * py + row[14] * pz
    g0 = row[3] - abs(q0)
    g1 = row[4] - abs(q1)
    g2 = row[5] - abs(q2)
    if g0 < 0.0 or g1 < 0.0 or g2 < 0.0:
        return False, x, y, z
    # out through the nearest face: move along one box axis by gap + offset
    if g0 <= g1 and g0 <= g2:
        k = 0
        m = (g0 + offset) if q0 >= 0.0 else -(g0 + offset)
    elif g1 <= g2:
        k = 1
        m = (g1 + offset) if q1 >= 0.0 else -(g1 + offset)
    else:
        k = 2
        m = (g2 + offset) if q2 >= 0.0 else -(g2 + offset)
    return True, x + row[6 + k] * m, y + row[9 + k] * m, z + row[12 + k] * m


@njit(**KERNEL)
def collide_cuboids(pos: np.ndarray, last: np.ndarray, free: np.ndarray, cuboids: np.ndarray, on: np.ndarray,
                    offset: float) -> None:
    """Push the points inside each reachable box out of its nearest face, with friction (see module)."""
    for o in range(cuboids.shape[0]):
        if on[o]:
            row = cuboids[o]
            push_out(pos, last, free, row, 1.0 - row[15], 0.5 * min(row[3], min(row[4], row[5])), CUBOID_CARRY,
                      cuboid_surface, offset)


@njit(**KERNEL)
def reach_cuboids(box: np.ndarray, cuboids: np.ndarray, on: np.ndarray, offset: float) -> int:
    """Mark the boxes whose bounds (world-axis box around the oriented one) meet the cloth's box;
    returns how many were ruled out."""
    skipped = 0
    for o in range(cuboids.shape[0]):
        row = cuboids[o]
        # half size of the world-axis bounds: sum over the box axes of |R[c, k]| h_k (plus the
        # offset a corrected point may be put at, so a point on the surface stays in reach)
        ex = abs(row[6]) * row[3] + abs(row[7]) * row[4] + abs(row[8]) * row[5] + offset
        ey = abs(row[9]) * row[3] + abs(row[10]) * row[4] + abs(row[11]) * row[5] + offset
        ez = abs(row[12]) * row[3] + abs(row[13]) * row[4] + abs(row[14]) * row[5] + offset
        on[o] = overlaps(box, row[CUBOID_CARRY], row[CUBOID_CARRY + 1], row[CUBOID_CARRY + 2],
                         row[0] - ex, row[1] - ey, row[2] - ez, row[0] + ex, row[1] + ey, row[2] + ez)
        skipped += 0 if on[o] else 1
    return skipped


# -- the kind's passes (see clothsim.sim.passes.colliders) -----------------------------------------

@njit(**KERNEL)
def pose(g: Boxes, substep: int) -> None:
    """Put the moving boxes at their pose at the end of substep ``substep``."""
    pose_rows(g.tracks, g.rows, 1, g.rows, CUBOID_CARRY, substep)


@njit(**KERNEL)
def reach(g: Boxes, box: np.ndarray, on: np.ndarray, offset: float) -> int:
    """Mark the boxes the cloth's box reaches in ``on``; returns how many were ruled out."""
    return reach_cuboids(box, g.rows, on, offset)


@njit(**KERNEL)
def collide(g: Boxes, pos: np.ndarray, last: np.ndarray, free: np.ndarray, c: int, on: np.ndarray,
            offset: float) -> None:
    """Work item ``c`` (of CHUNKS) of the free points against the reachable boxes."""
    collide_cuboids(pos, last, chunk_of(free, c), g.rows, on, offset)
