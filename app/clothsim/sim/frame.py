"""One frame = ``steps`` substeps in a single compiled call, in the spec's substep order:
forces -> integrate -> self-collision -> colliders -> Provot.

Passes a scene does not need are switched off by the caller (empty arrays, mode 0 or a
negative limit) and never run. Colliders are tested against the cloth's bounding box first:
a sphere the box does not reach, or a plane the box (of current and last positions) lies
wholly on one side of, cannot act this substep and is skipped exactly.
"""

from __future__ import annotations

import numpy as np
from numba import njit, prange

from .jit import CHUNKS, EXACT, KERNEL, PARALLEL

from .collide import collide_planes, collide_spheres
from .constraints import provot
from .forces import accumulate_forces
from .integrate import verlet
from .selfcollide import self_collide


@njit(**KERNEL)
def cloth_bounds(pos: np.ndarray, last: np.ndarray, box: np.ndarray) -> None:
    """box = [min xyz, max xyz] over the current and last positions of all points.

    Pinned points are included: they only widen the box, which keeps the skip test exact, and
    the sweep stays contiguous (vectorised).
    """
    # Columns of the grid as independent running minima/maxima: one running value would chain
    # every comparison, and LLVM does not vectorise a floating-point min reduction unless NaNs
    # are ruled out. Here the inner loop is element-wise over a row, so it vectorises.
    n = pos.shape[1]
    w = min(n, 64)
    for c in range(3):
        lo = pos[c, :w].copy()
        hi = pos[c, :w].copy()
        for r0 in range(0, n, w):
            x = pos[c, r0 : r0 + w]
            xl = last[c, r0 : r0 + w]
            for j in range(x.shape[0]):
                a = x[j]
                b = xl[j]
                m = a if a < b else b
                lo[j] = m if m < lo[j] else lo[j]
                m = a if a > b else b
                hi[j] = m if m > hi[j] else hi[j]
        box[c] = lo.min()
        box[3 + c] = hi.max()


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


@njit(**PARALLEL)
def collide_reachable(pos: np.ndarray, last: np.ndarray, free: np.ndarray, spheres: np.ndarray,
                      planes: np.ndarray, offset: float, box: np.ndarray, sphere_on: np.ndarray,
                      plane_on: np.ndarray) -> int:
    """Collide with the colliders the cloth can reach; returns the number skipped.

    A point's correction depends on that point alone, so the free points are split over the
    cores; each point meets the spheres, then the planes, in scene order.
    """
    cloth_bounds(pos, last, box)
    skipped = reachable_colliders(box, spheres, planes, sphere_on, plane_on)
    n = free.shape[0]
    for c in prange(CHUNKS):
        part = free[c * n // CHUNKS : (c + 1) * n // CHUNKS]
        for o in range(spheres.shape[0]):
            if sphere_on[o]:
                collide_spheres(pos, last, part, spheres[o : o + 1])
        for o in range(planes.shape[0]):
            if plane_on[o]:
                collide_planes(pos, last, part, planes[o : o + 1], offset)
    return skipped


@njit(**EXACT)
def run_substeps(steps: int, pos: np.ndarray, last: np.ndarray, forces: np.ndarray, free: np.ndarray,
                 pinned: np.ndarray, blocks: np.ndarray, stream: tuple, rest: np.ndarray, nw: int,
                  mass: float, gravity: np.ndarray, dt: float, keep: float, spheres: np.ndarray,
                 planes: np.ndarray, offset: float, self_mode: int, thickness: float, sim_steps: int,
                 cell: np.ndarray, keys: np.ndarray, slots: np.ndarray, start: np.ndarray,
                 order: np.ndarray, stretch_limit: float, box: np.ndarray, sphere_on: np.ndarray,
                 plane_on: np.ndarray) -> int:
    """Advance ``steps`` substeps of the spec's Verlet model; returns colliders skipped.

    State arrays are (3, N). Springs come twice: as whole-grid streams for the forces
    (:func:`clothsim.cloth.spring_streams`) and as block rows for Provot's in-place pass
    (:func:`clothsim.cloth.spring_blocks`).

    ``self_mode`` 0 turns self-collision off; ``stretch_limit`` <= 0 turns Provot off.
    """
    inv_mass = 1.0 / mass
    has_colliders = spheres.shape[0] + planes.shape[0] > 0
    pins = np.flatnonzero(pinned)
    skipped = 0
    for _ in range(steps):
        accumulate_forces(pos, forces, stream, mass, gravity)
        verlet(pos, last, forces, pins, inv_mass, dt, keep)
        if self_mode != 0:
            self_collide(pos, free, thickness, sim_steps, self_mode, cell[0], cell[1], cell[2], keys, slots,
                         start, order)
        if has_colliders:
            skipped += collide_reachable(pos, last, free, spheres, planes, offset, box, sphere_on, plane_on)
        if stretch_limit > 0.0:
            provot(pos, pinned, blocks, rest, nw, stretch_limit)
    return skipped
