"""The contact pass's group (:class:`Contact`): its constants, its arrays and how they are made,
saved, restored and grown (the method: :mod:`.contact`)."""

from __future__ import annotations

from typing import NamedTuple

import numpy as np

from ...jit import CHUNKS
from .nearby import Nearby, nearby_index


#: Fraction of the distance to the nearest other element a point may move from its reference.
GAMMA = 0.45
#: No two elements come closer than this fraction of the contact distance: a ball's radius is
#: GAMMA x (d - FLOOR x h), so a pair at d >= FLOOR x h stays at (1 - 2 GAMMA) d + 2 GAMMA FLOOR x h
#: >= FLOOR x h. Without it distances may shrink by 1 - 2 GAMMA at every rebuild, down to below
#: the spacing of floats (1e-16 m near 1 m), where a neighbour's move flips the exact crossing test
#: (seen in the twist: two edges 4e-17 m apart).
FLOOR = 1e-6
#: Fraction of the remaining overlap a contact removes per substep beyond stopping the approach.
PUSH = 0.1
#: While pins move (a pin track, or pins put elsewhere through the API between calls) the response
#: runs SWEEPS_MOVING Jacobi sweeps of PUSH_MOVING each: one sweep averages the pushes a point gets,
#: so cloth wrung between pins turning against each other does not make way for them fast enough,
#: and the pins' balls shrink below their step (the stress set's twist). Four sweeps of 30 % leave
#: 24 % of an isolated pair's overlap, where one of 10 % leaves 90 %.
PUSH_MOVING = 0.3
SWEEPS_MOVING = 4
#: Cloth-on-cloth Coulomb friction coefficient.
FRICTION = 0.3
#: The contact distance is at most this fraction of the shortest rest edge: a flat cloth's own
#: non-adjacent elements lie 0.7 edge apart, and a thicker contact would push the sheet from itself.
MAX_THICKNESS_PER_EDGE = 0.5
#: Query radius over the contact distance.
REACH = 1.5
#: ... or over the shortest rest edge, where that is larger: a flat grid's nearest elements that
#: share no point lie 1/sqrt(2) edge apart (a quad's diagonal and the next quad's corner), so a
#: cloth thin against its edges still gets balls as large as its own mesh allows. A ball never
#: shrinks when the radius grows (a pair newly within it is further than the old radius); only
#: the search grows (docs/history/self-collision-limits.md, 2026-12-08).
REACH_PER_EDGE = 0.69
#: A point about to leave its ball calls for a new reference only if its ball is at least this
#: fraction of the largest (GAMMA x the query radius): a point held a hair from another element
#: would otherwise rebuild every substep and gain nothing; it waits, clamped, for the next rebuild
#: (which another point's leaving, a frame whose pins move or a point found outside its ball at a
#: substep's start calls for).
ROOMY = 0.25
#: Parts a rebuild is cut into, each a contiguous range of points and of edges with its own share
#: of the pair arrays: the thread team's members search as many parts each as costs them alike
#: (the previous rebuild's costs), and the bits do not depend on who searched which.
PARTS = 32

#: A member's flag, an int64 row of FLAG: whether the substep rebuilds the reference, the member's
#: first part and end part, the team's size (the rows of ``dmins`` written), the parts the
#: rebuild is cut into, and whether any point calls for a new reference (so that a substep in
#: which none does skips :func:`rereference`'s own pass over the points).
STALE, FIRST, END, SIZE, CUT, CALLS = range(6)
FLAG = 6

#: A substep whose points about to leave their balls are more than this fraction of the cloth
#: rebuilds the whole reference (one search of the cloth, shared by the team) instead of moving
#: those points' references one by one (:func:`rereference`, run by one member).
LOCAL_SHARE = 1.0 / 128.0

# meta fields (MOVING: 1 in a frame whose pins move, set by the simulation; CLAMPED: 1 when the
# bound has moved a point since its reference was set; REBUILDS counts the whole rebuilds, LOCALS
# the substeps that moved some points' references, MOVED those points; SQUEEZED counts the substeps
# in which a moving collider put a point out of its ball after the bound, SQUEEZING is 1 in such a
# substep until it is counted: see contactreference.left_balls)
VALID, N_PT, N_EE, REBUILDS, DROPPED, UNSAFE, MOVING, CLAMPED, LOCALS, MOVED, SQUEEZING, SQUEEZED = range(12)
META = 12


class Contact(NamedTuple):
    """The contact pass's arrays: the mesh (triangles (3, T), edges (2, E)), the movable mask, the
    reference state (3, N) and each point's squared ball radius, the stored pairs (point-triangle:
    indices (2, P) and weights + normal (6, P); edge-edge: indices (2, Q) and parameters + normal
    (5, Q)), the Jacobi sums, ``meta`` counters (see VALID ... SQUEEZED), a rebuild's work space
    (each member's bounds on the balls, each part's pairs found and cost, see :func:`search`), the
    points by cell and the elements by point (for :func:`rereference`), the contact distance,
    the query radius and the broad phase's cell edge."""

    tris: np.ndarray
    edges: np.ndarray
    movable: np.ndarray
    ref: np.ndarray
    rho2: np.ndarray
    pt: np.ndarray
    ptf: np.ndarray
    ee: np.ndarray
    eef: np.ndarray
    acc: np.ndarray
    cnt: np.ndarray
    meta: np.ndarray
    dmins: np.ndarray
    found: np.ndarray
    cost: np.ndarray
    near: Nearby
    thickness: float
    radius: float
    cell: float


