"""The ``export`` subcommand: simulate a scene and write a USD stage or an OBJ sequence."""

from __future__ import annotations

import argparse
import sys
import time

from ..commands import add_command, add_output, add_scene_overrides, apply_overrides
from ..validate import check, integer


def add_parser(sub: argparse._SubParsersAction) -> None:
    """Register ``clothsim export``."""
    p = add_command(sub, "export",
                    "simulate a scene and export the animated cloth (.usd/.usda/.usdc, or a folder of OBJs)",
                    "Simulate SCENE for --frames frames and export frame 0, every --every-th frame and the "
                    "last one, for Blender, Houdini and other tools: OUT ending in .usd, .usda or .usdc is "
                    "one USD stage (needs the 'usd' extra: pip install 'clothsim[usd]'); OUT with no suffix "
                    "or a trailing / is a folder of cloth_NNNNN.obj files plus colliders.obj. --out-fps "
                    "resamples the clip to another frame rate (e.g. 24 for Blender's default scene).")
    add_output(p, ".usd, .usda, .usdc, or a folder (no suffix or trailing /) for an OBJ sequence")
    p.add_argument("--frames", type=int, default=90, metavar="N", help="frames to simulate (default: 90 = 1 s)")
    p.add_argument("--every", type=int, default=1, metavar="K", help="export every K-th frame (default: 1)")
    p.add_argument("--out-fps", type=float, metavar="R",
                   help="frames a second of the exported clip: positions interpolated linearly between "
                        "simulated frames, --every counting frames at this rate (default: the simulation's "
                        "frames_per_sec, no resampling). Not --fps, which sets the simulation's own rate")
    add_scene_overrides(p)
    p.set_defaults(func=run_export)


def run_export(args: argparse.Namespace) -> int:
    """Body of ``clothsim export``."""
    from ..scene import load_scene
    from ..sim import Simulation
    from .api import _write, check_export_output
    from .timing import check_out_fps

    frames = check(integer(ge=0), args.frames, "--frames")
    every = check(integer(ge=1), args.every, "--every")
    out_fps = check_out_fps(args.out_fps, "--out-fps")
    fmt = check_export_output(args.output)  # before the simulation, not after it
    scene = apply_overrides(load_scene(args.scene), args)
    start = time.perf_counter()
    numbers = _write(Simulation(scene), fmt, args.output, frames, every, True, out_fps, "--out-fps")
    elapsed = time.perf_counter() - start
    what = "USD stage" if fmt == "usd" else "OBJ sequence"
    rate = "" if out_fps is None else f" at {out_fps:g} fps"
    print(f"exported {len(numbers)} frames{rate} ({numbers[0]}..{numbers[-1]}) of {frames} simulated "
          f"in {elapsed:.2f} s; wrote {what} {args.output}", file=sys.stderr)
    return 0
