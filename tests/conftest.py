"""Shared fixtures: paths and a helper to run the real CLI in a subprocess."""

from __future__ import annotations

import os
import subprocess
import sys
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


def run_cli(*args: str, cwd: Path | None = None, timeout: float = 300) -> subprocess.CompletedProcess:
    """Run ``python -m clothsim ARGS`` and capture its output."""
    env = dict(os.environ)
    env.pop("DISPLAY", None)
    return subprocess.run([sys.executable, "-m", "clothsim", *args], cwd=cwd, capture_output=True, text=True,
                          timeout=timeout, env=env)


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


@pytest.fixture
def cli():
    return run_cli
