"""The contact pass's reference state between rebuilds (:mod:`.contact`): which points are about
to leave their balls or have left them, and a few points' references moved one by one
(:func:`rereference`) instead of a whole rebuild."""

from __future__ import annotations

import numpy as np
from numba import njit

from ...jit import BORROWED, CHUNKS, EXACT, INNER, KERNEL
from ..team import share
from .contactgroup import CLAMPED, DROPPED, FLOOR, GAMMA, LOCALS, MOVED, N_EE, N_PT, ROOMY, SQUEEZED, SQUEEZING, \
    VALID, Contact
from .contactsearch import BATCH, Batch, _add_pair, _tested_ee, _tested_pt, new_batch
from .nearby import box_key, element_box, extent, key_of, listed_in, relist


@njit(inline="always", **KERNEL)
def _leaves(x: np.ndarray, c: Contact, p: int, roomy: float) -> bool:
    """True when point ``p`` of ``x`` lies outside its ball and calls for a new reference: a
    pinned point (it cannot wait clamped: its motion is prescribed), or a free point whose squared
    radius is at least ``roomy`` (see ROOMY)."""
    if c.rho2[p] < roomy and c.movable[p]:
        return False
    dx = x[0, p] - c.ref[0, p]
    dy = x[1, p] - c.ref[1, p]
    dz = x[2, p] - c.ref[2, p]
    return dx * dx + dy * dy + dz * dz > c.rho2[p]


# A moving collider gets the last word, after the bound: the bound pulls a point towards its
# reference, which a collider that has moved since may have passed over, and a point pulled there
# would stay on the collider's far side for good (a lid pressing a heap thinner than it can be went
# through it, 414 of 900 points left over the lid). So in a scene whose colliders move the collider
# pass runs again after the bound; a point it then puts outside its ball is one the bound cannot
# hold (the collider squeezes the cloth against something), counted, never hidden. It leaves its
# ball, so the next substep builds a new reference.


@njit(inline="always", **KERNEL)
def left_balls(pos: np.ndarray, c: Contact, free: np.ndarray, lo: int, hi: int) -> None:
    """After the collider pass's work items ``lo`` to ``hi`` (of CHUNKS, over the free points
    ``free``) ran again after the bound: flag the substep (``meta[SQUEEZING]``) when one of their
    points is outside its ball."""
    n = free.shape[0]
    for k in range(share(n, lo, CHUNKS)[0], share(n, hi, CHUNKS)[0]):
        if _leaves(pos, c, free[k], 0.0):
            c.meta[SQUEEZING] = 1
            return


@njit(inline="always", **KERNEL)
def count_squeezed(c: Contact) -> None:
    """Count a substep :func:`left_balls` flagged (once, whichever members flagged it)."""
    if c.meta[SQUEEZING] != 0:
        c.meta[SQUEEZED] += 1
        c.meta[SQUEEZING] = 0


@njit(**KERNEL, **INNER)
def _leaving(x: np.ndarray, c: Contact, most: int) -> int:
    """How many points of ``x`` call for a new reference (they are :func:`_leaves`, or the bound has
    held them back since their reference was set), counted up to ``most`` + 1."""
    roomy = (ROOMY * GAMMA * c.radius) ** 2
    count = 0
    for p in range(x.shape[1]):
        if c.near.held[p] or _leaves(x, c, p, roomy):
            count += 1
            if count > most:
                break
    return count


#: A point is outside its ball when its squared distance from its reference passes the squared
#: radius x (1 + OUTSIDE_REL) + OUTSIDE_ABS: by more than rounding (a ball of a few nanometres,
#: next to an element the cloth was given crossing, is placed to 1e-16 m).
OUTSIDE_REL = 1e-6
OUTSIDE_ABS = 1e-28


