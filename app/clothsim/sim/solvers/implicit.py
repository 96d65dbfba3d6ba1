"""Backward Euler linearised once per substep (Baraff & Witkin style), solved matrix-free.

Per substep: (M (1 + c dt) + dt^2 K) dv = dt (F(x0) - c M v0 - dt K v0), v1 = v0 + dv,
x1 = x0 + dt v1, with K = -dF/dx assembled per spring as 3x3 blocks
Ks = k (d d^T + max(0, 1 - L/l) (I - d d^T)). The compressive part of the transverse term is
dropped (clamped at 0) so the matrix stays symmetric positive definite and conjugate gradient
applies. Pinned points are removed by masking (their dv is 0). Jacobi preconditioner. M is the
one mass of a grid's points, or a mesh cloth's point masses on the diagonal (``Implicit.point_mass``;
the forces arrive scaled by m / m_p, :mod:`~clothsim.sim.passes.meshsprings`, and are unscaled here).

The rule is one compiled function, :func:`implicit_update` (its helpers inlined into it), that the
substep calls by address (``Implicit.at``): its fast-math code then exists once, as compiled, and a
run gives the same bits whether that code was just compiled or loaded from the cache. Linked into
the substep as a plain call, it existed twice (its own compile, and a copy re-optimised inside the
substep's module), and which copy ran depended on which had been loaded first: a cold start ran
the one, a warm start the other, and their sums, reassociated differently, differed in the last
bits (docs/history/determinism.md, 2026-12-07).
"""

from __future__ import annotations

from typing import NamedTuple

import numpy as np
from numba import njit, types
from numba.extending import overload

from ...jit import KERNEL
from ...jit.internals import native_address


class Implicit(NamedTuple):
    """The implicit Euler rule's arrays: the free-point mask, the springs (ends, stiffness), the
    Jacobian blocks (6, S) and the CG work space (7, 3, N), the damping rate ``c``, the factor on
    the solved velocity (spec damping), the CG stopping rule, the CG iterations of the last
    substep (``its``, one int64) and the address of :func:`implicit_update` (:func:`update_address`)."""

    mask: np.ndarray
    si: np.ndarray
    sj: np.ndarray
    kspr: np.ndarray
    jac: np.ndarray
    scratch: np.ndarray
    c: float
    keep_after: float
    tol: float
    max_iter: int
    its: np.ndarray
    #: a mesh cloth's point masses (N,); None for a grid (one mass, the substep's)
    point_mass: np.ndarray | None = None
    at: int = 0


# Relative residual at which CG stops, and its iteration cap (a stiff run hitting the cap is
# still damped, not unstable: the partial solve is a descent step of the SPD system).
CG_TOLERANCE = 1e-9
CG_MAX_ITERATIONS = 400


@njit(inline="always", **KERNEL)
def _across(x: np.ndarray, a: int, b: int) -> tuple[float, float, float]:
    """x[:, b] - x[:, a]: from point ``a`` to point ``b``."""
    return x[0, b] - x[0, a], x[1, b] - x[1, a], x[2, b] - x[2, a]


@njit(inline="always", **KERNEL)
def spring_jacobians(pos: np.ndarray, si: np.ndarray, sj: np.ndarray, rest: np.ndarray, kspr: np.ndarray,
                     jac: np.ndarray) -> None:
    """jac (6, S) = the symmetric blocks Ks as (xx, yy, zz, xy, xz, yz)."""
    for s in range(si.shape[0]):
        ex, ey, ez = _across(pos, si[s], sj[s])
        ln = np.sqrt(ex * ex + ey * ey + ez * ez)
        if not ln > 0.0:
            for q in range(6):
                jac[q, s] = 0.0
            continue
        dx = ex / ln
        dy = ey / ln
        dz = ez / ln
        t = 1.0 - rest[s] / ln
        if t < 0.0:
            t = 0.0
        k = kspr[s]
        u = k * (1.0 - t)
        w = k * t
        jac[0, s] = u * dx * dx + w
        jac[1, s] = u * dy * dy + w
        jac[2, s] = u * dz * dz + w
        jac[3, s] = u * dx * dy
        jac[4, s] = u * dx * dz
        jac[5, s] = u * dy * dz


