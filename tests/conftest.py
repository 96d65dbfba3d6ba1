"""Shared fixtures: paths and a helper to run the real CLI in a subprocess."""

from __future__ import annotations

import os
import shutil
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import pytest
from hypothesis import settings

# The fuzz tests draw the same examples on every run, so a red suite is reproducible and the
# suite cannot turn red on a fresh clone by chance. HYPOTHESIS_PROFILE=explore draws new ones.
settings.register_profile("repeatable", derandomize=True)
settings.register_profile("explore", derandomize=False)
settings.load_profile(os.environ.get("HYPOTHESIS_PROFILE", "repeatable"))

REPO = Path(__file__).resolve().parent.parent
SCENES = REPO / "scenes"


def _worker_threads() -> int | None:
    """Threads each of pytest-xdist's workers may use: the cores shared out among the workers
    (None outside a worker: a serial run keeps them all)."""
    workers = os.environ.get("PYTEST_XDIST_WORKER_COUNT")
    if not os.environ.get("PYTEST_XDIST_WORKER") or not workers:
        return None
    return max(1, len(os.sched_getaffinity(0)) // int(workers))


#: The suite runs one worker per core, each with a core's share of threads: the frame kernel's
#: thread team spins at its barriers, so two workers each running a team of two on two cores
#: waited for members that had no core (a 600-frame render took 13.5 s instead of 2.2 s next to
#: another busy process). The kernels give the same bits on any number of threads; the tests of
#: the team itself ask for every thread (:func:`all_threads`). Children started through
#: :func:`run_cli` get the same share, and llvmpipe (Mesa's renderer) one render thread per share.
WORKER_THREADS = _worker_threads()
if WORKER_THREADS is not None:
    import numba

    numba.set_num_threads(min(WORKER_THREADS, numba.config.NUMBA_NUM_THREADS))
    os.environ.setdefault("LP_NUM_THREADS", str(WORKER_THREADS))


@pytest.fixture
def all_threads():
    """Numba's every thread for this test (the team's own tests), the worker's share after it."""
    import numba

    before = numba.get_num_threads()
    numba.set_num_threads(numba.config.NUMBA_NUM_THREADS)
    yield numba.config.NUMBA_NUM_THREADS
    numba.set_num_threads(before)


def run_cli(*args: str, cwd: Path | None = None, timeout: float = 300) -> subprocess.CompletedProcess:
    """Run ``python -m clothsim ARGS`` and capture its output."""
    env = dict(os.environ)
    env.pop("DISPLAY", None)
    if WORKER_THREADS is not None:
        env.setdefault("NUMBA_NUM_THREADS", str(WORKER_THREADS))
    return subprocess.run([sys.executable, "-m", "clothsim", *args], cwd=cwd, capture_output=True, text=True,
                          timeout=timeout, env=env)


def warm_copy(site: Path, *drop: str) -> None:
    """The package the tests import, with its kernel cache, copied into ``site`` (a folder for
    PYTHONPATH), less the cache files that the globs ``drop`` name (e.g. ``frame._member-*``): a
    process running the copy loads what the suite has compiled and compiles those kernels alone.
    (The cache is keyed on the package's text, not on where it lies.)"""
    import shutil

    import clothsim

    shutil.copytree(Path(clothsim.__file__).resolve().parent, site / "clothsim",
                    ignore=shutil.ignore_patterns("*.pyc", "*.compiling"))
    for data in ("scenes", "glsl"):
        if not (site / "clothsim" / data).exists():
            shutil.copytree(REPO / data, site / "clothsim" / data)
    for pattern in drop:
        for cached in (site / "clothsim").rglob(f"__pycache__/{pattern}"):
            cached.unlink()


def ctrl_c_as_on_a_terminal() -> None:
    """A child's ``preexec_fn`` for the tests that press Ctrl-C: a suite started as a background
    job (``cmd &`` in a script, where the shell ignores SIGINT for it) passes that on to every
    child, which then rightly ignores Ctrl-C, as any program started so does; a command started
    from a terminal has SIGINT's default."""
    import signal

    signal.signal(signal.SIGINT, signal.SIG_DFL)


def after_ctrl_c(proc: subprocess.Popen, what: str, seconds: float) -> tuple[str, str]:
    """``proc``'s output once it ends, after a Ctrl-C; one still running after ``seconds`` is
    made to print every thread's stack (its ``PYTHONFAULTHANDLER=1`` turns SIGABRT into that),
    and the test fails with it."""
    import signal

    try:
        return proc.communicate(timeout=seconds)
    except subprocess.TimeoutExpired:
        proc.send_signal(signal.SIGABRT)
        _, stderr = proc.communicate(timeout=30)
        raise AssertionError(f"the {what} did not stop within {seconds:g} s of Ctrl-C; its threads:\n{stderr}") from None


def child_pids(pid: int) -> list[int]:
    """The process ids of ``pid``'s children (Linux's /proc)."""
    kids: list[int] = []
    for task in Path(f"/proc/{pid}/task").iterdir():
        try:
            kids += [int(x) for x in (task / "children").read_text().split()]
        except OSError:
            pass
    return kids


def error_line(r: subprocess.CompletedProcess) -> str:
    """The single stderr line of a failed command, checked for shape: exit 2, no traceback."""
    assert r.returncode == 2, (r.returncode, r.stderr)
    assert "Traceback" not in r.stderr, r.stderr
    lines = r.stderr.splitlines()
    assert len(lines) == 1, r.stderr
    assert lines[0].startswith("clothsim: error: "), lines[0]
    return lines[0]


def pytest_sessionstart(session: pytest.Session) -> None:
    """Compile every kernel once, before the test workers start.

    The suite runs on pytest-xdist's workers (``-n auto`` in pyproject.toml); without this, every
    worker compiled the same kernels on first use, each in its own process, and the compile landed
    inside whichever tests came first. ``clothsim compile`` fills the on-disk cache (Numba writes
    each file under a temporary name and renames it, so workers that still compile one meanwhile
    cannot corrupt it); with a warm cache it only loads, in a few seconds. A serial run
    (``-n 0``) skips it: kernels then compile on first use, as for a user.
    """
    config = session.config
    if hasattr(config, "workerinput") or not config.getoption("numprocesses", None):
        return
    started = time.perf_counter()
    done = subprocess.run([sys.executable, "-m", "clothsim", "compile"], capture_output=True, text=True,
                          timeout=1800, cwd=REPO)
    if done.returncode != 0:
        raise pytest.UsageError(f"clothsim compile failed before the tests:\n{done.stderr}")
    config.stash[_COMPILE_SECONDS] = time.perf_counter() - started
    # its report, for the test of `clothsim compile`'s report (the workers inherit the variable)
    report = Path(tempfile.mkdtemp(prefix="clothsim-compile-")) / "report.txt"
    report.write_text(done.stdout)
    os.environ[COMPILE_REPORT] = str(report)


def pytest_unconfigure(config: pytest.Config) -> None:
    report = os.environ.get(COMPILE_REPORT)
    if report and not hasattr(config, "workerinput"):
        shutil.rmtree(Path(report).parent, ignore_errors=True)


def pytest_terminal_summary(terminalreporter: pytest.TerminalReporter, config: pytest.Config) -> None:
    seconds = config.stash.get(_COMPILE_SECONDS, None)
    if seconds is not None:
        terminalreporter.write_line(f"kernels compiled (or loaded) before the tests: {seconds:.1f} s")


_COMPILE_SECONDS = pytest.StashKey[float]()
#: the environment variable naming the file with the report of the ``clothsim compile`` run before the tests
COMPILE_REPORT = "CLOTHSIM_TESTS_COMPILE_REPORT"


@pytest.fixture
def cli():
    return run_cli
