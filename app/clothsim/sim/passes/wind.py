"""Aerodynamic forces of the wind on the cloth's triangles (the pass runs only in a scene with wind).

Model, per triangle of the render mesh (area A, unit normal n, air velocity u at its centroid,
cloth velocity v = the mean of its three points' Verlet velocities (x - x_last) / dt, and
v_rel = u - v):

* drag along the normal, F_D = 1/2 rho C_d A (v_rel . n) |v_rel . n| n: the normal-pressure
  ("cross-flow") form of a flat plate's drag (Hoerner, *Fluid-Dynamic Drag*, 1965), applied per
  triangle as cloth simulators do (e.g. Keckeisen, Kimmerle, Thomaszewski and Wacker, "Modelling
  effects of wind fields in cloth animations", Journal of WSCG 12, 2004: drag and lift per
  triangle);
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

Work is split the frame kernel's way (:data:`~clothsim.jit.CHUNKS` ranges): per triangle a
force into ``tforce``, then per point the sum over its triangles in a fixed order, so the result
does not depend on the number of threads.

This module is a force of :mod:`.forces` (its ``Group``, ``pack``, ``work`` and ``gather``), the
registry's worked example.
"""

from __future__ import annotations

from typing import Any, NamedTuple

import numpy as np
from numba import njit

from ...cloth import cloth_triangles
from ...jit import CHUNKS, KERNEL
from ...wind import wind_rows
from ..clock import substep_time
from ..team import share


class Wind(NamedTuple):
    """The winds: their rows and gust modes (:func:`clothsim.wind.wind_rows`), the mesh's
    triangles (3, T), each point's triangles (``start`` (N + 1,), ``incident``), the per-triangle
    force buffer (3, T) and work space (12, T), 1/dt, dt and the simulation's clock
    (:mod:`clothsim.sim.clock`)."""

    rows: np.ndarray
    modes: np.ndarray
    tris: np.ndarray
    start: np.ndarray
    incident: np.ndarray
    tforce: np.ndarray
    scratch: np.ndarray
    inv_dt: float
    dt: float
    clock: np.ndarray


#: The force's group, name, and why a scene has no such pass (see :mod:`.forces`).
Group = Wind
NAME = "wind"
ABSENT = "scene has no wind (or only still air)"


@njit(inline="always", **KERNEL)
def wave(phase: float) -> float:
    """A periodic wave of period 1 (cycles) in [-1, 1], C1: 4x(1 - |x|) with x = 2 frac(phase) - 1."""
    x = 2.0 * (phase - np.floor(phase)) - 1.0
    return 4.0 * x * (1.0 - abs(x))


@njit(inline="always", **KERNEL)
def air_velocity(rows: np.ndarray, modes: np.ndarray, w: int, x: float, y: float, z: float, t: float) -> tuple:
    """Wind ``w``'s air velocity at (x, y, z) and time t: its mean plus its gusts (one point; the
    pass evaluates the same sums for a range of triangles at once in :func:`wind_chunk`)."""
    ux = rows[w, 0]
    uy = rows[w, 1]
    uz = rows[w, 2]
    turb = rows[w, 5]
    if turb > 0.0:
        for m in range(modes.shape[1]):
            s = turb * wave(modes[w, m, 0] * x + modes[w, m, 1] * y + modes[w, m, 2] * z
                            + (modes[w, m, 7] - modes[w, m, 6] * t))
            ux += modes[w, m, 3] * s
            uy += modes[w, m, 4] * s
            uz += modes[w, m, 5] * s
    return ux, uy, uz


@njit(inline="always", **KERNEL)
def _at(pos: np.ndarray, p: int) -> tuple[float, float, float]:
    """Point ``p``'s coordinates."""
    return pos[0, p], pos[1, p], pos[2, p]


