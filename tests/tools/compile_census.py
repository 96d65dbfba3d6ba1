"""A pytest plugin that records every Numba compile made in the test processes, test by test, as
JSON lines: which tests pay for which kernels on a cold cache (docs/performance-compile.md, The test
suite). Compiles inside a test's subprocesses (the command-line tests) are not seen.

    PYTHONPATH=tests/tools COMPILE_CENSUS=/tmp/census.jsonl .venv/bin/python -m pytest -p compile_census

Each line: the test's node id and a :class:`clothsim.jit.watch.Compiled` record (kernel, the
groups it was compiled for, seconds, own seconds, depth: 0 for a compile the test asked for).
"""

from __future__ import annotations

import json
import os

import pytest

_recorder = None
_OUT = os.environ.get("COMPILE_CENSUS", "compile_census.jsonl")


def pytest_configure(config: pytest.Config) -> None:
    global _recorder
    from numba.core import event

    from clothsim.jit.watch import CompileRecorder

    _recorder = CompileRecorder()
    event.register("numba:compile", _recorder)


@pytest.hookimpl(hookwrapper=True)
def pytest_runtest_protocol(item: pytest.Item, nextitem: pytest.Item | None):  # noqa: ANN201
    before = len(_recorder.records)
    yield
    made = _recorder.records[before:]
    if made:
        with open(_OUT, "a", encoding="utf-8") as fh:
            for record in made:
                fh.write(json.dumps({"test": item.nodeid, **record.__dict__}) + "\n")
