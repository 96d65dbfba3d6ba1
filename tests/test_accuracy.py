"""``clothsim bench accuracy``: observed orders and the command's outputs (tiny settings)."""

from __future__ import annotations

import json
import math
from pathlib import Path

import pytest

import numpy as np

from clothsim.bench.accuracy import (GROWTH_LIMIT, Run, observed_order, perturbation_growth, problem_scene,
                                     run_problem, simulate, two_mass_exact, two_mass_scene, two_mass_start,
                                     well_conditioned_frames)
from clothsim.cli import main
from clothsim.scene import INTEGRATORS
from clothsim.sim import Simulation
from clothsim.sim.solvers import damping_rate

EXPECTED = {"verlet": (1.8, 2.2), "symplectic_euler": (0.8, 1.2), "implicit_euler": (0.8, 1.2),
            "xpbd": (0.8, 1.2)}


def _errors_fall_with_the_step(runs) -> None:
    """Each integrator's error shrinks every time its step is halved (a soft, smooth problem)."""
    by_method: dict[tuple[str, str], list] = {}
    for r in runs:
        by_method.setdefault((r.problem, r.integrator), []).append(r)
    for key, mine in by_method.items():
        errors = [r.error for r in sorted(mine, key=lambda r: r.substeps)]
        assert all(e is not None and math.isfinite(e) and e > 0 for e in errors), (key, errors)
        assert all(b < a for a, b in zip(errors, errors[1:])), (key, errors)


def test_two_mass_orders() -> None:
    runs, orders, _, _ = run_problem("two_mass", INTEGRATORS, [8, 16, 32, 64], 0, 2, 1.0, log=lambda *_: None)
    for name, (lo, hi) in EXPECTED.items():
        assert lo <= orders[name] <= hi, (name, orders[name])
    _errors_fall_with_the_step(runs)


def test_two_mass_closed_form_starts_where_the_run_starts_and_solves_the_ode() -> None:
    """The reference is only as good as its formula: at t = 0 it must be the state the runs start
    from, and at every t it must satisfy r'' = -(2k/m)(r - L) - c r' (checked by finite
    differences, independently of how the formula was solved)."""
    scene = two_mass_scene()
    sim = Simulation(scene.with_simulation(integrator="verlet"))
    two_mass_start(sim)
    assert np.allclose(two_mass_exact(scene, 0.0), sim.positions, rtol=0, atol=1e-15)  # up to rounding

    def r(t: float) -> float:
        pos = two_mass_exact(scene, t)
        return float(pos[1, 0] - pos[0, 0])

    k, m, L = scene.cloth.ks, scene.cloth.width * scene.cloth.height * scene.cloth.density / 4, scene.cloth.width
    c = damping_rate(scene.cloth.damping)
    h = 1e-4
    assert abs(r(h) - r(-h)) / (2 * h) < 1e-6  # starts at rest
    for t in (0.05, 0.3, 0.77):
        rdd = (r(t + h) - 2 * r(t) + r(t - h)) / h**2
        rd = (r(t + h) - r(t - h)) / (2 * h)
        # Both sides are about w0^2 * stretch = 20; the differences are good to h^2 times the
        # fourth derivative (w0^4 * stretch = 4e3), about 4e-5, plus rounding (1e-16 / h^2 = 1e-8).
        assert rdd == pytest.approx(-(2 * k / m) * (r(t) - L) - c * rd, abs=1e-3)


def test_pinned2_buckles_out_of_convergence_pinned4_does_not() -> None:
    """The spec's 50 x 50 pinned2 cloth, hanging from two corners, buckles at ~0.6 s: a 1e-12
    nudge then grows by orders of magnitude, so its 1 s state cannot converge; pinned4 stays tame."""
    tame = perturbation_growth(problem_scene("pinned4", 50), 90, substeps=64)
    wild = perturbation_growth(problem_scene("pinned2", 50), 90, substeps=64)
    assert tame.max() < GROWTH_LIMIT and well_conditioned_frames(tame) == 90
    assert wild.max() > 1e4
    assert 30 < well_conditioned_frames(wild) < 80


def test_observed_order_of_exact_power_laws() -> None:
    def runs(order: float, substeps: list[int]) -> list[Run]:
        return [Run("p", "i", n, 0.0, 3e-2 * (1.0 / n) ** order) for n in substeps]

    assert observed_order([]) is None
    assert observed_order(runs(2.0, [8])) is None
    assert observed_order(runs(2.0, [8, 16, 32, 64])) == pytest.approx(2.0, abs=1e-12)
    assert observed_order(runs(1.0, [1, 2, 4, 8, 16, 32])) == pytest.approx(1.0, abs=1e-12)
    # errors below the floor (the reference's own error) are left out
    assert observed_order(runs(1.0, [8, 16, 32, 64]), floor=3e-2 / 20) == pytest.approx(1.0, abs=1e-12)
    assert observed_order(runs(1.0, [8, 16, 32, 64]), floor=3e-2 / 10) is None


def test_command_json_and_png(tmp_path: Path) -> None:
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
    # Nothing blows up at these settings (stable explicit steps, soft springs): every run has an
    # error, and it falls as the step is halved.
    _errors_fall_with_the_step([Run(**r) for r in doc["runs"]])
    assert png.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"
    assert sorted(tmp_path.iterdir()) == sorted([out, png])  # no temporary left beside them


def test_a_run_that_blows_up_has_no_error() -> None:
    """A run that the guard stops is reported without an error (JSON null), not with a number."""
    stiff = problem_scene("pinned4", 8).with_cloth(ks=1e7)
    seconds, pos = simulate(stiff, "pinned4", "verlet", 1, 5)
    assert pos is None and seconds >= 0.0
    assert Run("pinned4", "verlet", 1, seconds, None).as_dict()["error"] is None
    _, pos = simulate(stiff, "pinned4", "implicit_euler", 1, 5)
    assert pos is not None and np.isfinite(pos).all()


def test_command_rejects_bad_limits(capsys: pytest.CaptureFixture[str]) -> None:
    assert main(["bench", "accuracy", "--max-substeps", "8", "--reference-substeps", "8"]) == 2
