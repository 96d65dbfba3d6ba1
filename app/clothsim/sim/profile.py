"""A visible account of the work a scene does: which passes ran, their share of the time, and
which were skipped and why (``clothsim simulate --profile``); and each pass timed inside whole
frames of the frame kernel, with the thread team's waiting (:class:`FrameLaps`, ``clothsim bench
passes``)."""

from __future__ import annotations

import time

import numpy as np

from ..colliders import kinds_text
from .passes.forces import FORCES
from .solvers.frame import LAP_NAMES, PASS_ALL, PASS_COLLIDERS, PASS_CONTACT, PASS_INTEGRATE, PASS_PROVOT, \
    PASS_SELF, PASS_TIMED
from .team import LAPS, MOST_LAPS

PASSES = ("forces+integrate", "self-collision", "colliders", "provot", "contact bound")


class Profiler:
    """Steps a :class:`~clothsim.sim.Simulation` pass by pass, timing each one.

    Each pass is the fast path's own frame kernel told to run that pass alone, one substep at a
    time, in the same order, so the numbers are identical to an unprofiled run; only the timing
    calls (and a thread team started per pass) are added. Frames go through the same blow-up
    guard and team recovery as :meth:`~clothsim.sim.Simulation.step`.
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
        if sim.self_mode == 0:
            out["self-collision"] = "simulation.self_collision is false"
        if sim.n_colliders == 0:
            out["colliders"] = f"scene has no {kinds_text()}"
        present = {type(group) for group in sim.plan.forces}
        for force in FORCES:
            if force.Group not in present:
                out[force.NAME] = force.ABSENT
        if sim.plan.pins is None:
            out["moving pins"] = "cloth has no pin_motion"
        if sim.plan.st.stretch_limit <= 0:
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
        sim._advance_frame(self._run_passes)

    def _run_passes(self, steps: int, saved: tuple | None) -> None:
        sim = self.sim
        size = sim.team.size() if saved is not None else 1
        if not self._passes(steps, size):
            sim._restore(saved)
            self._passes(steps, 1)

    def _passes(self, steps: int, size: int) -> bool:
        sim = self.sim
        t = time.perf_counter
        n_colliders = sim.n_colliders
        plan = sim.plan
        hashed = sim.self_mode != 0  # (the contact mode's response runs in this slot)
        for _ in range(steps):
            for name, bit, on in (("forces+integrate", PASS_INTEGRATE, True),
                                  ("self-collision", PASS_SELF, hashed),
                                  ("colliders", PASS_COLLIDERS, n_colliders > 0),
                                  ("provot", PASS_PROVOT, sim.plan.st.stretch_limit > 0),
                                  ("contact bound", PASS_CONTACT, plan.contact is not None)):
                if on:
                    before = sim.colliders_skipped
                    t0 = t()
                    finished = sim.run_kernel(1, bit, size)
                    self._add(name, t() - t0)
                    if not finished:
                        return False
                    if bit == PASS_COLLIDERS:
                        self.collider_tests += n_colliders
                        self.collider_skips += sim.colliders_skipped - before
            sim._clock[1] += 1  # the substep is done: every pass of it ran at the same time, as in a whole frame
        return True

    def _add(self, name: str, seconds: float) -> None:
        self.seconds[name] += seconds
        self.calls[name] += 1

    def report(self) -> str:
        """The table: pass, calls, total ms, share, per call; then the skipped passes."""
        total = sum(self.seconds.values()) or 1e-12
        lines = [f"{'pass':<18}{'calls':>8}{'total ms':>11}{'share':>8}{'us/call':>10}"]
        for name in PASSES:
            n = self.calls[name]
            if n == 0:
                continue
            s = self.seconds[name]
            lines.append(f"{name:<18}{n:>8}{s * 1e3:>11.2f}{s / total:>8.1%}{s / n * 1e6:>10.2f}")
        lines.append(f"{'total':<18}{'':>8}{total * 1e3:>11.2f}")
        if self.collider_tests:
            lines.append(f"collider tests skipped by the bounding-box check: {self.collider_skips} of "
                         f"{self.collider_tests} ({self.collider_skips / self.collider_tests:.0%})")
        skipped = self.skipped()
        if skipped:
            lines.append("skipped:")
            lines.extend(f"  {name}: {why}" for name, why in skipped.items())
        return "\n".join(lines)


class FrameLaps:
    """Times every pass of whole frames inside the frame kernel (the spec's Verlet path): for each
    barrier of a substep, the time from the barrier before it (the pass's slowest member) and the
    members' time spent waiting at it (:func:`clothsim.sim.team.barrier`). Unlike
    :class:`Profiler`, which runs each pass in a call of its own, the frame runs as it always
    does, with its team; only a few clock reads a barrier are added, and the numbers are the
    same."""

    def __init__(self, sim) -> None:  # noqa: ANN001
        if not sim.uses_spec_path:
            raise ValueError("only the spec's Verlet (integrator \"verlet\", damping_mode \"spec\") runs the "
                             "frame kernel whose passes are timed")
        self.sim = sim
        #: (lap, [time, members' waiting]) nanoseconds summed over the timed frames
        self.ns = np.zeros((MOST_LAPS, 2), dtype=np.int64)
        self.frames = 0
        self.substeps = 0
        self.seconds = 0.0
        self.members = 1

    def frame(self) -> None:
        """Advance one frame, timing its passes."""
        self.sim._advance_frame(self._run)

    def _run(self, steps: int, saved: tuple | None) -> None:
        sim = self.sim
        t0 = time.perf_counter()
        self.members = max(self.members, sim._run(steps, saved, PASS_ALL | PASS_TIMED))
        self.seconds += time.perf_counter() - t0
        self.ns += sim._sync[LAPS:LAPS + 2 * MOST_LAPS].reshape(MOST_LAPS, 2)
        self.frames += 1
        self.substeps += steps

    def report(self) -> str:
        """The table: each pass the frame ran, its microseconds a substep (from the barrier before
        it to the one after) and the members' microseconds spent waiting at the one after, and its
        share of the substep."""
        per = 1e-3 / max(self.substeps, 1)
        total = self.ns[:, 0].sum() or 1
        lines = [f"{'pass':<32}{'us':>9}{'waiting':>9}{'share':>8}"]
        for k, name in enumerate(LAP_NAMES):
            if self.ns[k, 0] == 0:
                continue
            lines.append(f"{name:<32}{self.ns[k, 0] * per:>9.2f}{self.ns[k, 1] * per:>9.2f}"
                         f"{self.ns[k, 0] / total:>8.1%}")
        lines.append(f"{'substep':<32}{total * per:>9.2f}{self.ns[:, 1].sum() * per:>9.2f}")
        lines.append(f"{self.frames} frames, {self.substeps} substeps, {self.members} member"
                     f"{'s' if self.members != 1 else ''}: {self.seconds / max(self.frames, 1) * 1e3:.3f} ms a "
                     f"frame ({self.seconds / max(self.substeps, 1) * 1e6:.2f} us a substep) around the kernel")
        return "\n".join(lines)
