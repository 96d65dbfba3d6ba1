"""Extended position-based dynamics: springs as compliant distance constraints.

Each spring of stiffness k is a constraint C = |xj - xi| - L with compliance alpha = 1/k; per
substep the accumulated multiplier lambda starts at 0 and each Gauss-Seidel pass applies
dlambda = (-C - alpha~ lambda)/(wi + wj + alpha~), alpha~ = alpha/dt^2. Because lambda carries the
compliance term, the converged result is the implicit spring force, so the effective stiffness
does not depend on the iteration count or on dt (unlike plain PBD stiffness factors).
"""

from __future__ import annotations

from typing import NamedTuple

import numpy as np
from numba import njit

from ...jit import KERNEL


class Xpbd(NamedTuple):
    """The XPBD rule's arrays: inverse masses ``w`` (0 for pinned points), the springs (ends,
    stiffness), their multipliers and the Gauss-Seidel passes per substep."""

    w: np.ndarray
    si: np.ndarray
    sj: np.ndarray
    kspr: np.ndarray
    lam: np.ndarray
    iterations: int


# Gauss-Seidel passes over all springs per substep.
XPBD_ITERATIONS = 4


@njit(**KERNEL)
def predict(pos: np.ndarray, last: np.ndarray, vel: np.ndarray, free: np.ndarray, gravity: np.ndarray,
            dt: float, f: float, phi: float) -> None:
    """Damp and kick velocities by gravity, then move free points: x~ = x + dt v; last <- x."""
    for ax in range(3):
        g = gravity[ax] * dt * phi
        for k in range(free.shape[0]):
            q = free[k]
            v = f * vel[ax, q] + g
            vel[ax, q] = v
            last[ax, q] = pos[ax, q]
            pos[ax, q] += dt * v


@njit(**KERNEL)
def kick(vel: np.ndarray, forces: np.ndarray, free: np.ndarray, w: np.ndarray, h: float) -> None:
    """v += h * F / m for the free points (``w`` = 1/m)."""
    for ax in range(3):
        for k in range(free.shape[0]):
            q = free[k]
            vel[ax, q] += h * w[q] * forces[ax, q]


@njit(**KERNEL)
def solve_constraints(pos: np.ndarray, w: np.ndarray, si: np.ndarray, sj: np.ndarray, rest: np.ndarray,
                      kspr: np.ndarray, lam: np.ndarray, dt: float, iterations: int) -> None:
    """``iterations`` Gauss-Seidel passes over the springs in storage order (in place)."""
    lam[:] = 0.0
    inv_h2 = 1.0 / (dt * dt)
    for _ in range(iterations):
        for s in range(si.shape[0]):
            a = si[s]
            b = sj[s]
            wsum = w[a] + w[b]
            k = kspr[s]
            if wsum == 0.0 or k <= 0.0:
                continue
            ex = pos[0, b] - pos[0, a]
            ey = pos[1, b] - pos[1, a]
            ez = pos[2, b] - pos[2, a]
            ln = np.sqrt(ex * ex + ey * ey + ez * ez)
            if not ln > 0.0:
                continue
            at = inv_h2 / k
            dl = (rest[s] - ln - at * lam[s]) / (wsum + at)
            lam[s] += dl
            g = dl / ln
            wa = w[a] * g
            wb = w[b] * g
            pos[0, a] -= wa * ex
            pos[1, a] -= wa * ey
            pos[2, a] -= wa * ez
            pos[0, b] += wb * ex
            pos[1, b] += wb * ey
            pos[2, b] += wb * ez
