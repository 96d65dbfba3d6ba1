"""Force accumulation: uniform external acceleration plus Hooke springs.

State is struct-of-arrays: ``pos`` and ``forces`` are (3, N). Springs of a grid come in
blocks, one per family direction (see :func:`clothsim.cloth.spring_blocks`): inside a block
row both end points advance by one index per spring, so the row is a contiguous stream that
LLVM vectorises. Each row is computed into a scratch buffer first and then added to both ends
in two separate loops, because adding in place would chain every spring to its neighbour.
"""

from __future__ import annotations

import numpy as np
from numba import njit

from .jit import FASTMATH


@njit(cache=True, fastmath=FASTMATH)
def accumulate_forces(pos: np.ndarray, forces: np.ndarray, blocks: np.ndarray, block_k: np.ndarray,
                      rest: np.ndarray, nw: int, mass: float, gravity: np.ndarray, tmp: np.ndarray) -> None:
    """forces = mass * gravity + sum of spring forces ``k * (length - rest)`` along each spring.

    ``blocks`` rows are (dx, dy, x0, x1, first_spring, num_rows); ``block_k`` the stiffness of
    each block (bending blocks already scaled); ``tmp`` is a (3, nw) scratch buffer.
    """
    px = pos[0]
    py = pos[1]
    pz = pos[2]
    fx = forces[0]
    fy = forces[1]
    fz = forces[2]
    tx = tmp[0]
    ty = tmp[1]
    tz = tmp[2]
    fx[:] = mass * gravity[0]
    fy[:] = mass * gravity[1]
    fz[:] = mass * gravity[2]
    for g in range(blocks.shape[0]):
        dx = blocks[g, 0]
        dy = blocks[g, 1]
        x0 = blocks[g, 2]
        length = blocks[g, 3] - x0
        first = blocks[g, 4]
        rows = blocks[g, 5]
        k = block_k[g]
        for r in range(rows):
            a0 = r * nw + x0 - dx
            b0 = (r + dy) * nw + x0
            s0 = first + r * length
            for t in range(length):
                ex = px[b0 + t] - px[a0 + t]
                ey = py[b0 + t] - py[a0 + t]
                ez = pz[b0 + t] - pz[a0 + t]
                d = np.sqrt(ex * ex + ey * ey + ez * ez)
                f = k * (d - rest[s0 + t]) / d if d > 0.0 else 0.0
                tx[t] = f * ex
                ty[t] = f * ey
                tz[t] = f * ez
            for t in range(length):
                fx[a0 + t] += tx[t]
                fy[a0 + t] += ty[t]
                fz[a0 + t] += tz[t]
            for t in range(length):
                fx[b0 + t] -= tx[t]
                fy[b0 + t] -= ty[t]
                fz[b0 + t] -= tz[t]
