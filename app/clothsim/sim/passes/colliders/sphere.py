"""The sphere collider kind: rows (ox, oy, oz, radius, friction), one per sphere.

A point inside a sphere goes to its surface, moving from its last position towards that surface
point by (1 - friction). In a scene where nothing moves this tests the current position (the
spec's rule). In a scene where any collider moves, every sphere takes the swept test instead
(``carry`` is then an array; zero for a sphere that does not move): the point's path relative to
the sphere, from its carried last position, is sub-sampled at most half a radius apart and the
first sample inside is pushed out, with friction relative to the sphere's motion.
"""

from __future__ import annotations

from typing import Any, NamedTuple

import numpy as np
from numba import njit

from ....jit import KERNEL
from ...team import chunk_of
from .moving import Tracks, pack_tracks, pose_rows
from .shapes import samples


class Spheres(NamedTuple):
    """The scene's spheres: their rows, reach flags, carries (None where nothing in the scene
    moves) and the tracks of the moving ones (None when none moves)."""

    rows: np.ndarray
    on: np.ndarray
    carry: np.ndarray | None
    tracks: Tracks | None


Group = Spheres
#: In every plan with colliders, empty when the scene has no spheres: the course's kinds, so that the
#: course's scenes (a sphere, a plane, both) share one compiled plan, as they always have.
ALWAYS = True


def pack(scene: Any, clock: np.ndarray, dt: float, swept: bool) -> Spheres:
    """The group of ``scene``'s spheres; ``swept``: something in the scene moves. Always a group,
    empty for a scene without spheres (see :data:`ALWAYS`)."""
    rows = np.array([[*s.origin, s.radius, s.friction] for s in scene.spheres], dtype=np.float64).reshape(-1, 5)
    return Spheres(rows, np.zeros(len(rows), dtype=np.bool_), np.zeros((len(rows), 3)) if swept else None,
                   pack_tracks(scene.spheres, clock, dt, lambda s: s.origin))


@njit(**KERNEL)
def collide_spheres(pos: np.ndarray, last: np.ndarray, free: np.ndarray, spheres: np.ndarray) -> None:
    """Push points inside a sphere to its surface, moving from ``last`` scaled by (1 - friction)."""
    for o in range(spheres.shape[0]):
        ox = spheres[o, 0]
        oy = spheres[o, 1]
        oz = spheres[o, 2]
        r = spheres[o, 3]
        keep = 1.0 - spheres[o, 4]
        r2 = r * r
        for k in range(free.shape[0]):
            p = free[k]
            dx = pos[0, p] - ox
            dy = pos[1, p] - oy
            dz = pos[2, p] - oz
            d2 = dx * dx + dy * dy + dz * dz
            if d2 <= r2 and d2 > 0.0:
                s = r / np.sqrt(d2)
                # tangent point = origin + r * direction; move from last towards it
                pos[0, p] = last[0, p] + (ox + dx * s - last[0, p]) * keep
                pos[1, p] = last[1, p] + (oy + dy * s - last[1, p]) * keep
                pos[2, p] = last[2, p] + (oz + dz * s - last[2, p]) * keep


@njit(**KERNEL)
def collide_moving_spheres(pos: np.ndarray, last: np.ndarray, free: np.ndarray, spheres: np.ndarray,
                           on: np.ndarray, carry: np.ndarray) -> None:
    """Spheres tested along each point's path relative to the sphere, sub-sampled at most half a
    radius apart; the first sample inside is pushed to the surface, with friction relative to the
    sphere's motion."""
    for o in range(spheres.shape[0]):
        if not on[o]:
            continue
        ox = spheres[o, 0]
        oy = spheres[o, 1]
        oz = spheres[o, 2]
        r = spheres[o, 3]
        keep = 1.0 - spheres[o, 4]
        r2 = r * r
        step = 0.5 * r
        for k in range(free.shape[0]):
            p = free[k]
            lx = last[0, p] + carry[o, 0]
            ly = last[1, p] + carry[o, 1]
            lz = last[2, p] + carry[o, 2]
            x = pos[0, p]
            y = pos[1, p]
            z = pos[2, p]
            n = samples(x - lx, y - ly, z - lz, step)
            for j in range(1, n + 1):
                sx = x
                sy = y
                sz = z
                if j < n:
                    w = j / n
                    sx = lx + (x - lx) * w
                    sy = ly + (y - ly) * w
                    sz = lz + (z - lz) * w
                dx = sx - ox
                dy = sy - oy
                dz = sz - oz
                d2 = dx * dx + dy * dy + dz * dz
                if d2 <= r2 and d2 > 0.0:
                    s = r / np.sqrt(d2)
                    pos[0, p] = lx + (ox + dx * s - lx) * keep
                    pos[1, p] = ly + (oy + dy * s - ly) * keep
                    pos[2, p] = lz + (oz + dz * s - lz) * keep
                    break


