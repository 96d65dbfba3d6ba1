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
                nw: int, post: tuple) -> int:
    """Apply self-collision, colliders and Provot in place; returns the colliders skipped.

    ``post`` = (pinned, self_mode, thickness, sim_steps, cell, keys, slots, start, order,
    stretch_limit, spheres, planes, offset, box, sphere_on, plane_on, mesh); ``mesh`` is a
    :class:`~clothsim.sim.meshgrid.MeshGroup` or None.
    """
    (pinned, self_mode, thickness, sim_steps, cell, keys, slots, start, order, stretch_limit, spheres, planes,
     offset, box, sphere_on, plane_on, mesh) = post
    skipped = 0
    if self_mode != 0:
        self_collide(pos, free, thickness, sim_steps, self_mode, cell[0], cell[1], cell[2], keys, slots, start,
                     order)
    if spheres.shape[0] + planes.shape[0] > 0:
        skipped += collide_reachable(pos, last, free, spheres, planes, offset, box, sphere_on, plane_on)
    skipped += mesh_corrections(pos, last, free, mesh)
    if stretch_limit > 0.0:
        provot(pos, pinned, blocks, rest, nw, stretch_limit)
    return skipped


def has_corrections(post: tuple) -> bool:
    """True when any correction pass is on (then velocities must be re-derived from positions)."""
    return bool(post[1] != 0 or post[10].shape[0] + post[11].shape[0] > 0 or post[9] > 0.0 or post[16] is not None)
