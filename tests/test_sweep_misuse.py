"""A sweep treated badly: its command killed, interrupted, out of disk, its workers lost, its
arguments malformed. Every case ends within seconds, leaves no process behind, says one line,
and the next run of the same command finishes the work.

Everything runs through the installed ``clothsim`` in real processes; a Dask cluster, where
one is needed, is a ``LocalCluster`` of worker processes.
"""

from __future__ import annotations

import json
import os
import select
import shutil
import signal
import subprocess
import sys
import time
from pathlib import Path

import pytest

from conftest import after_ctrl_c, child_pids, ctrl_c_as_on_a_terminal, error_line
from test_locks import clothsim, kill9, manifest_ids, start, wait_for_holder

LONG = ("--set", "cloth.ks=3000,4000,5000,6000", "--frames", "100000")


def alive(pid: int) -> bool:
    """Running (a zombie waiting for a parent that does not reap it counts as ended)."""
    try:
        state = Path(f"/proc/{pid}/stat").read_text().rsplit(")", 1)[1].split()[0]
    except OSError:
        return False
    return state not in ("Z", "X")


def cmdline(pid: int) -> bytes:
    try:
        return Path(f"/proc/{pid}/cmdline").read_bytes()
    except OSError:
        return b""


def needs_proc() -> None:
    if not Path(f"/proc/{os.getpid()}/task").exists() or not sys.platform.startswith("linux"):
        pytest.skip("needs Linux's /proc to find the worker processes")


def workers_of(proc: subprocess.Popen, count: int, timeout: float = 60) -> tuple[list[int], list[int]]:
    """The sweep's worker processes (once ``count`` run) and its resource tracker."""
    deadline = time.monotonic() + timeout
    while time.monotonic() < deadline:
        assert proc.poll() is None, proc.communicate()
        kids = child_pids(proc.pid)
        workers = [k for k in kids if b"spawn_main" in cmdline(k)]
        tracker = [k for k in kids if b"resource_tracker" in cmdline(k)]
        if len(workers) == count and tracker:
            return workers, tracker
        time.sleep(0.05)
    raise AssertionError("the workers did not start")


def wait_gone(pids: list[int], seconds: float) -> float:
    start_time = time.monotonic()
    while any(alive(p) for p in pids):
        elapsed = time.monotonic() - start_time
        assert elapsed < seconds, [p for p in pids if alive(p)]
        time.sleep(0.05)
    return time.monotonic() - start_time


# -- the command killed or interrupted ------------------------------------------------------------
def test_kill_9_of_the_command_ends_its_workers_and_a_pipe_after_it(tmp_path):
    # As `clothsim sweep ... | tail`: this test holds the read end of the command's stdout, and
    # reads to its end once the command is killed. A worker holding that pipe would keep it open.
    needs_proc()
    out = tmp_path / "data"
    proc = start("sweep", "pinned2", *LONG, "--workers", "2", "-o", str(out))
    workers: list[int] = []
    tracker: list[int] = []
    try:
        workers, tracker = workers_of(proc, 2)
        time.sleep(0.5)  # the workers are simulating their first runs
        os.kill(proc.pid, signal.SIGKILL)
        # End of file within 5 s: nobody else holds the pipe (select, so a failure cannot hang).
        readable, _, _ = select.select([proc.stdout], [], [], 5)
        assert readable and os.read(proc.stdout.fileno(), 1) == b"", "the pipe is still held open"
        proc.wait()
        assert wait_gone(workers, 5) < 5
        assert wait_gone(tracker, 5) < 5
    finally:
        kill9(proc)
        for pid in workers + tracker:  # left running only if the case failed
            if alive(pid):
                os.kill(pid, signal.SIGKILL)
    # The lock of the killed command does not block the next one, which finishes quickly.
    assert (out / ".clothsim.lock").exists()
    r = clothsim("sweep", "pinned2", "--set", "cloth.ks=3000,4000,5000,6000", "--frames", "3",
                 "--workers", "1", "-o", str(tmp_path / "other"))
    assert r.returncode == 0, r.stderr


