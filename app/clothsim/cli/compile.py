"""``clothsim compile``: every Numba kernel compiled ahead of time (:func:`each_item`), and
:func:`record_command` for ``clothsim bench compile``. A cold start's second process is
:mod:`clothsim.jit.compile`; the notice and the record of compiles are :mod:`clothsim.jit.watch`.

Kernels are compiled for this CPU the first time a scene needs them and cached on disk (next to
the installed package, or in Numba's user-wide cache when that folder is read-only). A warm
cache compiles nothing, and then nothing here prints anything.
"""

from __future__ import annotations

import json
import time
from collections.abc import Callable, Sequence
from typing import TYPE_CHECKING, Any

if TYPE_CHECKING:
    from ..jit.watch import Compiled

# ---------------------------------------------------------------------------------------------
# Ahead of time


def _tiny_scene(self_collision: str, colliders: bool, integrator: str = "verlet", damping_mode: str = "spec",
                wind: bool = False, pin_motion: bool = False, meshes: bool = False):
    from ..resources import data_dir
    from ..scene import scene_from_dict

    data: dict[str, Any] = {
        "cloth": {"width": 1, "height": 1, "num_width_points": 6, "num_height_points": 6, "thickness": 0.01,
                  "orientation": 0, "pinned": [[0, 0]], "damping": 0.2, "density": 150, "ks": 5000},
        "simulation": {"self_collision": {"spec": True, "grid": "grid", "off": False, "contact": "contact"}[self_collision],
                       "integrator": integrator, "damping_mode": damping_mode, "simulation_steps": 2},
    }
    if colliders:
        data["sphere"] = {"origin": [0.5, 0.5, 0.5], "radius": 0.2, "friction": 0.3}
        data["plane"] = {"point": [0, 0, 0], "normal": [0, 1, 0], "friction": 0.5}
    if wind:
        data["wind"] = {"velocity": [1, 0, 0], "turbulence": 1}
    if pin_motion:
        data["cloth"]["pin_motion"] = {"velocity": [0, 0.1, 0]}
    if meshes:
        data["mesh"] = {"path": str(data_dir("scenes") / "torus.obj"), "translate": [0.5, 0.5, 0.5], "friction": 0.3}
    return scene_from_dict(data, "<compile>")


def _tiny_mesh_scene(self_collision: str, colliders: bool = False, integrator: str = "verlet",
                     damping_mode: str = "spec", wind: bool = False):
    """A tiny cloth read from an OBJ (the bundled skirt's): a mesh cloth's plans."""
    from ..resources import data_dir
    from ..scene import scene_from_dict

    data: dict[str, Any] = {
        "cloth": {"mesh": {"path": str(data_dir("scenes") / "skirt.obj")}, "thickness": 0.01, "damping": 0.2,
                  "density": 150, "ks": 5000, "pinned_vertices": [0]},
        "simulation": {"self_collision": self_collision, "integrator": integrator, "damping_mode": damping_mode,
                       "simulation_steps": 2},
    }
    if colliders:
        data["sphere"] = {"origin": [0.0, -0.5, 0.0], "radius": 0.2, "friction": 0.3}
        data["plane"] = {"point": [0, -1, 0], "normal": [0, 1, 0], "friction": 0.5}
    if wind:
        data["wind"] = {"velocity": [1, 0, 0], "turbulence": 1}
        data["cloth"]["pin_motion"] = {"velocity": [0, 0.1, 0]}
    return scene_from_dict(data, "<compile>")


