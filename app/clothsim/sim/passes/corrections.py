"""The position corrections every integrator shares, run after its update in the spec's order:
self-collision (or the contact mode's response) -> colliders -> Provot, then the contact mode's
bound (last: no later pass may move a point past it).

``post`` is the :class:`~clothsim.sim.state.Corrections` group packed by
:func:`clothsim.sim.solvers.post_args`, so the integrators' substep takes one argument for all of them.
"""

from __future__ import annotations

import numpy as np
from numba import njit

from ...jit import CHUNKS, EXACT
from ...jit.internals import call_native, type_ref

from .provot import provot
from .meshsprings import mesh_limit
from .colliders import SET_REACHABLE
from .selfcollide import self_collide
from .contact import contact_bound, contact_respond
from .contactreference import count_squeezed, left_balls
from ..state import Corrections


@njit(**EXACT)
def corrections(pos: np.ndarray, last: np.ndarray, free: np.ndarray, blocks: np.ndarray, rest: np.ndarray,
                nw: int, post: tuple, substep: int, scratch: np.ndarray) -> int:
    """Apply self-collision, colliders and Provot in place at substep ``substep`` of the call;
    returns the colliders skipped (``scratch``: one int64 the collider pass may write).

    ``post`` is the :class:`~clothsim.sim.state.Corrections` group, with the address of the
    collider kinds' groups in place of the tuple (so that one compiled kernel serves every set of
    kinds).
    """
    skipped = 0
    if post.self_mode != 0:
        h = post.hash
        self_collide(pos, free, h.thickness, h.sim_steps, post.self_mode, h.cell[0], h.cell[1], h.cell[2], h.keys,
                     h.slots, h.start, h.order)
    contact_group(pos, last, post.contact, True)
    skipped += collide_group(pos, last, post.col, post.colliders, substep, scratch)
    if post.stretch_limit > 0.0:
        if not mesh_limit(pos, post.pinned, post.mesh, post.stretch_limit, 0, CHUNKS, True):
            provot(pos, post.pinned, blocks, rest, nw, post.stretch_limit)
    contact_group(pos, last, post.contact, False)
    collide_again(pos, last, post.contact, post.col, post.colliders, substep, scratch)
    return skipped


@njit(**EXACT)
def corrections_into(pos: np.ndarray, last: np.ndarray, free: np.ndarray, blocks: np.ndarray, rest: np.ndarray,
                     nw: int, post: tuple, substep: int, skipped: np.ndarray) -> None:
    """:func:`corrections`, compiled on its own for a call by address (``Corrections.at``): the
    integrators' substeps share it, and none links it in and re-optimises it; the colliders
    skipped go to ``skipped[0]``."""
    skipped[0] = corrections(pos, last, free, blocks, rest, nw, post, substep, skipped)


@njit(**EXACT)
def collide_group(pos: np.ndarray, last: np.ndarray, col: tuple | None, at: int, substep: int,
                  scratch: np.ndarray) -> int:
    """The collider pass when the scene has colliders (``col`` is not None), the kinds' groups at
    the address ``at``: :func:`~clothsim.sim.passes.colliders.collide_reachable` for the plan's
    set of kinds, by its address (it writes the count into ``scratch[0]``); returns the colliders
    skipped."""
    if col is None:
        return 0
    call_native(col.sets[SET_REACHABLE], (pos, last, col, at, np.int64(substep), scratch, type_ref(None)))
    return scratch[0]


@njit(**EXACT)
def contact_group(pos: np.ndarray, last: np.ndarray, contact: tuple | None, respond: bool) -> None:
    """The contact mode's response (``respond``) or bound when on (``contact`` is not None: the
    branch is pruned otherwise)."""
    if contact is None:
        return
    if respond:
        contact_respond(pos, last, contact)
    else:
        contact_bound(pos, contact)


@njit(**EXACT)
def collide_again(pos: np.ndarray, last: np.ndarray, contact: tuple | None, col: tuple | None, at: int, substep: int,
                  scratch: np.ndarray) -> None:
    """In the contact mode, when a collider moves: the collider pass again, after the bound, and
    the substep counted when it put a point out of its ball (see
    :func:`~clothsim.sim.passes.contactreference.left_balls`); pruned when either is off."""
    if contact is None or col is None:
        return
    if col.moving:
        collide_group(pos, last, col, at, substep, scratch)
        left_balls(pos, contact, col.free, 0, CHUNKS)
        count_squeezed(contact)


def has_corrections(post: Corrections) -> bool:
    """True when any correction pass is on (then velocities must be re-derived from positions)."""
    return bool(post.self_mode != 0 or post.col is not None or post.stretch_limit > 0.0 or post.contact is not None)
