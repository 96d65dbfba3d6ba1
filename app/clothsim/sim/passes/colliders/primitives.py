"""Collisions with static spheres and planes, batched per collider kind.

Spheres are packed as rows (ox, oy, oz, radius, friction), planes as rows
(px, py, pz, nx, ny, nz, friction) with unit normals. Every point is tested against every
sphere, then every plane (the order only matters for a point touching two colliders).
"""

from __future__ import annotations

import numpy as np
from numba import njit

from ....jit import KERNEL

# The spec's SURFACE_OFFSET: how far above a plane a corrected point is put.
SURFACE_OFFSET = 0.0001


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
def collide_planes(pos: np.ndarray, last: np.ndarray, free: np.ndarray, planes: np.ndarray,
                   offset: float) -> None:
    """Bounce back points that crossed a plane during the last step.

    A point whose last position lies exactly on the plane counts as being on the normal's side,
    so a cloth row that starts on the floor does not fall through it.
    """
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
