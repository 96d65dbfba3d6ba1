"""Self-collision by contact (``simulation.self_collision: "contact"``): point-triangle and
edge-edge proximity, repulsion with friction, and a conservative displacement bound that lets no
element pass through another over a substep's whole motion. It is two passes of the substep: the
response in the self-collision slot (before the colliders, so that they have the last word on a
point the response pushed into them) and the bound at the very end (after Provot: no later pass
may move a point past it).

The method is the displacement bound of Vertex Block Descent and Offset Geometric Contact (Chen
et al. 2024, 2025): from a crossing-free reference state, every point gets a ball of radius
``GAMMA`` (< 1/2) times its distance to the nearest element it does not belong to (point-triangle
and edge-edge, both ways, within the query radius), less a floor (``FLOOR``) that keeps every pair
further apart than rounding. A state in which every point lies in its ball is crossing-free, and so
is every state on the straight path from the reference to it (a ball is convex): two elements at
distance d each move less than d/2. In each substep:

1. (self-collision slot) the points whose position after the integrator has left their ball
   (a pin, or a free point whose ball is not tiny: ROOMY) or that the bound held back since
   their reference was set have their references moved to where the substep started, one by
   one (:func:`~.contactreference.rereference`); the whole reference is rebuilt from there instead (crossing-free,
   by the same argument) when more than ``LOCAL_SHARE`` of the points call for it, when a
   point's position at the substep's start has left its ball, and when there is none (the first
   substep, a frame whose pins move, after ``reset``: the simulation clears ``meta[VALID]``);
2. (self-collision slot) every stored pair closer than the contact distance is pushed apart along its reference normal
   (inelastically, plus a fraction of the overlap), with Coulomb friction on the pair's relative
   tangential motion; corrections are averaged per point (Jacobi, in pair order), in one sweep,
   or in ``SWEEPS_MOVING`` stronger ones while pins move;
3. (after Provot) every free point is projected into its ball: on the segment from its
   reference, so a point that a convex collider left outside stays outside when its reference
   is outside too. Pinned points are never moved; their balls are
   checked in step 1 like every other point's. In a scene whose colliders move, the collider
   pass then runs again (a moving collider may have passed over a point's reference): a point it
   puts out of its ball is counted as a squeezed substep
   (:func:`~.contactreference.left_balls`).

The broad phase is a dense grid of cells over the cloth's extent (:mod:`.celltables`), built at
a rebuild only (:func:`~.contactsearch.rebuild` has the rule): the triangles' boxes, widened by the query radius,
in every cell they overlap, read by each point in its own cell; each edge's box, widened by half
of it, once in the cell of its lower corner, read by the other edges from the cells where an
overlapping box can start (cells of half the largest box, a column of them one run). A rebuild is
cut into ``PARTS`` parts, ranges of the points and of the edges (:func:`~.contactsearch.search`), which the thread
team's members search side by side; the first member joins them in order (:func:`~.contactsearch.join`), so the
pairs and balls are one sweep's whoever searched what. Moving a few points' references finds
what is near them through cells kept up to date as they move (:mod:`.nearby`). Between rebuilds
a substep costs three passes over the points and one over the stored pairs.

The pass's parts, one job each: :mod:`.contactgroup` (the group, its constants, and its arrays
made, saved, restored and grown), :mod:`.contactdistance` (closest points), :mod:`.contactsearch`
(a reference's pairs and balls), :mod:`.contactreference` (points leaving their balls, a few
references moved), :mod:`.contactresponse` (the response and the bound). This module holds the
passes as the substep and the thread team call them.
"""

from __future__ import annotations

import numpy as np
from numba import njit

from ...jit import EXACT, INNER, KERNEL
from ..team import share
from .contactgroup import CALLS, CUT, END, FIRST, FLAG, LOCAL_SHARE, PARTS, SIZE, STALE, UNSAFE, VALID, Contact
from .contactreference import _leaving, _outside, rereference
from .contactresponse import bound, respond
from .contactsearch import _ONE, _ZERO, _search_alone, join


