"""What the closed shapes (spheres, capsules, oriented boxes) share: the push onto a ball's surface,
the swept test along each point's relative path, and the reach test of their bounds.

Rows (float64), one per collider, each ending with ``carry``: how far the collider moved during
the current substep (zero for a static one; written by its kind's ``pose``): see :mod:`.capsule`
and :mod:`.box` for the columns.

A point is tested in the collider's frame of motion: its last position is carried along by the
collider's displacement (``last + carry``), so the test sees the point's motion relative to the
collider, and friction keeps ``1 - friction`` of that relative motion (a cloth resting on a moving
box is dragged along with it).

Tunnelling: a closed shape catches a point only while the point is inside it, and a point can
cross a thin shape within one substep when the shape moves fast. The relative path from the
carried last position to the current one is therefore sub-sampled, at most half the shape's
smallest size apart (:func:`samples`); the first sample found inside is pushed out to the nearest
surface point (for the usual small step that is one sample: the current position, as spheres are
tested). Pushed points land on the capsule's surface (as on a sphere) or SURFACE_OFFSET outside the
box's nearest face (as on a plane).
"""

from __future__ import annotations

from typing import Any

import numpy as np
from numba import njit

from ....jit import KERNEL
from .moving import carried, carried_box

#: Most samples taken along one point's relative path in one substep (a bound for blown-up states).
MAX_SAMPLES = 64


@njit(**KERNEL)
def samples(dx: float, dy: float, dz: float, step: float) -> int:
    """How many evenly spaced samples keep a path (dx, dy, dz) at most ``step`` apart (1..MAX_SAMPLES)."""
    d2 = dx * dx + dy * dy + dz * dz
    if d2 <= step * step:
        return 1
    n = np.sqrt(d2) / step
    if not n < MAX_SAMPLES - 1:  # also NaN
        return MAX_SAMPLES
    return int(n) + 1


@njit(inline="always", **KERNEL)
def ball_surface(x: float, y: float, z: float, cx: float, cy: float, cz: float,
                 r: float) -> tuple[bool, float, float, float]:
    """(inside, surface point) of the ball of radius ``r`` about c: a point inside goes to the
    surface point in its direction from c (c itself has no direction and is left alone). A
    sphere is one; a capsule is the one about the axis point nearest the point."""
    dx = x - cx
    dy = y - cy
    dz = z - cz
    d2 = dx * dx + dy * dy + dz * dz
    if d2 <= r * r and d2 > 0.0:
        s = r / np.sqrt(d2)
        return True, cx + dx * s, cy + dy * s, cz + dz * s
    return False, x, y, z


@njit(inline="always", **KERNEL)
def _push_from(pos: np.ndarray, p: int, lx: float, ly: float, lz: float, row: np.ndarray, keep: float, step: float,
               surface: Any, offset: float) -> None:
    # point p's relative path from (lx, ly, lz), sampled ``step`` apart: the first sample inside
    # is pushed out, keeping ``keep`` of the relative motion (the swept passes' one body)
    x = pos[0, p]
    y = pos[1, p]
    z = pos[2, p]
    n = samples(x - lx, y - ly, z - lz, step)
    for j in range(1, n + 1):
        if j < n:
            s = j / n
            hit, tx, ty, tz = surface(lx + (x - lx) * s, ly + (y - ly) * s, lz + (z - lz) * s, row, offset)
        else:
            hit, tx, ty, tz = surface(x, y, z, row, offset)
        if hit:
            pos[0, p] = lx + (tx - lx) * keep
            pos[1, p] = ly + (ty - ly) * keep
            pos[2, p] = lz + (tz - lz) * keep
            return


@njit(inline="always", **KERNEL)
def push_out(pos: np.ndarray, last: np.ndarray, free: np.ndarray, row: np.ndarray, keep: float, step: float,
             cx: float, cy: float, cz: float, surface: Any, offset: float) -> None:
    """One shape's swept pass: each free point's relative path from its last position carried by
    (cx, cy, cz), sampled ``step`` apart; the first sample ``surface`` (given the shape's ``row``)
    finds inside is pushed out, keeping ``keep`` of the relative motion (friction). The moving
    sphere's test is this pass too.

    The capsule's ``surface`` is declared ``inline="always"``, so it is always part of this loop's
    own code: compiled as a callee of its own, it left the loop's machine code (fast-math)
    different in the last bits depending on whether it had been compiled in the same process or
    loaded from the cache, so the capsule scene gave other numbers after a cold start than after
    a warm one (docs/history/determinism.md). The box's does not (checked the same way), and
    inlining it would change the box's numbers, so it is left a callee."""
    for k in range(free.shape[0]):
        p = free[k]
        lx = last[0, p] + cx
        ly = last[1, p] + cy
        lz = last[2, p] + cz
        _push_from(pos, p, lx, ly, lz, row, keep, step, surface, offset)


@njit(inline="always", **KERNEL)
def push_out_turning(pos: np.ndarray, last: np.ndarray, free: np.ndarray, row: np.ndarray, keep: float, step: float,
                     mo: np.ndarray, surface: Any, offset: float) -> None:
    """:func:`push_out` for a collider that may turn: each point's last position carried by the
    collider's motion over the substep ``mo`` (a row of :attr:`~.moving.Turns.motion`), so that the
    relative path, and the friction along it, are relative to the turning surface."""
    for k in range(free.shape[0]):
        p = free[k]
        lx, ly, lz = carried(mo, last[0, p], last[1, p], last[2, p])
        _push_from(pos, p, lx, ly, lz, row, keep, step, surface, offset)


@njit(**KERNEL)
def overlaps_turning(box: np.ndarray, mo: np.ndarray, lo_x: float, lo_y: float, lo_z: float, hi_x: float,
                     hi_y: float, hi_z: float) -> bool:
    """:func:`overlaps` for a collider that may turn: the cloth's box with its image under the
    collider's motion ``mo`` (:func:`~.moving.carried_box`) meets the box [lo, hi]."""
    b0, b1, b2, b3, b4, b5 = carried_box(box, mo)
    return not (hi_x < b0 or lo_x > b3 or hi_y < b1 or lo_y > b4 or hi_z < b2 or lo_z > b5)


@njit(**KERNEL)
def overlaps(box: np.ndarray, carry_x: float, carry_y: float, carry_z: float, lo_x: float, lo_y: float,
             lo_z: float, hi_x: float, hi_y: float, hi_z: float) -> bool:
    """True when the cloth's box, stretched by the collider's carry, meets the box [lo, hi].

    Every sample of a relative path lies between ``last + carry`` and ``pos``, so inside that
    stretched box: a collider whose bounds miss it cannot act this substep."""
    if hi_x < box[0] + min(carry_x, 0.0) or lo_x > box[3] + max(carry_x, 0.0):
        return False
    if hi_y < box[1] + min(carry_y, 0.0) or lo_y > box[4] + max(carry_y, 0.0):
        return False
    return not (hi_z < box[2] + min(carry_z, 0.0) or lo_z > box[5] + max(carry_z, 0.0))
