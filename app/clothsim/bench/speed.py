"""``clothsim bench speed``: milliseconds per frame of every bundled scene, next to the plain
vectorised-NumPy baseline timed in the same run."""

from __future__ import annotations

import argparse
import dataclasses
import statistics
import tempfile
import time
from pathlib import Path

from ..forces import FORCES
from ..scene import bundled_scene_names, load_scene, scene_from_dict
from ..sweeps.params import scene_json
from ..validate import check, integer


def median_ms_per_frame(step, frames: int, repeats: int) -> float:  # noqa: ANN001
    """Median over ``repeats`` of the mean milliseconds per frame of ``frames`` calls."""
    samples = []
    for _ in range(repeats):
        t0 = time.perf_counter()
        for _ in range(frames):
            step()
        samples.append((time.perf_counter() - t0) / frames * 1e3)
    return statistics.median(samples)


#: ``--as-mesh``'s second mesh renumbers the grid's points at random within runs of this many.
SHUFFLE_RUN = 64


def grid_as_mesh(scene, folder: Path, shuffle: int = 0):  # noqa: ANN001, ANN201
    """``scene`` with its grid cloth written out as an OBJ of quads (the grid's starting points,
    exactly, and its UVs) and read back as a mesh cloth, with the same pins and parameters: a mesh
    cloth of the grid's points and about as many springs (a 50 x 50 grid: 14,502 springs; the
    mesh: 14,406). Row by row, its springs fall on a few offsets, as a grid's (the simulator's
    streams); with ``shuffle`` > 0 the points are renumbered at random (a fixed seed) within runs
    of ``shuffle`` indices, as an unstructured mesh's are: near in index, near in space, but no
    common offsets (the simulator's spring lists)."""
    import numpy as np

    from ..cloth import cloth_uvs, grid_positions

    cloth = scene.cloth
    nw, nh = cloth.num_width_points, cloth.num_height_points
    pos = grid_positions(cloth, scene.simulation.seed)
    uvs = cloth_uvs(nw, nh)
    n = nw * nh
    new = np.arange(n)
    if shuffle > 0:
        rng = np.random.default_rng(0)
        for lo in range(0, n, shuffle):
            new[lo : lo + shuffle] = lo + rng.permutation(min(shuffle, n - lo))
    old = np.argsort(new)  # the grid point each new index holds
    lines = [f"v {x!r} {y!r} {z!r}" for x, y, z in pos[old].tolist()]
    lines += [f"vt {u!r} {v!r}" for u, v in uvs[old].astype(float).tolist()]
    for y in range(nh - 1):
        for x in range(nw - 1):
            a = y * nw + x
            corners = (new[a] + 1, new[a + nw] + 1, new[a + nw + 1] + 1, new[a + 1] + 1)
            lines.append("f " + " ".join(f"{c}/{c}" for c in corners))
    path = folder / "grid.obj"
    path.write_text("\n".join(lines) + "\n", encoding="ascii")
    mesh_cloth = {"mesh": {"path": str(path)}, "thickness": cloth.thickness, "damping": cloth.damping,
                  "density": cloth.density, "ks": cloth.ks,
                  "pinned_vertices": [int(new[y * nw + x]) for x, y in cloth.pinned]}
    data = dict(scene_json(scene))
    data["cloth"] = mesh_cloth
    return scene_from_dict(data, str(folder / "scene.json"))


def add_parser(bench_sub: argparse._SubParsersAction) -> None:
    """Register ``clothsim bench speed``."""
    p = bench_sub.add_parser("speed", help="ms per frame of each bundled scene vs a NumPy baseline")
    p.add_argument("--frames", type=int, default=30, help="frames per repeat (default 30)")
    p.add_argument("--repeats", type=int, default=7, help="repeats; the median is reported (default 7)")
    p.add_argument("--warmup", type=int, default=60,
                   help="frames simulated before timing, so the cloth is in motion (default 60)")
    p.add_argument("--baseline-frames", type=int, default=3, help="frames per repeat of the NumPy baseline")
    p.add_argument("--scenes", nargs="*", help="scene names or files (default: every bundled scene)")
    p.add_argument("--as-mesh", action="store_true",
                   help="also time each grid scene with its grid read as a mesh cloth (NAME as mesh: the grid's "
                        "points as an OBJ of quads, row by row; NAME shuffled: renumbered within runs of "
                        f"{SHUFFLE_RUN})")
    p.set_defaults(func=run)


