"""The integrators behind Simulation: shared behaviour, stiffness handling, damping modes, guard."""

from __future__ import annotations

import numpy as np
import pytest

import clothsim
from clothsim.errors import SimulationBlowUp
from clothsim.scene import INTEGRATORS, load_scene
from clothsim.sim.guard import estimate_stable_substeps, stability_warning
from clothsim.sim.solvers import IntegratorState, damping_factors, damping_rate


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


@pytest.mark.parametrize("name", ["pinned4", "sphere"])
def test_spec_path_matches_the_numpy_step_and_never_uses_advance(name: str, monkeypatch: pytest.MonkeyPatch) -> None:
    """The compiled frame kernel against the plain NumPy substep of bench/numpy_baseline.py, an
    independent implementation of the same forces, Verlet step and collisions. Provot is off: the
    NumPy version corrects all springs at once (Jacobi), the kernel in place, so they differ
    there by design."""
    import clothsim.sim.solvers as integrators
    from clothsim.bench.numpy_baseline import NumpyCloth

    monkeypatch.setattr(integrators, "advance", lambda sim, steps: pytest.fail("spec path must not call advance"))
    scene = small(name, n=12).with_simulation(max_stretch=None, self_collision="off")
    sim = clothsim.Simulation(scene)
    ref = NumpyCloth(sim)
    for _ in range(90):
        sim.step(1)
        ref.frame()
    assert sim.integrator_state is None
    moved = np.abs(sim.positions - sim.initial_positions).max()
    assert moved > 0.25  # pinned4 sags, the sphere's cloth falls onto the sphere
    if name == "sphere":
        assert np.ptp(sim.positions[:, 1]) > 0.05  # the sphere holds some points up
    # The same arithmetic summed in another order: rounding (up to 3e-12 measured) stays far below
    # 1e-10 of the distance moved, while any difference in the model moves points by a visible
    # fraction of it.
    assert np.abs(sim.positions - ref.pos).max() < 1e-10 * moved


def test_symplectic_euler_spec_matches_verlet_closely() -> None:
    # Kick-drift with the spec's damping is algebraically the spec's Verlet (rounding aside).
    scene = small(n=10)
    a = clothsim.Simulation(scene)
    b = clothsim.Simulation(scene.with_simulation(integrator="symplectic_euler"))
    a.step(10)
    b.step(10)
    assert np.abs(a.positions - b.positions).max() < 1e-9


def test_rate_and_spec_damping_agree_at_spec_dt() -> None:
    """At the spec's dt the rate mode keeps the spec's velocity factor exactly and scales the
    force term by phi = (1 - f)/(c dt) = 0.999: the runs differ by about 1 - phi times how far
    the cloth moved, no more."""
    scene = load_scene("pinned4").with_simulation(self_collision="off")
    a = clothsim.Simulation(scene)
    b = clothsim.Simulation(scene.with_simulation(damping_mode="rate"))
    f, phi, _ = damping_factors(b)
    assert f == pytest.approx(1 - 0.2 / 100, rel=1e-14)
    assert phi == pytest.approx(0.002 / -np.log(0.998), rel=1e-12)  # 0.99899967
    a.step(90)
    b.step(90)
    moved = np.linalg.norm(a.positions - a.initial_positions, axis=1).max()
    d = np.linalg.norm(a.positions - b.positions, axis=1)
    assert 0.0 < d.max() <= (1 - phi) * moved


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


HANG_KS, HANG_MASS = 2000.0, 1.0  # 2x2 points on 1 m x 1 m at density 4: 1 kg a point


def _hang(iterations: int, substeps: int, integrator: str = "xpbd") -> float:
    # 2x2 vertical cloth hanging from its top row: the static sag measures the stiffness.
    scene = load_scene("pinned4").with_cloth(num_width_points=2, num_height_points=2, orientation=1,
                                             pinned=((0, 1), (1, 1)), ks=HANG_KS, density=4.0, damping=1.0)
    scene = scene.with_simulation(integrator=integrator, simulation_steps=substeps, max_stretch=None,
                                  self_collision="off", damping_mode="rate")
    sim = clothsim.Simulation(scene)
    sim.xpbd_iterations = iterations
    sim.step(180)
    return float(sim.positions[:2, 1].mean())


