"""A brute-force count of a cloth's self-crossings for the tests: edges of the render mesh that
pierce a triangle they share no vertex with (every edge against every triangle, a box test first,
then the exact signed-volume test), in NumPy. Small grids only (O(E x T))."""

from __future__ import annotations

import numpy as np

from clothsim.cloth import cloth_triangles


def mesh(nw: int, nh: int) -> tuple[np.ndarray, np.ndarray]:
    """(triangles (T, 3), unique edges (E, 2)) of an nw x nh grid's render mesh."""
    tris = cloth_triangles(nw, nh).reshape(-1, 3).astype(np.int64)
    e = np.concatenate([tris[:, [0, 1]], tris[:, [1, 2]], tris[:, [2, 0]]])
    return tris, np.unique(np.sort(e, axis=1), axis=0)


def _vol(a: np.ndarray, b: np.ndarray, c: np.ndarray, d: np.ndarray) -> np.ndarray:
    return np.einsum("...i,...i->...", np.cross(b - a, c - a), d - a)


def crossings(x: np.ndarray, tris: np.ndarray, edges: np.ndarray, chunk: int = 256) -> int:
    """Edge-triangle pairs (no shared vertex) where the edge pierces the triangle; ``x`` (N, 3)."""
    x = np.asarray(x, dtype=np.float64)
    p, q = x[edges[:, 0]], x[edges[:, 1]]
    elo, ehi = np.minimum(p, q), np.maximum(p, q)
    total = 0
    for t0 in range(0, len(tris), chunk):
        t = tris[t0 : t0 + chunk]
        a, b, c = x[t[:, 0]], x[t[:, 1]], x[t[:, 2]]
        tlo = np.minimum(np.minimum(a, b), c)
        thi = np.maximum(np.maximum(a, b), c)
        near = np.all((elo[None] <= thi[:, None]) & (ehi[None] >= tlo[:, None]), axis=2)
        shared = np.zeros_like(near)
        for k in range(3):
            shared |= (edges[None, :, 0] == t[:, None, k]) | (edges[None, :, 1] == t[:, None, k])
        ti, ei = np.nonzero(near & ~shared)
        if ti.size == 0:
            continue
        A, B, C = a[ti], b[ti], c[ti]
        P, Q = p[ei], q[ei]
        sp = np.sign(_vol(A, B, C, P))
        sq = np.sign(_vol(A, B, C, Q))
        s1 = np.sign(_vol(P, Q, A, B))
        s2 = np.sign(_vol(P, Q, B, C))
        s3 = np.sign(_vol(P, Q, C, A))
        hit = (sp * sq < 0) & (s1 == s2) & (s2 == s3) & (s1 != 0)
        total += int(hit.sum())
    return total
