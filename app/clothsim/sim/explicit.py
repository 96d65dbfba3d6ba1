"""Explicit integrators other than the spec path: Verlet with rate damping, symplectic Euler.

Rate damping solves x'' = F/m - c x' with f = exp(-c dt) per substep. For Verlet the velocity
term is scaled by f and the force term by phi = (1 - f)/(c dt), which keeps the scheme second
order (at c = 0, phi = 1 and f = 1: plain Verlet). Symplectic Euler (kick, then drift) keeps an
explicit velocity; with no half-step start term it is globally first order.
"""

from __future__ import annotations

import numpy as np
from numba import njit

from .aero import add_wind
from .forces import accumulate_forces
from .jit import KERNEL, EXACT
from .passes import corrections
from .pinmotion import move_pins, substep_time


@njit(**KERNEL)
def verlet_start(pos: np.ndarray, last: np.ndarray, vel: np.ndarray, forces: np.ndarray, free: np.ndarray,
                 inv_mass: float, dt: float, c: float) -> None:
    """Second-order start: last = x0 - v0*dt + a0*dt^2/2 with a0 = F/m - c*v0 (free points)."""
    for ax in range(3):
        for k in range(free.shape[0]):
            p = free[k]
            a0 = forces[ax, p] * inv_mass - c * vel[ax, p]
            last[ax, p] = pos[ax, p] - vel[ax, p] * dt + 0.5 * a0 * dt * dt


@njit(**KERNEL)
def verlet_rate_step(pos: np.ndarray, last: np.ndarray, forces: np.ndarray, free: np.ndarray, inv_mass: float,
                     dt: float, f: float, phi: float) -> None:
    """x' = x + f*(x - x_last) + phi*a*dt^2 for free points; last <- x."""
    h2 = dt * dt * inv_mass * phi
    for ax in range(3):
        x = pos[ax]
        xl = last[ax]
        fa = forces[ax]
        for k in range(free.shape[0]):
            p = free[k]
            cur = x[p]
            x[p] = cur + f * (cur - xl[p]) + fa[p] * h2
            xl[p] = cur


@njit(**EXACT)
def run_verlet_rate(steps: int, pos: np.ndarray, last: np.ndarray, forces: np.ndarray, free: np.ndarray,
                    blocks: np.ndarray, stream: tuple, rest: np.ndarray, nw: int,
                    mass: float, gravity: np.ndarray, dt: float, f: float, phi: float, post: tuple,
                    wind: tuple | None, pins: tuple | None) -> int:
    """``steps`` substeps of rate-damped Verlet plus the shared corrections; returns colliders skipped.
    ``wind`` and ``pins`` are the :mod:`clothsim.sim.state` groups, None when the scene has none."""
    skipped = 0
    offset = np.empty(3)
    for substep in range(steps):
        accumulate_forces(pos, forces, stream, mass, gravity)
        if wind is not None:
            add_wind(pos, last, forces, wind, substep_time(wind.clock, substep, wind.dt))
        verlet_rate_step(pos, last, forces, free, 1.0 / mass, dt, f, phi)
        if pins is not None:
            move_pins(pos, last, pins, substep_time(pins.clock, substep + 1, pins.dt), offset)
        skipped += corrections(pos, last, free, blocks, rest, nw, post, substep)
    return skipped


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


@njit(**KERNEL)
def velocities_from_positions(pos: np.ndarray, last: np.ndarray, vel: np.ndarray, free: np.ndarray,
                              dt: float) -> None:
    """v = (x - x_last)/dt, so that collision and Provot corrections also change the velocity."""
    inv = 1.0 / dt
    for ax in range(3):
        for k in range(free.shape[0]):
            p = free[k]
            vel[ax, p] = (pos[ax, p] - last[ax, p]) * inv


@njit(**EXACT)
def run_symplectic(steps: int, pos: np.ndarray, last: np.ndarray, vel: np.ndarray, forces: np.ndarray,
                   free: np.ndarray, blocks: np.ndarray, stream: tuple, rest: np.ndarray, nw: int,
                    mass: float, gravity: np.ndarray, dt: float, f: float, phi: float,
                   post: tuple, fix_velocity: bool, wind: tuple | None, pins: tuple | None) -> int:
    """``steps`` substeps of symplectic Euler plus the shared corrections; returns colliders skipped."""
    skipped = 0
    offset = np.empty(3)
    for substep in range(steps):
        accumulate_forces(pos, forces, stream, mass, gravity)
        if wind is not None:
            add_wind(pos, last, forces, wind, substep_time(wind.clock, substep, wind.dt))
        symplectic_step(pos, last, vel, forces, free, 1.0 / mass, dt, f, phi)
        if pins is not None:
            move_pins(pos, last, pins, substep_time(pins.clock, substep + 1, pins.dt), offset)
        skipped += corrections(pos, last, free, blocks, rest, nw, post, substep)
        if fix_velocity:
            velocities_from_positions(pos, last, vel, free, dt)
    return skipped