@njit(**KERNEL, **INNER)
def _outside(x: np.ndarray, c: Contact) -> bool:
    """True when a point of ``x`` lies outside its ball (see OUTSIDE_REL)."""
    ref = c.ref
    rho2 = c.rho2
    for p in range(x.shape[1]):
        dx = x[0, p] - ref[0, p]
        dy = x[1, p] - ref[1, p]
        dz = x[2, p] - ref[2, p]
        if dx * dx + dy * dy + dz * dz > rho2[p] * (1.0 + OUTSIDE_REL) + OUTSIDE_ABS:
            return True
    return False


def any_outside(x: np.ndarray, c: Contact, points: np.ndarray) -> bool:
    """Whether one of ``points`` of ``x`` (3, N) lies outside its ball, by :func:`_outside`'s rule
    (for the simulation's few pins between frames, in NumPy)."""
    if not c.meta[VALID] or points.shape[0] == 0:
        return False
    d2 = ((x[:, points] - c.ref[:, points]) ** 2).sum(axis=0)
    return bool(np.any(d2 > c.rho2[points] * (1.0 + OUTSIDE_REL) + OUTSIDE_ABS))


# ------------------------------------------------------------------------------------------------
# a few points' references moved


@njit(**EXACT, **INNER)
def rereference(pos: np.ndarray, last: np.ndarray, c: Contact) -> bool:
    """Move the reference of each point about to leave its ball (:func:`_leaves`, in ``pos``) or
    held back by the bound since its reference was set to where it started the substep
    (``last``), find again every pair those points belong to, and give them new balls; the
    other points' balls shrink where a new pair is nearer, and a point whose ball shrank so
    that its starting position lies outside it is moved in a further round. Returns whether any
    point was moved.

    Why this keeps the guarantee: every point's starting position lies in its ball, so the
    state ``last`` is joined to the reference by straight paths that keep every pair apart. Once
    the rounds end, every pair closer than the query radius in the new reference (every such
    pair that has a moved point is searched again, and the others kept their distances) bounds
    the balls of its points, and every point's starting position lies in its ball: the new
    reference is joined to ``last``, which has no crossing, by paths that keep every pair apart,
    so it has none either, and the argument of the module's docstring holds from it.
    """
    return _rereference(pos, last, c, c.dmins[0], new_batch())


@njit(**BORROWED, **INNER)
def _rereference(pos: np.ndarray, last: np.ndarray, c: Contact, dmin: np.ndarray, batch: Batch) -> bool:
    nb = c.near
    roomy = (ROOMY * GAMMA * c.radius) ** 2
    nb.count[0] += 1
    moving = nb.count[0]
    k = 0
    for p in range(pos.shape[1]):
        if nb.held[p] or _leaves(pos, c, p, roomy):
            nb.todo[k] = p
            nb.mark[0, p] = moving
            k += 1
    if k == 0:
        return False
    npt = c.meta[N_PT]
    nee = c.meta[N_EE]
    cap_pt = c.pt.shape[1]
    cap_ee = c.ee.shape[1]
    done = 0
    while done < k:
        nb.count[0] += 1
        now = nb.count[0]
        _move_round(last, c, done, k, now)
        npt = _drop_pt(c, npt, now)
        nee = _drop_ee(c, nee, now)
        for p in range(dmin.shape[0]):
            dmin[p] = c.radius
        npt, nee = _round_pairs(c, done, k, now, dmin, npt, nee, batch)
        # (pairs beyond the arrays' room are counted, as a rebuild counts them)
        c.meta[DROPPED] += max(npt - cap_pt, 0) + max(nee - cap_ee, 0)
        npt = min(npt, cap_pt)
        nee = min(nee, cap_ee)
        more = _round_balls(last, c, done, k, now, moving, dmin)
        done = k
        k = more
    c.meta[N_PT] = npt
    c.meta[N_EE] = nee
    c.meta[LOCALS] += 1
    c.meta[MOVED] += k
    c.meta[CLAMPED] = 0
    return True


