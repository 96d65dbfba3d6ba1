"""Provot's deformation constraint: no spring longer than (1 + max_stretch) * rest."""

from __future__ import annotations

import numpy as np
from numba import njit

from .jit import FASTMATH


@njit(cache=True, fastmath=FASTMATH)
def provot(pos: np.ndarray, pinned: np.ndarray, blocks: np.ndarray, rest: np.ndarray, nw: int,
           limit: float) -> None:
    """Shorten over-stretched springs in place, block by block, row by row (Gauss-Seidel).

    ``limit`` is 1 + max_stretch. The correction is split evenly, or given wholly to the free end
    when the other is pinned; springs with both ends pinned are left alone. The test uses squared
    lengths, so the common case (not over-stretched) needs no square root.
    """
    px = pos[0]
    py = pos[1]
    pz = pos[2]
    lim2 = limit * limit
    for g in range(blocks.shape[0]):
        dx = blocks[g, 0]
        dy = blocks[g, 1]
        x0 = blocks[g, 2]
        length = blocks[g, 3] - x0
        first = blocks[g, 4]
        rows = blocks[g, 5]
        for r in range(rows):
            a0 = r * nw + x0 - dx
            b0 = (r + dy) * nw + x0
            s0 = first + r * length
            for t in range(length):
                a = a0 + t
                b = b0 + t
                ex = px[b] - px[a]
                ey = py[b] - py[a]
                ez = pz[b] - pz[a]
                d2 = ex * ex + ey * ey + ez * ez
                rl = rest[s0 + t]
                if d2 > lim2 * rl * rl:
                    pa = pinned[a]
                    pb = pinned[b]
                    if pa and pb:
                        continue
                    d = np.sqrt(d2)
                    excess = (d - limit * rl) / d
                    wa = 0.0 if pa else (1.0 if pb else 0.5)
                    wb = 1.0 - wa if (pa or pb) else 0.5
                    px[a] += ex * excess * wa
                    py[a] += ey * excess * wa
                    pz[a] += ez * excess * wa
                    px[b] -= ex * excess * wb
                    py[b] -= ey * excess * wb
                    pz[b] -= ez * excess * wb