def run(args: argparse.Namespace) -> int:
    """Print the table."""
    from ..sim import Simulation
    from .numpy_baseline import NumpyCloth

    for flag, value, low in (("--frames", args.frames, 1), ("--repeats", args.repeats, 1),
                             ("--warmup", args.warmup, 0), ("--baseline-frames", args.baseline_frames, 1)):
        check(integer(ge=low), value, flag)
    names = args.scenes or bundled_scene_names()
    scenes = [load_scene(name) for name in names]  # a bad name fails before any timing
    # A scene with a force (wind) or triangle meshes is timed again without them, in the same run:
    # their cost. A scene's rows are timed in turns, repeat by repeat, so a slow spell of the
    # machine falls on all of them alike: "vs" is each row's median over the scene's own.
    groups = []
    for name, scene in zip(names, scenes):
        rows = [(name, scene)]
        for kind in FORCES:
            if getattr(scene, kind.attr):
                rows.append((f"{name} -{kind.key}", dataclasses.replace(scene, **{kind.attr: ()})))
        if scene.meshes:
            rows.append((f"{name} -mesh", dataclasses.replace(scene, meshes=())))
        if args.as_mesh and not scene.cloth.is_mesh:
            for label, shuffle in (("as mesh", 0), ("shuffled", SHUFFLE_RUN)):
                folder = Path(tempfile.mkdtemp(prefix="clothsim-bench-"))
                rows.append((f"{name} {label}", grid_as_mesh(scene, folder, shuffle)))
        groups.append(rows)
    print(f"{'scene':<17}{'self-coll.':>11}{'ms/frame':>10}{'vs':>7}{'substeps/s':>12}{'x realtime':>11}"
          f"{'numpy ms':>10}{'speedup':>9}")
    for rows in groups:
        for mode in ("off", "spec"):
            runs = []
            for name, scene in rows:
                sc = scene.with_simulation(self_collision=mode)
                sim = Simulation(sc)
                sim.step(args.warmup)
                runs.append((name, sc, sim, []))
            for _ in range(args.repeats):
                for _, _, sim, samples in runs:
                    samples.append(median_ms_per_frame(sim.step, args.frames, 1))
            first = statistics.median(runs[0][3])
            for name, sc, sim, samples in runs:
                ms = statistics.median(samples)
                steps = sc.simulation.simulation_steps
                realtime = (1e3 / sc.simulation.frames_per_sec) / ms
                base = ""
                ratio = ""
                # the baseline knows only the course's static spheres and planes
                if mode == "off" and not (sc.capsules or sc.boxes or sc.moving or sc.meshes or sc.cloth.is_mesh):
                    baseline = NumpyCloth(Simulation(sc))
                    baseline_ms = median_ms_per_frame(baseline.frame, args.baseline_frames, 3)
                    base = f"{baseline_ms:.1f}"
                    ratio = f"{baseline_ms / ms:.0f}x"
                print(f"{name:<17}{mode:>11}{ms:>10.3f}{ms / first:>6.2f}x{steps * 1e3 / ms:>12.0f}{realtime:>10.1f}x"
                      f"{base:>10}{ratio:>9}", flush=True)
    print("medians of repeats, a scene's rows timed in turns; vs = over the scene's first row; numpy = vectorised NumPy baseline of the same step without self-collision "
          "(and without wind; none for scenes with capsules, boxes, meshes, moving colliders or a mesh cloth); NAME -wind: the "
          "scene above in still air; NAME -mesh: without its meshes; NAME as mesh: its grid read as a mesh cloth; "
          f"NAME shuffled: the same, renumbered within runs of {SHUFFLE_RUN}")
    return 0