@njit(**BORROWED, **INNER)
def _move_round(last: np.ndarray, c: Contact, lo: int, hi: int, now: int) -> None:
    # the round's points (todo[lo:hi]) to their starting positions, marked and listed in their
    # cells; the elements they belong to marked, their boxes and cells made the new reference's
    nb = c.near
    ref = c.ref
    inv = 1.0 / nb.cell
    for i in range(lo, hi):
        p = nb.todo[i]
        nb.mark[1, p] = now
        nb.held[p] = False
        for ax in range(3):
            ref[ax, p] = last[ax, p]
        relist(nb.points, p, key_of(ref[0, p], ref[1, p], ref[2, p], inv))
    for i in range(lo, hi):
        p = nb.todo[i]
        for j in range(nb.tri_at[p], nb.tri_at[p + 1]):
            t = nb.tri_ids[j]
            if nb.tri_mark[t] != now:
                nb.tri_mark[t] = now
                element_box(ref, c.tris, t, c.radius, nb.tri_box)
                relist(nb.tris, t, box_key(nb.tri_box, t, inv))
                nb.ext[0] = max(nb.ext[0], extent(nb.tri_box, t))
        for j in range(nb.edge_at[p], nb.edge_at[p + 1]):
            e = nb.edge_ids[j]
            if nb.edge_mark[e] != now:
                nb.edge_mark[e] = now
                element_box(ref, c.edges, e, 0.5 * c.radius, nb.edge_box)
                relist(nb.edges, e, box_key(nb.edge_box, e, inv))
                nb.ext[1] = max(nb.ext[1], extent(nb.edge_box, e))


@njit(**BORROWED, **INNER)
def _drop_pt(c: Contact, npt: int, now: int) -> int:
    # the stored point-triangle pairs the round's points belong to taken out, the others kept in order
    nb = c.near
    kept = 0
    for k in range(npt):
        if nb.mark[1, c.pt[0, k]] != now and nb.tri_mark[c.pt[1, k]] != now:
            kept = _keep(c.pt, c.ptf, k, kept)
    return kept


@njit(**BORROWED, **INNER)
def _drop_ee(c: Contact, nee: int, now: int) -> int:
    # (as _drop_pt, for the edge-edge pairs)
    nb = c.near
    kept = 0
    for k in range(nee):
        if nb.edge_mark[c.ee[0, k]] != now and nb.edge_mark[c.ee[1, k]] != now:
            kept = _keep(c.ee, c.eef, k, kept)
    return kept


@njit(inline="always", **EXACT)
def _keep(ids: np.ndarray, data: np.ndarray, k: int, kept: int) -> int:
    # stored pair k moved to column kept (the pairs before it that stay); returns kept + 1
    if kept != k:
        for r in range(ids.shape[0]):
            ids[r, kept] = ids[r, k]
        for r in range(data.shape[0]):
            data[r, kept] = data[r, k]
    return kept + 1


@njit(inline="always", **EXACT)
def _holds(lx: float, ly: float, lz: float, hx: float, hy: float, hz: float, x: float, y: float, z: float) -> bool:
    """Whether the box (lower, upper corner) holds the point (x, y, z), edges included; without
    branches, so that a loop that counts with it is vectorised."""
    return (x >= lx) & (x <= hx) & (y >= ly) & (y <= hy) & (z >= lz) & (z <= hz)


@njit(inline="always", **EXACT)
def _meets(box: np.ndarray, e: int, lx: float, ly: float, lz: float, hx: float, hy: float, hz: float) -> bool:
    """Whether box ``e`` of ``box`` (6, M) overlaps the box (lower, upper corner), without branches."""
    return ~((box[0, e] > hx) | (box[3, e] < lx) | (box[1, e] > hy) | (box[4, e] < ly) | (box[2, e] > hz)
             | (box[5, e] < lz))


