"""Symplectic Euler's advance rule: kick-drift with an explicit velocity (with no half-step start
term it is globally first order)."""

from __future__ import annotations

from typing import NamedTuple

import numpy as np
from numba import njit

from ...jit import KERNEL


class Symplectic(NamedTuple):
    """The symplectic Euler rule: 1 / mass."""

    inv_mass: float


@njit(**KERNEL)
def symplectic_step(pos: np.ndarray, last: np.ndarray, vel: np.ndarray, forces: np.ndarray, free: np.ndarray,
                    inv_mass: float, dt: float, f: float, phi: float) -> None:
    """Kick v <- f*v + phi*dt*F/m, then drift x <- x + dt*v; last <- x (free points)."""
    h = dt * inv_mass * phi
    for ax in range(3):
        for k in range(free.shape[0]):
            p = free[k]
            v = f * vel[ax, p] + forces[ax, p] * h
            vel[ax, p] = v
            last[ax, p] = pos[ax, p]
            pos[ax, p] += dt * v
