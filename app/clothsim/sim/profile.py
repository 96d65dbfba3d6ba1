"""A visible account of the work a scene does: which passes ran, their share of the time, and
which were skipped and why (``clothsim simulate --profile``)."""

from __future__ import annotations

import time

import numpy as np

from .collide import SURFACE_OFFSET
from .constraints import provot
from .forces import accumulate_forces
from .frame import collide_reachable
from .integrate import verlet
from .selfcollide import self_collide

PASSES = ("forces", "integrate", "self-collision", "colliders", "provot")


class Profiler:
    """Steps a :class:`~clothsim.sim.Simulation` pass by pass, timing each one.

    The passes are the same kernels the fast path fuses into one call, run in the same order,
    so the numbers are identical to an unprofiled run; only the timing calls are added.
    """

    def __init__(self, sim) -> None:  # noqa: ANN001
        self.sim = sim
        self.seconds = dict.fromkeys(PASSES, 0.0)
        self.calls = dict.fromkeys(PASSES, 0)
        self.collider_tests = 0
        self.collider_skips = 0

    def skipped(self) -> dict[str, str]:
        """Passes this scene never runs, with the reason."""
        sim = self.sim
        out: dict[str, str] = {}
        if len(sim.springs) == 0:
            out["springs"] = "every spring family disabled"
        else:
            off = [n for n, on in (("structural", sim.enable_structural), ("shearing", sim.enable_shearing),
                                   ("bending", sim.enable_bending)) if not on]
            if off:
                out["springs: " + ", ".join(off)] = "family disabled (absent from the spring arrays)"
        if sim._self_mode == 0:
            out["self-collision"] = "simulation.self_collision is false"
        if len(sim._spheres) + len(sim._planes) == 0:
            out["colliders"] = "scene has no sphere or plane"
        if sim._stretch_limit <= 0:
            out["provot"] = "simulation.max_stretch is null"
        if sim.pinned.any():
            out[f"integrate: {int(sim.pinned.sum())} pinned points"] = "put back after the sweep"
        return out

    def frame(self) -> None:
        """Advance one frame, pass by pass."""
        sim = self.sim
        if not sim.uses_spec_path:
            sim.step()
            return
        t = time.perf_counter
        steps = sim.scene.simulation.simulation_steps
        pos, last, free = sim._pos, sim._last, sim.free
        pins = np.flatnonzero(sim.pinned)
        inv_mass = 1.0 / sim.mass
        for _ in range(steps):
            t0 = t()
            accumulate_forces(pos, sim._forces, sim._stream, sim.mass, sim._gravity)
            t1 = t()
            verlet(pos, last, sim._forces, pins, inv_mass, sim.dt, sim._keep)
            t2 = t()
            self._add("forces", t1 - t0)
            self._add("integrate", t2 - t1)
            if sim._self_mode:
                self_collide(pos, free, sim.scene.cloth.thickness, steps, sim._self_mode, *sim._cell, sim._keys,
                             sim._slots, sim._table, sim._order)
                self._add("self-collision", t() - t2)
            n_colliders = len(sim._spheres) + len(sim._planes)
            if n_colliders:
                t3 = t()
                skips = collide_reachable(pos, last, free, sim._spheres, sim._planes, SURFACE_OFFSET, sim._box,
                                          sim._sphere_on, sim._plane_on)
                self._add("colliders", t() - t3)
                self.collider_tests += n_colliders
                self.collider_skips += skips
            if sim._stretch_limit > 0:
                t4 = t()
                provot(pos, sim.pinned, sim._blocks, sim._rest, sim.nw, sim._stretch_limit)
                self._add("provot", t() - t4)
        sim.frame += 1

    def _add(self, name: str, seconds: float) -> None:
        self.seconds[name] += seconds
        self.calls[name] += 1

    def report(self) -> str:
        """The table: pass, calls, total ms, share, per call; then the skipped passes."""
        total = sum(self.seconds.values()) or 1e-12
        lines = [f"{'pass':<16}{'calls':>8}{'total ms':>11}{'share':>8}{'us/call':>10}"]
        for name in PASSES:
            n = self.calls[name]
            if n == 0:
                continue
            s = self.seconds[name]
            lines.append(f"{name:<16}{n:>8}{s * 1e3:>11.2f}{s / total:>8.1%}{s / n * 1e6:>10.2f}")
        lines.append(f"{'total':<16}{'':>8}{total * 1e3:>11.2f}")
        if self.collider_tests:
            lines.append(f"collider tests skipped by the bounding-box check: {self.collider_skips} of "
                         f"{self.collider_tests} ({self.collider_skips / self.collider_tests:.0%})")
        skipped = self.skipped()
        if skipped:
            lines.append("skipped:")
            lines.extend(f"  {name}: {why}" for name, why in skipped.items())
        return "\n".join(lines)
