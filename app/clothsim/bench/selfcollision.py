"""``clothsim bench selfcollision``: frame time and crossings of every self-collision mode on the
stress set (:mod:`clothsim.bench.stress`).

Each run is simulated frame by frame; a frame's time is the wall time of its substeps alone, and
the cloth's edge-triangle crossings (:mod:`clothsim.sim.crossings`) are counted at the end of
every ``--every``-th frame and of the last one, outside the timing. The modes are every
``simulation.self_collision`` value the scene validator accepts, so a new mode is measured as soon
as a scene may name it. A run that blows up is reported with the frame at which it did.
"""

from __future__ import annotations

import argparse
import statistics
import time
from dataclasses import dataclass, field

from ..errors import ClothsimError, SimulationBlowUp
from ..validate import check, integer
from .stress import FOLDING_SCENES, STRESS_SCENES, StressRun, self_collision_modes

DEFAULT_FRAMES = 300
DEFAULT_EVERY = 3
DEFAULT_GRID = 50


@dataclass
class StressResult:
    """One stress run in one mode: per-frame times (ms), (frame, crossings) samples, and the
    frame that blew up (None when it did not)."""

    scene: str
    mode: str
    ms: list[float] = field(default_factory=list)
    samples: list[tuple[int, int]] = field(default_factory=list)
    blew_up: int | None = None
    #: contact mode: whole rebuilds of the reference, and the ms its search took in all (None
    #: where the frame's passes are not timed: the twist, whose pins are put through the API)
    rebuilds: int = 0
    search_ms: float | None = None
    #: contact mode: substeps in which a pin moved, or a moving collider put a point, further than
    #: the bound allows (Simulation.unsafe_substeps, Simulation.squeezed_substeps)
    unsafe: int = 0
    squeezed: int = 0

    @property
    def worst(self) -> tuple[int, int]:
        """(frame, crossings) of the sample with the most crossings (the first such)."""
        return max(self.samples, key=lambda s: (s[1], -s[0])) if self.samples else (0, 0)


def measure(scene: str, mode: str, frames: int, every: int = 1, grid: int = DEFAULT_GRID) -> StressResult:
    """Run stress scene ``scene`` in self-collision ``mode`` for ``frames`` frames; count crossings
    after frames every, 2*every, ... and after the last."""
    from ..sim.passes.contactgroup import REBUILDS
    from ..sim.profile import FrameLaps
    from ..sim.solvers.frame import LAP_NAMES

    run = StressRun(scene, mode, grid)
    out = StressResult(scene, mode)
    contact = run.sim._kernel_args.contact
    # the contact mode's frames are run with their passes timed (the same numbers, a few clock
    # reads a barrier more) to give the search's share of them
    laps = FrameLaps(run.sim) if contact is not None and not run.through_the_api else None
    advance = laps.frame if laps is not None else run.frame
    for f in range(1, frames + 1):
        t0 = time.perf_counter()
        try:
            advance()
        except SimulationBlowUp:
            out.blew_up = f
            break
        out.ms.append((time.perf_counter() - t0) * 1e3)
        if f % every == 0 or f == frames:
            out.samples.append((f, run.crossings()))
    if contact is not None:
        out.rebuilds = int(run.sim._kernel_args.contact.meta[REBUILDS])
        out.unsafe = run.sim.unsafe_substeps
        out.squeezed = run.sim.squeezed_substeps
    if laps is not None:
        out.search_ms = laps.ns[LAP_NAMES.index("contact: search"), 0] * 1e-6
    return out


def add_parser(bench_sub: argparse._SubParsersAction) -> None:
    """Register ``clothsim bench selfcollision``."""
    p = bench_sub.add_parser("selfcollision", help="frame time and crossings of each self-collision mode on "
                             "the stress set", description=__doc__)
    p.add_argument("--frames", type=int, default=DEFAULT_FRAMES, help=f"frames per run (default {DEFAULT_FRAMES})")
    p.add_argument("--every", type=int, default=DEFAULT_EVERY, metavar="K",
                   help=f"count crossings after every K-th frame and the last (default {DEFAULT_EVERY})")
    p.add_argument("--grid", type=int, default=DEFAULT_GRID, metavar="N",
                   help=f"points per side of the cloth (default {DEFAULT_GRID})")
    p.add_argument("--scenes", nargs="*", default=list(FOLDING_SCENES),
                   help=f"stress runs, from {' '.join(STRESS_SCENES)} (default: {' '.join(FOLDING_SCENES)})")
    p.add_argument("--modes", nargs="*", help="self-collision modes (default: every mode a scene may name)")
    p.set_defaults(func=run)


def run(args: argparse.Namespace) -> int:
    """Print the table."""
    check(integer(ge=1), args.frames, "--frames")
    check(integer(ge=1), args.every, "--every")
    check(integer(ge=3, le=1024), args.grid, "--grid")
    known = self_collision_modes()
    modes = args.modes or list(known)
    for name in args.scenes:
        if name not in STRESS_SCENES:
            raise ClothsimError(f"--scenes: unknown stress run {name!r} (expected: {', '.join(STRESS_SCENES)})")
    for mode in modes:
        if mode not in known:
            raise ClothsimError(f"--modes: unknown self-collision mode {mode!r} (expected: {', '.join(known)})")
    print(f"{'scene':<15}{'mode':<9}{'ms/frame':>10}{'max crossings':>15}{'at frame':>10}{'final':>8}"
          f"{'rebuilds/frame':>16}{'ms/rebuild':>12}  note")
    for name in args.scenes:
        for mode in modes:
            r = measure(name, mode, args.frames, args.every, args.grid)
            ms = f"{statistics.median(r.ms):.2f}" if r.ms else "-"
            frame, most = r.worst
            final = str(r.samples[-1][1]) if r.samples else "-"
            notes = [f"blew up at frame {r.blew_up}"] if r.blew_up is not None else []
            notes += [f"{n} substeps {what}" for n, what in ((r.unsafe, "unsafe (pins)"), (r.squeezed, "squeezed"))
                      if n]
            note = "; ".join(notes)
            done = max(len(r.ms), 1)
            per_frame = f"{r.rebuilds / done:.2f}" if mode == "contact" else "-"
            per_rebuild = f"{r.search_ms / r.rebuilds:.2f}" if r.search_ms is not None and r.rebuilds else "-"
            print(f"{name:<15}{mode:<9}{ms:>10}{most:>15}{frame:>10}{final:>8}{per_frame:>16}{per_rebuild:>12}"
                  f"  {note}".rstrip(), flush=True)
    print(f"{args.grid}x{args.grid} points, {args.frames} frames; ms/frame = median over frames; crossings "
          f"(edges through triangles they share no point with) counted every {args.every} frames and after the "
          "last; final = the last count before the end or a blow-up; contact: whole rebuilds of its reference a "
          "frame, and the ms of a rebuild's search (the twist's passes are not timed); the substeps in which a pin "
          "moved (unsafe) or a moving collider put a point (squeezed) further than its bound allows")
    return 0