@njit(inline="always", **KERNEL)
def apply_stiffness(jac: np.ndarray, si: np.ndarray, sj: np.ndarray, y: np.ndarray, out: np.ndarray) -> None:
    """out = K y for the assembled spring blocks (K positive semidefinite)."""
    out[:, :] = 0.0
    for s in range(si.shape[0]):
        a = si[s]
        b = sj[s]
        rx, ry, rz = _across(y, b, a)
        gx = jac[0, s] * rx + jac[3, s] * ry + jac[4, s] * rz
        gy = jac[3, s] * rx + jac[1, s] * ry + jac[5, s] * rz
        gz = jac[4, s] * rx + jac[5, s] * ry + jac[2, s] * rz
        out[0, a] += gx
        out[1, a] += gy
        out[2, a] += gz
        out[0, b] -= gx
        out[1, b] -= gy
        out[2, b] -= gz


def _own_mass(m: float, point_mass: np.ndarray | None, q: int) -> float:
    """Point q's mass: ``m`` for a grid (``point_mass`` None), else ``point_mass[q]`` (compiled code only)."""
    raise NotImplementedError("compiled code only")


@overload(_own_mass, jit_options=KERNEL, inline="always")
def _own_mass_impl(m, point_mass, q):  # noqa: ANN001, ANN202
    if isinstance(point_mass, types.NoneType):
        return lambda m, point_mass, q: m
    return lambda m, point_mass, q: point_mass[q]


def _own_factor(m_eff: float, one: float, point_mass: np.ndarray | None, q: int) -> float:
    """Point q's ``m (1 + c dt)``: ``m_eff`` for a grid, else ``point_mass[q] * one`` (compiled code only)."""
    raise NotImplementedError("compiled code only")


@overload(_own_factor, jit_options=KERNEL, inline="always")
def _own_factor_impl(m_eff, one, point_mass, q):  # noqa: ANN001, ANN202
    if isinstance(point_mass, types.NoneType):
        return lambda m_eff, one, point_mass, q: m_eff
    return lambda m_eff, one, point_mass, q: point_mass[q] * one


def _own_force(forces: np.ndarray, ax: int, q: int, m: float, point_mass: np.ndarray | None) -> float:
    """Point q's force along ``ax``: as given for a grid, else unscaled from m / m_p (compiled code only)."""
    raise NotImplementedError("compiled code only")


@overload(_own_force, jit_options=KERNEL, inline="always")
def _own_force_impl(forces, ax, q, m, point_mass):  # noqa: ANN001, ANN202
    if isinstance(point_mass, types.NoneType):
        return lambda forces, ax, q, m, point_mass: forces[ax, q]
    return lambda forces, ax, q, m, point_mass: forces[ax, q] * (point_mass[q] / m)


@njit(inline="always", **KERNEL)
def _dot(x: np.ndarray, y: np.ndarray) -> float:
    acc = 0.0
    for ax in range(3):
        for p in range(x.shape[1]):
            acc += x[ax, p] * y[ax, p]
    return acc


