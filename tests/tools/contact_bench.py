"""Frame time of the contact self-collision mode against the spec's hash, and the crossings each
leaves: ``python tests/tools/contact_bench.py --sizes 50 100 256``.

Each size runs ``selfCollision`` scaled to n x n points (same cloth, same thickness). The modes are
timed alternately, repeat by repeat, after a warm-up, so both see the same load; the medians are
printed with the contact mode's ratio to the spec's, its cost per point, its whole rebuilds a
frame, and the substeps a frame that moved some points' references (and the points each moved).
"""

from __future__ import annotations

import argparse
import statistics
import sys
import time
from pathlib import Path

import numpy as np

from clothsim.scene import load_scene
from clothsim.sim import Simulation
from clothsim.sim.passes.contactgroup import LOCALS, MOVED, REBUILDS

SCENES = Path(__file__).resolve().parents[2] / "scenes"


def main(argv: list[str] | None = None) -> int:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--sizes", type=int, nargs="*", default=[50, 100, 256])
    p.add_argument("--scene", default="selfCollision")
    p.add_argument("--modes", nargs="*", default=["spec", "contact"])
    p.add_argument("--warmup", type=int, default=60, help="frames before timing (default 60: the cloth folds)")
    p.add_argument("--frames", type=int, default=10, help="frames per repeat")
    p.add_argument("--repeats", type=int, default=5)
    args = p.parse_args(argv)
    base = load_scene(SCENES / f"{args.scene}.json")
    print(f"{'n':>5}{'mode':>9}{'ms/frame':>10}{'us/point':>10}{'vs spec':>9}{'rebuilds/frame':>16}"
          f"{'moves/frame':>13}{'points/move':>13}", flush=True)
    for n in args.sizes:
        sims = {}
        for mode in args.modes:
            sim = Simulation(base.with_cloth(num_width_points=n, num_height_points=n)
                             .with_simulation(self_collision=mode))
            sim.step(args.warmup)
            sims[mode] = sim
        samples: dict[str, list[float]] = {m: [] for m in args.modes}
        rebuilt: dict[str, int] = dict.fromkeys(args.modes, 0)
        moves: dict[str, int] = dict.fromkeys(args.modes, 0)
        moved: dict[str, int] = dict.fromkeys(args.modes, 0)
        for _ in range(args.repeats):
            for mode, sim in sims.items():
                c = sim._kernel_args.contact
                before = None if c is None else c.meta.copy()
                t0 = time.perf_counter()
                sim.step(args.frames)
                samples[mode].append((time.perf_counter() - t0) / args.frames * 1e3)
                if c is not None:
                    rebuilt[mode] += int(c.meta[REBUILDS] - before[REBUILDS])
                    moves[mode] += int(c.meta[LOCALS] - before[LOCALS])
                    moved[mode] += int(c.meta[MOVED] - before[MOVED])
        med = {m: statistics.median(v) for m, v in samples.items()}
        for mode in args.modes:
            ratio = med[mode] / med["spec"] if "spec" in med else float("nan")
            rb = rebuilt[mode] / (args.frames * args.repeats)
            mv = moves[mode] / (args.frames * args.repeats)
            per = moved[mode] / max(moves[mode], 1)
            print(f"{n:>5}{mode:>9}{med[mode]:>10.2f}{med[mode] * 1e3 / (n * n):>10.3f}{ratio:>9.2f}{rb:>16.1f}"
                  f"{mv:>13.1f}{per:>13.1f}", flush=True)
        for mode, sim in sims.items():
            assert np.isfinite(sim.positions).all(), mode
            if n <= 100:
                print(f"      {mode}: {sim.crossings()} crossings after {sim.frame} frames", flush=True)
    return 0


if __name__ == "__main__":
    sys.exit(main())
