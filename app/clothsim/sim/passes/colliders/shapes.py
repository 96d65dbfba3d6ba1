"""Capsule and oriented-box colliders, batched per kind, with friction and moving poses.

Rows (float64), one per collider, each ending with ``carry``: how far the collider moved during
the current substep (zero for a static one; written by :mod:`clothsim.sim.passes.colliders.moving`):

* capsules (C, 11): ax ay az, bx by bz, radius, friction, carry xyz;
* cuboids (B, 19): cx cy cz, hx hy hz (half extents), R (9, row-major; column k is the box's
  k-th axis in world space), friction, carry xyz.

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

#: Columns of a capsule row and of a box row (see the module's docstring).
CAPSULE_COLUMNS = 11
CUBOID_COLUMNS = 19
#: Where the carry (displacement over the substep) starts in each row.
CAPSULE_CARRY = 8
CUBOID_CARRY = 16
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


@njit(**KERNEL)
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


@njit(inline="always", **KERNEL)
def _push_out(pos: np.ndarray, last: np.ndarray, free: np.ndarray, row: np.ndarray, keep: float, step: float,
              carry_at: int, surface: Any, offset: float) -> None:
    """One closed shape's pass: each free point's relative path from its carried last position,
    sampled ``step`` apart; the first sample ``surface`` finds inside is pushed out, keeping
    ``keep`` of the relative motion (friction)."""
    cx = row[carry_at]
    cy = row[carry_at + 1]
    cz = row[carry_at + 2]
    for k in range(free.shape[0]):
        p = free[k]
        lx = last[0, p] + cx
        ly = last[1, p] + cy
        lz = last[2, p] + cz
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
                break


@njit(**KERNEL)
def collide_capsules(pos: np.ndarray, last: np.ndarray, free: np.ndarray, capsules: np.ndarray,
                     on: np.ndarray) -> None:
    """Push the points inside each reachable capsule to its surface, with friction (see module)."""
    for o in range(capsules.shape[0]):
        if on[o]:
            row = capsules[o]
            _push_out(pos, last, free, row, 1.0 - row[7], 0.5 * row[6], CAPSULE_CARRY, capsule_surface, 0.0)


@njit(**KERNEL)
def collide_cuboids(pos: np.ndarray, last: np.ndarray, free: np.ndarray, cuboids: np.ndarray, on: np.ndarray,
                    offset: float) -> None:
    """Push the points inside each reachable box out of its nearest face, with friction (see module)."""
    for o in range(cuboids.shape[0]):
        if on[o]:
            row = cuboids[o]
            _push_out(pos, last, free, row, 1.0 - row[15], 0.5 * min(row[3], min(row[4], row[5])), CUBOID_CARRY,
                      cuboid_surface, offset)


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


@njit(**KERNEL)
def reach_shapes(box: np.ndarray, capsules: np.ndarray | None, cuboids: np.ndarray | None,
                 capsule_on: np.ndarray | None, cuboid_on: np.ndarray | None, offset: float) -> int:
    """:func:`reach_capsules` and :func:`reach_cuboids` for the kinds the scene has (``None``
    otherwise: Numba prunes a kind that is ``None`` before typing, so it costs no compile time)."""
    skipped = 0
    if capsules is not None:
        skipped += reach_capsules(box, capsules, capsule_on)
    if cuboids is not None:
        skipped += reach_cuboids(box, cuboids, cuboid_on, offset)
    return skipped


@njit(**KERNEL)
def collide_shapes(pos: np.ndarray, last: np.ndarray, part: np.ndarray, capsules: np.ndarray | None,
                   cuboids: np.ndarray | None, capsule_on: np.ndarray | None, cuboid_on: np.ndarray | None,
                   offset: float) -> None:
    """Capsules, then boxes, for the points ``part`` (kinds the scene lacks are ``None``)."""
    if capsules is not None:
        collide_capsules(pos, last, part, capsules, capsule_on)
    if cuboids is not None:
        collide_cuboids(pos, last, part, cuboids, cuboid_on, offset)


@njit(**KERNEL)
def flags_for(rows: np.ndarray | None, flags: np.ndarray | None) -> np.ndarray | None:
    """A member's own reach flags for one kind's rows: ``flags`` itself (None) for a kind the
    scene lacks. (Both branches return the same type when the kind is there: a ``return None``
    there would make the flags an optional array, checked at every use.)"""
    if rows is None:
        return flags
    return np.empty(rows.shape[0], dtype=np.bool_)


def collider_rows(scene: Any) -> tuple[np.ndarray, np.ndarray, np.ndarray | None, np.ndarray | None]:
    """The kernels' rows of ``scene``'s colliders as the scene places them: spheres (S, 5), planes
    (P, 7) (the course's kinds: always arrays), capsules (C, 11) and boxes (B, 19), or None for a
    kind the scene does not have."""
    spheres = np.array([[*s.origin, s.radius, s.friction] for s in scene.spheres], dtype=np.float64).reshape(-1, 5)
    planes = np.array([[*p.point, *p.normal, p.friction] for p in scene.planes], dtype=np.float64).reshape(-1, 7)
    capsules = cuboids = None
    if scene.capsules:
        capsules = np.array([[*c.a, *c.b, c.radius, c.friction, 0.0, 0.0, 0.0] for c in scene.capsules],
                            dtype=np.float64)
    if scene.boxes:
        cuboids = np.array([[*b.center, *b.half_extents, *(x for r in b.matrix() for x in r), b.friction, 0.0, 0.0,
                             0.0] for b in scene.boxes], dtype=np.float64)
    return spheres, planes, capsules, cuboids