def _turning_scene():
    """A tiny scene whose colliders of every kind turn: the turning groups' kernels (a plan that
    holds them is compiled from these, whichever other kinds it has)."""
    from ..colliders import KINDS
    from ..resources import data_dir
    from ..scene import scene_from_dict

    turn = {"angular_velocity": [0, 90, 0]}
    shapes = {"sphere": {"origin": [0.5, 0.5, 0.5], "radius": 0.2, "friction": 0.3, "motion": turn},
              "plane": {"point": [0, 0, 0], "normal": [0, 1, 0], "friction": 0.5, "motion": turn},
              "capsule": {"a": [0, 0.3, 0], "b": [1, 0.3, 0], "radius": 0.1, "friction": 0.3, "motion": turn},
              "box": {"center": [0.5, 0.2, 0.5], "half_extents": [0.2, 0.1, 0.2], "friction": 0.3, "motion": turn},
              "mesh": {"path": str(data_dir("scenes") / "torus.obj"), "translate": [0.5, 0.5, 0.5], "friction": 0.3,
                       "motion": turn}}
    assert set(shapes) == {kind.key for kind in KINDS}
    data: dict[str, Any] = {
        "cloth": {"width": 1, "height": 1, "num_width_points": 6, "num_height_points": 6, "thickness": 0.01,
                  "orientation": 0, "damping": 0.2, "density": 150, "ks": 5000},
        "simulation": {"self_collision": False, "simulation_steps": 2}, **shapes}
    return scene_from_dict(data, "<compile>")


def work_items() -> list[tuple[str, Callable[[], None]]]:
    """Everything ``clothsim compile`` compiles: each frame-kernel plan (self-collision mode x
    colliders; wind and moving pins with the spec's self-collision, as the bundled ``flag`` uses),
    the plans of the bundled capsule, box, moving-collider and mesh scenes, colliders of every kind
    turning, a cloth read from an OBJ (each self-collision mode and integrator), the contact mode's plan
    with colliders, each other integrator, the rest detector and the renderer's mesh kernel."""
    from ..sim import Simulation

    def step(scene) -> Callable[[], None]:  # noqa: ANN001
        return lambda: Simulation(scene).step(1)

    from ..scene import load_scene

    # the longest first: with two or more processes the items are handed out in this order as
    # processes free up, so a long item started last would keep one process busy alone
    items = [("frame kernel: self-collision contact, colliders", step(_tiny_scene("contact", True))),
             ("frame kernel: self-collision spec, colliders and meshes", step(_tiny_scene("spec", True, meshes=True))),
             ("integrator symplectic_euler", step(_tiny_scene("spec", True, "symplectic_euler")))]
    # the bundled scenes with capsules, boxes and moving colliders (each kind present or absent,
    # moving or not, is a plan of its own: these are the ones shipped)
    items += [(f"frame kernel: bundled scene {name}", step(load_scene(name))) for name in ("tablecloth", "curtain",
                                                                                          "capsule", "breathing")]
    items.append(("colliders of every kind turning", step(_turning_scene())))
    # a cloth read from an OBJ: its own plans (the cloth's group has its springs' lists)
    items += [("mesh cloth: bundled scene skirt", step(load_scene("skirt"))),
              ("mesh cloth: bundled scene drum", step(load_scene("drum"))),
              ("mesh cloth: self-collision contact, colliders", step(_tiny_mesh_scene("contact", True)))]
    items += [(f"mesh cloth: self-collision {mode}", step(_tiny_mesh_scene(mode))) for mode in ("contact", "spec",
                                                                                                "grid", "off")]
    items += [(f"mesh cloth: integrator {name}/{damping}", step(_tiny_mesh_scene("off", False, name, damping)))
              for name, damping in (("verlet", "rate"), ("symplectic_euler", "spec"), ("implicit_euler", "spec"),
                                    ("xpbd", "spec"))]
    items.append(("mesh cloth: wind and moving pins", step(_tiny_mesh_scene("spec", wind=True))))
    items += [(f"frame kernel: self-collision {mode}, {'colliders' if col else 'no colliders'}",
               step(_tiny_scene(mode, col))) for mode in ("spec", "off", "grid") for col in (True, False)]
    items += [("frame kernel: self-collision spec, wind", step(_tiny_scene("spec", False, wind=True))),
              ("frame kernel: self-collision spec, moving pins", step(_tiny_scene("spec", False, pin_motion=True)))]
    items += [(f"integrator {name}", step(_tiny_scene("spec", True, name))) for name in ("implicit_euler", "xpbd")]
    items.append(("verlet, rate damping", step(_tiny_scene("spec", True, "verlet", "rate"))))
    items.append(("guard, rest detector, render mesh, overlap and id pass", side_kernels))
    return items


