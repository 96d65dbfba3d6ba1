"""Self-collision through a spatial hash rebuilt every substep.

Points are binned by integer cell coordinates; the cell keys are hashed into a power-of-two
table and the points counting-sorted by table slot, so the build is O(N) with no per-cell
allocation. Two query modes:

* ``spec``: only the points of a point's own cell are candidates (the spec's hash, with cell
  w x h x t, w = 3*width/nw, h = 3*height/nh, t = max(w, h)). Pairs straddling a cell
  boundary are missed, as in the spec.
* ``grid``: cubic cells of edge >= 2*thickness and a search of the 27 neighbouring cells, so
  no pair closer than 2*thickness is missed.

Both repel a point from every candidate closer than 2*thickness, average the corrections,
divide by simulation_steps and apply them in place in point order (Gauss-Seidel): a point sees
the already-corrected positions of lower-indexed points, while cell membership is fixed at the
positions the map was built from.
"""

from __future__ import annotations

import numpy as np
from numba import njit, prange
from numba.cpython.unsafe.numbers import trailing_zeros

from ...jit import CHUNKS, EXACT, KERNEL, PARALLEL
from ..team import share

MODE_SPEC = 1
MODE_GRID = 2

_BITS = 21
_ONE = np.uint64(1)
_MASK = (1 << _BITS) - 1


def table_size(n_points: int) -> int:
    """Power-of-two hash table size, at least twice the number of points."""
    m = 1
    while m < 2 * n_points:
        m *= 2
    return m


