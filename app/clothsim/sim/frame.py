"""One frame = ``steps`` substeps in a single compiled call, in the spec's substep order:
forces -> integrate -> self-collision -> colliders -> Provot.

The call is run by a team of threads (:mod:`clothsim.sim.team`) that share out each pass by
the same work items as the per-pass parallel kernels (``spring_pass``, ``verlet``, ...) and meet
at a barrier between passes, so a substep costs a few barriers instead of a fork and join per
pass. Those kernels stay for the other integrators.

Passes a scene does not need are switched off by the caller (empty arrays, mode 0 or a
negative limit) and never run. Colliders are tested against the cloth's bounding box first:
a sphere the box does not reach, or a plane the box (of current and last positions) lies
wholly on one side of, cannot act this substep and is skipped exactly.
"""

from __future__ import annotations

import numpy as np
from numba import njit, prange

from .jit import CHUNKS, KERNEL, PARALLEL

from .collide import collide_planes, collide_spheres
from .constraints import provot_band, provot_bands, provot_cut
from .forces import gather_chunk, spring_job
from .integrate import verlet_chunk
from .selfcollide import (MODE_SPEC, cell_keys, count_slots, place_slots, repel_slots, scatter_slots, query_share,
                          self_collide, slot_copies)
from .team import barrier, roll_call, share

#: Pass bits of :func:`run_substeps`: spring forces and Verlet, self-collision, colliders, Provot.
PASS_INTEGRATE, PASS_SELF, PASS_COLLIDERS, PASS_PROVOT = 1, 2, 4, 8
PASS_ALL = 15


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
        lo_c[:] = pos[c, lo : lo + w]
        hi_c[:] = lo_c
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
    """Work item ``c`` of :func:`collide_reachable`: the c-th of CHUNKS parts of the free points."""
    n = free.shape[0]
    f0, f1 = share(n, c, CHUNKS)
    part = free[f0:f1]
    for o in range(spheres.shape[0]):
        if sphere_on[o]:
            collide_spheres(pos, last, part, spheres[o : o + 1])
    for o in range(planes.shape[0]):
        if plane_on[o]:
            collide_planes(pos, last, part, planes[o : o + 1], offset)


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
    for c in prange(CHUNKS):
        collide_chunk(pos, last, free, spheres, planes, offset, sphere_on, plane_on, c)
    return skipped


