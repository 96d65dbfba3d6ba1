"""``clothsim bench sweep``: runs per minute of a plain loop over the API and of ``clothsim sweep``
with 1 and 2 worker processes, measured in the same run on the same runs.

Every variant does the same work per run: build the run's scene, simulate F frames, keep every
frame's positions as float32 and save them to an ``.npz``. Each is timed as a user runs it, from
a fresh process to its exit: the plain loop is a script (``python -c``) that steps each run on one
Numba thread, like a worker; the sweeps are the ``clothsim sweep`` command. So every variant pays
its interpreter start and its kernel loading once, and the sweeps' extra time is what the sweep
adds: its parent process, starting the workers and sending the results back. ``--repeat`` runs the
variants in turns and prints medians (the machines are noisy). Two rows for reference follow,
timed in this process with the kernels already loaded: one Numba thread, and every thread.
"""

from __future__ import annotations

import argparse
import io
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

from ..errors import ClothsimError
from ..validate import check, integer


def add_parser(bench_sub: argparse._SubParsersAction) -> None:
    """Register ``clothsim bench sweep``."""
    p = bench_sub.add_parser("sweep", help="runs per minute: a plain API loop vs clothsim sweep with 1 and 2 workers",
                             description="Runs per minute of the same runs (--runs values of cloth.ks) as a plain "
                                         "loop over the API and as a sweep dataset with 1 and with 2 local worker "
                                         "processes, each timed from a fresh process to its exit.")
    p.add_argument("scene", nargs="?", default="selfCollision", help="scene (default: selfCollision, 50x50)")
    p.add_argument("--runs", type=int, default=16, metavar="N",
                   help="runs per variant (default 16, a 4 x 4 grid; each variant pays its start-up, "
                        "about 1-1.5 s, once, so fewer runs weigh it more)")
    p.add_argument("--frames", type=int, default=300, metavar="F",
                   help="frames per run (default 300: a course run's fall to rest)")
    p.add_argument("--workers", default="1,2", metavar="LIST", help="worker counts to time (default 1,2)")
    p.add_argument("--repeat", type=int, default=1, metavar="R",
                   help="run the variants R times in turns and print medians (default 1)")
    p.set_defaults(func=run)


def plain_loop(scene_path: str, values: list[float], frames: int, folder: str, threads: int | None = 1) -> float:
    """The loop a user writes over the API: one run per ks value, every frame's positions saved.
    Returns its seconds (kernel loading included when this process has not run them yet)."""
    import json

    import numba

    from ..scene import resolve_scene_path
    from ..sim import Simulation
    from ..sweeps.params import build_scene

    if threads is not None:
        numba.set_num_threads(threads)
    path = str(resolve_scene_path(scene_path))
    base = json.loads(Path(path).read_text(encoding="utf-8"))
    start = time.perf_counter()
    for i, ks in enumerate(values):
        sim = Simulation(build_scene(base, {"cloth.ks": ks}, path))
        out = np.empty((frames + 1, sim.nw * sim.nh, 3), dtype=np.float32)
        out[0] = sim.positions
        for f in range(1, frames + 1):
            sim.step(1)
            out[f] = sim.positions
        buffer = io.BytesIO()
        np.savez(buffer, positions=out, pinned=sim.pinned)
        (Path(folder) / f"plain_{i:05d}.npz").write_bytes(buffer.getbuffer())
    return time.perf_counter() - start


def _timed(command: list[str]) -> float:
    start = time.perf_counter()
    done = subprocess.run(command, capture_output=True, text=True)
    seconds = time.perf_counter() - start
    if done.returncode != 0:
        last = (done.stderr.strip().splitlines() or ["(no message)"])[-1]
        raise ClothsimError(f"bench sweep: {' '.join(command[2:5])} ... exited with {done.returncode}: {last}")
    return seconds


def _plain_script(scene: str, values: list[float], frames: int, folder: Path) -> list[str]:
    code = (f"from clothsim.bench.sweep import plain_loop; "
            f"plain_loop({scene!r}, {values!r}, {frames}, {str(folder)!r})")
    return [sys.executable, "-c", code]


def _sweep_command(scene: str, values: list[float], frames: int, workers: int, out: Path) -> list[str]:
    return [sys.executable, "-m", "clothsim", "sweep", scene, "--set", "cloth.ks=" + ",".join(map(repr, values)),
            "--frames", str(frames), "--workers", str(workers), "-o", str(out)]


def run(args: argparse.Namespace) -> int:
    """Print the table."""
    import numba

    runs = check(integer(ge=1), args.runs, "--runs")
    frames = check(integer(ge=1), args.frames, "--frames")
    repeat = check(integer(ge=1), args.repeat, "--repeat")
    try:
        counts = [int(x) for x in args.workers.split(",")]
    except ValueError:
        counts = []
    if not counts or min(counts) < 1:
        raise ClothsimError(f"--workers: expected a comma-separated list of counts >= 1, got {args.workers!r}")
    values = [float(v) for v in np.linspace(4000.0, 6000.0, runs)]
    names = ["plain API loop (script), 1 Numba thread"] + [f"clothsim sweep --workers {n}" for n in counts]
    times: dict[str, list[float]] = {name: [] for name in names}
    all_threads = numba.get_num_threads()
    with tempfile.TemporaryDirectory(prefix="clothsim-bench-sweep.") as tmp:
        folder = Path(tmp)
        # Compile (or load) the kernels once, so no variant pays a cold compile.
        subprocess.run(_plain_script(args.scene, values[:1], 2, folder), check=True, capture_output=True)
        for r in range(repeat):
            times[names[0]].append(_timed(_plain_script(args.scene, values, frames, folder)))
            for n, name in zip(counts, names[1:]):
                times[name].append(_timed(_sweep_command(args.scene, values, frames, n, folder / f"sweep_{n}_{r}")))
        loaded = [f"plain loop in this process (kernels loaded), {t} Numba thread{'s' if t > 1 else ''}"
                  for t in (1, all_threads)]
        plain_loop(args.scene, values[:1], 2, tmp, threads=1)
        for name, t in zip(loaded, (1, all_threads)):
            times[name] = [plain_loop(args.scene, values, frames, tmp, threads=t) for _ in range(repeat)]
        numba.set_num_threads(all_threads)
    medians = {name: statistics.median(ts) for name, ts in times.items()}
    base = medians[names[0]]
    one = medians.get("clothsim sweep --workers 1")
    print(f"bench sweep: {args.scene}, {runs} runs x {frames} frames (positions of every frame saved), "
          f"median of {repeat}")
    print(f"{'variant':<58}{'seconds':>9}{'runs/min':>10}{'vs plain':>10}{'vs 1 worker':>13}")
    for name, seconds in medians.items():
        if name == loaded[0]:
            print("for reference, timed inside this process:")
        vs_one = f"{one / seconds:>12.2f}x" if one is not None and name.startswith("clothsim sweep") else ""
        print(f"{name:<58}{seconds:>9.2f}{60.0 * runs / seconds:>10.1f}{base / seconds:>9.2f}x{vs_one}")
    return 0
