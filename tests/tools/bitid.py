"""Bit-identity table: every bundled scene x every integrator x every self-collision mode.

Runs each combination for ``--frames`` frames through the public API and prints one line per
combination with a SHA-256 over the final positions, last positions and (for the integrators that
keep one) velocities. Two checkouts on the same machine that print the same table simulate the
same thing, bit for bit. Usage (from a checkout, with its own environment):

    python tests/tools/bitid.py > table.txt
    python tests/tools/bitid.py --compare table-a.txt table-b.txt   # rows equal / differing, per scene
    python tests/tools/bitid.py --scenes flag heap --modes contact     # a subset

A run that blows up prints a hash of its error message instead, so a change in where it blows up
shows too.
"""

from __future__ import annotations

import argparse
import hashlib
import sys
import time
from pathlib import Path

import numpy as np

from clothsim.errors import SimulationBlowUp
from clothsim.scene import INTEGRATORS, SELF_COLLISION_MODES, load_scene
from clothsim.sim import Simulation

SCENES = Path(__file__).resolve().parents[2] / "scenes"
#: Frames per scene: enough to reach contact. The horizontal cloths fall from y = 1 at a damped
#: speed of at most about 1.8 m/s (the spec's 0.2 % per substep), so they meet the sphere and the
#: floor after more than a second and the capsule, torus and table after well over half of one;
#: the curtain's sphere arrives after 0.6 s; selfCollision folds on the floor.
FRAMES = {"sphere": 150, "plane": 150, "capsule": 120, "mesh": 120, "tablecloth": 120, "curtain": 90,
          "selfCollision": 90}
DEFAULT_FRAMES = 40
#: (integrator, damping mode): the spec path and every other integrator, Verlet in both modes.
INTEGRATIONS = [("verlet", "spec"), ("verlet", "rate")] + [(i, "spec") for i in INTEGRATORS if i != "verlet"]


def digest(sim: Simulation) -> str:
    """SHA-256 of the state a run leaves: positions, last positions, velocities if kept."""
    h = hashlib.sha256()
    for a in (sim.positions, sim.last_positions):
        h.update(np.ascontiguousarray(a, dtype=np.float64).tobytes())
    state = sim.integrator_state
    if state is not None and getattr(state, "vel", None) is not None:
        h.update(np.ascontiguousarray(state.vel, dtype=np.float64).tobytes())
    return h.hexdigest()


def run(name: str, integrator: str, damping: str, mode: str, frames: int) -> str:
    scene = load_scene(SCENES / f"{name}.json").with_simulation(integrator=integrator, damping_mode=damping,
                                                                 self_collision=mode)
    sim = Simulation(scene)
    try:
        sim.step(frames)
    except SimulationBlowUp as exc:
        return "blowup:" + hashlib.sha256(str(exc).encode()).hexdigest()[:56] + f" frame={sim.frame}"
    return digest(sim)


def read_table(path: str) -> dict[tuple[str, str, str], str]:
    """A printed table as {(scene, integrator/damping, mode): hash}."""
    rows = {}
    for line in Path(path).read_text().splitlines():
        scene, integration, rest = line[:14].strip(), line[14:36].strip(), line[36:]
        mode = next((m for m in SELF_COLLISION_MODES if rest.startswith(m)), None)
        if scene and integration and mode:
            rows[(scene, integration, mode)] = rest[len(mode):].strip()
    return rows


def compare(a_path: str, b_path: str) -> int:
    """Print, per scene, how many rows both tables have and how many are equal; then each row
    that differs."""
    a, b = read_table(a_path), read_table(b_path)
    common = [k for k in b if k in a]
    scenes = sorted({k[0] for k in common})
    print(f"{'scene':<14}{'rows':>5}{'equal':>7}")
    for scene in scenes:
        rows = [k for k in common if k[0] == scene]
        print(f"{scene:<14}{len(rows):>5}{sum(a[k] == b[k] for k in rows):>7}")
    print(f"{'all':<14}{len(common):>5}{sum(a[k] == b[k] for k in common):>7}")
    for k in common:
        if a[k] != b[k]:
            print("differs:", *k)
    return 0


def main(argv: list[str] | None = None) -> int:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--compare", nargs=2, metavar=("A", "B"), help="compare two printed tables instead of running")
    p.add_argument("--frames", type=int, default=None,
                   help=f"frames per combination (default: {DEFAULT_FRAMES}, more for the scenes in FRAMES)")
    p.add_argument("--scenes", nargs="*", help="bundled scene names (default: every scenes/*.json)")
    p.add_argument("--integrators", nargs="*", help="integrator/damping pairs, e.g. implicit_euler/spec (default: all)")
    p.add_argument("--modes", nargs="*", help="self-collision modes, e.g. contact (default: all)")
    args = p.parse_args(argv)
    if args.compare:
        return compare(*args.compare)
    names = args.scenes or sorted(f.stem for f in SCENES.glob("*.json"))
    began = time.perf_counter()
    for name in names:
        for integrator, damping in INTEGRATIONS:
            if args.integrators and f"{integrator}/{damping}" not in args.integrators:
                continue
            for mode in SELF_COLLISION_MODES:
                if args.modes and mode not in args.modes:
                    continue
                t = time.perf_counter()
                h = run(name, integrator, damping, mode, args.frames or FRAMES.get(name, DEFAULT_FRAMES))
                print(f"{name:<14}{integrator + '/' + damping:<22}{mode:<6}{h}", flush=True)
                print(f"  {time.perf_counter() - t:.1f} s", file=sys.stderr, flush=True)
    print(f"total {time.perf_counter() - began:.0f} s", file=sys.stderr)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
