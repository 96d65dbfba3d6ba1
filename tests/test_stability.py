"""``clothsim bench stability`` and the guard's explicit step bound."""

from __future__ import annotations

import json
import math
from pathlib import Path

import pytest

from clothsim.bench.stability import measured_edges, sweep
from clothsim.cli import main
from clothsim.scene import load_scene
from clothsim.sim.guard import estimate_stable_substeps, omega_max, stability_warning, stable_dt


def test_gershgorin_bound_of_the_spec_scene() -> None:
    scene = load_scene("pinned4")
    m = 150.0 / 2500
    # interior point: 4 structural + 4 shearing + 4 bending springs (x0.2) = 8.8 ks
    assert math.isclose(omega_max(scene), math.sqrt(2 * 8.8 * 5000.0 / m))
    # By hand: omega = sqrt(1,466,666.7) = 1211.06 rad/s, dt < 2 / omega = 1.6514 ms, and a
    # 1/90 s frame needs 11.11 / 1.6514 = 6.73 -> 7 substeps.
    assert stable_dt(scene) == pytest.approx(1.6514e-3, rel=1e-4)
    assert estimate_stable_substeps(scene) == 7
    assert stability_warning(scene) is None  # the spec's 30 substeps are well inside
    assert estimate_stable_substeps(scene.with_simulation(integrator="xpbd")) is None


def test_all_pinned_has_no_bound() -> None:
    scene = load_scene("pinned4").with_cloth(num_width_points=2, num_height_points=2,
                                             pinned=((0, 0), (0, 1), (1, 0), (1, 1)))
    assert estimate_stable_substeps(scene) == 1


def test_bound_is_never_optimistic_on_a_small_sweep() -> None:
    runs = sweep(("verlet",), [1e3, 1e5, 1e6], [1.0, 100.0], [1, 2, 4, 8, 16, 32], 6, 0.2, log=lambda *_: None)
    for ks, rho, measured, predicted in measured_edges(runs, "verlet"):
        if measured is not None:
            assert measured <= 2 ** math.ceil(math.log2(predicted)), (ks, rho, measured, predicted)
    assert any(not r["stable"] for r in runs) and any(r["stable"] for r in runs)


def test_command_outputs(tmp_path: Path) -> None:
    out = tmp_path / "s.json"
    png = tmp_path / "s.png"
    rc = main(["bench", "stability", "--ks-count", "3", "--density-count", "2", "--max-substeps", "4", "--grid", "5",
               "--end-time", "0.1", "--json", str(out), "--png", str(png)])
    assert rc == 0
    doc = json.loads(out.read_text())
    assert len(doc["runs"]) == 4 * 3 * 2 * 3
    assert {"verlet", "symplectic_euler", "implicit_euler", "xpbd"} == set(doc["summary"])
    assert all(r["stable"] for r in doc["runs"] if r["integrator"] in ("implicit_euler", "xpbd"))
    assert png.read_bytes()[:4] == b"\x89PNG"