@njit(inline="always", **KERNEL)
def solve_velocity_change(jac: np.ndarray, si: np.ndarray, sj: np.ndarray, mask: np.ndarray, b: np.ndarray,
                          diag: np.ndarray, m_eff: float, h2: float, dv: np.ndarray, r: np.ndarray,
                          z: np.ndarray, p: np.ndarray, ap: np.ndarray, tol: float, max_iter: int, one: float,
                          point_mass: np.ndarray | None) -> int:
    """Preconditioned CG for (M_eff + h2 K) dv = b on the free points, M_eff = m_eff I for a grid
    or diag(point_mass) (1 + c dt) = ``one``; returns iterations used."""
    n = b.shape[1]
    dv[:, :] = 0.0
    bb = _dot(b, b)
    if bb == 0.0 or not np.isfinite(bb):
        return 0
    for ax in range(3):
        for q in range(n):
            r[ax, q] = b[ax, q]
            z[ax, q] = r[ax, q] / diag[ax, q]
            p[ax, q] = z[ax, q]
    rz = _dot(r, z)
    limit = tol * tol * bb
    it = 0
    while it < max_iter:
        it += 1
        apply_stiffness(jac, si, sj, p, ap)
        for ax in range(3):
            for q in range(n):
                ap[ax, q] = (_own_factor(m_eff, one, point_mass, q) * p[ax, q] + h2 * ap[ax, q]) * mask[q]
        pap = _dot(p, ap)
        if not pap > 0.0:
            break
        alpha = rz / pap
        for ax in range(3):
            for q in range(n):
                dv[ax, q] += alpha * p[ax, q]
                r[ax, q] -= alpha * ap[ax, q]
        if _dot(r, r) <= limit:
            break
        for ax in range(3):
            for q in range(n):
                z[ax, q] = r[ax, q] / diag[ax, q]
        rz_new = _dot(r, z)
        beta = rz_new / rz
        rz = rz_new
        for ax in range(3):
            for q in range(n):
                p[ax, q] = z[ax, q] + beta * p[ax, q]
    return it


@njit(**KERNEL)
def implicit_update(pos: np.ndarray, last: np.ndarray, vel: np.ndarray, forces: np.ndarray, free: np.ndarray,
                    mask: np.ndarray, si: np.ndarray, sj: np.ndarray, rest: np.ndarray, kspr: np.ndarray,
                    jac: np.ndarray, scratch: np.ndarray, mass: float, dt: float, c: float, keep_after: float,
                    tol: float, max_iter: int, its: np.ndarray, point_mass: np.ndarray | None) -> None:
    """One linearised backward-Euler update of velocities and positions (free points only), with
    one mass ``mass`` (a grid; ``point_mass`` None) or each point's own.

    ``scratch`` is (7, 3, N): b, diag, dv, r, z, p, Ap. The CG iterations used go to ``its[0]``.
    Called by address only (see the module's notes).
    """
    b = scratch[0]
    diag = scratch[1]
    dv = scratch[2]
    n = pos.shape[1]
    spring_jacobians(pos, si, sj, rest, kspr, jac)
    one = 1.0 + c * dt
    m_eff = mass * (1.0 + c * dt)
    h2 = dt * dt
    apply_stiffness(jac, si, sj, vel, scratch[6])
    for ax in range(3):
        for q in range(n):
            b[ax, q] = dt * (_own_force(forces, ax, q, mass, point_mass) - c * _own_mass(mass, point_mass, q)
                             * vel[ax, q] - dt * scratch[6][ax, q]) * mask[q]
            diag[ax, q] = _own_factor(m_eff, one, point_mass, q)
    for s in range(si.shape[0]):
        for ax in range(3):
            diag[ax, si[s]] += h2 * jac[ax, s]
            diag[ax, sj[s]] += h2 * jac[ax, s]
    its[0] = solve_velocity_change(jac, si, sj, mask, b, diag, m_eff, h2, dv, scratch[3], scratch[4], scratch[5],
                                   scratch[6], tol, max_iter, one, point_mass)
    for ax in range(3):
        for k in range(free.shape[0]):
            q = free[k]
            v = (vel[ax, q] + dv[ax, q]) * keep_after
            vel[ax, q] = v
            last[ax, q] = pos[ax, q]
            pos[ax, q] += dt * v


def update_address(args: tuple) -> int:
    """``Implicit.at``: the address of :func:`implicit_update` compiled (or loaded) for the types
    of ``args``, its arguments as the substep passes them, by one process at a time (see
    :func:`clothsim.jit.compile.compiling_alone`)."""
    from numba import typeof

    from ...jit.compile import compiling_alone

    argtypes = tuple(typeof(a) for a in args)
    with compiling_alone(implicit_update, argtypes):
        return native_address(implicit_update, argtypes)
