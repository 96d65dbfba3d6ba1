"""Aerodynamic forces of the wind on the cloth's triangles (the pass runs only in a scene with wind).

Model, per triangle of the render mesh (area A, unit normal n, air velocity u at its centroid,
cloth velocity v = the mean of its three points' Verlet velocities (x - x_last) / dt, and
v_rel = u - v):

* drag along the normal, F_D = 1/2 rho C_d A (v_rel . n) |v_rel . n| n: the normal-pressure
  ("cross-flow") form of a flat plate's drag (Hoerner, *Fluid-Dynamic Drag*, 1965, ch. 3), as
  used per triangle for cloth by Provot-style mass-spring aerodynamics and by Keckeisen,
  Kimmerle, Thomaszewski and Wacker, "Modelling effects of wind fields in cloth animations",
  Journal of WSCG 12 (2004);
* lift across the flow, F_L = 1/2 rho C_L A |v_rel|^2 sin(2 alpha) l, alpha the angle of attack
  (between v_rel and the triangle's plane) and l the unit vector perpendicular to v_rel in the
  plane of v_rel and n, on the side the air pushes: the flat plate's lift curve C_L sin 2 alpha
  (zero edge-on and face-on, largest at 45 degrees; Hoerner and Borst, *Fluid-Dynamic Lift*, 1985,
  flat plates), written without angles as F_L = rho C_L A (v_rel . n)(|v_rel| n - (v_rel . n) v_rel / |v_rel|).

Both are unchanged when n is flipped, so the triangles' winding does not matter. Each
triangle's force goes a third to each of its points. With the cross product c = (b - a) x (c - a)
(|c| = 2A) no square root is needed for the drag: F_D = 1/4 rho C_d (v_rel . c)|v_rel . c| c / |c|^2.

The cloth velocity is the one the Verlet state holds (the last substep's), so the drag is
explicit: like the damping it must satisfy dt * rho C_d |v_rel| / density << 1 (true by orders
of magnitude for cloth: 1e-4 at 10 m/s, density 1 kg/m^2 and the spec's dt).

Gusts (:mod:`clothsim.wind`) use :func:`wave`, a C1 periodic wave made of two parabolas, instead
of a sine: four modes at every triangle and every substep are 19,000 evaluations a substep on a
50 x 50 cloth, and the parabolas are plain arithmetic (a floor and three products) where ``sin``
is a library call. Its range is exactly [-1, 1], so the field stays bounded.

Work is split the frame kernel's way (:data:`~clothsim.sim.jit.CHUNKS` ranges): per triangle a
force into ``tforce``, then per point the sum over its triangles in a fixed order, so the result
does not depend on the number of threads.
"""

from __future__ import annotations

import numpy as np
from numba import njit

from .jit import CHUNKS, KERNEL
from .team import share


@njit(inline="always", **KERNEL)
def wave(phase: float) -> float:
    """A periodic wave of period 1 (cycles) in [-1, 1], C1: 4x(1 - |x|) with x = 2 frac(phase) - 1."""
    x = 2.0 * (phase - np.floor(phase)) - 1.0
    return 4.0 * x * (1.0 - abs(x))


@njit(inline="always", **KERNEL)
def air_velocity(rows: np.ndarray, modes: np.ndarray, w: int, x: float, y: float, z: float, t: float) -> tuple:
    """Wind ``w``'s air velocity at (x, y, z) and time t: its mean plus its gusts."""
    ux = rows[w, 0]
    uy = rows[w, 1]
    uz = rows[w, 2]
    turb = rows[w, 5]
    if turb > 0.0:
        gx = 0.0
        gy = 0.0
        gz = 0.0
        for m in range(modes.shape[1]):
            s = wave(modes[w, m, 0] * x + modes[w, m, 1] * y + modes[w, m, 2] * z - modes[w, m, 6] * t
                     + modes[w, m, 7])
            gx += modes[w, m, 3] * s
            gy += modes[w, m, 4] * s
            gz += modes[w, m, 5] * s
        ux += turb * gx
        uy += turb * gy
        uz += turb * gz
    return ux, uy, uz


