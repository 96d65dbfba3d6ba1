"""The cloth's points and its mesh's elements by the cell they lie in, kept up to date as single
points move: what the contact pass reads to find again the pairs of a few points whose reference
moved (:func:`~clothsim.sim.passes.contactreference.rereference`) without searching the whole cloth.

Three lists of cells: the points by their position, the triangles by the lower corner of their
box widened by the query radius, the edges by the lower corner of their box widened by half of
it. Each hash slot holds a linked list of the items whose cell falls in it (``head`` the first,
``nxt`` the next, -1 ending it), so moving one item to another cell is a few writes, where the
counting-sorted tables of a full rebuild would have to be built again. A box that overlaps a
given box has its lower corner between that box's lower corner less the largest box's extent and
its upper corner (``ext``), so a query reads one side only.
"""

from __future__ import annotations

from typing import NamedTuple

import numpy as np
from numba import njit

from ...jit import BORROWED, EXACT, KERNEL
from .selfcollide import _cell_key


class Cells(NamedTuple):
    """Items by cell: ``head`` (slots,) the first item of each hash slot's list, ``nxt`` (M,) the
    next item of the same slot, ``key`` (M,) each item's cell; ``shift`` the hash's shift for
    ``head``'s size."""

    head: np.ndarray
    nxt: np.ndarray
    key: np.ndarray
    shift: int


class Nearby(NamedTuple):
    """The points' cells, the triangles' and the edges' (:class:`Cells`), the elements' boxes at
    the reference (``tri_box`` (6, T) widened by the query radius, ``edge_box`` (6, E) by half of
    it; lower then upper corner) and ``ext`` (2,) a bound on each kind's box extent along any
    axis, the elements by point in compressed rows (``tri_at`` (N + 1,) into ``tri_ids``, the
    same for edges), and a re-reference's work space: ``held`` (N,) the points the bound has
    moved since their reference was set, ``mark`` (2, N) / ``tri_mark`` (T,) / ``edge_mark`` (E,)
    stamps (the points being moved in this re-reference, or in this round; the elements they
    belong to), ``todo`` (N,) the points to move, ``count`` (1,) the last stamp given, ``hits``
    the items a query found and ``picked`` those an element takes of them. ``cell`` is the cells'
    edge."""

    points: Cells
    tris: Cells
    edges: Cells
    tri_box: np.ndarray
    edge_box: np.ndarray
    ext: np.ndarray
    tri_at: np.ndarray
    tri_ids: np.ndarray
    edge_at: np.ndarray
    edge_ids: np.ndarray
    held: np.ndarray
    mark: np.ndarray
    tri_mark: np.ndarray
    edge_mark: np.ndarray
    todo: np.ndarray
    count: np.ndarray
    hits: np.ndarray
    picked: np.ndarray
    cell: float


def _cells(m: int) -> Cells:
    slots = 2
    while slots < 2 * m:
        slots *= 2
    return Cells(np.full(slots, -1, dtype=np.int64), np.full(m, -1, dtype=np.int64), np.zeros(m, dtype=np.int64),
                 64 - (slots.bit_length() - 1))


def _rows(ids: np.ndarray, n: int) -> tuple[np.ndarray, np.ndarray]:
    """Compressed rows: the elements (columns of ``ids`` (k, M)) each point is a corner of."""
    owner = ids.reshape(-1)
    order = np.argsort(owner, kind="stable").astype(np.int64)
    at = np.zeros(n + 1, dtype=np.int64)
    np.cumsum(np.bincount(owner, minlength=n), out=at[1:])
    return at, order % ids.shape[1]


def nearby_index(n: int, tris: np.ndarray, edges: np.ndarray, cell: float) -> Nearby:
    """An empty index for ``n`` points and the mesh's triangles (3, T) and edges (2, E), with
    cells of edge ``cell`` (filled when a reference is set)."""
    t = tris.shape[1]
    e = edges.shape[1]
    tri_at, tri_ids = _rows(tris, n)
    edge_at, edge_ids = _rows(edges, n)
    return Nearby(_cells(n), _cells(t), _cells(e), np.zeros((6, t)), np.zeros((6, e)), np.zeros(2), tri_at, tri_ids,
                  edge_at, edge_ids, np.zeros(n, dtype=np.bool_), np.zeros((2, n), dtype=np.int64),
                  np.zeros(t, dtype=np.int64), np.zeros(e, dtype=np.int64), np.zeros(n, dtype=np.int64),
                  np.zeros(1, dtype=np.int64), np.zeros(max(n, t, e), dtype=np.int64),
                  np.zeros(max(n, t, e), dtype=np.int64), cell)


