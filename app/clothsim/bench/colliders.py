"""``clothsim bench colliders``: milliseconds per frame with and without each collider feature.

Each bundled collider scene (``capsule``, ``tablecloth``, ``curtain``, ``mesh``) is timed as it is,
without its collider's motion, with the collider moved far out of the cloth's reach, and with the
collider removed; self-collision off so that the rows differ by the collider pass alone. ``mesh``
is timed a second time with its torus replaced by a finely tessellated one generated here
(``mesh 20k``: 100 x 100 quads, 20,000 triangles, the same size). With ``mesh`` among the
scenes, then the cost of the mesh pass per cloth point: the ``mesh`` scene at 50 x 50, 100 x 100
and 200 x 200 (thickness scaled with the point spacing, as ``clothsim bench scaling`` does), with
and without its mesh; the difference per point and substep. The variants of a scene are timed round-robin (one repeat of each in turn), so a slow
period of a shared machine hits them all alike.
"""

from __future__ import annotations

import argparse
import dataclasses
import statistics
import time
from collections.abc import Callable

from typing import Any

from ..meshcollider import check_topology
from ..objfile import parse_obj
from ..objshapes import TORUS, torus_obj
from ..scene import Scene, load_scene
from ..validate import check, integer

SCENES = ("capsule", "tablecloth", "curtain", "mesh", "mesh 20k")
#: The generated torus of ``mesh 20k``: the bundled one's radii, 100 x 100 quads.
FINE_TORUS = (TORUS[0], TORUS[1], 100, 100)
#: Cloth sizes (points per side) of the per-point table (with ``mesh`` among the scenes).
SIZES = (50, 100, 200)
#: How far a "far" collider is moved: well beyond any bundled cloth.
FAR = 100.0


def _far(spec: object) -> object:
    """``spec`` moved FAR along x (its motion too), so the skip test rules it out."""
    out = spec
    for name in ("origin", "center", "a", "b"):
        if hasattr(spec, name):
            v = getattr(spec, name)
            out = dataclasses.replace(out, **{name: (v[0] + FAR, v[1], v[2])})
    if hasattr(spec, "translate"):
        v = spec.translate
        out = dataclasses.replace(out, translate=(v[0] + FAR, v[1], v[2]))
    motion = getattr(spec, "motion", None)
    if motion is not None and motion.keyframes:
        frames = tuple((t, (p[0] + FAR, p[1], p[2])) for t, p in motion.keyframes)
        out = dataclasses.replace(out, motion=dataclasses.replace(motion, keyframes=frames))
    return out


def variants(scene: Scene) -> dict[str, Scene]:
    """The scene as it is, its colliders static, far away, and gone (the planes of the bundled
    scenes are floors the cloth reaches late, so they stay in every variant)."""
    kinds = ("spheres", "capsules", "boxes", "meshes")
    out = {"as is": scene}
    if scene.moving:
        out["static"] = dataclasses.replace(scene, **{k: tuple(dataclasses.replace(c, motion=None)
                                                              for c in getattr(scene, k)) for k in kinds})
    out["far away"] = dataclasses.replace(scene, **{k: tuple(_far(c) for c in getattr(scene, k)) for k in kinds})
    out["none"] = dataclasses.replace(scene, **{k: () for k in kinds})
    return out


def fine_mesh(scene: Scene, torus: tuple[float, float, int, int] = FINE_TORUS) -> Scene:
    """``scene`` with each mesh's triangles replaced by a generated torus (placement kept)."""
    obj = parse_obj(torus_obj(*torus))
    tris, closed = check_topology(obj.vertices, obj.triangles, obj.lines)
    meshes = tuple(dataclasses.replace(m, vertices=obj.vertices, triangles=tris, closed=closed) for m in scene.meshes)
    return dataclasses.replace(scene, meshes=meshes)


def _load(name: str) -> Scene:
    if name == "mesh 20k":
        return fine_mesh(load_scene("mesh"))
    return load_scene(name)