def _static_sag() -> float:
    """The hanging square's equilibrium, solved directly: the bottom-left point (u, -s) held by
    its vertical spring, the shear spring to the far pin and the bottom spring to its mirror
    image (1 - u, -s), against its weight (Newton's method on the two force components)."""
    def force(p: np.ndarray) -> np.ndarray:
        total = np.array([0.0, -HANG_MASS * 9.8])
        for anchor, rest in (((0.0, 1.0), 1.0), ((1.0, 1.0), np.sqrt(2.0)), ((1.0 - p[0], p[1]), 1.0)):
            d = np.asarray(anchor) - p
            length = np.linalg.norm(d)
            total += HANG_KS * (length - rest) * d / length
        return total

    p = np.zeros(2)
    for _ in range(20):
        jac = np.column_stack([(force(p + e) - force(p - e)) / 2e-7 for e in np.eye(2) * 1e-7])
        p = p - np.linalg.solve(jac, force(p))
    assert np.abs(force(p)).max() < 1e-9
    return float(-p[1])


def test_xpbd_stiffness_independent_of_iterations_and_dt() -> None:
    static = _static_sag()  # 3.4957 mm; a vertical spring alone would give 4.9 mm
    # Implicit Euler's fixed point is the static equilibrium whatever dt; 2 s of damping leave
    # no swing to speak of. 1e-3 covers the z jitter of a vertical cloth (1e-3 m -> 1e-6 relative).
    assert -_hang(0, 30, "implicit_euler") == pytest.approx(static, rel=1e-3)
    sags = {it: (-_hang(it, 10), -_hang(it, 40)) for it in (1, 4, 16)}
    for it, (coarse, fine) in sags.items():
        # xpbd is first order: its sag converges to the static one, 4x closer at a 4x smaller step
        ratio = (static - coarse) / (static - fine)
        assert 4**0.8 <= ratio <= 4**1.2, (it, coarse, fine, ratio)
        # and the iterations matter much less than the step: they move the sag by under a
        # quarter of what refining the step does
        for n in range(2):
            assert abs(sags[it][n] - sags[1][n]) < 0.25 * abs(fine - coarse), (it, sags)


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


@pytest.mark.parametrize("n, expected", [(6, 1), (91, 2)])
def test_small_cloths_off_the_spec_path_run_on_one_thread(n: int, expected: int, monkeypatch: pytest.MonkeyPatch,
                                                          all_threads: int) -> None:
    # Each pass of these integrators is its own parallel loop: below PARALLEL_MIN_POINTS (8192) the
    # fork and join cost more than the work, so a frame runs on one thread and the caller's thread
    # count is back afterwards.
    import numba

    from clothsim.sim import solvers as integrators

    if numba.config.NUMBA_NUM_THREADS < 2:
        pytest.skip("Numba has a single thread here: nothing to compare")
    numba.set_num_threads(2)
    seen = []
    monkeypatch.setattr(integrators, "_advance", lambda sim, steps: seen.append(numba.get_num_threads()))
    sim = clothsim.Simulation(small(n=n).with_simulation(integrator="xpbd"))
    sim.step(1)
    assert seen == [expected]
    assert numba.get_num_threads() == 2


def test_implicit_euler_gives_the_same_bits_compiled_or_loaded(tmp_path) -> None:
    # The same scene must give the same bits whether its kernels were compiled in the process or
    # loaded from the cache. The substep and implicit Euler's kernels are compiled in the first run
    # and loaded in the second, the rest loaded in both from a copy of the suite's cache (a cold
    # cache for everything took 21-28 s). Until implicit Euler's rule was called by address, its
    # fast-math CG ran as its own compile in the first run and as the copy linked into the substep
    # in the second, and the two differed in the last bits.
    import os
    import subprocess
    import sys

    from conftest import warm_copy

    site = tmp_path / "site"
    warm_copy(site, "substep.integrate_substeps-*", "implicit.*")
    code = ("import hashlib; from clothsim.scene import load_scene; from clothsim.sim import Simulation; "
            "s = Simulation(load_scene('pinned2').with_simulation(integrator='implicit_euler', "
            "self_collision='off')); s.step(40); print(hashlib.sha256(s.positions.tobytes()).hexdigest())")
    env = {k: v for k, v in os.environ.items() if k not in ("NUMBA_CACHE_DIR", "PYTHONPATH")}
    env["PYTHONPATH"] = str(site)
    runs = [subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, env=env, timeout=300)
            for _ in ("compiled", "loaded")]
    for r in runs:
        assert r.returncode == 0, r.stderr
    assert list(site.rglob("__pycache__/implicit.implicit_update-*.nbi"))  # the first run cached them
    assert runs[0].stdout == runs[1].stdout