@njit(**KERNEL)
def _member(member: int, size: int, steps: int, pos: np.ndarray, last: np.ndarray, forces: np.ndarray,
            free: np.ndarray, pinned: np.ndarray, pins: np.ndarray, blocks: np.ndarray, stream: tuple,
            rest: np.ndarray, nw: int, h2: float, mass: float, gravity: np.ndarray, keep: float,
            spheres: np.ndarray, planes: np.ndarray, offset: float, self_mode: int, thickness: float,
            sim_steps: int, cell: np.ndarray, keys: np.ndarray, slots: np.ndarray, start: np.ndarray,
            order: np.ndarray, stretch_limit: float, box: np.ndarray, sphere_on: np.ndarray,
            plane_on: np.ndarray, scratch: tuple, sorting: tuple, sync: np.ndarray, passes: int) -> None:
    """One member's part of ``steps`` substeps; members meet at a barrier between passes."""
    offsets, k, spring_rest, buf = stream
    movable, busy, xs, ys, zs, ks, skips, boxes, cum = scratch
    spring_jobs = offsets.shape[0] * CHUNKS
    # a member alone (see team.roll_call) sorts with one row of counts, not the team's
    counted, tally = sorting
    hist, cursor = counted[0, :size], counted[1, :size]
    bands = provot_bands(pos, nw)
    dist = 2.0 * thickness
    n = pos.shape[1]
    table = start.shape[0] - 1
    integrate = passes & PASS_INTEGRATE != 0
    if passes & PASS_SELF == 0:
        self_mode = 0
    have_colliders = spheres.shape[0] + planes.shape[0] > 0
    colliders = have_colliders and passes & PASS_COLLIDERS != 0
    # Each member tests the colliders itself (no barrier between the test and its use); member 0
    # in the caller's arrays, the others in their own.
    if member != 0:
        box = np.empty(6)
        sphere_on = np.empty(spheres.shape[0], dtype=np.bool_)
        plane_on = np.empty(planes.shape[0], dtype=np.bool_)
    # The members' boxes are taken right after Verlet, before self-collision, which moves no point
    # by dist / sim_steps or more (an average of pushes each shorter than dist, over sim_steps):
    # widened by that, the box still bounds the cloth the colliders see, so skipping stays exact.
    margin = 0.0 if self_mode == 0 else 1.001 * dist / sim_steps
    cols = np.empty((2, 64))
    provot_on = stretch_limit > 0.0 and passes & PASS_PROVOT != 0
    # the member's own points (its chunks) and its part of the hash table
    c0, c1 = share(CHUNKS, member, size)
    own0, own1 = share(n, c0, CHUNKS)[0], share(n, c1, CHUNKS)[0]
    t0, t1 = share(table, member, size)
    gen = 0
    for _ in range(steps):
        if integrate:
            lo, hi = share(spring_jobs, member, size)
            for job in range(lo, hi):
                spring_job(pos, offsets, k, spring_rest, buf, job)
            gen = barrier(sync, size, gen)
            # a point's force is final once gathered, so its Verlet step follows at once
            lo, hi = share(CHUNKS, member, size)
            if self_mode == MODE_SPEC:
                hist[member] = 0
            for c in range(lo, hi):
                gather_chunk(offsets, buf, mass, gravity, forces, c)
                verlet_chunk(pos, last, forces, pins, h2, keep, c)
                if self_mode == MODE_SPEC:
                    # the spec's map is of the positions just integrated: bin them while in cache
                    p0, p1 = share(n, c, CHUNKS)
                    cell_keys(pos, cell[0], cell[1], cell[2], keys, slots, table, p0, p1)
                    count_slots(slots, hist[member], p0, p1)
            if have_colliders:
                member_bounds(pos, last, boxes, cols, lo, hi)
            gen = barrier(sync, size, gen)
        elif self_mode == MODE_SPEC:
            cell_keys(pos, cell[0], cell[1], cell[2], keys, slots, table, own0, own1)
            hist[member] = 0
            count_slots(slots, hist[member], own0, own1)
            gen = barrier(sync, size, gen)
        if self_mode == MODE_SPEC:
            # A counting sort split over the team: each member places the slots of its part of the
            # table, then puts its own points in place. A point's owner copies it into its slot
            # (its position is in the owner's cache): on selfCollision 2.47-2.49 ms a frame (medians
            # of 15 x 30 frames from frame 60), against 2.68-2.70 when the member repelling a slot
            # copied it, and 2.50-2.56 with one member sorting alone. Then the busy slots of all
            # parts are shared out by estimated cost.
            tally[member, 0], tally[member, 1] = place_slots(hist, cursor, start, busy, cum, t0, t1)
            gen = barrier(sync, size, gen)
            scatter_slots(pos, keys, slots, cursor[member], order, xs, ys, zs, ks, own0, own1)
            gen = barrier(sync, size, gen)
            for r in range(size):
                i0, i1 = query_share(cum, tally, table, r, member, size)
                if i0 < i1:
                    r0 = share(table, r, size)[0]
                    repel_slots(pos, movable, dist, sim_steps, start, order, busy, xs, ys, zs, ks, r0 + i0, r0 + i1)
            gen = barrier(sync, size, gen)
        elif self_mode != 0:
            if member == 0:
                self_collide(pos, free, thickness, sim_steps, self_mode, cell[0], cell[1], cell[2], keys, slots,
                             start, order)
            gen = barrier(sync, size, gen)
        if colliders:
            lo, hi = share(CHUNKS, member, size)
            if integrate:
                merge_bounds(boxes, margin, box)
            else:
                # run on its own (profile): bound the positions as they are now
                member_bounds(pos, last, boxes, cols, lo, hi)
                gen = barrier(sync, size, gen)
                merge_bounds(boxes, 0.0, box)
            skipped = reachable_colliders(box, spheres, planes, sphere_on, plane_on)
            if member == 0:
                skips[0] += skipped
            for c in range(lo, hi):
                collide_chunk(pos, last, free, spheres, planes, offset, sphere_on, plane_on, c)
            gen = barrier(sync, size, gen)
        if provot_on:
            lo, hi = share(bands, member, size)
            for b in range(lo, hi):
                provot_band(pos, pinned, blocks, rest, nw, stretch_limit, b, bands)
            gen = barrier(sync, size, gen)
            lo, hi = share(bands - 1, member, size)
            for b in range(lo, hi):
                provot_cut(pos, pinned, blocks, rest, nw, stretch_limit, b, bands)
            gen = barrier(sync, size, gen)