def add_parser(bench_sub: argparse._SubParsersAction) -> None:
    """Register ``clothsim bench colliders``."""
    p = bench_sub.add_parser("colliders", help="ms per frame with and without capsules, boxes and motion",
                             description=__doc__)
    p.add_argument("--frames", type=int, default=30, help="frames per repeat (default 30)")
    p.add_argument("--repeats", type=int, default=7, help="repeats; the median is reported (default 7)")
    p.add_argument("--warmup", type=int, default=60, help="frames simulated before timing (default 60)")
    p.add_argument("--scenes", nargs="*", default=list(SCENES),
                   help=f"scenes (default: {' '.join(repr(x) for x in SCENES)}; 'mesh 20k' is generated)")
    p.set_defaults(func=run)


def _timer(sim: Any, frames: int) -> Callable[[], float]:
    def once() -> float:
        t0 = time.perf_counter()
        sim.step(frames)
        return (time.perf_counter() - t0) / frames * 1e3
    return once


def _round_robin(sims: dict[str, Any], frames: int, repeats: int) -> dict[str, float]:
    """Median ms per frame of each simulation, one repeat of each in turn."""
    timers = {label: _timer(sim, frames) for label, sim in sims.items()}
    samples: dict[str, list[float]] = {label: [] for label in sims}
    for _ in range(repeats):
        for label, timer in timers.items():
            samples[label].append(timer())
    return {label: statistics.median(s) for label, s in samples.items()}


def run(args: argparse.Namespace) -> int:
    """Print the tables."""
    from ..sim import Simulation  # only when it runs: building the parser loads no Numba

    for flag, value, low in (("--frames", args.frames, 1), ("--repeats", args.repeats, 1),
                             ("--warmup", args.warmup, 0)):
        check(integer(ge=low), value, flag)
    scenes = [_load(name) for name in args.scenes]
    print(f"{'scene':<14}{'colliders':<12}{'ms/frame':>10}{'vs none':>9}{'skipped':>10}")
    for name, scene in zip(args.scenes, scenes):
        sims = {label: Simulation(v.with_simulation(self_collision="off")) for label, v in variants(scene).items()}
        for sim in sims.values():
            sim.step(args.warmup)
        ms = _round_robin(sims, args.frames, args.repeats)
        for label, sim in sims.items():
            tests = sim.frame * sim.simulation_steps * max(sim.n_colliders, 1)
            skipped = f"{sim.colliders_skipped / tests:.0%}" if sim.n_colliders else "-"
            print(f"{name:<14}{label:<12}{ms[label]:>10.3f}{ms[label] / ms['none']:>8.2f}x{skipped:>10}", flush=True)
    print("self-collision off; medians of repeats taken round-robin; skipped = collider tests ruled out by the "
          "bounding box")
    if "mesh" in args.scenes:
        _per_point(Simulation, load_scene("mesh").with_simulation(self_collision="off"), args)
    return 0


def _per_point(simulation: Callable[[Scene], Any], base: Scene, args: argparse.Namespace) -> None:
    """The mesh pass's cost per cloth point and substep at each size: (with - without) / points."""
    print()
    print(f"{'points':>9}{'ms/frame':>10}{'-mesh':>9}{'ratio':>8}{'mesh ns/point/substep':>23}{'vs first':>10}")
    first = None
    for n in SIZES:
        thickness = base.cloth.thickness * (base.cloth.num_width_points - 1) / (n - 1)
        scene = base.with_cloth(num_width_points=n, num_height_points=n, thickness=thickness)
        sims = {"as is": simulation(scene), "none": simulation(dataclasses.replace(scene, meshes=()))}
        for sim in sims.values():
            sim.step(args.warmup)
        ms = _round_robin(sims, args.frames, args.repeats)
        steps = scene.simulation.simulation_steps
        per_point = (ms["as is"] - ms["none"]) * 1e6 / (n * n * steps)
        first = per_point if first is None else first
        print(f"{n:>5}x{n:<3}{ms['as is']:>10.3f}{ms['none']:>9.3f}{ms['as is'] / ms['none']:>7.2f}x"
              f"{per_point:>23.1f}{per_point / first:>9.2f}x", flush=True)
    print("the mesh scene at each size (thickness scaled with the point spacing), with and without its torus; "
          "self-collision off; medians of repeats taken round-robin")
