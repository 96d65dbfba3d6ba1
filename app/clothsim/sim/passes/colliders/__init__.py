"""The collider pass: the cloth's bounding box, the test of which colliders it can reach (a sphere
the box does not reach, or a plane the box of current and last positions lies wholly on one side
of, cannot act this substep and is skipped exactly), and the collisions themselves, kind by kind in
scene order. The thread team (:mod:`clothsim.sim.solvers.frame`) runs the work items (:func:`collide_part`) of the same
functions as :func:`collide_reachable`, the other integrators' pass.
"""

from __future__ import annotations

import numpy as np
from numba import njit, prange

from ....jit import CHUNKS, KERNEL, PARALLEL
from .primitives import collide_planes, collide_spheres
from .moving import collide_moving_planes, collide_moving_spheres, reach_moving, update_poses
from .shapes import collide_shapes, reach_shapes
from ...team import share


@njit(**KERNEL)
def cloth_bounds(pos: np.ndarray, last: np.ndarray, box: np.ndarray) -> None:
    """box = [min xyz, max xyz] over the current and last positions of all points.

    Pinned points are included: they only widen the box, which keeps the skip test exact, and
    the sweep stays contiguous (vectorised).
    """
    range_bounds(pos, last, 0, pos.shape[1], box, np.empty((2, 64)))


@njit(inline="always", **KERNEL)
def range_bounds(pos: np.ndarray, last: np.ndarray, lo: int, hi: int, box: np.ndarray, cols: np.ndarray) -> None:
    """box = [min xyz, max xyz] over the current and last positions of the points lo..hi-1;
    ``cols`` is (2, 64) work space."""
    # Columns of the range as independent running minima/maxima: one running value would chain
    # every comparison, and LLVM does not vectorise a floating-point min reduction unless NaNs
    # are ruled out. Here the inner loop is element-wise over a row, so it vectorises.
    n = hi - lo
    if n <= 0:
        box[:3] = np.inf
        box[3:] = -np.inf
        return
    w = min(n, 64)
    lo_c = cols[0, :w]
    hi_c = cols[1, :w]
    for c in range(3):
        first = pos[c, lo : lo + w]
        for j in range(w):
            lo_c[j] = first[j]
            hi_c[j] = first[j]
        for r0 in range(lo, hi, w):
            x = pos[c, r0 : min(r0 + w, hi)]
            xl = last[c, r0 : min(r0 + w, hi)]
            for j in range(x.shape[0]):
                a = x[j]
                b = xl[j]
                m = a if a < b else b
                lo_c[j] = m if m < lo_c[j] else lo_c[j]
                m = a if a > b else b
                hi_c[j] = m if m > hi_c[j] else hi_c[j]
        box[c] = lo_c.min()
        box[3 + c] = hi_c.max()


@njit(inline="always", **KERNEL)
def member_bounds(pos: np.ndarray, last: np.ndarray, boxes: np.ndarray, cols: np.ndarray, lo: int, hi: int) -> None:
    """Bound the points of chunks lo..hi-1 (a member's share) in one sweep into boxes[lo], and
    empty the rows lo+1..hi-1: the union of the rows is then the cloth's box whatever the team
    size (min and max are exact), and one long sweep vectorises where eight short ones ran at
    half the speed."""
    if lo >= hi:
        return
    n = pos.shape[1]
    range_bounds(pos, last, share(n, lo, CHUNKS)[0], share(n, hi, CHUNKS)[0], boxes[lo], cols)
    for c in range(lo + 1, hi):
        boxes[c, :3] = np.inf
        boxes[c, 3:] = -np.inf


@njit(inline="always", **KERNEL)
def merge_bounds(boxes: np.ndarray, margin: float, box: np.ndarray) -> None:
    """box = the union of the rows of ``boxes``, widened by ``margin`` on every side."""
    for c in range(3):
        lo = boxes[0, c]
        hi = boxes[0, 3 + c]
        for r in range(1, boxes.shape[0]):
            lo = min(lo, boxes[r, c])
            hi = max(hi, boxes[r, 3 + c])
        box[c] = lo - margin
        box[3 + c] = hi + margin


