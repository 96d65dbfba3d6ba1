"""``clothsim bench sweep``: runs per minute of a plain loop over the API and of ``clothsim.sweep``
with 1 and 2 worker processes, measured in the same run on the same runs.

Every variant does the same work per run: build the run's scene, simulate F frames, keep every
frame's positions as float32 and save them to an ``.npz``. The sweeps' times include starting
their worker processes and sending the results back; the plain loop runs in this process with
one Numba thread, like a worker, so the difference is the sweep's overhead (a last row shows the
plain loop with every Numba thread, for comparison).
"""

from __future__ import annotations

import argparse
import io
import tempfile
import time
from pathlib import Path

import numpy as np

from ..validate import check, integer


def add_parser(bench_sub: argparse._SubParsersAction) -> None:
    """Register ``clothsim bench sweep``."""
    p = bench_sub.add_parser("sweep", help="runs per minute: a plain API loop vs clothsim sweep with 1 and 2 workers",
                             description="Runs per minute of the same runs (--runs values of cloth.ks) as a plain "
                                         "loop over the API in this process, and as a sweep dataset with 1 and "
                                         "with 2 local worker processes (start-up and transfers included).")
    p.add_argument("scene", nargs="?", default="selfCollision", help="scene (default: selfCollision, 50x50)")
    p.add_argument("--runs", type=int, default=8, metavar="N", help="runs per variant (default 8)")
    p.add_argument("--frames", type=int, default=300, metavar="F",
                   help="frames per run (default 300: a course run's fall to rest)")
    p.add_argument("--workers", default="1,2", metavar="LIST", help="worker counts to time (default 1,2)")
    p.set_defaults(func=run)


def _plain_loop(scene_path: str, values: list[float], frames: int, folder: Path) -> float:
    import json

    from ..scene import resolve_scene_path
    from ..sim import Simulation
    from ..sweeps.params import build_scene

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
        (folder / f"plain_{i:05d}.npz").write_bytes(buffer.getbuffer())
    return time.perf_counter() - start


def run(args: argparse.Namespace) -> int:
    """Print the table."""
    import numba

    from ..sweeps.api import sweep

    runs = check(integer(ge=1), args.runs, "--runs")
    frames = check(integer(ge=1), args.frames, "--frames")
    try:
        counts = [int(x) for x in args.workers.split(",")]
    except ValueError:
        counts = []
    if not counts or min(counts) < 1:
        from ..errors import ClothsimError

        raise ClothsimError(f"--workers: expected a comma-separated list of counts >= 1, got {args.workers!r}")
    values = [float(v) for v in np.linspace(4000.0, 6000.0, runs)]
    rows: list[tuple[str, float]] = []
    all_threads = numba.get_num_threads()
    with tempfile.TemporaryDirectory(prefix="clothsim-bench-sweep.") as tmp:
        folder = Path(tmp)
        _plain_loop(args.scene, values[:1], 2, folder)  # load the kernels before timing
        numba.set_num_threads(1)
        rows.append(("plain API loop, 1 Numba thread", _plain_loop(args.scene, values, frames, folder)))
        for n in counts:
            t0 = time.perf_counter()
            records = sweep(args.scene, {"cloth.ks": values}, folder / f"sweep_{n}", frames=frames, workers=n)
            seconds = time.perf_counter() - t0
            failed = [r for r in records if r["status"] != "done"]
            if failed:
                print(f"warning: {len(failed)} runs failed: {failed[0]['error']}")
            rows.append((f"sweep --workers {n}", seconds))
        numba.set_num_threads(all_threads)
        rows.append((f"plain API loop, {all_threads} Numba threads", _plain_loop(args.scene, values, frames, folder)))
    base = rows[0][1]
    print(f"bench sweep: {args.scene}, {runs} runs x {frames} frames (positions of every frame saved)")
    print(f"{'variant':<34}{'seconds':>9}{'runs/min':>10}{'vs plain':>10}")
    for name, seconds in rows:
        print(f"{name:<34}{seconds:>9.2f}{60.0 * runs / seconds:>10.1f}{base / seconds:>9.2f}x")
    return 0
