"""The sphere collider kind: rows (ox, oy, oz, radius, friction), one per sphere.

A point inside a sphere goes to its surface, moving from its last position towards that surface
point by (1 - friction). In a scene where nothing moves this tests the current position (the
spec's rule). In a scene where any collider moves, every sphere takes the swept test instead
(``carry`` is then an array; zero for a sphere that does not move): the point's path relative to
the sphere, from its carried last position, is sub-sampled at most half a radius apart and the
first sample inside is pushed out, with friction relative to the sphere's motion. A turning sphere
(a turn about its origin) keeps its shape, but carries what rests on it round with friction: its
points' last positions are carried by its motion over the substep (:func:`~.shapes.push_out_turning`).
"""

from __future__ import annotations


import numpy as np
from numba import njit

from ....jit import KERNEL
from .rows import collide, packer, pose, reach, row_group
from .moving import carried_box
from .shapes import ball_surface, push_out, push_out_turning

__all__ = ["ALWAYS", "CARRY_AT", "Group", "POINTS", "Spheres", "TURNS", "collide", "collide_rows", "pack", "pose", "reach",
           "reach_rows", "sphere_surface"]


#: The scene's spheres: their rows (ox, oy, oz, radius, friction), reach flags, carries and tracks.
Group = Spheres = row_group("Spheres", __name__, "The scene's spheres (see clothsim.sim.passes.colliders.rows).",
                            True)
#: In every plan with colliders, empty when the scene has no spheres: the course's kinds, so that the
#: course's scenes (a sphere, a plane, both) share one compiled plan, as they always have.
ALWAYS = True
#: A pose moves a sphere's origin; its carry is the group's own array (see :mod:`.rows`).
POINTS, CARRY_AT = 1, 0
#: A turn turns no direction of a sphere's row.
TURNS = ()
pack = packer(Spheres, "spheres", lambda s: (*s.origin, s.radius, s.friction), 5, lambda s: s.origin)


@njit(inline="always", **KERNEL)
def sphere_surface(x: float, y: float, z: float, row: np.ndarray, offset: float) -> tuple[bool, float, float, float]:
    """(inside, surface point): the point of the sphere's surface in the direction of (x, y, z)
    from its centre, when the point is inside (the centre itself has no direction and is left
    alone). ``offset`` is unused: points land on a sphere's surface."""
    return ball_surface(x, y, z, row[0], row[1], row[2], row[3])


@njit(**KERNEL)
def collide_rows(pos: np.ndarray, last: np.ndarray, free: np.ndarray, spheres: np.ndarray, on: np.ndarray,
                 carry: np.ndarray | None, turn: np.ndarray | None, offset: float) -> None:
    """Push points inside a reachable sphere to its surface, moving from ``last`` by
    (1 - friction): the point as it is now (the spec's rule), or, with ``carry`` (a scene where
    something moves), the first sample inside along its path relative to the sphere, at most half
    a radius apart (:func:`~.shapes.push_out`)."""
    for o in range(spheres.shape[0]):
        if not on[o]:
            continue
        row = spheres[o]
        keep = 1.0 - row[4]
        if carry is None:
            for k in range(free.shape[0]):
                p = free[k]
                hit, tx, ty, tz = sphere_surface(pos[0, p], pos[1, p], pos[2, p], row, offset)
                if hit:
                    # move from last towards the surface point
                    pos[0, p] = last[0, p] + (tx - last[0, p]) * keep
                    pos[1, p] = last[1, p] + (ty - last[1, p]) * keep
                    pos[2, p] = last[2, p] + (tz - last[2, p]) * keep
        elif turn is None:
            push_out(pos, last, free, row, keep, 0.5 * row[3], carry[o, 0], carry[o, 1], carry[o, 2], sphere_surface,
                     offset)
        else:
            push_out_turning(pos, last, free, row, keep, 0.5 * row[3], turn[o], sphere_surface, offset)


@njit(**KERNEL)
def reach_rows(box: np.ndarray, spheres: np.ndarray, on: np.ndarray, carry: np.ndarray | None,
               turn: np.ndarray | None, offset: float) -> int:
    """Mark the spheres the cloth's box (stretched by each sphere's carry where something moves)
    reaches; returns how many were ruled out."""
    skipped = 0
    for o in range(spheres.shape[0]):
        d2 = 0.0
        if turn is not None:
            cb = carried_box(box, turn[o])
        for c in range(3):
            x = spheres[o, c]
            lo = box[c]
            hi = box[3 + c]
            if turn is not None:
                lo = cb[c]
                hi = cb[3 + c]
            elif carry is not None:
                lo = lo + min(carry[o, c], 0.0)
                hi = hi + max(carry[o, c], 0.0)
            if x < lo:
                d2 += (lo - x) ** 2
            elif x > hi:
                d2 += (x - hi) ** 2
        on[o] = d2 <= spheres[o, 3] ** 2
        skipped += 0 if on[o] else 1
    return skipped