def side_kernels() -> None:
    """Compile (or load) the small kernels every command meets after its first frame: the blow-up
    guard, the rest detector and the renderer's mesh kernel, overlap test and id pass, with the
    argument types they get."""
    from ..jit.compile import warm_side_kernels
    from ..render import mesh, overlap, seen  # noqa: F401 - mesh, guard and rest register their warm-ups on import
    from ..sim import guard, rest  # noqa: F401

    overlap.register_warm()  # the renderer registers these for the scenes and looks that use them only
    seen.register_warm()
    mesh.register_surface_warm()  # a mesh cloth's

    warm_side_kernels()


def record_command(log_path: str, argv: Sequence[str]) -> int:
    """Run the CLI with ``argv`` and write what it compiled to ``log_path`` as JSON (used by
    ``clothsim bench compile`` in a fresh process)."""
    from . import main

    from numba.core import event

    from ..jit.watch import CompileRecorder

    recorder = CompileRecorder()
    event.register("numba:compile", recorder)
    began = time.perf_counter()
    code = main(list(argv))
    wall = time.perf_counter() - began
    with open(log_path, "w", encoding="utf-8") as fh:
        json.dump({"code": code, "seconds": wall, "compiled": [r.__dict__ for r in recorder.records]}, fh)
    return code


def add_parser(sub: Any) -> None:
    """Register ``clothsim compile``."""
    p = sub.add_parser(
        "compile", help="compile every kernel ahead of time (container images, CI caches, cluster workers)",
        description="Compile every Numba kernel for this CPU now (each frame-kernel plan, the other "
                    "integrators, the renderer's mesh kernel) and cache them, so that no later command waits "
                    "for a compile. Prints what it compiled and how long it took; with a warm cache it only "
                    "loads them.")
    p.add_argument("--jobs", type=int, default=None, metavar="N",
                   help="processes compiling at once (default: one per core this process may use)")
    p.set_defaults(func=run_compile)


def run_compile(args: Any) -> int:
    """Body of ``clothsim compile``."""
    from ..jit.compile import available_cores
    from ..validate import check, integer

    jobs = available_cores() if args.jobs is None else check(integer(ge=1), args.jobs, "--jobs")
    total = 0.0
    count = 0
    began = time.perf_counter()
    print(f"{'work item':<46}{'seconds':>9}  compiled")
    for label, seconds, compiled in each_item(jobs):
        total += seconds
        mine = [c for c in compiled if c.depth == 0]
        count += len(compiled)
        names = ", ".join(sorted({c.kernel.rsplit('.', 1)[-1] for c in mine})) or "(cached)"
        print(f"{label:<46}{seconds:>9.1f}  {names}", flush=True)
    wall = time.perf_counter() - began
    print(f"{'total':<46}{total:>9.1f}  {count} compiles, {wall:.1f} s in {jobs} process{'es' if jobs > 1 else ''}")
    return 0


def each_item(jobs: int = 1):  # noqa: ANN201
    """Run :func:`work_items`, yielding (label, seconds, compiles made) after each, in order. With
    ``jobs`` > 1 the items run in that many fresh processes at once (Numba's cache is safe for
    processes that compile at the same time: see :func:`clothsim.jit.internals.install_shared_cache`),
    each item's compiles reported by the process that made them."""
    if jobs <= 1:
        yield from _items_here(None)
        return
    import multiprocessing
    from concurrent.futures import ProcessPoolExecutor

    count = len(work_items())
    with ProcessPoolExecutor(max_workers=min(jobs, count), mp_context=multiprocessing.get_context("spawn")) as pool:
        # one item a task, handed out as processes free up: the items' compile times differ fivefold
        yield from pool.map(_item_elsewhere, range(count))


def _item_elsewhere(index: int) -> tuple[str, float, list[Compiled]]:
    return next(_items_here([index]))


def _items_here(indices: list[int] | None):  # noqa: ANN202
    """Run the work items at ``indices`` (every one for None) in this process."""
    from numba.core import event

    from ..jit.watch import CompileRecorder

    items = work_items()
    if indices is None:
        indices = range(len(items))
    recorder = CompileRecorder()
    event.register("numba:compile", recorder)
    try:
        for index in indices:
            label, work = items[index]
            before = len(recorder.records)
            began = time.perf_counter()
            work()
            yield label, time.perf_counter() - began, recorder.records[before:]
    finally:
        event.unregister("numba:compile", recorder)
