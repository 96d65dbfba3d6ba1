"""Compiling the kernels: the first-run notice, caching from a read-only install, and
``clothsim compile`` / ``clothsim bench compile`` through the real CLI."""

from __future__ import annotations

import os
import re
import shutil
import subprocess
import sys
from pathlib import Path

import pytest

from conftest import COMPILE_REPORT, REPO, run_cli, warm_copy

NOTICE = "clothsim: compiling kernels for this CPU (first run only"


def _read_only_mounts_work(folder: Path) -> str | None:
    if shutil.which("unshare") is None:
        return "unshare (util-linux) is not installed"
    probe = subprocess.run(["unshare", "-rm", "sh", "-c", f"mount --bind {folder} {folder} && "
                            f"mount -o remount,bind,ro {folder} && ! touch {folder}/probe 2>/dev/null"],
                           capture_output=True, text=True)
    if probe.returncode != 0:
        return f"this machine does not allow a private read-only bind mount: {probe.stderr.strip()[:120]}"
    return None


def test_kernels_cache_from_a_read_only_install(tmp_path: Path) -> None:
    # A system-wide install: the package folder cannot be written (here a read-only bind mount, which
    # binds root as well), so Numba keeps the compiled kernels in the user's cache instead.
    site = tmp_path / "site"
    site.mkdir()
    why = _read_only_mounts_work(site)
    if why:
        pytest.skip(why)
    shutil.copytree(REPO / "app" / "clothsim", site / "clothsim",
                    ignore=shutil.ignore_patterns("__pycache__", "*.nbi", "*.nbc"))
    for data in ("scenes", "glsl"):
        shutil.copytree(REPO / data, site / "clothsim" / data)
    home = tmp_path / "home"
    home.mkdir()
    # The user's cache starts with what the suite has compiled, less the plan's small entry kernel:
    # the first run compiles that one alone (a few seconds, not the whole plan cold) and must keep it there.
    user_cache = home / ".cache" / "numba"
    _copy_kernel_cache(site / "clothsim", user_cache, drop="frame._enter-*")
    assert not list(user_cache.rglob("frame._enter-*"))
    scene = tmp_path / "small.json"
    scene.write_text('{"cloth": {"width": 1, "height": 1, "num_width_points": 8, "num_height_points": 8, '
                     '"thickness": 0.01, "orientation": 0, "pinned": [[0, 0]], "damping": 0.2, "density": 150, '
                     '"ks": 5000}, "simulation": {"self_collision": false}}')
    env = {k: v for k, v in os.environ.items() if k not in ("NUMBA_CACHE_DIR", "XDG_CACHE_HOME", "PYTHONPATH")}
    env.update(HOME=str(home), PYTHONPATH=str(site))
    command = (f"mount --bind {site} {site} && mount -o remount,bind,ro {site} && "
               f"exec {sys.executable} -m clothsim simulate {scene} --frames 2 --out {tmp_path}/s.npz")

    def run() -> subprocess.CompletedProcess:
        return subprocess.run(["unshare", "-rm", "sh", "-c", command], capture_output=True, text=True, env=env,
                              cwd=tmp_path, timeout=600)

    first = run()
    assert first.returncode == 0, first.stderr
    assert first.stderr.count(NOTICE) == 1
    second = run()
    assert second.returncode == 0, second.stderr
    assert NOTICE not in second.stderr  # loaded from the cache: nothing compiled, nothing said
    assert not list(site.rglob("*.nbi"))
    assert list(user_cache.rglob("frame._enter-*.nbi"))


def _copy_kernel_cache(package: Path, user_cache: Path, drop: str) -> None:
    """The suite's compiled kernels (those of the package the tests import) put where Numba's
    user-wide cache looks for the kernels of ``package``, a copy of it: one folder per module
    folder, named for that folder's path (Numba's ``UserWideCacheLocator``); the files ``drop``
    names are left out. (The cache is keyed on the package's text, not on where it lies.)"""
    import fnmatch
    import hashlib

    import clothsim

    installed = Path(clothsim.__file__).resolve().parent
    for cached in installed.rglob("__pycache__/*.nb[ic]"):
        if fnmatch.fnmatch(cached.name, drop):
            continue
        folder = package / cached.parent.parent.relative_to(installed)
        into = user_cache / f"{folder.name}_{hashlib.sha1(str(folder).encode()).hexdigest()}"
        into.mkdir(parents=True, exist_ok=True)
        shutil.copy2(cached, into / cached.name)


