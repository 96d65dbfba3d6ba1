"""The contact pass's response and bound (:mod:`.contact`): every stored pair closer than the
contact distance pushed apart with friction, and every free point projected into its ball."""

from __future__ import annotations

import numpy as np
from numba import njit

from ...jit import BORROWED, INNER, KERNEL
from .contactgroup import CLAMPED, FRICTION, MOVING, N_EE, N_PT, PUSH, PUSH_MOVING, SWEEPS_MOVING, Contact


@njit(inline="always", **KERNEL)
def _respond(pos: np.ndarray, last: np.ndarray, c: Contact, ids: np.ndarray, coef: np.ndarray, nx: float, ny: float,
             nz: float, h: float, push: float) -> None:
    """One pair's response: ``ids`` its four points, ``coef`` their signed weights (the pair's
    separation is sum coef_k x_k along n); pushes the pair apart towards ``h`` (``push`` of the
    overlap left) with friction."""
    s_now = 0.0
    for k in range(4):
        q = ids[k]
        s_now += coef[k] * (pos[0, q] * nx + pos[1, q] * ny + pos[2, q] * nz)
    if s_now >= h:
        return
    # (the start's separation only for a pair in contact: most stored pairs are not)
    s_last = 0.0
    for k in range(4):
        q = ids[k]
        s_last += coef[k] * (last[0, q] * nx + last[1, q] * ny + last[2, q] * nz)
    # inelastic: no closer than at the substep's start (or the contact distance), then part of
    # what overlap is left
    base = max(s_now, min(s_last, h))
    delta = base + push * (h - base) - s_now
    den = 0.0
    for k in range(4):
        if c.movable[ids[k]]:
            den += coef[k] * coef[k]
    if den <= 0.0 or delta <= 0.0:
        return
    imp = delta / den
    # relative tangential motion over the substep, reduced by up to friction x the normal push
    ux = 0.0
    uy = 0.0
    uz = 0.0
    for k in range(4):
        q = ids[k]
        ux += coef[k] * (pos[0, q] - last[0, q])
        uy += coef[k] * (pos[1, q] - last[1, q])
        uz += coef[k] * (pos[2, q] - last[2, q])
    un = ux * nx + uy * ny + uz * nz
    ux -= un * nx
    uy -= un * ny
    uz -= un * nz
    ut = np.sqrt(ux * ux + uy * uy + uz * uz)
    fx = 0.0
    fy = 0.0
    fz = 0.0
    if ut > 0.0:
        j = min(ut, FRICTION * delta) / (den * ut)
        fx, fy, fz = ux * j, uy * j, uz * j
    for k in range(4):
        q = ids[k]
        if c.movable[q] and coef[k] != 0.0:
            c.acc[0, q] += coef[k] * (imp * nx - fx)
            c.acc[1, q] += coef[k] * (imp * ny - fy)
            c.acc[2, q] += coef[k] * (imp * nz - fz)
            c.cnt[q] += 1


@njit(**KERNEL)
def respond(pos: np.ndarray, last: np.ndarray, c: Contact) -> None:
    """The response: one :func:`sweep` of ``PUSH``, or ``SWEEPS_MOVING`` of ``PUSH_MOVING`` in a
    frame whose pins move (``meta[MOVING]``)."""
    _sweeps(pos, last, c, np.empty(4, dtype=np.int64), np.empty(4))


@njit(**BORROWED, **INNER)
def _sweeps(pos: np.ndarray, last: np.ndarray, c: Contact, ids: np.ndarray, coef: np.ndarray) -> None:
    # Apart from respond, which makes the scratch: compiled without reference counting, since
    # handing the group to the inlined per-pair response counted every one of its arrays up and
    # down, pair by pair (about 200 ns a pair, most of a substep between rebuilds); and in IEEE
    # order, so that its bits are the source's, not whatever the optimiser makes of the loop.
    sweeps, push = (SWEEPS_MOVING, PUSH_MOVING) if c.meta[MOVING] else (1, PUSH)
    for _ in range(sweeps):
        sweep(pos, last, c, ids, coef, push)


@njit(inline="always", **KERNEL)
def sweep(pos: np.ndarray, last: np.ndarray, c: Contact, ids: np.ndarray, coef: np.ndarray, push: float) -> None:
    """Every stored pair's response, averaged per point and applied (Jacobi); ``ids`` and
    ``coef`` are (4,) scratch."""
    h = c.thickness
    tris = c.tris
    edges = c.edges
    npt = c.meta[N_PT]
    # the point-triangle pairs, then the edge-edge pairs, through one inlined response (two
    # copies of it were a second of the first run's compile)
    for j in range(npt + c.meta[N_EE]):
        if j < npt:
            t = c.pt[1, j]
            ids[0] = c.pt[0, j]
            ids[1] = tris[0, t]
            ids[2] = tris[1, t]
            ids[3] = tris[2, t]
            coef[0] = 1.0
            coef[1] = -c.ptf[0, j]
            coef[2] = -c.ptf[1, j]
            coef[3] = -c.ptf[2, j]
            nx, ny, nz = c.ptf[3, j], c.ptf[4, j], c.ptf[5, j]
        else:
            k = j - npt
            e1 = c.ee[0, k]
            e2 = c.ee[1, k]
            u = c.eef[0, k]
            v = c.eef[1, k]
            ids[0] = edges[0, e1]
            ids[1] = edges[1, e1]
            ids[2] = edges[0, e2]
            ids[3] = edges[1, e2]
            coef[0] = 1.0 - u
            coef[1] = u
            coef[2] = v - 1.0
            coef[3] = -v
            nx, ny, nz = c.eef[2, k], c.eef[3, k], c.eef[4, k]
        _respond(pos, last, c, ids, coef, nx, ny, nz, h, push)
    for p in range(pos.shape[1]):
        m = c.cnt[p]
        if m > 0:
            inv = 1.0 / m
            pos[0, p] += c.acc[0, p] * inv
            pos[1, p] += c.acc[1, p] * inv
            pos[2, p] += c.acc[2, p] * inv
            c.acc[0, p] = 0.0
            c.acc[1, p] = 0.0
            c.acc[2, p] = 0.0
            c.cnt[p] = 0


@njit(**KERNEL)
def bound(pos: np.ndarray, c: Contact) -> None:
    """Project every free point into its ball (pinned points are never moved)."""
    ref = c.ref
    rho2 = c.rho2
    for p in range(pos.shape[1]):
        if not c.movable[p]:
            continue
        dx = pos[0, p] - ref[0, p]
        dy = pos[1, p] - ref[1, p]
        dz = pos[2, p] - ref[2, p]
        r2 = dx * dx + dy * dy + dz * dz
        if r2 > rho2[p]:
            # (a hair inside, so rounding does not leave it outside and force a rebuild)
            f = np.sqrt(rho2[p] / r2) * (1.0 - 1e-9)
            pos[0, p] = ref[0, p] + dx * f
            pos[1, p] = ref[1, p] + dy * f
            pos[2, p] = ref[2, p] + dz * f
            c.near.held[p] = True
            c.meta[CLAMPED] = 1
