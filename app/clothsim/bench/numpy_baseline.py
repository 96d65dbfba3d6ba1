"""A plain vectorised-NumPy implementation of the spec's substep, kept as the speed baseline.

It does the same work as the Numba path without self-collision: forces with ``np.bincount``,
damped Verlet, sphere and plane collisions, and Provot. NumPy cannot express the in-place
Gauss-Seidel Provot pass, so it corrects all springs from the same positions (Jacobi); its
numbers therefore differ slightly from the Numba path, its cost is what is compared.
"""

from __future__ import annotations

import numpy as np

from ..cloth import BENDING, BENDING_STIFFNESS_FACTOR
from ..sim.passes.colliders.plane import Planes, SURFACE_OFFSET
from ..sim.passes.colliders.sphere import Spheres


def scatter_add(index: np.ndarray, values: np.ndarray, n: int) -> np.ndarray:
    """Sum (S, 3) ``values`` into n rows by ``index`` (bincount is NumPy's fast scatter-add)."""
    return np.stack([np.bincount(index, weights=values[:, c], minlength=n) for c in range(3)], axis=1)


class NumpyCloth:
    """The state of one :class:`~clothsim.sim.Simulation`, stepped with NumPy array operations."""

    def __init__(self, sim) -> None:  # noqa: ANN001
        self.pos = sim.positions.copy()
        self.last = sim.last_positions.copy()
        self.free = ~sim.pinned
        sp = sim.springs
        self.i, self.j, self.rest = sp.i, sp.j, sp.rest
        self.k = np.where(sp.kind == BENDING, sim.ks * BENDING_STIFFNESS_FACTOR, sim.ks)[:, None]
        self.pinned = sim.pinned
        self.mass = sim.mass
        self.gravity = np.asarray(sim.gravity)
        self.dt = sim.dt
        self.keep = 1.0 - sim.damping / 100.0
        groups = {type(g): g.rows for g in sim.plan.colliders}
        self.spheres = groups.get(Spheres, np.zeros((0, 5)))
        self.planes = groups.get(Planes, np.zeros((0, 7)))
        self.limit = sim._stretch_limit
        self.steps = sim.simulation_steps

    def substep(self) -> None:
        """One substep: forces, Verlet, colliders, Provot (Jacobi)."""
        pos, last, i, j = self.pos, self.last, self.i, self.j
        forces = np.broadcast_to(self.mass * self.gravity, pos.shape).copy()
        d = pos[j] - pos[i]
        length = np.linalg.norm(d, axis=1, keepdims=True)
        f = self.k * (length - self.rest[:, None]) / np.where(length > 0, length, 1.0) * d
        forces += scatter_add(i, f, len(pos)) - scatter_add(j, f, len(pos))
        new = pos + self.keep * (pos - last) + forces / self.mass * self.dt**2
        free = self.free
        last[free] = pos[free]
        pos[free] = new[free]
        for ox, oy, oz, r, fr in self.spheres:
            rel = pos - (ox, oy, oz)
            dist = np.linalg.norm(rel, axis=1, keepdims=True)
            hit = (dist[:, 0] <= r) & free & (dist[:, 0] > 0)
            tangent = np.array([ox, oy, oz]) + rel / np.where(dist > 0, dist, 1.0) * r
            pos[hit] = last[hit] + (tangent[hit] - last[hit]) * (1.0 - fr)
        for px, py, pz, nx, ny, nz, fr in self.planes:
            n = np.array([nx, ny, nz])
            now = (pos - (px, py, pz)) @ n
            before = (last - (px, py, pz)) @ n
            hit = ((before >= 0) != (now >= 0)) & free
            side = np.where(before >= 0, SURFACE_OFFSET, -SURFACE_OFFSET)
            target = pos + np.outer(side - now, n)
            pos[hit] = last[hit] + (target[hit] - last[hit]) * (1.0 - fr)
        if self.limit > 0:
            d = pos[j] - pos[i]
            length = np.linalg.norm(d, axis=1)
            over = length > self.limit * self.rest
            pa, pb = self.pinned[i], self.pinned[j]
            act = over & ~(pa & pb)
            excess = np.where(act, (length - self.limit * self.rest) / np.where(length > 0, length, 1.0), 0.0)
            wa = np.where(pa, 0.0, np.where(pb, 1.0, 0.5))
            wb = np.where(pb, 0.0, np.where(pa, 1.0, 0.5))
            corr = d * excess[:, None]
            pos += scatter_add(i, corr * wa[:, None], len(pos)) - scatter_add(j, corr * wb[:, None], len(pos))

    def frame(self) -> None:
        """One frame of ``simulation_steps`` substeps."""
        for _ in range(self.steps):
            self.substep()
