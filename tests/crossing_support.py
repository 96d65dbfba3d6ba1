"""A brute-force reference for the crossing counter, and the stress runs that count crossings frame by frame."""

from __future__ import annotations

from fractions import Fraction

import numpy as np

from clothsim.sim.crossings import mesh_edges


def _orient(a: np.ndarray, b: np.ndarray, c: np.ndarray, d: np.ndarray) -> np.ndarray:
    """det[a-d; b-d; c-d] for broadcast (..., 3) arrays (exact for small integer coordinates in int64)."""
    u, v, w = a - d, b - d, c - d
    return (u[..., 0] * (v[..., 1] * w[..., 2] - v[..., 2] * w[..., 1])
            - u[..., 1] * (v[..., 0] * w[..., 2] - v[..., 2] * w[..., 0])
            + u[..., 2] * (v[..., 0] * w[..., 1] - v[..., 1] * w[..., 0]))


def brute_force_pairs(points: np.ndarray, triangles: np.ndarray) -> set[tuple[int, int]]:
    """Every (edge index, triangle index) crossing, testing all E x T pairs at once."""
    tris = np.asarray(triangles).reshape(-1, 3)
    edges = mesh_edges(tris)
    p = points[edges[:, 0]][:, None, :]
    q = points[edges[:, 1]][:, None, :]
    a, b, c = (points[tris[:, k]][None, :, :] for k in range(3))
    sp, sq = np.sign(_orient(a, b, c, p)), np.sign(_orient(a, b, c, q))
    s1, s2, s3 = np.sign(_orient(p, q, a, b)), np.sign(_orient(p, q, b, c)), np.sign(_orient(p, q, c, a))
    shares = ((edges[:, None, 0:1] == tris[None, :, :]) | (edges[:, None, 1:2] == tris[None, :, :])).any(axis=2)
    hit = (sp * sq < 0) & (s1 != 0) & (s1 == s2) & (s2 == s3) & ~shares
    return {(int(e), int(t)) for e, t in zip(*np.nonzero(hit))}


def _exact_sign(a, b, c, d) -> int:  # noqa: ANN001
    """Sign of det[a-d; b-d; c-d] in rational arithmetic (each float is an exact rational)."""
    m = [[Fraction(float(x)) - Fraction(float(y)) for x, y in zip(r, d)] for r in (a, b, c)]
    det = (m[0][0] * (m[1][1] * m[2][2] - m[1][2] * m[2][1]) - m[0][1] * (m[1][0] * m[2][2] - m[1][2] * m[2][0])
           + m[0][2] * (m[1][0] * m[2][1] - m[1][1] * m[2][0]))
    return (det > 0) - (det < 0)


def exact_brute_force_pairs(points: np.ndarray, triangles: np.ndarray) -> set[tuple[int, int]]:
    """:func:`brute_force_pairs` in exact rational arithmetic, pair by pair (small meshes only)."""
    tris = np.asarray(triangles).reshape(-1, 3)
    edges = mesh_edges(tris)
    out = set()
    for e, (i, j) in enumerate(edges):
        p, q = points[i], points[j]
        for t, (ia, ib, ic) in enumerate(tris):
            if {int(i), int(j)} & {int(ia), int(ib), int(ic)}:
                continue
            a, b, c = points[ia], points[ib], points[ic]
            if _exact_sign(a, b, c, p) * _exact_sign(a, b, c, q) >= 0:
                continue
            s = (_exact_sign(p, q, a, b), _exact_sign(p, q, b, c), _exact_sign(p, q, c, a))
            if s[0] != 0 and s[0] == s[1] == s[2]:
                out.add((e, t))
    return out