def test_compile_compiles_everything_ahead_of_time(tmp_path: Path) -> None:
    # the suite's own run before the tests (tests/conftest.py), or one now when there was none (-n 0)
    report = os.environ.get(COMPILE_REPORT)
    if report:
        out = Path(report).read_text()
    else:
        first = run_cli("compile", "--jobs", "2", timeout=900)
        assert first.returncode == 0, first.stderr
        out = first.stdout
    lines = out.splitlines()
    assert re.fullmatch(r"total +[0-9.]+ +[0-9]+ compiles, [0-9.]+ s in [0-9]+ process(es)?", lines[-1]), lines[-1]
    assert lines[0].split()[:2] == ["work", "item"]
    items = [line for line in lines[1:-1]]
    assert len(items) == 32 and any("self-collision grid, colliders" in i for i in items)
    assert any("mesh cloth: bundled scene skirt" in i for i in items)
    assert any("colliders of every kind turning" in i for i in items)
    assert any("bundled scene tablecloth" in i for i in items)
    assert any("wind" in i for i in items) and any("moving pins" in i for i in items)
    assert lines[-1].startswith("total")
    # afterwards no command needs a compile: running it again loads every kernel
    again = run_cli("compile", "--jobs", "1", timeout=900)
    assert again.returncode == 0, again.stderr
    assert all(line.rstrip().endswith("(cached)") for line in again.stdout.splitlines()[1:-1])
    assert NOTICE not in again.stderr
    warm = run_cli("simulate", "sphere", "--frames", "2", "--self-collision", "grid", "--out", str(tmp_path / "s.npz"))
    assert warm.returncode == 0, warm.stderr
    assert NOTICE not in warm.stderr


def test_bench_compile_reports_each_kernel_of_a_cold_start() -> None:
    done = run_cli("bench", "compile", "--commands", "simulate", timeout=900)
    assert done.returncode == 0, done.stderr
    out = done.stdout
    header, command = out.splitlines()[1], out.splitlines()[2]
    assert header.split() == ["command", "/", "kernel", "wall", "compile"]
    assert command.startswith("simulate: clothsim simulate pinned2 --frames 90")
    wall, compile_s = (float(x) for x in command.split()[-2:])
    assert 0 < compile_s < wall
    # the passes every plan shares compile here while the plan's member compiles in a second
    # process (its row is the wait for it, under the --min threshold when it finished first)
    assert "sim.passes.springs.spring_jobs" in out
    assert "sim.solvers.frame._launch" in out


def test_bench_compile_rejects_an_unknown_command() -> None:
    done = run_cli("bench", "compile", "--commands", "simulate,nope")
    assert done.returncode == 2
    assert done.stderr.strip().splitlines() == [
        "clothsim: error: --commands: unknown command 'nope' (expected some of: simulate, render, sphere, grid, xpbd, flag, capsule, tablecloth, mesh, selfcollision, contact)"]

@pytest.mark.parametrize("jobs, message", [
    ("0", "clothsim: error: --jobs: must be >= 1, got 0"),
    ("two", "clothsim: error: argument --jobs: invalid int value: 'two' (see clothsim compile --help)"),
])
def test_compile_rejects_a_bad_number_of_jobs(jobs: str, message: str) -> None:
    done = run_cli("compile", "--jobs", jobs)
    assert done.returncode == 2 and done.stdout == ""
    assert done.stderr.strip().splitlines() == [message]


