"""``clothsim bench passes``: where a frame's time goes, pass by pass, measured inside the frame
kernel. Each scene is simulated past its warm-up, then frames are timed whole, with the thread
team (:class:`clothsim.sim.profile.FrameLaps`): the microseconds a substep of each pass, from
the barrier before it to the one after it (its slowest member), and the members' microseconds
spent waiting at the one after it. ``clothsim simulate --profile`` runs each pass in a call of
its own instead, which adds a call's cost to every pass."""

from __future__ import annotations

import argparse

from ..scene import SELF_COLLISION_MODES, load_scene
from ..validate import check, integer

#: Scenes timed by default: the spec's two timed scenes.
SCENES = ("sphere", "selfCollision")


def add_parser(bench_sub: argparse._SubParsersAction) -> None:
    """Register ``clothsim bench passes``."""
    p = bench_sub.add_parser("passes", help="us a substep of each pass of the frame, timed inside it",
                             description=__doc__)
    p.add_argument("scenes", nargs="*", default=list(SCENES), metavar="SCENE",
                   help=f"scene files or bundled names (default: {' '.join(SCENES)})")
    p.add_argument("--frames", type=int, default=30, help="frames timed (default 30)")
    p.add_argument("--warmup", type=int, default=60, help="frames simulated before timing (default 60)")
    p.add_argument("--self-collision", choices=SELF_COLLISION_MODES, default=None,
                   help="self-collision mode for every scene (default: each scene's own)")
    p.set_defaults(func=run)


def run(args: argparse.Namespace) -> int:
    """Print a table per scene."""
    from ..sim import Simulation  # only when it runs: building the parser loads no Numba
    from ..sim.profile import FrameLaps

    check(integer(ge=1), args.frames, "--frames")
    check(integer(ge=0), args.warmup, "--warmup")
    scenes = [load_scene(name) for name in args.scenes]
    for name, scene in zip(args.scenes, scenes):
        if args.self_collision is not None:
            scene = scene.with_simulation(self_collision=args.self_collision)
        sim = Simulation(scene)
        if not sim.uses_spec_path:
            print(f"{name}: integrator {scene.simulation.integrator!r} with damping_mode "
                  f"{scene.simulation.damping_mode!r} does not run the frame kernel; nothing to time", flush=True)
            continue
        sim.step(args.warmup)
        laps = FrameLaps(sim)
        for _ in range(args.frames):
            laps.frame()
        cloth = scene.cloth
        print(f"{name} (self-collision {scene.simulation.self_collision}, {cloth.num_width_points} x "
              f"{cloth.num_height_points}), frames {args.warmup} to {args.warmup + args.frames}:")
        print(laps.report(), flush=True)
        print()
    print("us a substep of each pass, from the barrier before it to the one after it; waiting = the thread "
          "team's members' us a substep spent at the one after it; share = of the substep")
    return 0
