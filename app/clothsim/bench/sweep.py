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

from ..commands import add_command
from ..errors import ClothsimError
from ..validate import check, integer


def add_parser(bench_sub: argparse._SubParsersAction) -> None:
    """Register ``clothsim bench sweep``."""
    p = add_command(bench_sub, "sweep", "runs per minute: a plain API loop vs clothsim sweep with 1 and 2 workers",
                    "Runs per minute of the same runs (--runs values of cloth.ks) as a plain loop over the API "
                    "and as a sweep dataset with 1 and with 2 local worker processes, each timed from a fresh "
                    "process to its exit. The default scene is the 50 x 50 selfCollision.", scene="selfCollision")
    p.add_argument("--runs", type=int, default=16, metavar="N",
                   help="runs per variant (default 16, a 4 x 4 grid; each variant pays its start-up, "
                        "about 1-1.5 s, once, so fewer runs weigh it more)")
    p.add_argument("--frames", type=int, default=300, metavar="F",
                   help="frames per run (default 300: a course run's fall to rest)")
    p.add_argument("--workers", default="1,2", metavar="LIST", help="worker counts to time (default 1,2)")
    p.add_argument("--repeat", type=int, default=1, metavar="R",
                   help="run the variants R times in turns and print medians (default 1)")
    p.add_argument("--views", type=int, default=0, metavar="V",
                   help="the dataset case: every run also draws V views x all channels (rgb, depth, normal, mask, "
                        "flow) of every --every-th frame at --size; timed with the parent writing and with "
                        "--write-in-workers, with the renderer's share of a run")
    p.add_argument("--size", default="256x256", metavar="WxH", help="with --views: image size (default 256x256)")
    p.add_argument("--every", type=int, default=10, metavar="K", help="with --views: sample every K frames (default 10)")
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


def _views_command(scene: str, values: list[float], frames: int, workers: int, out: Path, views: int, size: str,
                   every: int, direct: bool) -> list[str]:
    return [*_sweep_command(scene, values, frames, workers, out), "--views", str(views), "--size", size,
            "--every", str(every), *(["--write-in-workers"] if direct else [])]


def _render_share(folder: Path) -> tuple[float, float]:
    """Seconds of drawing and of whole runs, summed over a dataset's manifest."""
    import json

    drawn = total = 0.0
    for line in (folder / "manifest.jsonl").read_text(encoding="utf-8").splitlines():
        record = json.loads(line)
        drawn += float(record.get("render_seconds") or 0.0)
        total += float(record.get("seconds") or 0.0)
    return drawn, total


def run_views(args: argparse.Namespace, runs: int, frames: int, repeat: int, counts: list[int]) -> int:
    """The dataset case: runs per minute with views and every channel, 1 vs 2 workers, and
    where a run's time goes."""
    views = check(integer(ge=1, le=64), args.views, "--views")
    every = check(integer(ge=1), args.every, "--every")
    values = [float(v) for v in np.linspace(4000.0, 6000.0, runs)]
    variants = [(n, direct) for direct in (False, True) for n in counts]
    names = {(n, d): f"sweep --workers {n}{' --write-in-workers' if d else ''}" for n, d in variants}
    times: dict[tuple[int, bool], list[float]] = {v: [] for v in variants}
    shares: dict[tuple[int, bool], list[tuple[float, float]]] = {v: [] for v in variants}
    with tempfile.TemporaryDirectory(prefix="clothsim-bench-sweep.") as tmp:
        folder = Path(tmp)
        # Compile (or load) the kernels and start the renderer once, so no variant pays a cold compile.
        _timed(_views_command(args.scene, values[:1], 2, 1, folder / "warm", views, args.size, every, False))
        for r in range(repeat):
            for n, direct in variants:
                out = folder / f"views_{n}_{int(direct)}_{r}"
                times[(n, direct)].append(_timed(_views_command(args.scene, values, frames, n, out, views, args.size,
                                                                every, direct)))
                shares[(n, direct)].append(_render_share(out))
    samples = len(range(0, frames + 1, every)) + (0 if frames % every == 0 else 1)
    print(f"bench sweep: {args.scene}, {runs} runs x {frames} frames, {views} views x rgb,depth,normal,mask,flow "
          f"at {args.size} of {samples} sampled frames per run, median of {repeat}")
    print(f"{'variant':<44}{'seconds':>9}{'runs/min':>10}{'vs 1 worker':>13}{'renderer share':>16}")
    for direct in (False, True):
        one = statistics.median(times[(counts[0], direct)]) if counts[0] == 1 else None
        for n in counts:
            seconds = statistics.median(times[(n, direct)])
            drawn = sum(d for d, _ in shares[(n, direct)])
            total = sum(t for _, t in shares[(n, direct)])
            vs_one = f"{one / seconds:>12.2f}x" if one is not None else " " * 13
            print(f"{names[(n, direct)]:<44}{seconds:>9.2f}{60.0 * runs / seconds:>10.1f}{vs_one}"
                  f"{100.0 * drawn / max(total, 1e-9):>15.0f}%")
    print("renderer share: the workers' drawing time (views' RGB and channels) over their whole runs' time")
    return 0


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
    if args.views:
        return run_views(args, runs, frames, repeat, counts)
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
