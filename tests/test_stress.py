"""Stress scenes: every one either runs with finite state or stops with the one-line blow-up
error (state restored, still finite); never NaN silently."""

from __future__ import annotations

import numpy as np
import pytest

import clothsim
from clothsim.errors import SimulationBlowUp
from clothsim.scene import INTEGRATORS, load_scene
from clothsim.sim.guard import stability_warning


def grid(n: int, **cloth):
    scene = load_scene("pinned2")
    return scene.with_cloth(num_width_points=n, num_height_points=n, pinned=((0, 0), (n - 1, 0)), **cloth)


def run_or_stop(scene, frames: int) -> str:
    """'ran' or 'stopped'; asserts the contract either way."""
    sim = clothsim.Simulation(scene)
    try:
        sim.step(frames)
    except SimulationBlowUp as exc:
        msg = str(exc)
        assert "\n" not in msg and msg.startswith("simulation blew up at frame ") and ", substep " in msg
        assert np.isfinite(sim.positions).all()
        return "stopped"
    assert np.isfinite(sim.positions).all()
    return "ran"


CASES = {
    "ks10_density1": dict(ks=10.0, density=1.0),
    "ks200000_density1": dict(ks=200000.0, density=1.0),
    "ks200000_density1000": dict(ks=200000.0, density=1000.0),
    "ks10_density1000": dict(ks=10.0, density=1000.0),
    "zero_damping": dict(damping=0.0),
    "thickness_near_zero": dict(thickness=1e-9),
    "no_structural": dict(enable_structural=False),
    "no_shearing": dict(enable_shearing=False),
    "no_bending": dict(enable_bending=False),
}


@pytest.mark.parametrize("integrator", INTEGRATORS)
@pytest.mark.parametrize("case", sorted(CASES))
def test_stress_grid(case: str, integrator: str) -> None:
    scene = grid(10, **CASES[case]).with_simulation(integrator=integrator)
    outcome = run_or_stop(scene, 20)
    if outcome == "stopped":
        # a stop must have been predictable: the guard warned before the run
        assert stability_warning(scene) is not None


@pytest.mark.parametrize("integrator", INTEGRATORS)
def test_implicit_variants_never_stop_on_stiff_light_cloth(integrator: str) -> None:
    scene = grid(10, ks=200000.0, density=1.0).with_simulation(integrator=integrator)
    outcome = run_or_stop(scene, 10)
    if integrator in ("implicit_euler", "xpbd"):
        assert outcome == "ran"
    else:
        assert outcome == "stopped"


@pytest.mark.parametrize("integrator", INTEGRATORS)
def test_every_point_pinned(integrator: str) -> None:
    n = 5
    pins = tuple((x, y) for x in range(n) for y in range(n))
    scene = grid(n).with_cloth(pinned=pins).with_simulation(integrator=integrator)
    sim = clothsim.Simulation(scene)
    start = sim.positions.copy()
    sim.step(5)
    assert np.array_equal(sim.positions, start)


@pytest.mark.parametrize("integrator", INTEGRATORS)
def test_nothing_pinned_falls(integrator: str) -> None:
    scene = grid(8, damping=0.0).with_cloth(pinned=()).with_simulation(integrator=integrator)
    sim = clothsim.Simulation(scene)
    start = sim.positions.mean(axis=0)
    sim.step(10)
    assert np.isfinite(sim.positions).all()
    # Spring forces cancel in the sum, so the centre of mass falls freely: from rest, n steps of
    # dt reach y0 - g dt^2 n(n+1)/2 exactly in every integrator. That is g t dt / 2 = 2e-4 below
    # the continuous fall; rounding stays near 1e-12, so 1e-9 tells the two apart.
    n = 10 * sim.simulation_steps
    centre = sim.positions.mean(axis=0)
    assert centre[1] == pytest.approx(start[1] - 9.8 * sim.dt**2 * n * (n + 1) / 2, abs=1e-9)
    assert centre[[0, 2]] == pytest.approx(start[[0, 2]], abs=1e-9)


def _row_cut(sim, row: int) -> np.ndarray:
    """Mask of the springs joining rows <= row to rows > row."""
    ri = sim.all_springs.i // sim.nw
    rj = sim.all_springs.j // sim.nw
    return (np.minimum(ri, rj) <= row) & (np.maximum(ri, rj) > row)


@pytest.mark.parametrize("integrator", INTEGRATORS)
def test_single_row_of_springs_disabled(integrator: str) -> None:
    """Cut every spring between rows 4 and 5 of a cloth hanging from its row-0 corners: the lower
    half must fall away (no force, no Provot limit across the cut), with finite state throughout."""
    sim = clothsim.Simulation(grid(10).with_simulation(integrator=integrator))
    cut = _row_cut(sim, 4)
    assert cut.sum() == 10 + 2 * 9 + 2 * 10  # structural, shearing, bending (rows 3-5 and 4-6)
    sim.cut_springs(cut)
    assert len(sim.live_springs) == len(sim.springs) - cut.sum()
    spacing = 1.0 / 9
    sim.step(60)  # 0.67 s: a free piece falls 2.2 m
    assert np.isfinite(sim.positions).all()
    rows = sim.positions.reshape(10, 10, 3).mean(axis=1)
    gap = np.linalg.norm(rows[5] - rows[4])
    assert gap > 3 * spacing  # torn apart: Provot would hold the rows within 1.1 spacings
    assert np.linalg.norm(rows[4] - rows[3]) < 1.5 * spacing  # the upper half still hangs together


def test_two_rows_one_row_of_springs() -> None:
    # two rows of points: one row of vertical springs between them, no bending rows at all
    scene = load_scene("pinned2").with_cloth(num_width_points=10, num_height_points=2, pinned=((0, 0), (9, 0)))
    for integrator in INTEGRATORS:
        assert run_or_stop(scene.with_simulation(integrator=integrator), 20) == "ran"


def test_cut_springs_api() -> None:
    scene = grid(6)
    plain = clothsim.Simulation(scene)
    sim = clothsim.Simulation(scene)
    with pytest.raises(ValueError, match="mask needs"):
        sim.cut_springs(np.ones(3, dtype=bool))
    sim.cut_springs(_row_cut(sim, 2))
    sim.enable_bending = False  # cuts survive a re-plan
    sim.enable_bending = True
    sim.step(5)
    plain.step(5)
    assert not np.array_equal(sim.positions, plain.positions)
    sim.restore_springs()
    sim.reset()
    plain.reset()
    sim.step(5)
    plain.step(5)
    assert np.array_equal(sim.positions, plain.positions)


@pytest.mark.parametrize("mode", ["spec", "grid"])
def test_thickness_near_zero_self_collision_modes(mode: str) -> None:
    scene = grid(10, thickness=1e-9).with_simulation(self_collision=mode)
    assert run_or_stop(scene, 10) == "ran"


def test_large_grid_200() -> None:
    scene = grid(200).with_simulation(self_collision="off")
    assert stability_warning(scene) is None
    assert run_or_stop(scene, 2) == "ran"


def test_large_grid_200_implicit() -> None:
    scene = grid(200).with_simulation(self_collision="off", integrator="implicit_euler", simulation_steps=3)
    assert run_or_stop(scene, 1) == "ran"
