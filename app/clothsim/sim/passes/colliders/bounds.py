"""The cloth's bounding box over its current and last positions: what every collider kind's reach
test reads. The thread team (:mod:`clothsim.sim.solvers.frame`) bounds each member's points into
a row of its own and merges the rows; the other integrators bound the whole cloth at once.
"""

from __future__ import annotations

import numpy as np
from numba import njit

from ....jit import CHUNKS, KERNEL
from ...team import share


@njit(**KERNEL)
def cloth_bounds(pos: np.ndarray, last: np.ndarray, box: np.ndarray) -> None:
    """box = [min xyz, max xyz] over the current and last positions of all points.

    Pinned points are included: they only widen the box, which keeps the skip test exact, and
    the sweep stays contiguous (vectorised).
    """
    range_bounds(pos, last, 0, pos.shape[1], box, np.empty((2, 64)))


@njit(inline="always", **KERNEL)
def range_bounds(pos: np.ndarray, last: np.ndarray, lo: int, hi: int, box: np.ndarray, cols: np.ndarray) -> None:
    """box = [min xyz, max xyz] over the current and last positions of the points lo..hi-1;
    ``cols`` is (2, 64) work space."""
    # Columns of the range as independent running minima/maxima: one running value would chain
    # every comparison, and LLVM does not vectorise a floating-point min reduction unless NaNs
    # are ruled out. Here the inner loop is element-wise over a row, so it vectorises.
    n = hi - lo
    if n <= 0:
        box[:3] = np.inf
        box[3:] = -np.inf
        return
    w = min(n, 64)
    lo_c = cols[0, :w]
    hi_c = cols[1, :w]
    for c in range(3):
        first = pos[c, lo : lo + w]
        for j in range(w):
            lo_c[j] = first[j]
            hi_c[j] = first[j]
        for r0 in range(lo, hi, w):
            x = pos[c, r0 : min(r0 + w, hi)]
            xl = last[c, r0 : min(r0 + w, hi)]
            for j in range(x.shape[0]):
                a = x[j]
                b = xl[j]
                m = a if a < b else b
                lo_c[j] = m if m < lo_c[j] else lo_c[j]
                m = a if a > b else b
                hi_c[j] = m if m > hi_c[j] else hi_c[j]
        box[c] = lo_c.min()
        box[3 + c] = hi_c.max()


@njit(inline="always", **KERNEL)
def member_bounds(pos: np.ndarray, last: np.ndarray, boxes: np.ndarray, cols: np.ndarray, lo: int, hi: int) -> None:
    """Bound the points of chunks lo..hi-1 (a member's share) in one sweep into boxes[lo], and
    empty the rows lo+1..hi-1: the union of the rows is then the cloth's box whatever the team
    size (min and max are exact), and one long sweep vectorises where eight short ones ran at
    half the speed."""
    if lo >= hi:
        return
    n = pos.shape[1]
    range_bounds(pos, last, share(n, lo, CHUNKS)[0], share(n, hi, CHUNKS)[0], boxes[lo], cols)
    for c in range(lo + 1, hi):
        boxes[c, :3] = np.inf
        boxes[c, 3:] = -np.inf


@njit(inline="always", **KERNEL)
def merge_bounds(boxes: np.ndarray, margin: float, box: np.ndarray) -> None:
    """box = the union of the rows of ``boxes``, widened by ``margin`` on every side."""
    for c in range(3):
        lo = boxes[0, c]
        hi = boxes[0, 3 + c]
        for r in range(1, boxes.shape[0]):
            lo = min(lo, boxes[r, c])
            hi = max(hi, boxes[r, 3 + c])
        box[c] = lo - margin
        box[3 + c] = hi + margin