@njit(**KERNEL)
def reachable_colliders(box: np.ndarray, spheres: np.ndarray, planes: np.ndarray, sphere_on: np.ndarray,
                        plane_on: np.ndarray) -> int:
    """Mark which colliders the bounding box may touch; returns how many were ruled out."""
    skipped = 0
    for o in range(spheres.shape[0]):
        d2 = 0.0
        for c in range(3):
            x = spheres[o, c]
            if x < box[c]:
                d2 += (box[c] - x) ** 2
            elif x > box[3 + c]:
                d2 += (x - box[3 + c]) ** 2
        sphere_on[o] = d2 <= spheres[o, 3] ** 2
        skipped += 0 if sphere_on[o] else 1
    for o in range(planes.shape[0]):
        lo = 0.0
        hi = 0.0
        for c in range(3):
            n = planes[o, 3 + c]
            a = (box[c] - planes[o, c]) * n
            b = (box[3 + c] - planes[o, c]) * n
            lo += a if a < b else b
            hi += a if a > b else b
        # every point strictly on the normal's side, or strictly behind: nothing can cross
        plane_on[o] = not (lo > 0.0 or hi < 0.0)
        skipped += 0 if plane_on[o] else 1
    return skipped


@njit(inline="always", **KERNEL)
def collide_chunk(pos: np.ndarray, last: np.ndarray, free: np.ndarray, spheres: np.ndarray, planes: np.ndarray,
                  offset: float, sphere_on: np.ndarray, plane_on: np.ndarray, c: int) -> None:
    """The static spheres and planes for the c-th of CHUNKS parts of the free points."""
    n = free.shape[0]
    f0, f1 = share(n, c, CHUNKS)
    part = free[f0:f1]
    for o in range(spheres.shape[0]):
        if sphere_on[o]:
            collide_spheres(pos, last, part, spheres[o : o + 1])
    for o in range(planes.shape[0]):
        if plane_on[o]:
            collide_planes(pos, last, part, planes[o : o + 1], offset)


@njit(**KERNEL)
def reach_colliders(box: np.ndarray, col: tuple, sphere_on: np.ndarray, plane_on: np.ndarray,
                    capsule_on: np.ndarray | None, cuboid_on: np.ndarray | None, motion: tuple | None,
                    capsules: np.ndarray | None, cuboids: np.ndarray | None) -> int:
    """Mark which colliders of every kind the cloth's box may reach; returns how many were ruled out.

    ``motion``, ``capsules`` and ``cuboids`` are the group's optional fields passed on their own:
    Numba prunes a branch on an argument that is ``None`` (not on a tuple's field), so a scene
    compiles only the kinds it has."""
    if motion is None:
        skipped = reachable_colliders(box, col.spheres, col.planes, sphere_on, plane_on)
    else:
        skipped = reach_moving(box, col.spheres, col.planes, sphere_on, plane_on, motion)
    return skipped + reach_shapes(box, capsules, cuboids, capsule_on, cuboid_on, col.offset)


@njit(**KERNEL)
def collide_part(pos: np.ndarray, last: np.ndarray, col: tuple, sphere_on: np.ndarray, plane_on: np.ndarray,
                 capsule_on: np.ndarray | None, cuboid_on: np.ndarray | None, motion: tuple | None,
                 capsules: np.ndarray | None, cuboids: np.ndarray | None, c: int) -> None:
    """Work item ``c`` of the collider pass: the c-th of CHUNKS parts of the free points meets the
    reachable spheres, planes, capsules and boxes, kind by kind in scene order."""
    n = col.free.shape[0]
    f0, f1 = share(n, c, CHUNKS)
    part = col.free[f0:f1]
    if motion is None:
        collide_chunk(pos, last, col.free, col.spheres, col.planes, col.offset, sphere_on, plane_on, c)
    else:
        collide_moving_spheres(pos, last, part, col.spheres, sphere_on, motion.sphere_carry)
        collide_moving_planes(pos, last, part, col.planes, plane_on, motion.plane_carry, col.offset)
    collide_shapes(pos, last, part, capsules, cuboids, capsule_on, cuboid_on, col.offset)


@njit(**PARALLEL)
def collide_reachable(pos: np.ndarray, last: np.ndarray, col: tuple, motion: tuple | None,
                      capsules: np.ndarray | None, cuboids: np.ndarray | None, substep: int) -> int:
    """Collide with the colliders the cloth can reach at substep ``substep`` of the call (moving
    ones put at their pose first); returns the number skipped.

    A point's correction depends on that point alone, so the free points are split over the
    cores; each point meets the spheres, then the planes, capsules and boxes, in scene order.
    """
    update_poses(motion, col.spheres, col.planes, capsules, cuboids, substep)
    cloth_bounds(pos, last, col.box)
    skipped = reach_colliders(col.box, col, col.sphere_on, col.plane_on, col.capsule_on, col.cuboid_on, motion,
                              capsules, cuboids)
    for c in prange(CHUNKS):
        collide_part(pos, last, col, col.sphere_on, col.plane_on, col.capsule_on, col.cuboid_on, motion, capsules,
                     cuboids, c)
    return skipped
