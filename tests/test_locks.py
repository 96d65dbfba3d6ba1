"""One writer at a time: every output built over time is locked while it is written.

Each case runs the installed ``clothsim`` in real processes: a first writer that runs long
enough to be caught holding its output, a second writer of the same output that must stop with
one line naming the first (and write nothing), then ``kill -9`` of the first and a third writer
that must not be blocked by the dead one's lock.
"""

from __future__ import annotations

import json
import os
import re
import signal
import socket
import subprocess
import sys
import time
from pathlib import Path

import pytest

from conftest import error_line

HOLDER = re.compile(r"being written by clothsim \(pid (\d+) on host (.+), started (\S+)\); "
                    r"wait for it to end or choose another output$")


def clothsim(*args: str, cwd: Path | None = None, timeout: float = 120) -> subprocess.CompletedProcess:
    return subprocess.run([*command(), *args], cwd=cwd, capture_output=True, text=True, timeout=timeout,
                          env=environment())


def command() -> list[str]:
    """The installed ``clothsim`` script beside this interpreter, else ``python -m clothsim``."""
    script = Path(sys.executable).with_name("clothsim")
    return [str(script)] if script.exists() else [sys.executable, "-m", "clothsim"]


def environment() -> dict[str, str]:
    env = dict(os.environ)
    env.pop("DISPLAY", None)
    env["PYTHONFAULTHANDLER"] = "1"  # a command that hangs shows where, on SIGABRT
    return env


def start(*args: str, **kwargs) -> subprocess.Popen:
    return subprocess.Popen([*command(), *args], stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True,
                            env=environment(), **kwargs)


def wait_for_holder(lock: Path, proc: subprocess.Popen, timeout: float = 60) -> dict:
    """The holder record the writer ``proc`` put in ``lock`` once it holds it."""
    deadline = time.monotonic() + timeout
    while time.monotonic() < deadline:
        assert proc.poll() is None, proc.communicate()
        try:
            data = json.loads(lock.read_text())
            if data.get("pid") == proc.pid:
                return data
        except (OSError, ValueError):
            pass
        time.sleep(0.02)
    raise AssertionError(f"{lock} was never taken by pid {proc.pid}")


def kill9(proc: subprocess.Popen) -> None:
    """End ``proc`` if still running; its pipes are closed unread (a leftover child may hold them)."""
    if proc.poll() is None:
        proc.kill()
    proc.wait()
    for pipe in (proc.stdout, proc.stderr):
        if pipe is not None:
            pipe.close()


def tree(folder: Path) -> dict[str, bytes | None]:
    """Every entry below ``folder`` (hidden ones too), files with their bytes."""
    return {str(p.relative_to(folder)): (None if p.is_dir() else p.read_bytes()) for p in sorted(folder.rglob("*"))}


def assert_refused_by(r: subprocess.CompletedProcess, label: str, holder: subprocess.Popen) -> None:
    line = error_line(r)
    assert line.startswith(f"clothsim: error: {label}: "), line
    m = HOLDER.search(line)
    assert m is not None, line
    assert int(m[1]) == holder.pid and m[2] == socket.gethostname(), line


def lock_cases():
    # (command and its slow arguments, fast arguments, output name, lock file relative to the
    # parent when the output does not exist yet)
    render = ("render", "pinned2", "--size", "32x32", "--every", "1")
    return {
        "render frames folder": (render, "frames", "--frames"),
        "export OBJ folder": (("export", "pinned2", "--every", "1"), "objs", "--frames"),
        "export USD stage": (("export", "pinned2"), "stage.usda", "--frames"),
    }


@pytest.mark.parametrize("case", list(lock_cases()))
@pytest.mark.parametrize("existing", [False, True], ids=["new", "existing"])
def test_second_writer_is_refused_with_the_holder_and_a_killed_holder_blocks_nothing(tmp_path, case, existing):
    args, name, frames = lock_cases()[case]
    if name.endswith(".usda"):
        pytest.importorskip("pxr")
    out = tmp_path / name
    if existing:  # an earlier output of the same command: locked inside a folder, beside a file
        r = clothsim(*args, frames, "1", "-o", str(out))
        assert r.returncode == 0, r.stderr
    inside = out.is_dir()
    lock = out / ".clothsim.lock" if inside else tmp_path / f".{name}.clothsim.lock"
    first = start(*args, frames, "1000000", "-o", str(out))
    try:
        wait_for_holder(lock, first)
        os.kill(first.pid, signal.SIGSTOP)  # frozen while it holds the lock: its files stay as they are
        before = tree(tmp_path)
        second = clothsim(*args, frames, "2", "-o", str(out))
        assert_refused_by(second, str(out), first)
        assert tree(tmp_path) == before  # the second wrote nothing, not even a temporary file
    finally:
        kill9(first)
    # The dead holder's lock file is still there (nothing ran to remove it), with the
    # temporary output it was writing; neither stops the next run, which removes both.
    assert lock.exists()
    third = clothsim(*args, frames, "2", "-o", str(out))
    assert third.returncode == 0, third.stderr
    left = sorted(p.name for p in tmp_path.rglob(".*"))
    assert left == [], left
    if out.is_dir():
        assert len([p for p in out.iterdir()]) >= 3
    else:
        assert out.stat().st_size > 0


