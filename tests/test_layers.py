"""The package's structure: the import layers of pyproject.toml hold, and the Numba internals the
kernels rely on are there."""

from __future__ import annotations

import shutil
import subprocess
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]


def _lint_imports() -> str:
    beside = Path(sys.executable).with_name("lint-imports")
    return str(beside) if beside.exists() else (shutil.which("lint-imports") or "lint-imports")


def test_import_layers_and_no_cycles():
    done = subprocess.run([_lint_imports()], cwd=ROOT,  # reads the contracts in pyproject.toml
                          capture_output=True, text=True, timeout=120)
    assert done.returncode == 0, f"import-linter contracts broken:\n{done.stdout}{done.stderr}"
    assert "0 broken" in done.stdout


def test_numba_private_api_present():
    from clothsim.jit.internals import missing_private_api

    missing = missing_private_api()
    assert not missing, ("this Numba release lacks private API that clothsim.jit.internals uses: "
                         + ", ".join(missing) + "; pin numba to the version in pyproject.toml")


def test_jit_layer_imports_nothing_above_it():
    # the bottom layer loads on its own: no module beyond what ``import clothsim`` loads comes with it
    code = ("import sys, clothsim; before = set(sys.modules); "
            "import clothsim.jit, clothsim.jit.compile, clothsim.jit.internals, clothsim.jit.watch; "
            "print(sorted(m for m in set(sys.modules) - before if m.startswith('clothsim') and "
            "not m.startswith('clothsim.jit')))")
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=60, check=True).stdout
    assert out.strip() == "[]"