def mesh_edges(tris: np.ndarray) -> np.ndarray:
    """The unique edges (2, E) int64 of triangles (3, T), lower index first, sorted."""
    t = tris.astype(np.int64)
    e = np.concatenate([t[[0, 1]], t[[1, 2]], t[[2, 0]]], axis=1)
    e = np.sort(e, axis=0)
    e = np.unique(e.T, axis=0).T
    return np.ascontiguousarray(e)


def contact_group(pos: np.ndarray, tris: np.ndarray, movable: np.ndarray, thickness: float) -> Contact:
    """The pass's group for a cloth at rest positions ``pos`` (3, N) with triangles ``tris``."""
    tris = np.ascontiguousarray(tris, dtype=np.int64)
    edges = mesh_edges(tris)
    lengths = np.sqrt(((pos[:, edges[0]] - pos[:, edges[1]]) ** 2).sum(axis=0))
    shortest = float(lengths[lengths > 0].min()) if (lengths > 0).any() else thickness
    h = min(thickness, MAX_THICKNESS_PER_EDGE * shortest)
    radius = max(REACH * h, REACH_PER_EDGE * shortest)
    n = pos.shape[1]
    cap = 16 * n + 64
    cell = max(radius, 2.0 * float(np.median(lengths)))
    return Contact(tris, edges, np.ascontiguousarray(movable, dtype=np.bool_), np.zeros((3, n)), np.zeros(n),
                   np.zeros((2, cap), dtype=np.int64), np.zeros((6, cap)), np.zeros((2, cap), dtype=np.int64),
                   np.zeros((5, cap)), np.zeros((3, n)), np.zeros(n, dtype=np.int64), np.zeros(META, dtype=np.int64),
                   np.zeros((CHUNKS, n)), np.zeros((PARTS, 2), dtype=np.int64), np.zeros(PARTS, dtype=np.int64),
                   nearby_index(n, tris, edges, cell), h, radius, cell)


def snapshot_reference(c: Contact) -> tuple:
    """A copy of what the pass carries from one substep to the next (the reference, the balls,
    the stored pairs, the counters, the points' cells, the points held), for
    :func:`restore_reference`."""
    npt, nee = int(c.meta[N_PT]), int(c.meta[N_EE])
    nb = c.near
    kept = (nb.tri_box, nb.edge_box, nb.ext, nb.held, *(a for cells in (nb.points, nb.tris, nb.edges) for a in cells[:3]))
    return (c.ref.copy(), c.rho2.copy(), c.pt[:, :npt].copy(), c.ptf[:, :npt].copy(), c.ee[:, :nee].copy(),
            c.eef[:, :nee].copy(), c.meta.copy(), tuple(a.copy() for a in kept))


def restore_reference(c: Contact, saved: tuple) -> None:
    """Put back a :func:`snapshot_reference` (a frame replayed from its start)."""
    ref, rho2, pt, ptf, ee, eef, meta, kept = saved
    nb = c.near
    for a, b in zip((nb.tri_box, nb.edge_box, nb.ext, nb.held,
                     *(a for cells in (nb.points, nb.tris, nb.edges) for a in cells[:3])), kept):
        a[...] = b
    c.ref[...] = ref
    c.rho2[...] = rho2
    c.pt[:, :pt.shape[1]] = pt
    c.ptf[:, :ptf.shape[1]] = ptf
    c.ee[:, :ee.shape[1]] = ee
    c.eef[:, :eef.shape[1]] = eef
    c.meta[...] = meta


#: The pair arrays grow while frames drop pairs (see :func:`with_more_room`), up to this many
#: bytes in all.
MOST_PAIR_BYTES = 1 << 30


def with_more_room(c: Contact) -> Contact | None:
    """``c`` with pair arrays twice as long (what they hold copied over), or None when they would
    pass ``MOST_PAIR_BYTES``. A frame whose rebuilds or moves found more pairs than the arrays
    hold (``meta[DROPPED]`` grew) is run again from its start with them (the simulation does
    it): a pair left out is one the response does not push, and cloth wrung between moving pins
    then closes on them faster than their balls allow (the stress set's twist crossed itself)."""
    cap = 2 * c.pt.shape[1]
    if cap * 8 * (c.pt.shape[0] + c.ptf.shape[0] + c.ee.shape[0] + c.eef.shape[0]) > MOST_PAIR_BYTES:
        return None

    def grown(a: np.ndarray) -> np.ndarray:
        b = np.zeros((a.shape[0], cap), dtype=a.dtype)
        b[:, : a.shape[1]] = a
        return b

    return c._replace(pt=grown(c.pt), ptf=grown(c.ptf), ee=grown(c.ee), eef=grown(c.eef))


def response_reach(c: Contact) -> float:
    """The furthest the response moves a point in one substep: an average of pushes of at most
    the contact distance (plus friction), over a weight sum of at least 1/2."""
    return 2.0 * (1.0 + FRICTION) * c.thickness
