"""The ``simulate`` subcommand: run a scene and save the final state as ``.npz``."""

from __future__ import annotations

import argparse
import sys
import time
from pathlib import Path

import numpy as np

from .atomic import atomic_output, check_destination, check_name
from .errors import ClothsimError
from .scene import SIMULATION, Scene, check_memory, load_scene
from .validate import At, check, integer


def add_command(sub: argparse._SubParsersAction, name: str, summary: str, description: str,
                scene: str | None = "pinned2") -> argparse.ArgumentParser:
    """Register command ``name`` on ``sub``, with its one-line ``summary`` (the command list's),
    its ``description`` (its own ``--help``'s) and its SCENE argument: optional with ``scene`` as
    the default, or required when ``scene`` is None. Every command that runs a scene starts so."""
    p = sub.add_parser(name, help=summary, description=description)
    if scene is None:
        p.add_argument("scene", help="scene file or bundled scene name")
    else:
        p.add_argument("scene", nargs="?", default=scene, help=f"scene file or bundled scene name (default: {scene})")
    return p


def add_output(p: argparse.ArgumentParser, what: str) -> None:
    """The required ``-o/--output OUT`` of a command that writes ``what``."""
    p.add_argument("-o", "--output", required=True, metavar="OUT", help=f"output: {what}")


def add_scene_overrides(p: argparse.ArgumentParser) -> None:
    """Options shared by simulate and render that override the scene's ``simulation`` object."""
    p.add_argument("--steps", type=int, metavar="S", help="simulation_steps: substeps per frame (default: scene, else 30)")
    p.add_argument("--fps", type=float, metavar="F", help="frames_per_sec (default: scene, else 90)")
    p.add_argument("--seed", type=int, metavar="N", help="seed of the vertical cloth's jitter (default: scene, else 0)")
    p.add_argument("--self-collision", choices=("spec", "grid", "off", "contact"),
                   help="self-collision: the spec's same-cell hash, a 27-cell grid search, off, or contact (no crossings)")
    p.add_argument("--integrator", choices=("verlet", "symplectic_euler", "implicit_euler", "xpbd"),
                   help="time integrator (default: scene, else verlet as in the spec)")
    p.add_argument("--auto-substeps", action="store_true",
                   help="pick the smallest stable number of substeps per frame and say which")


# Flags that set a field of the scene's ``simulation`` object, checked by that field's rule.
_SIMULATION_FLAGS = (("steps", "--steps", "simulation_steps"), ("fps", "--fps", "frames_per_sec"),
                     ("seed", "--seed", "seed"))


def apply_overrides(scene: Scene, args: argparse.Namespace) -> Scene:
    """Apply the shared command-line overrides to a loaded scene (errors name the flag)."""
    changes: dict[str, object] = {}
    for attr, flag, key in _SIMULATION_FLAGS:
        value = getattr(args, attr)
        if value is not None:
            changes[key] = SIMULATION.check_one(key, value, At(None, flag))
    if args.self_collision is not None:
        changes["self_collision"] = args.self_collision
    if args.integrator is not None:
        changes["integrator"] = args.integrator
    if changes:
        scene = scene.with_simulation(**changes)
        check_memory(scene)  # another integrator keeps more per point
    return _stability_check(scene, args.auto_substeps)


def _stability_check(scene: Scene, auto: bool) -> Scene:
    from .sim import guard

    if auto:
        steps = guard.estimate_stable_substeps(scene)
        if steps is not None:
            print(f"clothsim: --auto-substeps: using {steps} substeps per frame", file=sys.stderr)
            return scene.with_simulation(simulation_steps=steps)
        return scene
    message = guard.stability_warning(scene)
    if message:
        print(f"clothsim: warning: {message}", file=sys.stderr)
    return scene


def progress(total: int, desc: str, show: bool = True):  # noqa: ANN201
    """A tqdm progress bar on stderr, shown only when ``show``, on a terminal and for runs worth
    watching (otherwise its updates do nothing)."""
    from tqdm import tqdm

    return tqdm(total=total, desc=desc, unit="frame", disable=not show or not sys.stderr.isatty() or total < 30,
                leave=False, file=sys.stderr)


