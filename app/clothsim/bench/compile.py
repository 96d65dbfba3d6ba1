"""``clothsim bench compile``: where a cold start's time goes. Each command runs in a fresh process
with every cache empty (a new ``NUMBA_CACHE_DIR``, ``HOME`` and ``XDG_CACHE_HOME``), and the
seconds Numba spent compiling each kernel are printed under the command's wall time."""

from __future__ import annotations

import argparse
import json
import os
import subprocess
import sys
import tempfile
import time
from collections import defaultdict
from pathlib import Path

from ..errors import ClothsimError

#: name -> the CLI arguments it runs ({tmp} is a fresh folder)
COMMANDS: dict[str, list[str]] = {
    "simulate": ["simulate", "pinned2", "--frames", "90", "--out", "{tmp}/s.npz"],
    "render": ["render", "pinned2", "--shader", "phong", "-o", "{tmp}/cloth.png"],
    "sphere": ["simulate", "sphere", "--frames", "10", "--out", "{tmp}/s.npz"],
    "grid": ["simulate", "pinned2", "--self-collision", "grid", "--frames", "10", "--out", "{tmp}/s.npz"],
    "xpbd": ["simulate", "pinned2", "--integrator", "xpbd", "--frames", "10", "--out", "{tmp}/s.npz"],
    "flag": ["simulate", "flag", "--frames", "10", "--out", "{tmp}/s.npz"],
    "capsule": ["simulate", "capsule", "--frames", "10", "--out", "{tmp}/s.npz"],
    "tablecloth": ["simulate", "tablecloth", "--frames", "10", "--out", "{tmp}/s.npz"],
    "mesh": ["simulate", "mesh", "--frames", "10", "--out", "{tmp}/s.npz"],
    "selfcollision": ["simulate", "selfCollision", "--frames", "10", "--out", "{tmp}/s.npz"],
    "contact": ["simulate", "selfCollision", "--self-collision", "contact", "--frames", "10", "--out", "{tmp}/s.npz"],
}
_RUNNER = ("import sys; from clothsim.cli.compile import record_command; "
           "sys.exit(record_command(sys.argv[1], sys.argv[2:]))")


def add_parser(bench_sub: argparse._SubParsersAction) -> None:
    """Register ``clothsim bench compile``."""
    p = bench_sub.add_parser("compile", help="cold compile time of each command, kernel by kernel",
                             description="Run each command in a fresh process with every cache empty and print "
                                         "its wall time and the seconds spent compiling each kernel (own time: "
                                         "not counting kernels compiled inside it).")
    p.add_argument("--commands", default="simulate,render", metavar="LIST",
                   help=f"comma-separated, from {','.join(COMMANDS)} (default: simulate,render)")
    p.add_argument("--min", type=float, default=0.1, metavar="S",
                   help="kernels under S seconds are summed into one 'other' row (default 0.1)")
    p.set_defaults(func=run)


def cold_run(argv: list[str]) -> dict:
    """Run the CLI with ``argv`` in a fresh process with empty caches; its compile record plus the
    process's wall time (``wall``, interpreter start and imports included)."""
    with tempfile.TemporaryDirectory(prefix="clothsim-cold-") as tmp:
        env = dict(os.environ, NUMBA_CACHE_DIR=f"{tmp}/numba", HOME=f"{tmp}/home", XDG_CACHE_HOME=f"{tmp}/cache")
        env.pop("DISPLAY", None)
        for d in ("numba", "home", "cache"):
            Path(tmp, d).mkdir()
        log = f"{tmp}/compile.json"
        args = [a.replace("{tmp}", tmp) for a in argv]
        began = time.perf_counter()
        done = subprocess.run([sys.executable, "-c", _RUNNER, log, *args], env=env, capture_output=True, text=True)
        wall = time.perf_counter() - began
        if done.returncode != 0 or not Path(log).is_file():
            last = (done.stderr.strip().splitlines() or ["no output"])[-1]
            raise ClothsimError(f"bench compile: clothsim {' '.join(argv)} failed: {last}")
        record = json.loads(Path(log).read_text(encoding="utf-8"))
    record["wall"] = wall
    return record


def run(args: argparse.Namespace) -> int:
    """Print the table."""
    names = [n.strip() for n in args.commands.split(",") if n.strip()]
    for n in names:
        if n not in COMMANDS:
            raise ClothsimError(f"--commands: unknown command {n!r} (expected some of: {', '.join(COMMANDS)})")
    print("cold start: each command in a fresh process, every cache empty; seconds")
    print(f"{'command / kernel':<58}{'wall':>8}{'compile':>9}")
    for n in names:
        record = cold_run(COMMANDS[n])
        compiled = record["compiled"]
        total = sum(c["seconds"] for c in compiled if c["depth"] == 0)
        print(f"{n + ': clothsim ' + ' '.join(a for a in COMMANDS[n] if '{tmp}' not in a):<58}"
              f"{record['wall']:>8.1f}{total:>9.1f}")
        own: dict[str, float] = defaultdict(float)
        for c in compiled:
            label = c["kernel"].replace("clothsim.", "") + (f" [{c['variant']}]" if c["variant"] else "")
            own[label] += c["own"]
        other = 0.0
        for label, seconds in sorted(own.items(), key=lambda kv: -kv[1]):
            if seconds < args.min:
                other += seconds
                continue
            print(f"  {label[:72]:<72}{seconds:>9.2f}")
        print(f"  {'other (' + str(sum(1 for s in own.values() if s < args.min)) + ' kernels)':<72}{other:>9.2f}")
    return 0
