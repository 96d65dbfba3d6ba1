"""``clothsim bench scaling``: cost per point per substep for square cloths of growing size."""

from __future__ import annotations

import argparse
import statistics
import time

from ..scene import BYTES_PER_POINT, MAX_SUBSTEPS, available_memory, load_scene
from ..validate import check, integer


def add_parser(bench_sub: argparse._SubParsersAction) -> None:
    """Register ``clothsim bench scaling``."""
    p = bench_sub.add_parser("scaling", help="ms per substep and ns per point per substep vs cloth size")
    p.add_argument("--sizes", type=int, nargs="*", default=[32, 64, 128, 256, 512],
                   help="points per side (default 32 64 128 256 512; sizes that do not fit in memory are skipped)")
    p.add_argument("--substeps", type=int, default=60, help="substeps timed per repeat (default 60)")
    p.add_argument("--repeats", type=int, default=5, help="repeats; the median is reported (default 5)")
    p.set_defaults(func=run)


def run(args: argparse.Namespace) -> int:
    """Print the table: the pinned4 scene at each size (1 m cloth, spec parameters, thickness
    scaled with the point spacing)."""
    from ..sim import Simulation

    for n in args.sizes:
        check(integer(ge=2), n, "--sizes")  # a side of one point has no springs (and no spacing)
    check(integer(ge=1, le=MAX_SUBSTEPS), args.substeps, "--substeps")
    check(integer(ge=1), args.repeats, "--repeats")
    base = load_scene("pinned4")
    print(f"{'points':>8}{'self-coll.':>11}{'ms/substep':>12}{'ns/point/substep':>18}{'vs 64x64':>10}")
    ref: dict[str, float] = {}
    for n in args.sizes:
        if n * n * BYTES_PER_POINT * 4 > available_memory():
            print(f"{n:>5}x{n:<3} skipped: not enough memory")
            continue
        pins = ((0, 0), (0, n - 1), (n - 1, 0), (n - 1, n - 1))
        for mode in ("off", "grid", "spec"):
            # thickness scales with the point spacing so every size has the same neighbours per point
            thickness = base.cloth.thickness * (base.cloth.num_width_points - 1) / (n - 1)
            scene = base.with_cloth(num_width_points=n, num_height_points=n, pinned=pins, thickness=thickness)
            scene = scene.with_simulation(self_collision=mode, simulation_steps=args.substeps)
            sim = Simulation(scene)
            sim.step(2)  # compile and get the cloth moving
            samples = []
            for _ in range(args.repeats):
                t0 = time.perf_counter()
                sim.step(1)
                samples.append((time.perf_counter() - t0) / args.substeps)
            sec = statistics.median(samples)
            ns_point = sec / (n * n) * 1e9
            if n == 64:
                ref[mode] = ns_point
            ratio = f"{ns_point / ref[mode]:.2f}" if mode in ref else ""
            print(f"{n:>5}x{n:<3}{mode:>10}{sec * 1e3:>12.3f}{ns_point:>18.1f}{ratio:>10}", flush=True)
    print("medians of repeats; ratio = ns per point per substep relative to 64x64 with the same mode")
    return 0