def test_ctrl_c_ends_a_local_sweep_within_seconds(tmp_path):
    needs_proc()
    out = tmp_path / "data"
    # Ctrl-C on a terminal reaches the whole process group.
    proc = start("sweep", "pinned2", *LONG, "--workers", "2", "-o", str(out), start_new_session=True,
                 preexec_fn=ctrl_c_as_on_a_terminal)
    workers: list[int] = []
    tracker: list[int] = []
    try:
        workers, tracker = workers_of(proc, 2)
        time.sleep(0.5)
        os.killpg(proc.pid, signal.SIGINT)
        sent = time.monotonic()
        _, err = after_ctrl_c(proc, "sweep", 15)
        took = time.monotonic() - sent
    finally:
        kill9(proc)
        for pid in workers + tracker:  # left running only if the case failed
            if alive(pid):
                os.kill(pid, signal.SIGKILL)
    assert took < 5, took
    assert proc.returncode == 130 and err.strip().splitlines()[-1] == "clothsim: interrupted", err
    assert "Traceback" not in err, err
    wait_gone(workers + tracker, 5)
    assert not (out / ".clothsim.lock").exists()


@pytest.fixture
def tiny_disk(tmp_path):
    """A 3 MiB tmpfs; skipped where mounting is not allowed."""
    if not sys.platform.startswith("linux") or os.geteuid() != 0 or not shutil.which("mount"):
        pytest.skip("a small tmpfs needs Linux and root (mount -t tmpfs)")
    mount = tmp_path / "disk"
    mount.mkdir()
    r = subprocess.run(["mount", "-t", "tmpfs", "-o", "size=3m", "tmpfs", str(mount)], capture_output=True, text=True)
    if r.returncode != 0:
        pytest.skip(f"cannot mount a tmpfs here: {r.stderr.strip()}")
    try:
        yield mount
    finally:
        if subprocess.run(["umount", str(mount)], capture_output=True).returncode != 0:
            subprocess.run(["umount", "-l", str(mount)], capture_output=True)


def test_full_disk_ends_every_attempt_with_one_line_and_no_partial_file(tiny_disk):
    # Each run's result is about 420 KB; two workers send theirs while the command, failing to
    # write, kills them: one killed mid-send used to leave the command waiting for ever.
    out = tiny_disk / "data"
    ks = ",".join(str(k) for k in range(3000, 3000 + 100 * 32, 100))
    args = ("sweep", "pinned2", "--set", f"cloth.ks={ks}", "--frames", "10", "--workers", "2", "-o", str(out))
    for attempt in range(6):  # the hang needed a worker caught mid-send: one attempt in three
        began = time.monotonic()
        r = clothsim(*args, timeout=60)
        assert time.monotonic() - began < 20
        line = error_line(r)
        assert line.endswith(": cannot write: No space left on device"), line
        assert not [p for p in out.rglob("*") if ".tmp" in p.name or p.name.endswith(".lock")]
        for text in (out / "manifest.jsonl").read_text().splitlines():
            record = json.loads(text)
            assert record["status"] == "done"
            assert (out / record["path"]).stat().st_size > 400_000


# -- Dask ------------------------------------------------------------------------------------------
@pytest.fixture
def cluster():
    distributed = pytest.importorskip("distributed")
    import dask

    # One lost worker is enough for the scheduler to give up on a run (KilledWorker).
    with dask.config.set({"distributed.scheduler.allowed-failures": 0}):
        with distributed.LocalCluster(n_workers=1, threads_per_worker=1, processes=True,
                                      dashboard_address=None) as local:
            with distributed.Client(local) as client:
                yield local, client


def test_ctrl_c_cancels_the_queued_dask_runs_at_once(tmp_path, cluster):
    local, client = cluster
    out = tmp_path / "data"
    proc = start("sweep", "pinned2", "--set", "cloth.ks=3000,3500,4000,4500,5000,5500", "--frames", "400",
                 "--scheduler", local.scheduler_address, "-o", str(out), start_new_session=True,
                 preexec_fn=ctrl_c_as_on_a_terminal)
    try:
        wait_for_holder(out / ".clothsim.lock", proc)
        deadline = time.monotonic() + 60
        while not any(client.processing().values()) and time.monotonic() < deadline:
            time.sleep(0.05)
        assert any(client.processing().values()), "no run started on the cluster"
        os.killpg(proc.pid, signal.SIGINT)
        sent = time.monotonic()
        _, err = proc.communicate(timeout=60)
        took = time.monotonic() - sent
    finally:
        kill9(proc)
    assert took < 5, (took, err)  # the queued runs were not waited for
    assert proc.returncode == 130 and "Traceback" not in err, err
    # and they are gone from the cluster: nothing queued for the sweep is left to run.
    deadline = time.monotonic() + 10
    while client.run_on_scheduler(lambda dask_scheduler: len(dask_scheduler.tasks)) and time.monotonic() < deadline:
        time.sleep(0.1)
    assert client.run_on_scheduler(lambda dask_scheduler: len(dask_scheduler.tasks)) == 0