@njit(**PARALLEL)
def run_substeps(steps: int, pos: np.ndarray, last: np.ndarray, forces: np.ndarray, free: np.ndarray,
                 pinned: np.ndarray, blocks: np.ndarray, stream: tuple, rest: np.ndarray, nw: int,
                 mass: float, gravity: np.ndarray, dt: float, keep: float, spheres: np.ndarray,
                 planes: np.ndarray, offset: float, self_mode: int, thickness: float, sim_steps: int,
                 cell: np.ndarray, keys: np.ndarray, slots: np.ndarray, start: np.ndarray,
                 order: np.ndarray, stretch_limit: float, box: np.ndarray, sphere_on: np.ndarray,
                 plane_on: np.ndarray, scratch: tuple, sync: np.ndarray, size: int,
                 passes: int = PASS_ALL) -> int:
    """Advance ``steps`` substeps of the spec's Verlet model; returns colliders skipped.

    State arrays are (3, N). Springs come twice: as whole-grid streams for the forces
    (:func:`clothsim.cloth.spring_streams`) and as block rows for Provot's in-place pass
    (:func:`clothsim.cloth.spring_blocks`). ``scratch`` is :func:`new_scratch`'s tuple,
    ``sync`` :func:`clothsim.sim.team.new_sync`'s array, ``size`` the team size (see
    :mod:`clothsim.sim.team`); the result does not depend on it.

    ``self_mode`` 0 turns self-collision off; ``stretch_limit`` <= 0 turns Provot off.
    ``passes`` (PASS_* bits) runs only some passes, for :mod:`clothsim.sim.profile`.
    """
    pins = np.flatnonzero(pinned)
    inv_mass = 1.0 / mass
    h2 = dt * dt * inv_mass
    skips = scratch[6]
    skips[0] = 0
    sync[:] = 0
    # the team's counting sort: counts and cursors per member and slot, busy slots and cost per range
    rows = size if self_mode == MODE_SPEC else 0
    sorting = (np.zeros((2, rows, start.shape[0] - 1), dtype=np.int32), np.zeros((rows, 2), dtype=np.int64))
    for member in prange(size):
        working = roll_call(sync, size)
        if working == size:
            _member(member, size, steps, pos, last, forces, free, pinned, pins, blocks, stream, rest, nw, h2, mass,
                    gravity, keep, spheres, planes, offset, self_mode, thickness, sim_steps, cell, keys, slots,
                    start, order, stretch_limit, box, sphere_on, plane_on, scratch, sorting, sync, passes)
        elif working == 1:
            _member(0, 1, steps, pos, last, forces, free, pinned, pins, blocks, stream, rest, nw, h2, mass,
                    gravity, keep, spheres, planes, offset, self_mode, thickness, sim_steps, cell, keys, slots,
                    start, order, stretch_limit, box, sphere_on, plane_on, scratch, sorting, sync, passes)
    return skips[0]


def new_scratch(n_points: int, table: int, pinned: np.ndarray) -> tuple:
    """Work arrays of :func:`run_substeps` for a cloth of ``n_points`` and a hash table of
    ``table`` slots: (movable, busy slots, x, y, z, keys in table order, colliders skipped (one
    counter), CHUNKS rows of bounding boxes (see :func:`member_bounds`), the busy slots' running
    cost per table range (see :func:`clothsim.sim.selfcollide.place_slots`))."""
    return (~pinned, np.zeros(table, dtype=np.int64), *slot_copies(n_points), np.zeros(1, dtype=np.int64),
            np.zeros((CHUNKS, 6)), np.zeros(table, dtype=np.int64))