@njit(inline="always", **KERNEL)
def cell_of(v: float, inv: float) -> np.int64:
    """The cell index of coordinate ``v`` for cells of edge 1 / ``inv``."""
    return np.int64(np.floor(v * inv))


@njit(inline="always", **KERNEL)
def slot_of(key: np.int64, shift: np.uint64) -> np.int64:
    """The hash slot of cell ``key``: the top bits of key x 2^64 / phi (Fibonacci hashing)."""
    # (Bits 32 and up, masked, had cells that differ only in x, 16 cells apart, share a slot: a
    # third of the edge-edge candidates read belonged to another cell.)
    return np.int64((np.uint64(key) * np.uint64(0x9E3779B97F4A7C15)) >> shift)


@njit(inline="always", **KERNEL)
def key_of(x: float, y: float, z: float, inv: float) -> np.int64:
    """The key of the cell holding (x, y, z)."""
    return _cell_key(cell_of(x, inv), cell_of(y, inv), cell_of(z, inv))


@njit(**BORROWED)
def list_all(cells: Cells, keys: np.ndarray, m: int) -> None:
    """Every item ``i`` < ``m`` in the list of cell ``keys[i]`` (the lists emptied first)."""
    shift = np.uint64(cells.shift)
    for s in range(cells.head.shape[0]):
        cells.head[s] = -1
    for i in range(m):
        s = slot_of(keys[i], shift)
        cells.key[i] = keys[i]
        cells.nxt[i] = cells.head[s]
        cells.head[s] = i


@njit(**BORROWED)
def relist(cells: Cells, i: int, key: np.int64) -> None:
    """Item ``i`` into the list of cell ``key``."""
    if key == cells.key[i]:
        return
    shift = np.uint64(cells.shift)
    s = slot_of(cells.key[i], shift)
    if cells.head[s] == i:
        cells.head[s] = cells.nxt[i]
    else:
        q = cells.head[s]
        while cells.nxt[q] != i:
            q = cells.nxt[q]
        cells.nxt[q] = cells.nxt[i]
    s = slot_of(key, shift)
    cells.key[i] = key
    cells.nxt[i] = cells.head[s]
    cells.head[s] = i


@njit(**BORROWED)
def listed_in(cells: Cells, out: np.ndarray, cell: float, lox: float, loy: float, loz: float, hix: float,
              hiy: float, hiz: float) -> int:
    """The items listed in the cells from the one holding (lo) to the one holding (hi), into
    ``out``; returns how many (each item once)."""
    inv = 1.0 / cell
    shift = np.uint64(cells.shift)
    k = 0
    for ix in range(cell_of(lox, inv), cell_of(hix, inv) + 1):
        for iy in range(cell_of(loy, inv), cell_of(hiy, inv) + 1):
            for iz in range(cell_of(loz, inv), cell_of(hiz, inv) + 1):
                key = _cell_key(ix, iy, iz)
                q = cells.head[slot_of(key, shift)]
                while q >= 0:
                    if cells.key[q] == key:
                        out[k] = q
                        k += 1
                    q = cells.nxt[q]
    return k


@njit(inline="always", **EXACT)
def element_box(x: np.ndarray, ids: np.ndarray, e: int, pad: float, box: np.ndarray) -> None:
    """Column ``e`` of ``box`` (6, M): the box of element ``e`` (corners the column ``e`` of ``ids``)
    in ``x``, widened by ``pad``."""
    for ax in range(3):
        lo = x[ax, ids[0, e]]
        hi = lo
        for k in range(1, ids.shape[0]):
            v = x[ax, ids[k, e]]
            lo = min(lo, v)
            hi = max(hi, v)
        box[ax, e] = lo - pad
        box[3 + ax, e] = hi + pad


@njit(inline="always", **EXACT)
def box_key(box: np.ndarray, e: int, inv: float) -> np.int64:
    """The key of the cell holding box ``e``'s lower corner."""
    return key_of(box[0, e], box[1, e], box[2, e], inv)


@njit(inline="always", **EXACT)
def extent(box: np.ndarray, e: int) -> float:
    """Box ``e``'s largest extent along an axis."""
    return max(box[3, e] - box[0, e], box[4, e] - box[1, e], box[5, e] - box[2, e])