@njit(inline="always", **KERNEL)
def triangle_force(rows: np.ndarray, modes: np.ndarray, ax: float, ay: float, az: float, bx: float, by: float,
                   bz: float, cx: float, cy: float, cz: float, vx: float, vy: float, vz: float, t: float) -> tuple:
    """The wind force on the triangle (a, b, c) whose mean velocity is v, at time t (all winds)."""
    ex = bx - ax
    ey = by - ay
    ez = bz - az
    fx = cx - ax
    fy = cy - ay
    fz = cz - az
    nx = ey * fz - ez * fy
    ny = ez * fx - ex * fz
    nz = ex * fy - ey * fx
    nn = nx * nx + ny * ny + nz * nz
    ox = 0.0
    oy = 0.0
    oz = 0.0
    if not nn > 0.0:
        return ox, oy, oz
    third = 1.0 / 3.0
    px = (ax + bx + cx) * third
    py = (ay + by + cy) * third
    pz = (az + bz + cz) * third
    for w in range(rows.shape[0]):
        ux, uy, uz = air_velocity(rows, modes, w, px, py, pz, t)
        rx = ux - vx
        ry = uy - vy
        rz = uz - vz
        d = rx * nx + ry * ny + rz * nz
        s = 0.5 * rows[w, 3] * d * abs(d) / nn
        ox += s * nx
        oy += s * ny
        oz += s * nz
        lift = rows[w, 4]
        if lift != 0.0:
            r = np.sqrt(rx * rx + ry * ry + rz * rz)
            if r > 0.0:
                q = 0.5 * lift * d / np.sqrt(nn)
                e = d / r
                ox += q * (r * nx - e * rx)
                oy += q * (r * ny - e * ry)
                oz += q * (r * nz - e * rz)
    return ox, oy, oz


@njit(inline="always", **KERNEL)
def wind_chunk(pos: np.ndarray, last: np.ndarray, wind: tuple, t: float, c: int) -> None:
    """Work item ``c``: a third of the wind force of each triangle of the c-th range into
    ``wind.tforce``. ``wind`` is a :class:`~clothsim.sim.state.Wind`."""
    tris = wind.tris
    out = wind.tforce
    inv = wind.inv_dt
    third = 1.0 / 3.0
    lo, hi = share(tris.shape[1], c, CHUNKS)
    for k in range(lo, hi):
        a = tris[0, k]
        b = tris[1, k]
        d = tris[2, k]
        vx = (pos[0, a] - last[0, a] + pos[0, b] - last[0, b] + pos[0, d] - last[0, d]) * (inv * third)
        vy = (pos[1, a] - last[1, a] + pos[1, b] - last[1, b] + pos[1, d] - last[1, d]) * (inv * third)
        vz = (pos[2, a] - last[2, a] + pos[2, b] - last[2, b] + pos[2, d] - last[2, d]) * (inv * third)
        fx, fy, fz = triangle_force(wind.rows, wind.modes, pos[0, a], pos[1, a], pos[2, a], pos[0, b], pos[1, b],
                                    pos[2, b], pos[0, d], pos[1, d], pos[2, d], vx, vy, vz, t)
        out[0, k] = fx * third
        out[1, k] = fy * third
        out[2, k] = fz * third


@njit(inline="always", **KERNEL)
def wind_gather(wind: tuple, forces: np.ndarray, c: int) -> None:
    """Work item ``c``: add to the forces of the c-th point range their triangles' shares."""
    start = wind.start
    inc = wind.incident
    out = wind.tforce
    lo, hi = share(forces.shape[1], c, CHUNKS)
    for p in range(lo, hi):
        for j in range(start[p], start[p + 1]):
            k = inc[j]
            forces[0, p] += out[0, k]
            forces[1, p] += out[1, k]
            forces[2, p] += out[2, k]


@njit(**KERNEL)
def add_wind(pos: np.ndarray, last: np.ndarray, forces: np.ndarray, wind: tuple, t: float) -> None:
    """forces += the wind's force on every point at time ``t`` (the other integrators' pass)."""
    for c in range(CHUNKS):
        wind_chunk(pos, last, wind, t, c)
    for c in range(CHUNKS):
        wind_gather(wind, forces, c)


def triangles(nw: int, nh: int) -> np.ndarray:
    """(3, T) int64 corners of the render mesh's triangles (:func:`clothsim.render.mesh.cloth_triangles`'
    order), without importing the renderer."""
    idx = np.arange(nw * nh, dtype=np.int64).reshape(nh, nw)
    a = idx[:-1, :-1].ravel()
    b = idx[:-1, 1:].ravel()
    c = idx[1:, :-1].ravel()
    d = idx[1:, 1:].ravel()
    return np.ascontiguousarray(np.stack([a, c, b, b, c, d], axis=1).reshape(-1, 3).T)


def incidence(tris: np.ndarray, n: int) -> tuple[np.ndarray, np.ndarray]:
    """Each point's triangles, in increasing triangle order: (start (n + 1,), triangle (3T,))."""
    corners = tris.T.ravel()  # triangle k's corners at 3k..3k+2
    order = np.argsort(corners, kind="stable")
    start = np.zeros(n + 1, dtype=np.int64)
    np.cumsum(np.bincount(corners, minlength=n), out=start[1:])
    return start, (order // 3).astype(np.int64)