def test_a_run_lost_with_a_dask_worker_is_redone_by_the_next_run(tmp_path, cluster):
    local, client = cluster
    out = tmp_path / "data"
    args = ("sweep", "pinned2", "--set", "cloth.ks=3000,4000,5000", "--frames", "60",
            "--scheduler", local.scheduler_address, "-o", str(out))
    proc = start(*args)
    try:
        wait_for_holder(out / ".clothsim.lock", proc)
        deadline = time.monotonic() + 60
        while not any(client.processing().values()) and time.monotonic() < deadline:
            time.sleep(0.02)
        time.sleep(0.3)
        for pid in client.run(os.getpid).values():
            os.kill(pid, signal.SIGKILL)  # the nanny starts a new worker
        _, err = proc.communicate(timeout=60)
    finally:
        kill9(proc)
    assert proc.returncode == 1, err
    assert "lost: KilledWorker: " in err and "lost with a worker that died" in err and "Traceback" not in err, err
    recorded = manifest_ids(out) if (out / "manifest.jsonl").exists() else []
    assert len(recorded) < 3  # the lost runs are not in the manifest, as failures or otherwise
    r = clothsim(*args)
    assert r.returncode == 0, r.stderr
    assert f"{3 - len(recorded)} done, 0 failed, {len(recorded)} skipped" in r.stderr
    assert sorted(manifest_ids(out)) == ["run_00000", "run_00001", "run_00002"]


# -- malformed arguments ---------------------------------------------------------------------------
LONG_NAME = "x" * 300


@pytest.mark.parametrize("args", [
    ("simulate", "pinned2", "--frames", "1", "-o", f"{LONG_NAME}.npz"),
    ("render", "pinned2", "--frames", "1", "--size", "32x32", "-o", LONG_NAME),
    ("render", "pinned2", "--frames", "1", "--size", "32x32", "-o", f"{LONG_NAME}.png"),
    ("export", "pinned2", "--frames", "1", "-o", LONG_NAME),
    ("export", "pinned2", "--frames", "1", "-o", f"sub/{LONG_NAME}.usda"),
    ("sweep", "pinned2", "--set", "cloth.ks=10", "--frames", "1", "-o", LONG_NAME),
    ("sweep", "pinned2", "--set", "cloth.ks=10", "--frames", "1", "-o", f"{LONG_NAME}.png"),
], ids=["simulate", "render-folder", "render-png", "export-obj", "export-usd", "sweep-folder", "sweep-sheet"])
def test_a_name_longer_than_the_file_system_allows_is_one_line(tmp_path, args):
    r = clothsim(*args, cwd=tmp_path)
    line = error_line(r)
    assert "name too long (" in line and "at most 255)" in line and len(line) < 200, line
    assert list(tmp_path.iterdir()) == []


@pytest.mark.parametrize("index", ["²", "①", "٣", "¹0"])
def test_a_list_index_in_other_digits_is_one_line(tmp_path, index):
    r = clothsim("sweep", "sphere", "--set", f"sphere.{index}.radius=1", "--frames", "1", "-o", "d", cwd=tmp_path)
    assert error_line(r) == (f"clothsim: error: --set sphere.{index}.radius: {index!r} is not a list index "
                             "(an index is written with the digits 0-9, e.g. sphere.1.radius)")
    assert list(tmp_path.iterdir()) == []


def test_a_ctrl_c_while_the_workers_start_is_held_and_raised():
    # The workers start with SIGINT blocked; a Ctrl-C reaching the command meanwhile used to be
    # ignored there, and the sweep ran on.
    import signal
    from concurrent.futures import Future

    from clothsim.sweeps import engines

    class Pool:
        def submit(self, fn):  # noqa: ANN001, ANN202
            os.kill(os.getpid(), signal.SIGINT)
            done = Future()
            done.set_result(fn())
            return done

    before = signal.getsignal(signal.SIGINT)
    with pytest.raises(KeyboardInterrupt):
        engines._start_workers(Pool(), 2)
    assert signal.getsignal(signal.SIGINT) is before
    assert not signal.pthread_sigmask(signal.SIG_BLOCK, set()) & {signal.SIGINT}