def _start_together(commands: list[list[str]], **popen: object) -> list[subprocess.Popen]:
    """Start ``commands``, wait until each has printed its "ready" line, then let them all go at
    once (a line on their standard input): what they do next, they do at the same moment."""
    procs = [subprocess.Popen(c, stdin=subprocess.PIPE, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True,
                              **popen) for c in commands]
    for p in procs:
        line = p.stdout.readline()
        if line != "ready\n":  # it failed before: its error is on stderr
            p.kill()
            raise AssertionError(f"{line!r}: {p.stderr.read()}")
    for p in procs:
        p.stdin.write("go\n")
        p.stdin.flush()
    return procs


_CACHE_PROBE = """
import numpy as np
from clothsim.sim.rest import max_displacement
max_displacement(np.zeros((3, 4)), np.zeros((3, 4)))
s = max_displacement.stats
print(sum(s.cache_hits.values()), sum(s.cache_misses.values()))
"""


def test_a_change_to_any_kernel_module_makes_every_cached_kernel_stale(tmp_path: Path) -> None:
    # Numba alone keys a cache on the kernel's own file; a kernel compiled against another module's
    # old code (after an upgrade) was loaded and ran it, or crashed. Here the rest detector must be
    # recompiled when passes/colliders/box.py, which it does not even call, changes, and loaded when nothing did.
    site = tmp_path / "site"
    shutil.copytree(REPO / "app" / "clothsim", site / "clothsim",
                    ignore=shutil.ignore_patterns("__pycache__", "*.nbi", "*.nbc"))
    env = {k: v for k, v in os.environ.items() if k not in ("NUMBA_CACHE_DIR", "PYTHONPATH")}
    env["PYTHONPATH"] = str(site)

    def hits_and_misses() -> tuple[int, int]:
        done = subprocess.run([sys.executable, "-c", _CACHE_PROBE], capture_output=True, text=True, env=env,
                              cwd=tmp_path, timeout=300)
        assert done.returncode == 0, done.stderr
        hits, misses = done.stdout.split()
        return int(hits), int(misses)

    assert hits_and_misses() == (0, 1)  # compiled, into the copy's __pycache__
    assert hits_and_misses() == (1, 0)  # loaded
    collide = site / "clothsim" / "sim" / "passes" / "colliders" / "box.py"
    collide.write_text(collide.read_text() + "\n# changed\n")
    assert hits_and_misses() == (0, 1)  # stale: compiled again
    assert hits_and_misses() == (1, 0)
    notes = site / "clothsim" / "README.txt"  # a file without kernels changes nothing
    notes.write_text("x")
    assert hits_and_misses() == (1, 0)


_CONCURRENT_PROBE = """
import sys
import numpy as np
from clothsim.sim.rest import max_displacement
dtype = np.dtype(sys.argv[1])
print("ready", flush=True)
sys.stdin.readline()  # every process compiles at the same moment: when all are ready
a = np.zeros((3, 4), dtype=dtype)
b = np.ones((3, 4), dtype=dtype)
print(max_displacement(a, b))
"""

_LOAD_PROBE = """
import numpy as np
from clothsim.sim.rest import max_displacement
for dtype in ("f8", "f4", "i8", "i4", "i2", "u4"):
    assert abs(max_displacement(np.zeros((3, 4), dtype=dtype), np.ones((3, 4), dtype=dtype)) - 3 ** 0.5) < 1e-6
s = max_displacement.stats
print(sum(s.cache_hits.values()), sum(s.cache_misses.values()))
"""


def test_processes_compiling_one_kernel_at_once_leave_a_cache_every_process_can_load(tmp_path: Path) -> None:
    # Six processes compile six signatures of one kernel into one cache at the same moment (a
    # cold start of the suite's workers or of a sweep's): afterwards a seventh loads all six from
    # the cache and each computes what it should. (Without the lock around Numba's save, one
    # run in three of the four-signature version failed here: two signatures shared a data file.)
    site = tmp_path / "site"
    shutil.copytree(REPO / "app" / "clothsim", site / "clothsim",
                    ignore=shutil.ignore_patterns("__pycache__", "*.nbi", "*.nbc"))
    env = {k: v for k, v in os.environ.items() if k not in ("NUMBA_CACHE_DIR", "PYTHONPATH")}
    env["PYTHONPATH"] = str(site)
    procs = _start_together([[sys.executable, "-c", _CONCURRENT_PROBE, kind] for kind in ("f8", "f4", "i8", "i4", "i2", "u4")],
                            env=env, cwd=tmp_path)
    for p in procs:
        out, err = p.communicate(timeout=120)
        assert p.returncode == 0, err
        assert abs(float(out) - 3 ** 0.5) < 1e-6
    done = subprocess.run([sys.executable, "-c", _LOAD_PROBE], capture_output=True, text=True, env=env,
                          cwd=tmp_path, timeout=120)
    assert done.returncode == 0, done.stderr
    assert done.stdout.split() == ["6", "0"]  # all six loaded, none compiled again