def spec_table_size(n_points: int) -> int:
    """Table size for the spec's cells, which are 3 x 3 point spacings and hold ~9 points of a
    flat cloth: twice the number of cells a cloth of that many points spread at 4 points a cell
    would fill. Every table pass (clear, prefix sum, busy scan) runs over the whole table, so the
    point-sized table cost selfCollision 9 us of 64 per substep; colliding cells only add
    comparisons that the key check rejects."""
    return table_size(max(n_points // 4, 1))


@njit(**EXACT)
def _cell_key(ix: np.int64, iy: np.int64, iz: np.int64) -> np.int64:
    return ((ix & _MASK) << (2 * _BITS)) | ((iy & _MASK) << _BITS) | (iz & _MASK)


_GOLDEN = np.uint64(0x9E3779B97F4A7C15)


@njit(**EXACT)
def _slot(key: np.int64, shift: np.int64) -> np.int64:
    # Fibonacci hashing: the top bits of key * 2^64/phi. On selfCollision (2048 slots) the slots
    # hold 8 % more candidate pairs than the cells; the XOR of the coordinates times three large
    # primes held 22 % more, the same at 1024, 2048 and 4096 slots.
    return np.int64((np.uint64(key) * _GOLDEN) >> np.uint64(shift))


@njit(**EXACT)
def _slot_shift(table: np.int64) -> np.int64:
    """64 - log2(table): the shift that leaves a slot index below ``table`` (a power of two)."""
    shift = 64
    t = table
    while t > 1:
        t >>= 1
        shift -= 1
    return shift


@njit(**KERNEL)
def cell_keys(pos: np.ndarray, cw: float, ch: float, ct: float, keys: np.ndarray, slots: np.ndarray,
              table: int, lo: int, hi: int) -> None:
    """Cell key and table slot of the points lo..hi-1 (``table`` slots, a power of two).

    Compiled on its own, with the fast-math flags it has always been compiled with (its callers'
    before they were set here: its division is x * (1 / w)), so that a point's cell does not
    depend on where the loop is inlined or which kernel compiled it first."""
    shift = _slot_shift(table)
    for p in range(lo, hi):
        ix = np.int64(np.floor(pos[0, p] / cw))
        iy = np.int64(np.floor(pos[1, p] / ch))
        iz = np.int64(np.floor(pos[2, p] / ct))
        key = _cell_key(ix, iy, iz)
        keys[p] = key
        slots[p] = _slot(key, shift)


@njit(**KERNEL)
def sort_by_slot(slots: np.ndarray, start: np.ndarray, order: np.ndarray, busy: np.ndarray) -> int:
    """Counting sort of the points by slot: the points of slot k are order[start[k]:start[k+1]],
    in increasing index order. Also lists the slots holding two or more points in busy[:nb]
    (returns nb). (A frame's team sorts with :func:`place_slots` and :func:`scatter_slots`.)"""
    n = slots.shape[0]
    m = start.shape[0] - 1
    start[:] = 0
    for p in range(n):
        start[slots[p] + 1] += 1
    # start[k + 1] becomes the first entry of slot k; the fill below advances it to the last
    # entry + 1, which is where slot k + 1 starts, so no pass shifts the bounds afterwards
    total = 0
    nb = 0
    for k in range(m):
        c = start[k + 1]
        start[k + 1] = total
        total += c
        if c >= 2:
            busy[nb] = k
            nb += 1
    for p in range(n):
        s = slots[p] + 1
        order[start[s]] = p
        start[s] += 1
    return nb


@njit(inline="always", **KERNEL)
def count_slots(slots: np.ndarray, hist: np.ndarray, lo: int, hi: int) -> None:
    """hist[k] += the number of the points lo..hi-1 in slot k."""
    for p in range(lo, hi):
        hist[slots[p]] += 1


@njit(inline="always", **KERNEL)
def place_slots(hist: np.ndarray, cursor: np.ndarray, start: np.ndarray, busy: np.ndarray, cum: np.ndarray, t0: int,
                t1: int) -> tuple[int, int]:
    """The prefix pass of a counting sort split over a team, for the table slots t0..t1-1.

    ``hist[j, k]`` holds how many of member j's points (a run of point indices, member j's after
    member j-1's) fall in slot k; cursor[j, k] becomes where member j's first point of slot k
    goes, so that :func:`scatter_slots` leaves every slot in increasing index order, as
    :func:`sort_by_slot` does. (The counts stay as they are: the other members read those before
    t0 at the same time.) start[k] becomes the slot's first entry (start[t1] too when t1 is the
    table's end); the slots holding two or more points are listed in busy[t0:t0 + nb], and
    cum[t0 + b] is the estimated query cost of busy[t0:t0 + b + 1]. Returns nb and the range's
    cost (see :func:`query_share`).
    """
    rows = hist.shape[0]
    base = 0
    for j in range(rows):
        base += hist[j, :t0].sum()
    # the slots' counts summed over the members in whole-row (vectorised) passes, turned into
    # starts in place, then each member's cursor row: 3.7 us for both halves of selfCollision's
    # table, against 4.8 with the members' counts read slot by slot
    # (element loops, not slice expressions: those bring in Numba's shape-mismatch error path,
    # 8 s of a cold compile for this function alone)
    counts = start[t0:t1]
    h = hist[0, t0:t1]
    for k in range(t1 - t0):
        counts[k] = h[k]
    for j in range(1, rows):
        h = hist[j, t0:t1]
        for k in range(t1 - t0):
            counts[k] += h[k]
    nb = 0
    cost = 0
    for k in range(t0, t1):
        c = start[k]
        start[k] = base
        base += c
        if c >= 2:
            busy[t0 + nb] = k
            # a sweep over the slot per point, plus a fixed cost per point
            cost += c * (c + 32)
            cum[t0 + nb] = cost
            nb += 1
    if t1 == start.shape[0] - 1:
        start[t1] = base
    first = start[t0:t1]
    for j in range(rows):
        row = cursor[j, t0:t1]
        for k in range(t1 - t0):
            row[k] = first[k]
        for e in range(j):
            h = hist[e, t0:t1]
            for k in range(t1 - t0):
                row[k] += h[k]
    return nb, cost


@njit(inline="always", **KERNEL)
def query_share(cum: np.ndarray, tally: np.ndarray, table: int, r: int, member: int, size: int) -> tuple[int, int]:
    """Member ``member``'s part of the busy slots of table range r (see :func:`place_slots`; tally[j]
    holds range j's busy count and cost), as indices into busy[t0:t0 + nb]: the busy slots of all
    ranges, in range order, are shared out by estimated cost, a slot going to the member whose
    share its first unit of cost falls in."""
    total = 0
    before = 0
    for j in range(size):
        if j < r:
            before += tally[j, 1]
        total += tally[j, 1]
    t0 = share(table, r, size)[0]
    nb = tally[r, 0]
    return (_first_from(cum[t0 : t0 + nb], member * total // size - before),
            _first_from(cum[t0 : t0 + nb], (member + 1) * total // size - before))


@njit(inline="always", **KERNEL)
def _first_from(cum: np.ndarray, x: int) -> int:
    """The first busy slot whose cost starts at x or later (cum: inclusive running costs)."""
    if x <= 0:
        return 0
    return min(1 + np.searchsorted(cum[: cum.shape[0] - 1], x), cum.shape[0])


@njit(inline="always", **KERNEL)
def scatter_slots(pos: np.ndarray, keys: np.ndarray, slots: np.ndarray, cursor: np.ndarray, order: np.ndarray,
                  xs: np.ndarray, ys: np.ndarray, zs: np.ndarray, ks: np.ndarray, lo: int, hi: int) -> None:
    """Put the points lo..hi-1 in their slots (``cursor`` is the member's row made by
    :func:`place_slots`), their positions and keys copied alongside as :func:`copy_slots` does."""
    for p in range(lo, hi):
        s = slots[p]
        t = cursor[s]
        cursor[s] = t + 1
        order[t] = p
        xs[t] = pos[0, p]
        ys[t] = pos[1, p]
        zs[t] = pos[2, p]
        ks[t] = keys[p]


@njit(**KERNEL)
def build_map(pos: np.ndarray, cw: float, ch: float, ct: float, keys: np.ndarray, slots: np.ndarray,
              start: np.ndarray, order: np.ndarray, busy: np.ndarray) -> int:
    """Bin every point; afterwards the points of table slot k are order[start[k]:start[k+1]] (see
    :func:`sort_by_slot`, whose busy-slot count it returns)."""
    cell_keys(pos, cw, ch, ct, keys, slots, start.shape[0] - 1, 0, pos.shape[1])
    return sort_by_slot(slots, start, order, busy)


@njit(**KERNEL)
def _repel(pos: np.ndarray, p: int, q: int, dist: float, acc: np.ndarray) -> int:
    dx = pos[0, p] - pos[0, q]
    dy = pos[1, p] - pos[1, q]
    dz = pos[2, p] - pos[2, q]
    d2 = dx * dx + dy * dy + dz * dz
    if d2 < dist * dist and d2 > 0.0:
        length = np.sqrt(d2)
        s = (dist - length) / length
        acc[0] += dx * s
        acc[1] += dy * s
        acc[2] += dz * s
        return 1
    return 0


@njit(inline="always", **KERNEL)
def copy_slots(pos: np.ndarray, keys: np.ndarray, start: np.ndarray, order: np.ndarray, busy: np.ndarray,
               xs: np.ndarray, ys: np.ndarray, zs: np.ndarray, ks: np.ndarray, b0: int, b1: int) -> None:
    """Copy the positions and keys of the points of slots busy[b0:b1] into xs, ys, zs, ks in table
    order, so that each slot's points are contiguous and the candidate loop is a vectorised
    sweep over the slot."""
    for b in range(b0, b1):
        for t in range(start[busy[b]], start[busy[b] + 1]):
            q = order[t]
            xs[t] = pos[0, q]
            ys[t] = pos[1, q]
            zs[t] = pos[2, q]
            ks[t] = keys[q]


#: Entries past the last slot in the copies (see :func:`slot_copies`): a slot's sweep is rounded up
#: to a multiple of 8 points and may read that far into the next slots.
_SPILL = 8


@njit(**EXACT)
def slot_copies(n_points: int) -> tuple:
    """Zeroed x, y, z and key arrays for the points copied in table order (:func:`copy_slots`,
    :func:`scatter_slots`), with _SPILL entries after the last point whose key (-1) is no cell's."""
    ks = np.zeros(n_points + _SPILL, dtype=np.int64)
    ks[n_points:] = -1
    return np.zeros(n_points + _SPILL), np.zeros(n_points + _SPILL), np.zeros(n_points + _SPILL), ks


@njit(**KERNEL)
def repel_slots(pos: np.ndarray, movable: np.ndarray, dist: float, steps: int, start: np.ndarray,
                order: np.ndarray, busy: np.ndarray, xs: np.ndarray, ys: np.ndarray, zs: np.ndarray,
                ks: np.ndarray, b0: int, b1: int) -> None:
    """The spec's query for the busy slots busy[b0:b1] (after :func:`copy_slots`, or the team's
    :func:`scatter_slots`; the copies come from :func:`slot_copies`).

    A point's candidates all share its slot, and only points of its own cell (same key) ever
    move it, so each slot can be finished on its own: its points are processed in increasing
    index order (the order both sorts list them in), which is exactly the sequential
    point-order pass restricted to that cell.
    """
    dist2 = dist * dist
    # A point moves once, at its turn, by an average of pushes each shorter than dist over
    # ``steps``: so a pair closer than dist at either point's turn was closer than
    # dist * (1 + 1/steps) before the slot was touched (widened a little against rounding).
    reach = dist * (1.0 + 1.0 / steps) * 1.001
    reach2 = reach * reach
    # Made here, once per call (a member's few calls a substep), not passed in by the caller: the
    # frame with it passed in ran at 1.017-1.049 of the time before (paired runs), 0.990-1.017 with
    # it made here (an argument may alias the copies).
    near = np.empty(64, dtype=np.uint64)
    for b in range(b0, b1):
        s0 = start[busy[b]]
        s1 = start[busy[b] + 1]
        # The slot is passed as slices whose length bounds the loops (97-100 -> 73-75 us per
        # substep for build and query, replayed, when the slices replaced bounds inside).
        points = order[s0:s1]
        if s1 - s0 <= 64:
            # The entries read past the slot may be another member's slot being corrected: their
            # values never matter, as their keys never match this slot's.
            s8 = s0 + ((s1 - s0 + 7) & ~7)
            _repel_slot(pos, movable, dist, dist2, reach2, steps, points, xs[s0:s8], ys[s0:s8], zs[s0:s8],
                        ks[s0:s8], near)
        else:
            _repel_big_slot(pos, movable, dist, dist2, steps, points, xs[s0:s1], ys[s0:s1], zs[s0:s1], ks[s0:s1])


@njit(inline="always", **KERNEL)
def _repel_slot(pos: np.ndarray, movable: np.ndarray, dist: float, dist2: float, reach2: float, steps: int,
                points: np.ndarray, cx: np.ndarray, cy: np.ndarray, cz: np.ndarray, ck: np.ndarray,
                near: np.ndarray) -> None:
    """The query of one slot of at most 64 points: its points, and their positions and keys
    copied in that order, rounded up to a multiple of 8 entries with those of the next slots
    (another key, so never a candidate).

    First every pair of the slot is tested at once against ``reach2``, from the positions before
    the slot's corrections, into one 64-bit row per point (``near``); then each point in turn
    checks only the marked points, at their current positions, against dist. Two passes because
    the first is a plain element-wise sweep of whole 8-wide vectors, while a sweep per point
    OR-reduces a mask, which ran no faster on slots of 9-20 points when they were padded to whole
    vectors (query replayed on one thread: 67 us per substep one pass, 91 padded, 50 in two
    passes, 70 in two passes unpadded).
    """
    n = points.shape[0]
    m = cx.shape[0]
    near[:m] = 0
    # Two points j a sweep, so that each row of ``near`` is read and written once for both (the
    # rows' loads and stores, not the tests, set the sweep's pace). For an odd n the second is the
    # first entry past the slot, which may not have been copied yet (a parallel loop's chunks copy
    # their slots side by side) and so may read as this slot's cell: its column is masked off.
    valid = np.uint64(0xFFFFFFFFFFFFFFFF) >> np.uint64(64 - n)
    for j in range(0, n, 2):
        x0, y0, z0, k0 = cx[j], cy[j], cz[j], ck[j]
        x1, y1, z1 = cx[j + 1], cy[j + 1], cz[j + 1]
        k1 = ck[j + 1]
        for i in range(m):
            xi, yi, zi, ki = cx[i], cy[i], cz[i], ck[i]
            pair = _within(xi, yi, zi, ki, x0, y0, z0, k0, reach2) | (_within(xi, yi, zi, ki, x1, y1, z1, k1,
                                                                              reach2) << _ONE)
            near[i] |= (pair << np.uint64(j)) & valid
    for i in range(n):
        bits = near[i]
        p = points[i]
        if bits == 0 or not movable[p]:
            continue
        count, sx, sy, sz = _push_marked(cx, cy, cz, bits, cx[i], cy[i], cz[i], dist, dist2)
        if count > 0:
            _move(pos, p, cx, cy, cz, i, sx, sy, sz, 1.0 / (count * steps))


@njit(inline="always", **KERNEL)
def _within(xi: float, yi: float, zi: float, ki: int, xj: float, yj: float, zj: float, kj: int,
            reach2: float) -> np.uint64:
    """1 when entry i is in entry j's cell and closer than sqrt(reach2), but not at its very
    position (which also drops the point itself), else 0."""
    dx = xi - xj
    dy = yi - yj
    dz = zi - zj
    d2 = dx * dx + dy * dy + dz * dz
    return np.uint64((ki == kj) & (d2 < reach2) & (d2 > 0.0))


@njit(**KERNEL)
def _repel_big_slot(pos: np.ndarray, movable: np.ndarray, dist: float, dist2: float, steps: int,
                    points: np.ndarray, cx: np.ndarray, cy: np.ndarray, cz: np.ndarray, ck: np.ndarray) -> None:
    """The query of one slot of more than 64 points (as :func:`_repel_slot`), window by window."""
    for i in range(cx.shape[0]):
        p = points[i]
        if not movable[p]:
            continue
        count = 0
        sx = 0.0
        sy = 0.0
        sz = 0.0
        for w0 in range(0, cx.shape[0], 64):
            w1 = w0 + 64
            n, ax, ay, az = _repel_window(cx[w0:w1], cy[w0:w1], cz[w0:w1], ck[w0:w1], cx[i], cy[i], cz[i],
                                          ck[i], dist, dist2)
            count += n
            sx += ax
            sy += ay
            sz += az
        if count > 0:
            _move(pos, p, cx, cy, cz, i, sx, sy, sz, 1.0 / (count * steps))


@njit(inline="always", **KERNEL)
def _move(pos: np.ndarray, p: int, cx: np.ndarray, cy: np.ndarray, cz: np.ndarray, i: int, sx: float, sy: float,
          sz: float, scale: float) -> None:
    """Apply point p's averaged correction (slot entry i) to the slot copy and the state."""
    cx[i] += sx * scale
    cy[i] += sy * scale
    cz[i] += sz * scale
    pos[0, p] = cx[i]
    pos[1, p] = cy[i]
    pos[2, p] = cz[i]


@njit(**PARALLEL)
def _collide_cells(pos: np.ndarray, movable: np.ndarray, dist: float, steps: int, keys: np.ndarray,
                   start: np.ndarray, order: np.ndarray, busy: np.ndarray, nb: int) -> None:
    """The spec's query over the whole table, the busy slots split over the cores."""
    xs, ys, zs, ks = slot_copies(order.shape[0])
    for chunk in prange(CHUNKS):
        b0, b1 = share(nb, chunk, CHUNKS)
        copy_slots(pos, keys, start, order, busy, xs, ys, zs, ks, b0, b1)
        repel_slots(pos, movable, dist, steps, start, order, busy, xs, ys, zs, ks, b0, b1)


@njit(inline="always", **KERNEL)
def _repel_window(wx: np.ndarray, wy: np.ndarray, wz: np.ndarray, wk: np.ndarray, px: float, py: float,
                  pz: float, key: int, dist: float, dist2: float) -> tuple[int, float, float, float]:
    """Repulsion of the point (px, py, pz) of cell ``key`` from the (at most 64) candidates
    w*[:] closer than dist: (count, sum x, y, z), for slots over 64 points (:func:`_repel_big_slot`).

    Most points have no neighbour that close, and those that do have one to three: a branch-free
    sweep marks them in a 64-bit mask, then only the marked ones are visited, in increasing
    order.
    """
    bits = np.uint64(0)
    for j in range(wx.shape[0]):
        bits |= _within(wx[j], wy[j], wz[j], wk[j], px, py, pz, key, dist2) << np.uint64(j)
    return _push_marked(wx, wy, wz, bits, px, py, pz, dist, dist2)


@njit(inline="always", **KERNEL)
def _push_marked(wx: np.ndarray, wy: np.ndarray, wz: np.ndarray, bits: np.uint64, px: float, py: float, pz: float,
                 dist: float, dist2: float) -> tuple[int, float, float, float]:
    """The pushes on the point (px, py, pz) from the candidates w*[j] marked in ``bits`` that are
    closer than dist (and not at its very position), visited in increasing j: (count, sum x, y, z)."""
    count = 0
    sx = 0.0
    sy = 0.0
    sz = 0.0
    while bits != 0:
        j = trailing_zeros(bits)
        bits &= bits - _ONE
        dx = px - wx[j]
        dy = py - wy[j]
        dz = pz - wz[j]
        d2 = dx * dx + dy * dy + dz * dz
        if d2 < dist2 and d2 > 0.0:
            length = np.sqrt(d2)
            f = (dist - length) / length
            sx += dx * f
            sy += dy * f
            sz += dz * f
            count += 1
    return count, sx, sy, sz


@njit(**KERNEL)
def self_collide(pos: np.ndarray, free: np.ndarray, thickness: float, steps: int, mode: int, cw: float,
                 ch: float, ct: float, keys: np.ndarray, slots: np.ndarray, start: np.ndarray,
                 order: np.ndarray) -> None:
    """Build the map from the current positions, then repel close pairs (see module doc)."""
    if mode != MODE_SPEC:
        grid_self_collide(pos, free, thickness, steps, cw, ch, ct, keys, slots, start, order)
        return
    busy = np.empty(start.shape[0] - 1, dtype=np.int64)
    nb = build_map(pos, cw, ch, ct, keys, slots, start, order, busy)
    movable = np.zeros(pos.shape[1], dtype=np.bool_)
    for k in range(free.shape[0]):
        movable[free[k]] = True
    _collide_cells(pos, movable, 2.0 * thickness, steps, keys, start, order, busy, nb)


@njit(**KERNEL)
def grid_self_collide(pos: np.ndarray, free: np.ndarray, thickness: float, steps: int, cw: float, ch: float,
                      ct: float, keys: np.ndarray, slots: np.ndarray, start: np.ndarray, order: np.ndarray) -> None:
    """The ``grid`` mode: build the map of cubic cells, then repel each free point, in index
    order, from every point of the 27 cells around its own closer than 2 * thickness."""
    busy = np.empty(start.shape[0] - 1, dtype=np.int64)
    build_map(pos, cw, ch, ct, keys, slots, start, order, busy)
    dist = 2.0 * thickness
    shift = _slot_shift(start.shape[0] - 1)
    acc = np.zeros(3)
    for k in range(free.shape[0]):
        p = free[k]
        acc[0] = 0.0
        acc[1] = 0.0
        acc[2] = 0.0
        count = 0
        key = keys[p]
        ix = (key >> (2 * _BITS)) & _MASK
        iy = (key >> _BITS) & _MASK
        iz = key & _MASK
        # undo the 21-bit wrap to signed cell coordinates
        if ix >= (1 << (_BITS - 1)):
            ix -= 1 << _BITS
        if iy >= (1 << (_BITS - 1)):
            iy -= 1 << _BITS
        if iz >= (1 << (_BITS - 1)):
            iz -= 1 << _BITS
        for ox in range(-1, 2):
            for oy in range(-1, 2):
                for oz in range(-1, 2):
                    nk = _cell_key(ix + ox, iy + oy, iz + oz)
                    s = _slot(nk, shift)
                    for t in range(start[s], start[s + 1]):
                        q = order[t]
                        if q != p and keys[q] == nk:
                            count += _repel(pos, p, q, dist, acc)
        if count > 0:
            scale = 1.0 / (count * steps)
            pos[0, p] += acc[0] * scale
            pos[1, p] += acc[1] * scale
            pos[2, p] += acc[2] * scale