@njit(**KERNEL)
def reach_spheres(box: np.ndarray, spheres: np.ndarray, on: np.ndarray) -> int:
    """Mark the spheres the cloth's box reaches; returns how many were ruled out."""
    skipped = 0
    for o in range(spheres.shape[0]):
        d2 = 0.0
        for c in range(3):
            x = spheres[o, c]
            if x < box[c]:
                d2 += (box[c] - x) ** 2
            elif x > box[3 + c]:
                d2 += (x - box[3 + c]) ** 2
        on[o] = d2 <= spheres[o, 3] ** 2
        skipped += 0 if on[o] else 1
    return skipped


@njit(**KERNEL)
def reach_moving_spheres(box: np.ndarray, spheres: np.ndarray, on: np.ndarray, carry: np.ndarray) -> int:
    """:func:`reach_spheres` with the cloth's box stretched by each sphere's carry."""
    skipped = 0
    for o in range(spheres.shape[0]):
        d2 = 0.0
        for c in range(3):
            x = spheres[o, c]
            lo = box[c] + min(carry[o, c], 0.0)
            hi = box[3 + c] + max(carry[o, c], 0.0)
            if x < lo:
                d2 += (lo - x) ** 2
            elif x > hi:
                d2 += (x - hi) ** 2
        on[o] = d2 <= spheres[o, 3] ** 2
        skipped += 0 if on[o] else 1
    return skipped


# -- the kind's passes (see clothsim.sim.passes.colliders) -----------------------------------------

@njit(**KERNEL)
def pose(g: Spheres, substep: int) -> None:
    """Put the moving spheres at their pose at the end of substep ``substep``."""
    pose_rows(g.tracks, g.rows, 1, g.carry, 0, substep)


@njit(**KERNEL)
def reach(g: Spheres, box: np.ndarray, on: np.ndarray, offset: float) -> int:
    """Mark the spheres the cloth's box reaches in ``on``; returns how many were ruled out."""
    return _reach(box, g.rows, on, g.carry)


@njit(**KERNEL)
def _reach(box: np.ndarray, rows: np.ndarray, on: np.ndarray, carry: np.ndarray | None) -> int:
    # (the carry passed on its own: Numba prunes a branch on an argument that is None)
    if carry is None:
        return reach_spheres(box, rows, on)
    return reach_moving_spheres(box, rows, on, carry)


@njit(**KERNEL)
def collide(g: Spheres, pos: np.ndarray, last: np.ndarray, free: np.ndarray, c: int, on: np.ndarray,
            offset: float) -> None:
    """Work item ``c`` (of CHUNKS) of the free points against the reachable spheres."""
    _collide(pos, last, chunk_of(free, c), g.rows, on, g.carry)


@njit(**KERNEL)
def _collide(pos: np.ndarray, last: np.ndarray, part: np.ndarray, rows: np.ndarray, on: np.ndarray,
             carry: np.ndarray | None) -> None:
    if carry is None:
        for o in range(rows.shape[0]):
            if on[o]:
                collide_spheres(pos, last, part, rows[o : o + 1])
    else:
        collide_moving_spheres(pos, last, part, rows, on, carry)
