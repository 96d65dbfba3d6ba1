"""Boxes by cell for a rebuild of the contact pass's reference: a dense grid of cubic cells over
the boxes' extent, each cell's entries one run of a counting-sorted array.

Dense, not hashed: a cell's run is found by its index alone (no key stored and compared, no
other cell's entries sharing a slot), and the cells of one column along z are consecutive, so a
query reads a box of cells as one run per column. The cells are those of the cloth's own
coordinates (``floor(v / cell)``), so the same boxes land in the same cells wherever the grid
starts. A grid that would have more than ``most`` cells (a cloth flung wide) has its cell edge
doubled until it fits; a coordinate outside the grid (not finite) is clamped into it, which only
adds candidates for the exact tests to reject.
"""

from __future__ import annotations

import numpy as np
from numba import njit

from ...jit import EXACT
from .nearby import cell_of

# grid fields: the lowest cell along x, y, z, then the cells along each
X0, Y0, Z0, NX, NY, NZ = range(6)


@njit(**EXACT)
def grid_over(box: np.ndarray, cell: float, most: int) -> tuple[np.ndarray, float]:
    """The grid (see X0 .. NZ) of cells of edge ``cell`` (doubled until there are at most ``most``)
    over the boxes (6, M) (lower then upper corner); returns it and the cell edge used."""
    lo = np.full(3, np.inf)
    hi = np.full(3, -np.inf)
    for k in range(box.shape[1]):
        for ax in range(3):
            lo[ax] = min(lo[ax], box[ax, k])
            hi[ax] = max(hi[ax], box[3 + ax, k])
    grid = np.ones(6, dtype=np.int64)
    for ax in range(3):
        grid[ax] = 0
    if box.shape[1] == 0 or not (np.isfinite(lo).all() and np.isfinite(hi).all()):
        return grid, cell
    for _ in range(64):
        inv = 1.0 / cell
        # (counted in floating point: a cloth blown up far enough would overflow the integers)
        size = 1.0
        for ax in range(3):
            size *= np.floor(hi[ax] * inv) - np.floor(lo[ax] * inv) + 1.0
        if size <= most:
            for ax in range(3):
                grid[ax] = cell_of(lo[ax], inv)
                grid[3 + ax] = cell_of(hi[ax], inv) - grid[ax] + 1
            return grid, cell
        cell *= 2.0
    return grid, cell


@njit(inline="always", **EXACT)
def cell_at(grid: np.ndarray, ax: int, v: float, inv: float) -> np.int64:
    """The cell along axis ``ax`` of coordinate ``v``, counted from the grid's first and clamped
    into the grid."""
    i = cell_of(v, inv) - grid[ax]
    return min(max(i, np.int64(0)), grid[3 + ax] - 1)


@njit(inline="always", **EXACT)
def index_of(grid: np.ndarray, ix: int, iy: int, iz: int) -> np.int64:
    """The index of the cell (``ix``, ``iy``, ``iz``), counted from the grid's first."""
    return (ix * grid[NY] + iy) * grid[NZ] + iz


@njit(**EXACT)
def box_table(box: np.ndarray, grid: np.ndarray, cell: float) -> tuple[np.ndarray, np.ndarray]:
    """Every box (6, M) in every cell of ``grid`` it overlaps: (start (cells + 1,), ids), the
    entries of cell i being ``ids[start[i]:start[i + 1]]``, in increasing id."""
    inv = 1.0 / cell
    cells = grid[NX] * grid[NY] * grid[NZ]
    start = np.zeros(cells + 1, dtype=np.int64)
    for k in range(box.shape[1]):
        for ix in range(cell_at(grid, 0, box[0, k], inv), cell_at(grid, 0, box[3, k], inv) + 1):
            for iy in range(cell_at(grid, 1, box[1, k], inv), cell_at(grid, 1, box[4, k], inv) + 1):
                i0 = index_of(grid, ix, iy, cell_at(grid, 2, box[2, k], inv))
                i1 = index_of(grid, ix, iy, cell_at(grid, 2, box[5, k], inv))
                for i in range(i0, i1 + 1):
                    start[i] += 1
    total = _run_ends(start, cells)
    ids = np.empty(total, dtype=np.int64)
    # (placed from the last box back, each cell filled from its end: a cell's ids increase, and
    # start ends up at each cell's first, with no copy of the starts as cursors)
    for k in range(box.shape[1] - 1, -1, -1):
        for ix in range(cell_at(grid, 0, box[0, k], inv), cell_at(grid, 0, box[3, k], inv) + 1):
            for iy in range(cell_at(grid, 1, box[1, k], inv), cell_at(grid, 1, box[4, k], inv) + 1):
                i0 = index_of(grid, ix, iy, cell_at(grid, 2, box[2, k], inv))
                i1 = index_of(grid, ix, iy, cell_at(grid, 2, box[5, k], inv))
                for i in range(i0, i1 + 1):
                    start[i] -= 1
                    ids[start[i]] = k
    return start, ids


@njit(**EXACT)
def corner_table(box: np.ndarray, grid: np.ndarray, cell: float) -> tuple[np.ndarray, np.ndarray]:
    """Every box (6, M) once, in the cell of ``grid`` that holds its lower corner: (start, ids) as
    :func:`box_table` gives them. With cells no smaller than any box, the boxes that overlap box
    b have their lower corner in the cells from b's lower corner's minus one to its upper
    corner's, along each axis."""
    inv = 1.0 / cell
    cells = grid[NX] * grid[NY] * grid[NZ]
    start = np.zeros(cells + 1, dtype=np.int64)
    where = np.empty(box.shape[1], dtype=np.int64)
    for k in range(box.shape[1]):
        i = index_of(grid, cell_at(grid, 0, box[0, k], inv), cell_at(grid, 1, box[1, k], inv),
                     cell_at(grid, 2, box[2, k], inv))
        where[k] = i
        start[i] += 1
    total = _run_ends(start, cells)
    ids = np.empty(total, dtype=np.int64)
    for k in range(box.shape[1] - 1, -1, -1):  # (as in box_table)
        start[where[k]] -= 1
        ids[start[where[k]]] = k
    return start, ids


@njit(inline="always", **EXACT)
def _run_ends(start: np.ndarray, cells: int) -> np.int64:
    """Each cell's count in ``start`` made the end of its run (and ``start[cells]`` the total,
    which is returned)."""
    acc = np.int64(0)
    for s in range(cells):
        acc += start[s]
        start[s] = acc
    start[cells] = acc
    return acc
