"""The position corrections every integrator shares, run after its update in the spec's order:
self-collision -> colliders -> Provot.

``post`` is a tuple packed once per run by :func:`clothsim.sim.integrators.post_args`, so each
integrator's compiled loop takes one argument for all of them.
"""

from __future__ import annotations

import numpy as np
from numba import njit

from .jit import EXACT

from .constraints import provot
from .frame import collide_reachable
from .meshcollide import mesh_corrections
from .selfcollide import self_collide


@njit(**EXACT)
def corrections(pos: np.ndarray, last: np.ndarray, free: np.ndarray, blocks: np.ndarray, rest: np.ndarray,
                nw: int, post: tuple, substep: int) -> int:
    """Apply self-collision, colliders and Provot in place at substep ``substep`` of the call;
    returns the colliders skipped.

    ``post`` = (pinned, self_mode, thickness, sim_steps, cell, keys, slots, start, order,
    stretch_limit, colliders, motion, mesh): the :class:`~clothsim.sim.state.Colliders` group, the
    :class:`~clothsim.sim.moving.Motion` group and the :class:`~clothsim.sim.meshgrid.MeshGroup`,
    each None when the scene has none.
    """
    (pinned, self_mode, thickness, sim_steps, cell, keys, slots, start, order, stretch_limit, col, mov, mesh) = post
    skipped = 0
    if self_mode != 0:
        self_collide(pos, free, thickness, sim_steps, self_mode, cell[0], cell[1], cell[2], keys, slots, start,
                     order)
    skipped += collide_group(pos, last, col, mov, substep)
    skipped += mesh_corrections(pos, last, free, mesh)
    if stretch_limit > 0.0:
        provot(pos, pinned, blocks, rest, nw, stretch_limit)
    return skipped


@njit(**EXACT)
def collide_group(pos: np.ndarray, last: np.ndarray, col: tuple | None, mov: tuple | None, substep: int) -> int:
    """The collider pass when the scene has colliders (``col`` is not None); returns those skipped."""
    if col is None:
        return 0
    return collide_reachable(pos, last, col, mov, col.capsules, col.cuboids, substep)


def has_corrections(post: tuple) -> bool:
    """True when any correction pass is on (then velocities must be re-derived from positions)."""
    return bool(post[1] != 0 or post[10] is not None or post[9] > 0.0 or post[12] is not None)
