"""The integrators behind Simulation: shared behaviour, stiffness handling, damping modes, guard."""

from __future__ import annotations

import numpy as np
import pytest

import clothsim
from clothsim.errors import SimulationBlowUp
from clothsim.scene import INTEGRATORS, load_scene
from clothsim.sim.guard import estimate_stable_substeps, stability_warning
from clothsim.sim.integrators import IntegratorState, damping_factors, damping_rate


def small(name: str = "pinned4", n: int = 6, **cloth):
    scene = load_scene(name)
    pins = tuple((x * (n - 1) // 49, y * (n - 1) // 49) for x, y in scene.cloth.pinned)
    return scene.with_cloth(num_width_points=n, num_height_points=n, pinned=pins, **cloth)


@pytest.mark.parametrize("integrator", INTEGRATORS)
@pytest.mark.parametrize("mode", ["spec", "rate"])
def test_pinned_fixed_and_free_fall(integrator: str, mode: str) -> None:
    # ks = 0 and no damping: free points fall freely, y = 1 - g t^2 / 2.
    scene = small(ks=0.0, damping=0.0).with_simulation(integrator=integrator, damping_mode=mode, max_stretch=None,
                                                       self_collision="off")
    sim = clothsim.Simulation(scene)
    start = sim.positions.copy()
    sim.step(9)
    t = 9 / 90
    assert np.array_equal(sim.positions[sim.pinned], start[sim.pinned])
    free = ~sim.pinned
    exact = 1.0 - 0.5 * 9.8 * t * t
    tol = 1e-12 if (integrator == "verlet" and mode == "rate") else 9.8 * t * sim.dt
    assert np.allclose(sim.positions[free, 1], exact, atol=tol)
    assert np.allclose(sim.positions[free][:, [0, 2]], start[free][:, [0, 2]])


def test_spec_path_bit_identical_and_never_uses_advance(monkeypatch: pytest.MonkeyPatch) -> None:
    import clothsim.sim.integrators as integrators

    monkeypatch.setattr(integrators, "advance", lambda sim, steps: pytest.fail("spec path must not call advance"))
    scene = small(n=12)
    sim = clothsim.Simulation(scene)
    sim.step(5)
    ref = clothsim.Simulation(scene)
    for _ in range(5):
        assert ref.run_kernel(30)
    assert np.array_equal(sim.positions, ref.positions)
    assert sim.integrator_state is None


def test_symplectic_euler_spec_matches_verlet_closely() -> None:
    # Kick-drift with the spec's damping is algebraically the spec's Verlet (rounding aside).
    scene = small(n=10)
    a = clothsim.Simulation(scene)
    b = clothsim.Simulation(scene.with_simulation(integrator="symplectic_euler"))
    a.step(10)
    b.step(10)
    assert np.abs(a.positions - b.positions).max() < 1e-9


def test_rate_and_spec_damping_agree_at_spec_dt() -> None:
    scene = load_scene("pinned4").with_simulation(self_collision="off")
    a = clothsim.Simulation(scene)
    b = clothsim.Simulation(scene.with_simulation(damping_mode="rate"))
    a.step(90)
    b.step(90)
    d = np.linalg.norm(a.positions - b.positions, axis=1)
    assert d.max() < 5e-4
    assert 1e-7 < np.sqrt((d**2).mean()) < 2e-4


def test_damping_rate_calibration() -> None:
    c = damping_rate(0.2)
    assert np.isclose(np.exp(-c / 2700.0), 0.998)
    sim = clothsim.Simulation(load_scene("pinned4").with_simulation(damping_mode="rate"))
    f, phi, _ = damping_factors(sim)
    assert np.isclose(f, 0.998) and 0.998 < phi < 1.0
    assert np.isfinite(damping_rate(100.0))


def test_implicit_stable_where_verlet_blows_up() -> None:
    scene = load_scene("pinned4").with_cloth(ks=1e6).with_simulation(self_collision="off")
    assert estimate_stable_substeps(scene) > 30
    warning = stability_warning(scene)
    assert warning is not None and "simulation_steps >=" in warning and "implicit_euler" in warning
    with pytest.raises(SimulationBlowUp) as info:
        clothsim.Simulation(scene).step(3)
    msg = str(info.value)
    assert "\n" not in msg and "frame 1, substep" in msg
    sim = clothsim.Simulation(scene.with_simulation(integrator="implicit_euler"))
    sim.step(3)
    assert np.isfinite(sim.positions).all()
    assert sim.positions[:, 1].min() > 0.9  # sagging a little, not exploding
    assert stability_warning(scene.with_simulation(integrator="implicit_euler")) is None


def test_auto_substeps_choice_is_stable() -> None:
    scene = small(n=12, ks=1e7).with_simulation(max_stretch=None, self_collision="off")
    n = estimate_stable_substeps(scene)
    assert n is not None and n > 30
    sim = clothsim.Simulation(scene.with_simulation(simulation_steps=n))
    sim.step(10)
    assert np.isfinite(sim.positions).all()
    assert stability_warning(scene.with_simulation(simulation_steps=n)) is None


def _hang(iterations: int, substeps: int, integrator: str = "xpbd") -> float:
    # 2x2 vertical cloth hanging from its top row: the static sag measures the stiffness.
    scene = load_scene("pinned4").with_cloth(num_width_points=2, num_height_points=2, orientation=1,
                                             pinned=((0, 1), (1, 1)), ks=2000.0, density=4.0, damping=1.0)
    scene = scene.with_simulation(integrator=integrator, simulation_steps=substeps, max_stretch=None,
                                  self_collision="off", damping_mode="rate")
    sim = clothsim.Simulation(scene)
    sim.xpbd_iterations = iterations
    sim.step(180)
    return float(sim.positions[:2, 1].mean())


def test_xpbd_stiffness_independent_of_iterations_and_dt() -> None:
    sags = [-_hang(it, n) for it in (1, 4, 16) for n in (10, 40)]
    implicit = -_hang(0, 30, "implicit_euler")
    assert 1e-3 < implicit < 1e-2
    for s in sags:
        assert abs(s - implicit) < 0.03 * implicit


def test_api_honours_the_three_keys() -> None:
    scene = small(n=8)
    sim = clothsim.Simulation(scene.with_simulation(integrator="xpbd", max_stretch=None, damping_mode="rate"))
    assert sim._stretch_limit < 0
    sim.step(2)
    assert isinstance(sim.integrator_state, IntegratorState)
    results = {}
    for mode in ("spec", "rate"):
        s = clothsim.Simulation(scene.with_simulation(integrator="implicit_euler", damping_mode=mode,
                                                      simulation_steps=5))
        s.step(5)
        results[mode] = s.positions.copy()
    assert not np.array_equal(results["spec"], results["rate"])
    sim.reset()
    assert sim.integrator_state is None


@pytest.mark.parametrize("integrator", INTEGRATORS)
def test_reset_and_rerun_is_deterministic(integrator: str) -> None:
    scene = small("sphere", n=10).with_simulation(integrator=integrator)
    sim = clothsim.Simulation(scene)
    sim.step(20)
    first = sim.positions.copy()
    sim.reset()
    sim.step(20)
    assert np.array_equal(first, sim.positions)