@njit(**KERNEL, **INNER)
def _stale(pos: np.ndarray, last: np.ndarray, c: Contact, flag: np.ndarray) -> bool:
    """True when the substep that started at ``last`` needs a whole new reference: there is none,
    a point has left its ball, or more than ``LOCAL_SHARE`` of the points are about to (fewer have
    their references moved one by one: :func:`rereference`; how many call for one goes in
    ``flag[CALLS]``)."""
    if c.meta[VALID] == 0 or _outside(last, c):
        return True
    most = np.int64(LOCAL_SHARE * pos.shape[1])
    flag[CALLS] = _leaving(pos, c, most)
    return flag[CALLS] > most


@njit(**KERNEL, **INNER)
def _rebuilt(pos: np.ndarray, c: Contact) -> None:
    # a pinned point that moved further than its ball in this one substep: the bound cannot hold
    # for its pairs (the pin's motion is prescribed); counted, not hidden
    for p in range(pos.shape[1]):
        if not c.movable[p]:
            dx = pos[0, p] - c.ref[0, p]
            dy = pos[1, p] - c.ref[1, p]
            dz = pos[2, p] - c.ref[2, p]
            if dx * dx + dy * dy + dz * dz > c.rho2[p]:
                c.meta[UNSAFE] += 1
                break


# The first half of the pass as the thread team runs it (solvers/frame.py): each member asks
# whether the reference is stale and, if so, which parts of the rebuild are its own (the same
# answers from the same arrays, so no member waits for another's, and the question costs the team
# no time: the others would wait for the first member meanwhile); if it is stale each searches
# its parts; after a barrier the first member joins them and responds. The parts' pairs, joined
# in order, are the pairs of one sweep in its order, and a ball's bound is a minimum, so the bits
# do not depend on the team's size. Before joining, the first member has a rebuild whose part
# overflowed its share searched again as one part (by the member's search called once more, not
# from inside the join, which would carry a second compiled copy of the search).


@njit(inline="always", **EXACT)
def _first_part(cost: np.ndarray, member: int, size: int) -> int:
    """The first part of member ``member`` of ``size``: parts cut where the running sum of
    ``cost`` reaches member / size of the whole (equal counts of parts before any cost is known)."""
    total = np.int64(0)
    for k in range(cost.shape[0]):
        total += cost[k]
    if total == 0:
        return share(cost.shape[0], member, size)[0]
    run = np.int64(0)
    for k in range(cost.shape[0]):
        if run * size >= total * member:
            return k
        run += cost[k]
    return cost.shape[0]


@njit(**EXACT)
def contact_stale(pos: np.ndarray, last: np.ndarray, c: Contact, flag: np.ndarray, member: int, size: int) -> None:
    """Member ``member``'s ``flag``: whether the substep that started at ``last`` rebuilds the
    reference, and if so its parts of the rebuild."""
    flag[CALLS] = 0
    flag[STALE] = 1 if _stale(pos, last, c, flag) else 0
    if flag[STALE] != 0:
        flag[FIRST] = _first_part(c.cost, member, size)
        flag[END] = _first_part(c.cost, member + 1, size) if member + 1 < size else PARTS
        flag[SIZE] = size
        flag[CUT] = PARTS


@njit(**EXACT, **INNER)
def contact_joined(pos: np.ndarray, last: np.ndarray, c: Contact, flag: np.ndarray) -> None:
    """The first member's end of the first half: the rebuild's parts joined (when ``flag`` says
    it is stale), or else the references of the points about to leave their balls moved, then
    the response."""
    if flag[STALE] != 0:
        join(last, c, flag[CUT], flag[SIZE])
        _rebuilt(pos, c)
    elif flag[CALLS] != 0 and rereference(pos, last, c):
        _rebuilt(pos, c)
    respond(pos, last, c)


@njit(**EXACT)
def contact_respond(pos: np.ndarray, last: np.ndarray, c: Contact) -> None:
    """The first half of the pass, in the self-collision slot of a substep that started at
    ``last``: rebuild the reference if a point has left its ball, then push the pairs apart (the
    team's three steps run by a team of one: the other integrators' substep)."""
    flag = np.empty(FLAG, dtype=np.int64)
    contact_stale(pos, last, c, flag, _ZERO, _ONE)
    if flag[STALE] != 0:
        _search_alone(last, c, flag)
    contact_joined(pos, last, c, flag)


@njit(**EXACT, **INNER)
def contact_bound(pos: np.ndarray, c: Contact) -> None:
    """The second half, last in the substep: every free point into its ball."""
    bound(pos, c)
