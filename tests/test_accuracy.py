"""``clothsim bench accuracy``: observed orders and the command's outputs (tiny settings)."""

from __future__ import annotations

import json
from pathlib import Path

import pytest

from clothsim.bench.accuracy import (GROWTH_LIMIT, observed_order, perturbation_growth, problem_scene, run_problem,
                                     two_mass_exact, two_mass_scene, well_conditioned_frames)
from clothsim.cli import main
from clothsim.scene import INTEGRATORS

EXPECTED = {"verlet": (1.8, 2.2), "symplectic_euler": (0.8, 1.2), "implicit_euler": (0.8, 1.2),
            "xpbd": (0.8, 1.2)}


def test_two_mass_orders() -> None:
    runs, orders, ref_err, _ = run_problem("two_mass", INTEGRATORS, [8, 16, 32, 64], 0, 2, 1.0, log=lambda *_: None)
    assert ref_err == 0.0
    for name, (lo, hi) in EXPECTED.items():
        assert lo <= orders[name] <= hi, (name, orders[name])
    assert all(r.error is not None and r.error < 1e-2 for r in runs)


def test_two_mass_closed_form_at_zero() -> None:
    scene = two_mass_scene()
    pos = two_mass_exact(scene, 0.0)
    assert abs(pos[1, 0] - pos[0, 0] - 1.1) < 1e-12


def test_pinned2_buckles_out_of_convergence_pinned4_does_not() -> None:
    """The spec's 50 x 50 pinned2 cloth, hanging from two corners, buckles at ~0.6 s: a 1e-12
    nudge then grows by orders of magnitude, so its 1 s state cannot converge; pinned4 stays tame."""
    tame = perturbation_growth(problem_scene("pinned4", 50), 90, substeps=64)
    wild = perturbation_growth(problem_scene("pinned2", 50), 90, substeps=64)
    assert tame.max() < GROWTH_LIMIT and well_conditioned_frames(tame) == 90
    assert wild.max() > 1e4
    assert 30 < well_conditioned_frames(wild) < 80


def test_observed_order_needs_two_points() -> None:
    assert observed_order([]) is None


def test_command_json_png_and_blow_ups(tmp_path: Path) -> None:
    out = tmp_path / "acc.json"
    png = tmp_path / "wp.png"
    rc = main(["bench", "accuracy", "--max-substeps", "4", "--reference-substeps", "16", "--grid", "8",
               "--end-time", "0.2", "--json", str(out), "--png", str(png)])
    assert rc == 0
    doc = json.loads(out.read_text())
    assert set(doc) >= {"runs", "orders"}
    problems = {"two_mass", "pinned4", "pinned2", "spec_model"}
    assert set(doc["orders"]) == problems
    assert {r["problem"] for r in doc["runs"]} == problems
    for r in doc["runs"]:
        assert set(r) == {"problem", "integrator", "substeps", "seconds", "error"}
        assert r["error"] is None or r["error"] >= 0.0
    assert png.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"
    assert not list(tmp_path.glob(".*tmp*"))


def test_command_rejects_bad_limits(capsys: pytest.CaptureFixture[str]) -> None:
    assert main(["bench", "accuracy", "--max-substeps", "8", "--reference-substeps", "8"]) == 2