@njit(inline="always", **KERNEL)
def _rows(a: np.ndarray, r: int, lo: int, hi: int) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Rows ``r``, ``r + 1`` and ``r + 2`` of ``a`` over columns ``lo`` to ``hi``: an x, y, z triple."""
    return a[r, lo:hi], a[r + 1, lo:hi], a[r + 2, lo:hi]


@njit(inline="always", **KERNEL)
def wind_chunk(pos: np.ndarray, last: np.ndarray, wind: tuple, t: float, c: int) -> None:
    """Work item ``c``: a third of the wind force of each triangle of the c-th range into
    ``wind.tforce``. ``wind`` is a :class:`Wind`.

    First the triangles' centroids, mean velocities and cross products are gathered into
    ``wind.scratch`` rows; every later loop runs over those contiguous rows (vectorised). On the
    flag's 1,610 triangles (one thread, best of 5 x 300 calls of the whole pass, a busy 2-core
    machine) a per-triangle loop took 57 us for the drag and 78 more for the gusts; this takes
    28-41 us for the drag and 8-13 more for the gusts (the gather dominates).
    """
    tris = wind.tris
    sc = wind.scratch
    rows = wind.rows
    modes = wind.modes
    inv = wind.inv_dt * (1.0 / 3.0)
    third = 1.0 / 3.0
    lo, hi = share(tris.shape[1], c, CHUNKS)
    for k in range(lo, hi):
        a = tris[0, k]
        b = tris[1, k]
        d = tris[2, k]
        ax, ay, az = _at(pos, a)
        bx, by, bz = _at(pos, b)
        cx, cy, cz = _at(pos, d)
        sc[0, k] = (ax + bx + cx) * third
        sc[1, k] = (ay + by + cy) * third
        sc[2, k] = (az + bz + cz) * third
        sc[3, k] = (ax - last[0, a] + bx - last[0, b] + cx - last[0, d]) * inv
        sc[4, k] = (ay - last[1, a] + by - last[1, b] + cy - last[1, d]) * inv
        sc[5, k] = (az - last[2, a] + bz - last[2, b] + cz - last[2, d]) * inv
        ex, ey, ez = bx - ax, by - ay, bz - az
        fx, fy, fz = cx - ax, cy - ay, cz - az
        sc[6, k] = ey * fz - ez * fy
        sc[7, k] = ez * fx - ex * fz
        sc[8, k] = ex * fy - ey * fx
    n = hi - lo
    # the gathered rows of this range: centroids, velocities, cross products, air; the forces
    px, py, pz = _rows(sc, 0, lo, hi)
    vx, vy, vz = _rows(sc, 3, lo, hi)
    nx, ny, nz = _rows(sc, 6, lo, hi)
    ux, uy, uz = _rows(sc, 9, lo, hi)
    ox, oy, oz = _rows(wind.tforce, 0, lo, hi)
    for j in range(n):
        ox[j] = 0.0
        oy[j] = 0.0
        oz[j] = 0.0
    for w in range(rows.shape[0]):
        # the air's velocity relative to each triangle
        for j in range(n):
            ux[j] = rows[w, 0] - vx[j]
            uy[j] = rows[w, 1] - vy[j]
            uz[j] = rows[w, 2] - vz[j]
        turb = rows[w, 5]
        if turb > 0.0:
            for m in range(modes.shape[1]):
                kx = modes[w, m, 0]
                ky = modes[w, m, 1]
                kz = modes[w, m, 2]
                gx = turb * modes[w, m, 3]
                gy = turb * modes[w, m, 4]
                gz = turb * modes[w, m, 5]
                ph = modes[w, m, 7] - modes[w, m, 6] * t
                for j in range(n):
                    s = wave(kx * px[j] + ky * py[j] + kz * pz[j] + ph)
                    ux[j] += gx * s
                    uy[j] += gy * s
                    uz[j] += gz * s
        drag = 0.5 * rows[w, 3] * third
        for j in range(n):
            nn = nx[j] * nx[j] + ny[j] * ny[j] + nz[j] * nz[j]
            d = ux[j] * nx[j] + uy[j] * ny[j] + uz[j] * nz[j]
            s = drag * d * abs(d) / nn if nn > 0.0 else 0.0
            ox[j] += s * nx[j]
            oy[j] += s * ny[j]
            oz[j] += s * nz[j]
        lift = 0.5 * rows[w, 4] * third
        if lift != 0.0:
            for j in range(n):
                nn = nx[j] * nx[j] + ny[j] * ny[j] + nz[j] * nz[j]
                r = np.sqrt(ux[j] * ux[j] + uy[j] * uy[j] + uz[j] * uz[j])
                d = ux[j] * nx[j] + uy[j] * ny[j] + uz[j] * nz[j]
                q = lift * d / np.sqrt(nn) if nn > 0.0 else 0.0
                e = d / r if r > 0.0 else 0.0
                ox[j] += q * (r * nx[j] - e * ux[j])
                oy[j] += q * (r * ny[j] - e * uy[j])
                oz[j] += q * (r * nz[j] - e * uz[j])


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
def wind_chunks(pos: np.ndarray, last: np.ndarray, wind: tuple, t: float, c0: int, c1: int) -> None:
    """Work items c0..c1-1 of :func:`wind_chunk`: the frame kernel's call. Compiled on its own, not
    inlined there: inlined into the frame kernel the pass ran 2.5x slower than alone (forces +
    integrate of the flag, one thread, ``--profile``: 147 us a substep against 57 in still air;
    called, 85 against 42)."""
    for c in range(c0, c1):
        wind_chunk(pos, last, wind, t, c)


@njit(**KERNEL)
def work(wind: tuple, pos: np.ndarray, last: np.ndarray, substep: int, c0: int, c1: int) -> None:
    """Work items c0..c1-1 at substep ``substep`` of the call (the force's ``work``)."""
    wind_chunks(pos, last, wind, substep_time(wind.clock, substep, wind.dt), c0, c1)


#: The force's ``gather`` (see :mod:`.forces`).
gather = wind_gather


def pack(sim: Any) -> Wind | None:
    """The group for ``sim`` (a :class:`~clothsim.sim.Simulation`), None with no wind or only still
    air (no pass: the same bits as none). The mesh's arrays are made once per simulation."""
    rows, modes = wind_rows(sim.scene.winds)
    if rows.shape[0] == 0:
        return None
    mesh = sim.pass_arrays.get("wind")
    if mesh is None:
        tris = np.ascontiguousarray(sim.surface.triangles.T.astype(np.uint64))
        mesh = sim.pass_arrays["wind"] = (tris, *incidence(tris, sim.num_points), np.zeros((3, tris.shape[1])),
                                          np.zeros((12, tris.shape[1])))
    dt = sim.dt
    return Wind(rows, modes, *mesh, 1.0 / dt, dt, sim.clock)


def triangles(nw: int, nh: int) -> np.ndarray:
    """(3, T) corners of the mesh's triangles (:func:`clothsim.cloth.cloth_triangles`, the
    renderer's), unsigned: an index that cannot be negative needs no wrap-around check on each load."""
    return np.ascontiguousarray(cloth_triangles(nw, nh).reshape(-1, 3).T.astype(np.uint64))


def incidence(tris: np.ndarray, n: int) -> tuple[np.ndarray, np.ndarray]:
    """Each point's triangles, in increasing triangle order: (start (n + 1,), triangle (3T,))."""
    corners = tris.T.ravel().astype(np.int64)  # triangle k's corners at 3k..3k+2
    order = np.argsort(corners, kind="stable")
    start = np.zeros(n + 1, dtype=np.int64)
    np.cumsum(np.bincount(corners, minlength=n), out=start[1:])
    return start, (order // 3).astype(np.uint64)