@njit(inline="always", **EXACT)
def _union(box: np.ndarray, ids: np.ndarray, first: int, end: int, mark: np.ndarray, now: int) -> tuple:
    """The union (lower, then upper corner) of the boxes of the elements ``ids[first:end]`` marked
    ``now``; its lower corner is +inf when none is."""
    lox = loy = loz = np.inf
    hix = hiy = hiz = -np.inf
    for j in range(first, end):
        e = ids[j]
        if mark[e] == now:
            lox, loy, loz = min(lox, box[0, e]), min(loy, box[1, e]), min(loz, box[2, e])
            hix, hiy, hiz = max(hix, box[3, e]), max(hiy, box[4, e]), max(hiz, box[5, e])
    return lox, loy, loz, hix, hiy, hiz


@njit(**BORROWED, **INNER)
def _round_pairs(c: Contact, lo: int, hi: int, now: int, dmin: np.ndarray, npt: int, nee: int,
                 batch: Batch) -> tuple[int, int]:
    # every pair the round's points (todo[lo:hi]) belong to, with the boxes and the exact tests
    # of a rebuild: each moved point against the triangles whose box holds it; each triangle a
    # moved point belongs to against the points in its box that did not move; each edge a moved
    # point belongs to against the edges whose boxes overlap its own (a pair of two such edges
    # once). The elements are found by their boxes' lower corners (see nearby.py), each once. The
    # pairs are tested BATCH at a time, in the order found, as a rebuild tests them.
    nb = c.near
    x = c.ref
    tris = c.tris
    edges = c.edges
    hits = nb.hits
    cell = nb.cell
    end_pt = c.pt.shape[1]
    end_ee = c.ee.shape[1]
    tbox = nb.tri_box
    ebox = nb.edge_box
    text = nb.ext[0]
    eext = nb.ext[1]
    k = np.int64(0)
    for i in range(lo, hi):
        p = nb.todo[i]
        px, py, pz = x[0, p], x[1, p], x[2, p]
        found = listed_in(nb.tris, hits, cell, px - text, py - text, pz - text, px, py, pz)
        kept = np.int64(0)
        for j in range(found):
            t = hits[j]
            hits[kept] = t
            kept += ((tris[0, t] != p) & (tris[1, t] != p) & (tris[2, t] != p)
                     & _holds(tbox[0, t], tbox[1, t], tbox[2, t], tbox[3, t], tbox[4, t], tbox[5, t], px, py, pz))
        for j in range(kept):
            t = hits[j]
            k = _add_pair(batch.rows, batch.pairs, k, x, p, tris[0, t], tris[1, t], tris[2, t], p, t)
            if k == BATCH:
                npt = _tested_pt(c, batch, k, dmin, npt, end_pt)
                k = 0
    # A moved point's triangles (and edges) are read against what one query of the union of their
    # boxes lists, kept where it is inside (overlaps) that union: an item inside (overlapping) one
    # element's box lies in that element's own query cells, which the union's query reads in the
    # same order (cell by cell, each cell's list in its order), so each element meets its items in
    # the order its own query gives. Each element then picks its own from the few kept, without
    # branches (as a rebuild reads its cells).
    picked = nb.picked
    for i in range(lo, hi):
        p = nb.todo[i]
        ulx, uly, ulz, uhx, uhy, uhz = _union(tbox, nb.tri_ids, nb.tri_at[p], nb.tri_at[p + 1], nb.tri_mark, now)
        if ulx > uhx:
            continue
        found = listed_in(nb.points, hits, cell, ulx, uly, ulz, uhx, uhy, uhz)
        m = np.int64(0)
        for j in range(found):
            q = hits[j]
            hits[m] = q
            m += _holds(ulx, uly, ulz, uhx, uhy, uhz, x[0, q], x[1, q], x[2, q])
        for j in range(nb.tri_at[p], nb.tri_at[p + 1]):
            t = nb.tri_ids[j]
            if nb.tri_mark[t] != now:
                continue
            nb.tri_mark[t] = -now  # (tested once)
            a, b, cc = tris[0, t], tris[1, t], tris[2, t]
            lx, ly, lz, hx, hy, hz = tbox[0, t], tbox[1, t], tbox[2, t], tbox[3, t], tbox[4, t], tbox[5, t]
            kept = np.int64(0)
            for jj in range(m):
                q = hits[jj]
                picked[kept] = q
                kept += ((nb.mark[1, q] != now) & (q != a) & (q != b) & (q != cc)
                         & _holds(lx, ly, lz, hx, hy, hz, x[0, q], x[1, q], x[2, q]))
            for jj in range(kept):
                k = _add_pair(batch.rows, batch.pairs, k, x, picked[jj], a, b, cc, picked[jj], t)
                if k == BATCH:
                    npt = _tested_pt(c, batch, k, dmin, npt, end_pt)
                    k = 0
    if k > 0:
        npt = _tested_pt(c, batch, k, dmin, npt, end_pt)
        k = 0
    for i in range(lo, hi):
        p = nb.todo[i]
        ulx, uly, ulz, uhx, uhy, uhz = _union(ebox, nb.edge_ids, nb.edge_at[p], nb.edge_at[p + 1], nb.edge_mark, now)
        if ulx > uhx:
            continue
        found = listed_in(nb.edges, hits, cell, ulx - eext, uly - eext, ulz - eext, uhx, uhy, uhz)
        m = np.int64(0)
        for j in range(found):
            e2 = hits[j]
            hits[m] = e2
            m += _meets(ebox, e2, ulx, uly, ulz, uhx, uhy, uhz)
        for j in range(nb.edge_at[p], nb.edge_at[p + 1]):
            e = nb.edge_ids[j]
            if nb.edge_mark[e] != now:
                continue
            nb.edge_mark[e] = -now  # (tested once)
            lx, ly, lz, hx, hy, hz = ebox[0, e], ebox[1, e], ebox[2, e], ebox[3, e], ebox[4, e], ebox[5, e]
            kept = np.int64(0)
            for jj in range(m):
                e2 = hits[jj]
                picked[kept] = e2
                # (a pair of two edges of the round's points once, from the lower)
                kept += ((e2 != e) & ((abs(nb.edge_mark[e2]) != now) | (e2 > e))
                         & _meets(ebox, e2, lx, ly, lz, hx, hy, hz))
            for jj in range(kept):
                f1, f2 = min(e, picked[jj]), max(e, picked[jj])  # (a pair stored lower edge first)
                p1, q1 = edges[0, f1], edges[1, f1]
                p2, q2 = edges[0, f2], edges[1, f2]
                if p1 == p2 or p1 == q2 or q1 == p2 or q1 == q2:
                    continue
                k = _add_pair(batch.rows, batch.pairs, k, x, p1, q1, p2, q2, f1, f2)
                if k == BATCH:
                    nee = _tested_ee(x, c, batch, k, dmin, nee, end_ee)
                    k = 0
    if k > 0:
        nee = _tested_ee(x, c, batch, k, dmin, nee, end_ee)
    return npt, nee


@njit(**BORROWED, **INNER)
def _round_balls(last: np.ndarray, c: Contact, lo: int, hi: int, now: int, moving: int, dmin: np.ndarray) -> int:
    # the round's points' new balls; every other point's ball shrunk to a nearer new pair, and a
    # point not yet moved whose start is then outside its ball put on the list for the next round
    # (one that only its position after the integrator has left is clamped by the bound, and
    # moved in the next substep: moving it now too moved many more points, at twice the cost on
    # the folding 100 x 100 cloth); returns the list's new length
    nb = c.near
    floor = FLOOR * c.thickness
    for i in range(lo, hi):
        p = nb.todo[i]
        r = GAMMA * max(dmin[p] - floor, 0.0)
        c.rho2[p] = r * r
    k = hi
    for q in range(dmin.shape[0]):
        if nb.mark[1, q] == now:
            continue
        r = GAMMA * max(dmin[q] - floor, 0.0)
        if r * r < c.rho2[q]:
            c.rho2[q] = r * r
            if nb.mark[0, q] != moving and _leaves(last, c, q, 0.0):
                nb.todo[k] = q
                nb.mark[0, q] = moving
                k += 1
    return k
