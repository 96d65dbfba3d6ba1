"""The oriented box collider kind: ``center``, half extents along its own axes and a rotation.

Rows (B, 19) float64: cx cy cz, hx hy hz (half extents), R (9, row-major; column k is the box's
k-th axis in world space), friction, carry xyz (how far the box moved during the current substep;
zero for a static one). Points inside are pushed ``SURFACE_OFFSET`` outside the nearest face (as
on a plane) along their path relative to the box (:func:`~.shapes.push_out`, or
:func:`~.shapes.push_out_turning` where a box turns: a turn turns its axes, the matrix's columns).
"""

from __future__ import annotations


import numpy as np
from numba import njit

from ....jit import KERNEL
from .rows import collide, packer, pose, reach, row_group
from .shapes import overlaps, overlaps_turning, push_out, push_out_turning

__all__ = ["Boxes", "CARRY_AT", "CUBOID_CARRY", "CUBOID_COLUMNS", "Group", "POINTS", "TURNS", "collide",
           "collide_rows", "cuboid_surface", "pack", "pose", "reach", "reach_rows"]

# (each kind of rows declares the same things, so the duplicate-code scan pairs this block with
# capsule.py's by shape; the values are the kind's own)
#: Columns of a row, and where its carry starts.
CUBOID_COLUMNS = 19
CUBOID_CARRY = 16


#: The scene's boxes: their rows, reach flags and tracks.
Group = Boxes = row_group("Boxes", __name__, "The scene's boxes (see clothsim.sim.passes.colliders.rows).")
#: A pose moves a box's center; its carry is the last three columns of its row (see :mod:`.rows`).
POINTS, CARRY_AT = 1, CUBOID_CARRY
#: A turn turns a box's three axes: the columns of R (row-major from column 6).
TURNS = ((6, 9, 12), (7, 10, 13), (8, 11, 14))
pack = packer(Boxes, "boxes", lambda b: (*b.center, *b.half_extents, *(x for r in b.matrix() for x in r), b.friction,
                                         0.0, 0.0, 0.0), CUBOID_COLUMNS, lambda b: b.center, TURNS,
              lambda b: tuple(b.matrix()[i][k] for k in range(3) for i in range(3)))


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
def collide_rows(pos: np.ndarray, last: np.ndarray, free: np.ndarray, cuboids: np.ndarray, on: np.ndarray,
                 turn: np.ndarray | None, offset: float) -> None:
    """Push the points inside each reachable box out of its nearest face, with friction (see module)."""
    for o in range(cuboids.shape[0]):
        if on[o]:
            row = cuboids[o]
            if turn is None:
                push_out(pos, last, free, row, 1.0 - row[15], 0.5 * min(row[3], min(row[4], row[5])),
                         row[CUBOID_CARRY], row[CUBOID_CARRY + 1], row[CUBOID_CARRY + 2], cuboid_surface, offset)
            else:
                push_out_turning(pos, last, free, row, 1.0 - row[15], 0.5 * min(row[3], min(row[4], row[5])),
                                 turn[o], cuboid_surface, offset)


@njit(**KERNEL)
def reach_rows(box: np.ndarray, cuboids: np.ndarray, on: np.ndarray, turn: np.ndarray | None, offset: float) -> int:
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
        if turn is None:
            on[o] = overlaps(box, row[CUBOID_CARRY], row[CUBOID_CARRY + 1], row[CUBOID_CARRY + 2],
                             row[0] - ex, row[1] - ey, row[2] - ez, row[0] + ex, row[1] + ey, row[2] + ez)
        else:
            on[o] = overlaps_turning(box, turn[o], row[0] - ex, row[1] - ey, row[2] - ez, row[0] + ex, row[1] + ey,
                                     row[2] + ez)
        skipped += 0 if on[o] else 1
    return skipped
