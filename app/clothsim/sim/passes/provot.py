"""Provot's deformation constraint: no spring longer than (1 + max_stretch) * rest."""

from __future__ import annotations

import numpy as np
from numba import njit, prange

from ...jit import CHUNKS, KERNEL, PARALLEL


@njit(inline="always", **KERNEL)
def _provot_row(pos: np.ndarray, pinned: np.ndarray, blocks: np.ndarray, rest: np.ndarray, nw: int,
                limit: float, g: int, r: int) -> None:
    """Row r of block g, in place, spring after spring.

    The row is first scanned in one vectorised sweep; a row with no over-stretched spring would
    make no correction, so it is left as it is. Otherwise the sequential loop runs in full.
    """
    lim2 = limit * limit
    dx = blocks[g, 0]
    dy = blocks[g, 1]
    x0 = blocks[g, 2]
    length = blocks[g, 3] - x0
    first = blocks[g, 4] + r * length
    a0 = r * nw + x0 - dx
    b0 = (r + dy) * nw + x0
    rl = rest[first : first + length]
    ax = pos[0, a0 : a0 + length]
    ay = pos[1, a0 : a0 + length]
    az = pos[2, a0 : a0 + length]
    bx = pos[0, b0 : b0 + length]
    by = pos[1, b0 : b0 + length]
    bz = pos[2, b0 : b0 + length]
    over = 0
    for t in range(length):
        ex = bx[t] - ax[t]
        ey = by[t] - ay[t]
        ez = bz[t] - az[t]
        over += (ex * ex + ey * ey + ez * ez) > lim2 * rl[t] * rl[t]
    if over == 0:
        return
    for t in range(length):
        ex = bx[t] - ax[t]
        ey = by[t] - ay[t]
        ez = bz[t] - az[t]
        d2 = ex * ex + ey * ey + ez * ez
        if d2 > lim2 * rl[t] * rl[t]:
            pa = pinned[a0 + t]
            pb = pinned[b0 + t]
            if pa and pb:
                continue
            d = np.sqrt(d2)
            excess = (d - limit * rl[t]) / d
            wa = 0.0 if pa else (1.0 if pb else 0.5)
            wb = 1.0 - wa if (pa or pb) else 0.5
            ax[t] += ex * excess * wa
            ay[t] += ey * excess * wa
            az[t] += ez * excess * wa
            bx[t] -= ex * excess * wb
            by[t] -= ey * excess * wb
            bz[t] -= ez * excess * wb


@njit(**KERNEL)
def provot_bands(pos: np.ndarray, nw: int) -> int:
    """How many horizontal bands :func:`provot` cuts the grid into."""
    return max(1, min(CHUNKS, (pos.shape[1] // nw) // 4))


@njit(inline="always", **KERNEL)
def provot_band(pos: np.ndarray, pinned: np.ndarray, blocks: np.ndarray, rest: np.ndarray, nw: int,
                limit: float, k: int, bands: int) -> None:
    """First phase of :func:`provot`, band k: the springs lying wholly inside it."""
    nh = pos.shape[1] // nw
    lo = k * nh // bands
    hi = (k + 1) * nh // bands
    for g in range(blocks.shape[0]):
        dy = blocks[g, 1]
        for r in range(lo, min(hi - dy, blocks[g, 5])):
            _provot_row(pos, pinned, blocks, rest, nw, limit, g, r)


@njit(inline="always", **KERNEL)
def provot_cut(pos: np.ndarray, pinned: np.ndarray, blocks: np.ndarray, rest: np.ndarray, nw: int,
               limit: float, k: int, bands: int) -> None:
    """Second phase of :func:`provot`, cut k (below band k): the springs crossing it."""
    nh = pos.shape[1] // nw
    cut = (k + 1) * nh // bands
    for g in range(blocks.shape[0]):
        dy = blocks[g, 1]
        for r in range(max(cut - dy, 0), min(cut, blocks[g, 5])):
            _provot_row(pos, pinned, blocks, rest, nw, limit, g, r)


@njit(**KERNEL)
def provot_bands_of(pos: np.ndarray, pinned: np.ndarray, blocks: np.ndarray, rest: np.ndarray, nw: int,
                    limit: float, lo: int, hi: int, bands: int) -> None:
    """Bands ``lo`` to ``hi`` of :func:`provot`'s first phase, compiled on its own, for a call by address."""
    for b in range(lo, hi):
        provot_band(pos, pinned, blocks, rest, nw, limit, b, bands)


@njit(**KERNEL)
def provot_cuts_of(pos: np.ndarray, pinned: np.ndarray, blocks: np.ndarray, rest: np.ndarray, nw: int,
                   limit: float, lo: int, hi: int, bands: int) -> None:
    """Cuts ``lo`` to ``hi`` of :func:`provot`'s second phase, compiled on its own, for a call by address."""
    for b in range(lo, hi):
        provot_cut(pos, pinned, blocks, rest, nw, limit, b, bands)


@njit(**PARALLEL)
def provot(pos: np.ndarray, pinned: np.ndarray, blocks: np.ndarray, rest: np.ndarray, nw: int,
           limit: float) -> None:
    """Shorten over-stretched springs in place (Gauss-Seidel), split over the cores.

    ``limit`` is 1 + max_stretch. The correction is split evenly, or given wholly to the free end
    when the other is pinned; springs with both ends pinned are left alone. The test uses squared
    lengths, so the common case (not over-stretched) needs no square root.

    Loop order (the spec leaves it open): the grid is cut into horizontal bands of at least 4
    rows. First the springs lying wholly inside each band, band by band (block by block, row by
    row within a band); bands share no point, so they run side by side. Then the springs that
    cross each cut; cuts are at least 4 rows apart and a spring spans at most 2, so those groups
    share no point either. The result is that of one fixed sequential order, whatever the
    number of threads.
    """
    bands = provot_bands(pos, nw)
    for k in prange(bands):
        provot_band(pos, pinned, blocks, rest, nw, limit, k, bands)
    for k in prange(bands - 1):
        provot_cut(pos, pinned, blocks, rest, nw, limit, k, bands)