_SAME_PLAN_PROBE = """
import sys
from clothsim.scene import load_scene
from clothsim.sim import Simulation
from clothsim.sim.solvers.frame import _member
from clothsim.sim.solvers.substep import integrate_substeps
integrator = sys.argv[1]
sim = Simulation(load_scene("pinned2").with_simulation(self_collision="off", integrator=integrator).with_cloth(
    num_width_points=8, num_height_points=8))
print("ready", flush=True)
sys.stdin.readline()  # both processes reach the first frame at the same moment: when both are ready
sim.step(1)
s = (_member if integrator == "verlet" else integrate_substeps).stats
print(sum(s.cache_hits.values()), sum(s.cache_misses.values()))
"""


@pytest.mark.parametrize("integrator, kernel", [("verlet", "frame._member-*"),
                                                ("symplectic_euler", "substep.integrate_substeps-*")])
def test_processes_starting_one_plan_at_once_compile_it_once(tmp_path: Path, integrator: str, kernel: str) -> None:
    # Two processes reach the first frame of the same plan at the same moment, its kernel not in
    # the cache (the suite's workers, a sweep's local workers on a cold cache): one compiles the
    # plan's kernel (the team's member, or another integrator's substep), the other waits for it
    # and loads it from the cache. (The rest is loaded from a copy of the suite's cache: a cold
    # cache took 9 and 20 s here, for the same check.)
    site = tmp_path / "site"
    warm_copy(site, kernel)
    env = {k: v for k, v in os.environ.items() if k not in ("NUMBA_CACHE_DIR", "PYTHONPATH")}
    env.update(PYTHONPATH=str(site), CLOTHSIM_COMPILE_JOBS="1")
    procs = _start_together([[sys.executable, "-c", _SAME_PLAN_PROBE, integrator]] * 2, env=env, cwd=tmp_path)
    counts = []
    for p in procs:
        out, err = p.communicate(timeout=240)
        assert p.returncode == 0, err
        counts.append(tuple(int(x) for x in out.split()))
    # (cache hits, cache misses) of that kernel in each process
    assert sorted(counts) == [(0, 1), (1, 0)], counts


def test_an_exact_kernel_stays_exact_whoever_calls_it_first() -> None:
    # Numba compiles a callee that leaves fastmath unset with its caller's flags and caches it
    # under its signature alone: an EXACT kernel first compiled by a fast-math caller was then
    # fast-math for every later caller (and every process loading that cache).
    import re

    from numba import njit

    from clothsim.jit import EXACT, KERNEL

    @njit(**{**EXACT, "cache": False})
    def exact(x: float, w: float) -> float:
        return x / w + 1.0

    @njit(**{**KERNEL, "cache": False})
    def fast(x: float, w: float) -> float:
        return exact(x, w) * 2.0

    assert fast(1.0, 3.0) == (1.0 / 3.0 + 1.0) * 2.0
    (sig,) = exact.overloads
    divisions = [line for line in exact.inspect_llvm(sig).splitlines() if " fdiv " in line]
    assert divisions and not any(re.search(r"fdiv (fast|reassoc|arcp|contract|afn|nsz)", d) for d in divisions)


