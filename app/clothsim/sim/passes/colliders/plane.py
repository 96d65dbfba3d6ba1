"""The plane collider kind: rows (px, py, pz, nx, ny, nz, friction) with unit normals.

A point that crossed a plane during the substep (its signed distance changed sign between its
last position and now) goes back onto the plane, lifted by ``SURFACE_OFFSET`` on the side it came
from, moving from its last position towards there by (1 - friction). A point whose last position
lies exactly on the plane counts as being on the normal's side, so a cloth row that starts on the
floor does not fall through it. In a scene where any collider moves, the test is made in the
plane's moving frame (the last position carried along by the plane's displacement): exact at any
speed of the plane. A turning plane (a turn about its point turns its normal) carries the last
position by its motion over the substep instead (:func:`~.moving.carried`): the same test, relative
to the turning plane.
"""

from __future__ import annotations


import numpy as np
from numba import njit

from ....jit import KERNEL
from .moving import carried, carried_box
from .rows import collide, packer, pose, reach, row_group

__all__ = ["ALWAYS", "CARRY_AT", "Group", "POINTS", "Planes", "SURFACE_OFFSET", "TURNS", "collide", "collide_rows", "pack",
           "pose", "reach", "reach_rows"]

#: The spec's SURFACE_OFFSET: how far above a plane (or outside a box) a corrected point is put.
SURFACE_OFFSET = 0.0001


#: The scene's planes: their rows (px, py, pz, nx, ny, nz, friction), reach flags, carries and tracks.
Group = Planes = row_group("Planes", __name__, "The scene's planes (see clothsim.sim.passes.colliders.rows).", True)
#: In every plan with colliders, empty when the scene has no planes: the course's kinds, so that the
#: course's scenes (a sphere, a plane, both) share one compiled plan, as they always have.
ALWAYS = True
#: A pose moves a plane's point; its carry is the group's own array (see :mod:`.rows`).
POINTS, CARRY_AT = 1, 0
#: A turn turns a plane's normal.
TURNS = ((3, 4, 5),)
pack = packer(Planes, "planes", lambda p: (*p.point, *p.normal, p.friction), 7, lambda p: p.point, TURNS,
              lambda p: p.normal)


@njit(**KERNEL)
def collide_rows(pos: np.ndarray, last: np.ndarray, free: np.ndarray, planes: np.ndarray, on: np.ndarray,
                 carry: np.ndarray | None, turn: np.ndarray | None, offset: float) -> None:
    """Bounce back points that crossed a reachable plane during the last step (see the module's
    notes); with ``carry`` (a scene where something moves), in each plane's moving frame: a
    point crossed a plane when its distance from it changed sign between its carried last
    position and now (exact for any speed of the plane)."""
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
            lx = last[0, p]
            ly = last[1, p]
            lz = last[2, p]
            if turn is not None:
                lx, ly, lz = carried(turn[o], lx, ly, lz)
            elif carry is not None:
                lx = lx + carry[o, 0]
                ly = ly + carry[o, 1]
                lz = lz + carry[o, 2]
            now = (pos[0, p] - px) * nx + (pos[1, p] - py) * ny + (pos[2, p] - pz) * nz
            before = (lx - px) * nx + (ly - py) * ny + (lz - pz) * nz
            if (before >= 0.0) != (now >= 0.0):
                side = offset if before >= 0.0 else -offset
                # target = projection of pos onto the plane, lifted to the side it came from
                shift = side - now
                pos[0, p] = lx + (pos[0, p] + nx * shift - lx) * keep
                pos[1, p] = ly + (pos[1, p] + ny * shift - ly) * keep
                pos[2, p] = lz + (pos[2, p] + nz * shift - lz) * keep


@njit(**KERNEL)
def reach_rows(box: np.ndarray, planes: np.ndarray, on: np.ndarray, carry: np.ndarray | None,
               turn: np.ndarray | None, offset: float) -> int:
    """Mark the planes the cloth's box (of current and last positions; stretched by each plane's
    carry where something moves) is not wholly on one side of; returns how many were ruled out."""
    skipped = 0
    # the box widened by the turn or the carry as in sphere.py's reach (the duplicate-code scan
    # pairs the two by shape): each kind then tests the box its own way inside the same loop
    for o in range(planes.shape[0]):
        lo = 0.0
        hi = 0.0
        if turn is not None:
            cb = carried_box(box, turn[o])
        for c in range(3):
            n = planes[o, 3 + c]
            near = box[c]
            far = box[3 + c]
            if turn is not None:
                near = cb[c]
                far = cb[3 + c]
            elif carry is not None:
                near = near + min(carry[o, c], 0.0)
                far = far + max(carry[o, c], 0.0)
            a = (near - planes[o, c]) * n
            b = (far - planes[o, c]) * n
            lo += a if a < b else b
            hi += a if a > b else b
        # every point strictly on the normal's side, or strictly behind: nothing can cross
        on[o] = not (lo > 0.0 or hi < 0.0)
        skipped += 0 if on[o] else 1
    return skipped