def test_an_existing_frames_folder_with_a_killed_writers_temporary_folder_is_ours(tmp_path):
    # A render killed while writing into an existing folder leaves .clothsim-frames.XXXXXXXX.tmp/
    # and its lock inside: the folder is still clothsim's, and the next render clears them.
    out = tmp_path / "frames"
    render = ("render", "pinned2", "--size", "32x32", "--every", "1")
    assert clothsim(*render, "--frames", "1", "-o", str(out)).returncode == 0
    first = start(*render, "--frames", "1000000", "-o", str(out))
    try:
        wait_for_holder(out / ".clothsim.lock", first)
        deadline = time.monotonic() + 60
        while not list(out.glob(".clothsim-frames.*.tmp/frame_*.png")) and time.monotonic() < deadline:
            time.sleep(0.02)
    finally:
        kill9(first)
    stale = list(out.glob(".clothsim-frames.*.tmp"))
    assert len(stale) == 1 and list(stale[0].iterdir())
    r = clothsim(*render, "--frames", "2", "-o", str(out))
    assert r.returncode == 0, r.stderr
    assert sorted(p.name for p in out.iterdir()) == [f"frame_{i:05d}.png" for i in range(3)]


# -- sweeps ---------------------------------------------------------------------------------------
SWEEP = ("--frames", "150", "--workers", "1")


def manifest_ids(out: Path) -> list[str]:
    return [json.loads(line)["id"] for line in (out / "manifest.jsonl").read_text().splitlines()]


def test_two_different_sweeps_started_together_one_runs_the_other_names_it(tmp_path):
    out = tmp_path / "data"
    ks = start("sweep", "pinned2", "--set", "cloth.ks=4000,6000", *SWEEP, "-o", str(out))
    density = start("sweep", "pinned2", "--set", "cloth.density=14,16", *SWEEP, "-o", str(out))
    results = {}
    for name, proc in (("ks", ks), ("density", density)):
        _, err = proc.communicate(timeout=120)
        results[name] = (proc.returncode, err)
    codes = sorted(code for code, _ in results.values())
    assert codes == [0, 2], results
    winner, loser = ("ks", "density") if results["ks"][0] == 0 else ("density", "ks")
    procs = {"ks": ks, "density": density}
    assert_refused_by(subprocess.CompletedProcess([], 2, "", results[loser][1]), str(out), procs[winner])
    definition = json.loads((out / "sweep.json").read_text())
    field = "cloth.ks" if winner == "ks" else "cloth.density"
    assert list(definition["params"]) == [field]
    records = [json.loads(line) for line in (out / "manifest.jsonl").read_text().splitlines()]
    assert sorted(r["id"] for r in records) == ["run_00000", "run_00001"]
    assert all(list(r["params"]) == [field] for r in records)
    assert sorted(p.name for p in out.rglob("*")) == ["manifest.jsonl", "meta.json", "run_00000.npz",
                                                      "run_00001.npz", "runs", "sweep.json"]


def test_the_same_sweep_started_twice_runs_each_run_once(tmp_path):
    out = tmp_path / "data"
    args = ("sweep", "pinned2", "--set", "cloth.ks=4000,5000,6000", *SWEEP, "-o", str(out))
    first = start(*args)
    try:
        wait_for_holder(out / ".clothsim.lock", first)
        second = clothsim(*args)
        assert_refused_by(second, str(out), first)
        _, err = first.communicate(timeout=120)
    finally:
        kill9(first)
    assert first.returncode == 0, err
    assert manifest_ids(out) == ["run_00000", "run_00001", "run_00002"]  # no duplicate records


def test_a_killed_sweeps_lock_and_temporary_files_do_not_survive_the_next_run(tmp_path):
    # The sweep is frozen (SIGSTOP) the moment a run's temporary .npz appears, then killed with
    # kill -9 if the file is still there: a real leftover of a write cut short.
    out = tmp_path / "data"
    args = ("sweep", "pinned2", "--set", "cloth.ks=3000,4000,5000,6000,7000,8000", "--frames", "60",
            "--workers", "1", "-o", str(out))
    proc = start(*args)
    runs = out / "runs"
    caught: list[str] = []
    try:
        deadline = time.monotonic() + 90
        while not caught and time.monotonic() < deadline and proc.poll() is None:
            temporary = [e.name for e in os.scandir(runs) if e.name.endswith(".tmp.npz")] if runs.is_dir() else []
            if temporary:
                os.kill(proc.pid, signal.SIGSTOP)
                caught = [e.name for e in os.scandir(runs) if e.name.endswith(".tmp.npz")]
                if not caught:
                    os.kill(proc.pid, signal.SIGCONT)
            else:
                time.sleep(0.0005)
    finally:
        kill9(proc)
    if not caught:
        pytest.fail("the sweep was never caught writing a run (no temporary .npz seen)")
    assert re.fullmatch(r"\.run_\d{5}\.[a-z0-9_]{8}\.tmp\.npz", caught[0]), caught
    assert (runs / caught[0]).exists() and (out / ".clothsim.lock").exists()
    done_before = len(manifest_ids(out)) if (out / "manifest.jsonl").exists() else 0
    r = clothsim(*args)
    assert r.returncode == 0, r.stderr
    assert f"{6 - done_before} done, 0 failed, {done_before} skipped" in r.stderr
    assert sorted(p.name for p in runs.iterdir()) == [f"run_{i:05d}.npz" for i in range(6)]
    assert sorted(p.name for p in out.iterdir()) == ["manifest.jsonl", "meta.json", "runs", "sweep.json"]