def test_every_kernel_says_its_floating_point_rules() -> None:
    # every @njit of the package takes one of the option sets, each of which sets fastmath
    import ast

    from clothsim import jit

    for options in (jit.KERNEL, jit.EXACT, jit.PARALLEL, jit.BORROWED):
        assert "fastmath" in options
    allowed = {"KERNEL", "EXACT", "PARALLEL", "BORROWED"}
    for path in (Path(jit.__file__).parent.parent).rglob("*.py"):
        for node in ast.walk(ast.parse(path.read_text())):
            if isinstance(node, ast.Call) and getattr(node.func, "id", None) == "njit":
                stars = {k.value.id for k in node.keywords if k.arg is None and isinstance(k.value, ast.Name)}
                assert stars & allowed or any(k.arg == "fastmath" for k in node.keywords), (path, node.lineno)


def test_two_versions_sharing_a_cache_folder_never_load_each_others_code(tmp_path: Path,
                                                                          monkeypatch: pytest.MonkeyPatch) -> None:
    # Numba numbers a kernel's data files only: a process of another version of the package found
    # the index stale, took file 1 again and overwrote it, and a process of this version that had
    # just read its index then loaded the other version's code.
    from numba.core import caching

    from clothsim.jit import internals

    mine = internals.package_stamp()
    other = "b" * 64
    ours = caching.IndexDataCacheFile(str(tmp_path), "kernel-1.py311", mine)
    ours.save("key", "this version's code")
    index = ours._load_index()  # a loader of this version has read its index...
    monkeypatch.setattr(internals, "package_stamp", lambda: other)
    theirs = caching.IndexDataCacheFile(str(tmp_path), "kernel-1.py311", other)
    theirs.save("key", "the other version's code")  # ...when the other version saves
    monkeypatch.setattr(internals, "package_stamp", lambda: mine)
    try:
        loaded = ours._load_data(index["key"])
    except OSError:  # its file is gone: a miss, and the kernel compiles again
        loaded = None
    assert loaded in (None, "this version's code")
    assert theirs.load("key") == "the other version's code"


@pytest.mark.parametrize(("mode", "expected"), [("spec", "FIRST_RUN_SECONDS"), ("contact", "CONTACT_FIRST_RUN_SECONDS")])
def test_the_notice_estimates_the_compile_of_the_mode_a_run_uses(monkeypatch: pytest.MonkeyPatch, mode: str,
                                                                expected: str) -> None:
    # the contact mode's kernels take most of a cold start: its notice must not promise a plain scene's
    import io

    import clothsim
    from clothsim.jit import watch

    notice = watch.CompileNotice(io.StringIO())
    monkeypatch.setattr(watch, "_installed", notice)
    scene = clothsim.load_scene("selfCollision")
    clothsim.Simulation(scene.with_simulation(self_collision=mode))
    assert notice.estimate == getattr(watch, expected)
    assert watch.CONTACT_FIRST_RUN_SECONDS > 2 * watch.FIRST_RUN_SECONDS


@pytest.mark.parametrize(("name", "expected"), [("mesh", "MESH_FIRST_RUN_SECONDS"), ("cape", "MESH_FIRST_RUN_SECONDS"),
                                              ("skirt", "CONTACT_MESH_FIRST_RUN_SECONDS"),
                                              ("drum", "CONTACT_MESH_FIRST_RUN_SECONDS")])
def test_the_notice_estimates_a_triangle_mesh_scene(monkeypatch: pytest.MonkeyPatch, name: str, expected: str) -> None:
    # a mesh collider (fixed or deforming) or a cloth read from an OBJ compiles passes of its own;
    # in the contact mode (skirt, drum) the mode's kernels too
    import io

    import clothsim
    from clothsim.jit import watch

    notice = watch.CompileNotice(io.StringIO())
    monkeypatch.setattr(watch, "_installed", notice)
    clothsim.Simulation(clothsim.load_scene(name))
    assert notice.estimate == getattr(watch, expected)
    assert watch.MESH_FIRST_RUN_SECONDS >= 2 * watch.FIRST_RUN_SECONDS
    assert watch.CONTACT_MESH_FIRST_RUN_SECONDS > watch.CONTACT_FIRST_RUN_SECONDS