def add_simulate_parser(sub: argparse._SubParsersAction) -> None:
    """Register ``clothsim simulate``."""
    p = add_command(sub, "simulate", "simulate a scene and save the final state (.npz)",
                    "Simulate a scene for a number of frames (each frame is simulation_steps substeps of "
                    "1/(frames_per_sec*simulation_steps) seconds, as in the course's clothsim) and save "
                    "positions, last_positions and pinned points to a NumPy .npz file.")
    p.add_argument("--frames", type=int, default=90, metavar="N", help="frames to simulate (default: 90 = 1 s)")
    p.add_argument("--out", "-o", default="state.npz", metavar="FILE", help="output .npz file (default: state.npz)")
    p.add_argument("--until-rest", action="store_true",
                   help="stop early once the cloth is at rest (simulation.rest_tolerance / rest_frames)")
    p.add_argument("--profile", action="store_true", help="print a table of the passes that ran and their time")
    add_scene_overrides(p)
    p.set_defaults(func=run_simulate)


def run_simulate(args: argparse.Namespace) -> int:
    """Body of ``clothsim simulate``."""
    from .sim import Simulation
    from .sim.rest import RestDetector

    check(integer(ge=0), args.frames, "--frames")
    check_name(args.out)
    out = Path(args.out)
    if out.suffix != ".npz":
        raise ClothsimError(f"--out: {out}: expected a .npz file name")
    check_destination(out, label=args.out)  # before the simulation, not after it
    scene = apply_overrides(load_scene(args.scene), args)
    sim = Simulation(scene)
    rest = RestDetector(scene.simulation.rest_tolerance, scene.simulation.rest_frames) if args.until_rest else None
    if rest is not None:
        rest.update(sim._pos)
    profiler = None
    if args.profile:
        from .sim.profile import Profiler

        profiler = Profiler(sim)
    rested_at = None
    start = time.perf_counter()
    with progress(args.frames, "simulate") as bar:
        for _ in range(args.frames):
            if profiler is not None:
                profiler.frame()
            else:
                sim.step()
            bar.update()
            if rest is not None and rest.update(sim._pos) and sim.time >= sim.colliders_still_after:
                rested_at = sim.frame
                break
    elapsed = time.perf_counter() - start
    # a grid's triangles follow from its size; a mesh cloth's are written out (check-intersections reads either)
    shape = ({"faces": sim.surface.triangles} if scene.cloth.is_mesh
             else {"num_width_points": np.int64(sim.nw), "num_height_points": np.int64(sim.nh)})
    with atomic_output(out, label=args.out) as tmp:
        with open(tmp, "wb") as fh:
            np.savez(
                fh,
                positions=np.ascontiguousarray(sim.positions),
                last_positions=np.ascontiguousarray(sim.last_positions),
                pinned=sim.pinned.copy(),
                frames=np.int64(sim.frame),
                simulation_steps=np.int64(scene.simulation.simulation_steps),
                frames_per_sec=np.float64(scene.simulation.frames_per_sec),
                seed=np.int64(scene.simulation.seed),
                **shape,
            )
    if args.until_rest:
        if rested_at is not None:
            print(f"at rest after frame {rested_at} (no point moved more than "
                  f"{scene.simulation.rest_tolerance:g} m per frame for {scene.simulation.rest_frames} frames)")
        else:
            print(f"not at rest after {sim.frame} frames (last frame moved {rest.last_displacement:.3g} m)")
    if profiler is not None:
        print(profiler.report())
    print(f"simulated {sim.frame} frames ({sim.frame / scene.simulation.frames_per_sec:.3f} s of cloth) "
          f"in {elapsed:.2f} s; wrote {out}", file=sys.stderr)
    crossings = None
    for count, what in ((sim.unsafe_substeps, "a pin moved farther than the bound allows"),
                        (sim.squeezed_substeps, "a moving collider pressed the cloth thinner than the bound allows")):
        if count:
            crossings = sim.crossings() if crossings is None else crossings
            print(f"clothsim: warning: self_collision \"contact\": in {count} substep{'s' if count != 1 else ''} "
                  f"{what}; the cloth may cross itself there ({crossings} crossings at the end)", file=sys.stderr)
    return 0
