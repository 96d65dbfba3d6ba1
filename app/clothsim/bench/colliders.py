"""``clothsim bench colliders``: milliseconds per frame with and without each collider feature.

Each bundled collider scene (``capsule``, ``tablecloth``, ``curtain``) is timed as it is, without
its collider's motion, with the collider moved far out of the cloth's reach, and with the collider
removed; self-collision off so that the rows differ by the collider pass alone. The variants are
timed round-robin (one repeat of each in turn), so a slow period of a shared machine hits them
all alike.
"""

from __future__ import annotations

import argparse
import dataclasses
import statistics
import time
from collections.abc import Callable

from typing import Any

from ..scene import Scene, load_scene
from ..validate import check, integer

SCENES = ("capsule", "tablecloth", "curtain")
#: How far a "far" collider is moved: well beyond any bundled cloth.
FAR = 100.0


def _far(spec: object) -> object:
    """``spec`` moved FAR along x (its motion too), so the skip test rules it out."""
    out = spec
    for name in ("origin", "center", "a", "b"):
        if hasattr(spec, name):
            v = getattr(spec, name)
            out = dataclasses.replace(out, **{name: (v[0] + FAR, v[1], v[2])})
    motion = getattr(spec, "motion", None)
    if motion is not None and motion.keyframes:
        frames = tuple((t, (p[0] + FAR, p[1], p[2])) for t, p in motion.keyframes)
        out = dataclasses.replace(out, motion=dataclasses.replace(motion, keyframes=frames))
    return out


def variants(scene: Scene) -> dict[str, Scene]:
    """The scene as it is, its colliders static, far away, and gone (the planes of the bundled
    scenes are floors the cloth reaches late, so they stay in every variant)."""
    kinds = ("spheres", "capsules", "boxes")
    out = {"as is": scene}
    if scene.moving:
        out["static"] = dataclasses.replace(scene, **{k: tuple(dataclasses.replace(c, motion=None)
                                                              for c in getattr(scene, k)) for k in kinds})
    out["far away"] = dataclasses.replace(scene, **{k: tuple(_far(c) for c in getattr(scene, k)) for k in kinds})
    out["none"] = dataclasses.replace(scene, **{k: () for k in kinds})
    return out


def add_parser(bench_sub: argparse._SubParsersAction) -> None:
    """Register ``clothsim bench colliders``."""
    p = bench_sub.add_parser("colliders", help="ms per frame with and without capsules, boxes and motion",
                             description=__doc__)
    p.add_argument("--frames", type=int, default=30, help="frames per repeat (default 30)")
    p.add_argument("--repeats", type=int, default=7, help="repeats; the median is reported (default 7)")
    p.add_argument("--warmup", type=int, default=60, help="frames simulated before timing (default 60)")
    p.add_argument("--scenes", nargs="*", default=list(SCENES), help=f"scenes (default: {' '.join(SCENES)})")
    p.set_defaults(func=run)


def _timer(sim: Any, frames: int) -> Callable[[], float]:
    def once() -> float:
        t0 = time.perf_counter()
        sim.step(frames)
        return (time.perf_counter() - t0) / frames * 1e3
    return once


def run(args: argparse.Namespace) -> int:
    """Print the table."""
    from ..sim import Simulation  # only when it runs: building the parser loads no Numba

    for flag, value, low in (("--frames", args.frames, 1), ("--repeats", args.repeats, 1),
                             ("--warmup", args.warmup, 0)):
        check(integer(ge=low), value, flag)
    scenes = [load_scene(name) for name in args.scenes]
    print(f"{'scene':<14}{'colliders':<12}{'ms/frame':>10}{'vs none':>9}{'skipped':>10}")
    for name, scene in zip(args.scenes, scenes):
        sims = {label: Simulation(v.with_simulation(self_collision="off")) for label, v in variants(scene).items()}
        for sim in sims.values():
            sim.step(args.warmup)
        timers = {label: _timer(sim, args.frames) for label, sim in sims.items()}
        samples: dict[str, list[float]] = {label: [] for label in sims}
        for _ in range(args.repeats):
            for label, timer in timers.items():
                samples[label].append(timer())
        ms = {label: statistics.median(s) for label, s in samples.items()}
        for label, sim in sims.items():
            tests = sim.frame * sim.simulation_steps * max(sim.n_colliders, 1)
            skipped = f"{sim.colliders_skipped / tests:.0%}" if sim.n_colliders else "-"
            print(f"{name:<14}{label:<12}{ms[label]:>10.3f}{ms[label] / ms['none']:>8.2f}x{skipped:>10}", flush=True)
    print("self-collision off; medians of repeats taken round-robin; skipped = collider tests ruled out by the "
          "bounding box")
    return 0
