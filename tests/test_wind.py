"""Wind (per-triangle drag and lift, gusts) and moving pins: forces against the closed form, the
no-wind bits, direction, determinism, exact pins, validation, and the commands."""

from __future__ import annotations

import json
import math

import numpy as np
import pytest
from numba import njit

import clothsim
from clothsim.errors import FieldError, SceneError
from clothsim.scene import scene_from_dict
from clothsim.sim.passes.forces import add_forces
from clothsim.sim.passes.wind import Wind, air_velocity, incidence, triangles
from clothsim.wind import GUST_MODES, WindSpec, gust_modes, wind_rows

from conftest import error_line, run_cli

INTEGRATORS = ["verlet", "symplectic_euler", "implicit_euler", "xpbd"]


def curtain(wind=None, nw: int = 10, nh: int = 10, **sim) -> dict:
    """A small vertical cloth hanging from its top row (y index nh - 1 is at y = height)."""
    data = {"cloth": {"width": 1.0, "height": 1.0, "num_width_points": nw, "num_height_points": nh,
                      "thickness": 0.01, "orientation": 1, "pinned": [[i, nh - 1] for i in range(nw)],
                      "damping": 0.2, "density": 1.0, "ks": 200.0},
            "simulation": {"simulation_steps": 20, **sim}}
    if wind is not None:
        data["wind"] = wind
    return data


def run(data: dict, frames: int) -> clothsim.Simulation:
    sim = clothsim.Simulation(scene_from_dict(data, "t.json"))
    sim.step(frames)
    return sim


# -- the force on one triangle -------------------------------------------------------------------
def closed_form(a, b, c, v_cloth, wind: WindSpec) -> np.ndarray:
    """Drag 1/2 rho C_d A (v.n)|v.n| n plus lift 1/2 rho C_L A |v|^2 sin(2 alpha) l, from angles."""
    cross = np.cross(b - a, c - a)
    area = np.linalg.norm(cross) / 2
    n = cross / np.linalg.norm(cross)
    v = np.asarray(wind.velocity) - v_cloth
    vn = v @ n
    drag = 0.5 * wind.air_density * wind.drag * area * vn * abs(vn) * n
    speed = np.linalg.norm(v)
    alpha = math.asin(abs(vn) / speed)  # angle of attack: between v and the plane
    across = n - (n @ v) / speed**2 * v  # n's part perpendicular to v
    lift_dir = np.sign(vn) * across / np.linalg.norm(across)
    lift = 0.5 * wind.air_density * wind.lift * area * speed**2 * math.sin(2 * alpha) * lift_dir
    return drag + lift


@pytest.mark.parametrize("velocity, lift", [((3.0, -1.0, 7.0), 0.0), ((3.0, -1.0, 7.0), 0.8),
                                            ((-5.0, 2.0, 0.5), 1.3), ((0.2, 9.0, -4.0), -0.4)])
def test_force_on_one_triangle_is_the_closed_form(velocity, lift):
    rng = np.random.default_rng(5)
    corners = rng.normal(size=(3, 3))
    moved = rng.normal(size=(3, 3)) * 1e-3  # the cloth moves: its velocity counts
    dt = 1 / 2700
    wind = WindSpec(velocity=velocity, drag=1.3, lift=lift, air_density=1.1)
    rows, modes = wind_rows((wind,))
    tris = np.array([[0], [1], [2]], dtype=np.uint64)
    pos = np.ascontiguousarray(corners.T)
    last = np.ascontiguousarray((corners - moved).T)
    group = Wind(rows, modes, tris, *incidence(tris, 3), np.zeros((3, 1)), np.zeros((12, 1)), 1 / dt, dt, np.zeros(2))
    forces = np.zeros((3, 3))
    add_forces((group,), pos, last, forces, 0)  # substep 0 of a clock at zero: t = 0
    expected = closed_form(*corners, moved.mean(axis=0) / dt, wind) / 3
    for p in range(3):  # a third to each corner
        np.testing.assert_allclose(forces[:, p], expected, rtol=1e-12, atol=1e-12)
    assert np.linalg.norm(expected) > 1.0


def test_every_point_gets_a_third_of_each_of_its_triangles():
    tris = triangles(4, 3)
    assert tris.shape == (3, 2 * 3 * 2)
    start, inc = incidence(tris, 12)
    for p in range(12):
        assert sorted(inc[start[p]:start[p + 1]].tolist()) == sorted(np.flatnonzero((tris == p).any(axis=0)).tolist())


# -- no wind, still wind, direction ------------------------------------------------------------------
@pytest.mark.parametrize("integrator", ["verlet", "xpbd"])
def test_still_wind_gives_the_same_bits_as_no_wind(integrator):
    none = run(curtain(integrator=integrator), 4)
    still = run(curtain({"velocity": [0, 0, 0], "turbulence": 0, "drag": 2.0, "lift": 1.0}, integrator=integrator), 4)
    assert still._kernel_args.forces == ()  # no pass at all
    assert np.array_equal(none.positions, still.positions)
    assert np.array_equal(none.last_positions, still.last_positions)
    gusty = run(curtain({"velocity": [0, 0, 0], "turbulence": 2.0}, integrator=integrator), 4)
    assert not np.array_equal(none.positions, gusty.positions)


@pytest.mark.parametrize("integrator", INTEGRATORS)
def test_curtain_is_blown_the_way_the_wind_blows(integrator):
    rest = run(curtain(integrator=integrator), 0).positions.copy()
    for sign in (1.0, -1.0):
        sim = run(curtain({"velocity": [0.0, 0.0, 4.0 * sign]}, integrator=integrator), 15)
        dz = sim.positions[:, 2] - rest[:, 2]
        free = ~sim.pinned
        assert np.sign(dz[free].mean()) == sign
        assert (dz[free] * sign > -1e-3).all()
        assert abs(dz[free]).max() > 0.01


def test_wind_along_the_cloth_barely_pushes_it():
    # edge-on air makes (v . n) ~ 0: the drag is much smaller than face-on
    rest = run(curtain(), 0).positions.copy()
    face = run(curtain({"velocity": [0, 0, 4.0]}), 10).positions - rest
    edge = run(curtain({"velocity": [4.0, 0, 0]}), 10).positions - rest
    assert abs(edge[:, 2]).max() < 0.1 * abs(face[:, 2]).max()


# -- gusts -------------------------------------------------------------------------------------------
@njit
def _gust_samples(rows, modes, pts, ts, out):
    for i in range(pts.shape[0]):
        out[i, 0], out[i, 1], out[i, 2] = air_velocity(rows, modes, 0, pts[i, 0], pts[i, 1], pts[i, 2], ts[i])


def gusts(wind: WindSpec, pts, ts) -> np.ndarray:
    rows, modes = wind_rows((wind,))
    out = np.zeros((len(pts), 3))
    _gust_samples(rows, modes, pts, ts, out)
    return out - np.asarray(wind.velocity)


def test_gusts_are_bounded_smooth_and_drawn_from_the_seed():
    rng = np.random.default_rng(0)
    pts = rng.uniform(-5, 5, (20000, 3))
    ts = rng.uniform(0, 100, 20000)
    wind = WindSpec(velocity=(3.0, 0.0, 1.0), turbulence=2.5, seed=11)
    g = gusts(wind, pts, ts)
    speed = np.linalg.norm(g, axis=1)
    assert speed.max() <= 2.5 + 1e-12
    assert speed.max() > 1.0  # the bound is not vacuous
    assert abs(g.mean(axis=0)).max() < 0.2  # gusts about the mean, not a second mean wind
    assert np.array_equal(g, gusts(wind, pts, ts))
    assert np.array_equal(gust_modes(wind), gust_modes(WindSpec(velocity=(3.0, 0.0, 1.0), turbulence=2.5, seed=11)))
    assert gust_modes(wind).shape == (GUST_MODES, 8)
    assert not np.array_equal(g, gusts(WindSpec(velocity=(3.0, 0.0, 1.0), turbulence=2.5, seed=12), pts, ts))
    # smooth in time and space: a small step changes the gust by at most slope x step
    h = 1e-4
    dt = np.linalg.norm(gusts(wind, pts, ts + h) - g, axis=1)
    dx = np.linalg.norm(gusts(wind, pts + [h, 0, 0], ts) - g, axis=1)
    assert dt.max() < 2.5 * 4 * 20 * h and dx.max() < 2.5 * 4 * 20 * h
    assert dt.max() > 0 and dx.max() > 0


def test_gusty_run_is_deterministic_from_its_seed():
    data = curtain({"velocity": [1.0, 0, 2.0], "turbulence": 3.0, "seed": 4, "lift": 0.5})
    a, b = run(data, 6), run(data, 6)
    assert np.array_equal(a.positions, b.positions)
    data["wind"]["seed"] = 5
    assert not np.array_equal(a.positions, run(data, 6).positions)


def test_the_frame_does_not_depend_on_how_its_substeps_are_grouped():
    # the profile runs one substep per call; a substep's time must not depend on that
    data = curtain({"velocity": [1.0, 0, 2.0], "turbulence": 3.0}, nw=8, nh=8)
    data["cloth"]["pin_motion"] = {"keyframes": [[0, [0, 0, 0]], [0.05, [0.02, 0.01, 0.03]]]}
    whole = run(data, 3)
    pieces = clothsim.Simulation(scene_from_dict(data, "t.json"))
    for _ in range(3 * 20):
        pieces._run(1)
    assert np.array_equal(whole.positions, pieces.positions)
    assert whole.time == pieces.time == pytest.approx(3 / 90)


# -- the setter --------------------------------------------------------------------------------------
def test_wind_is_settable_between_frames():
    data = curtain()
    sim = run(data, 2)
    assert sim.wind == () and sim._kernel_args.forces == ()
    sim.wind = {"velocity": [0, 0, 5.0]}
    assert sim.wind == (WindSpec(velocity=(0.0, 0.0, 5.0)),)
    before = sim.positions[:, 2].mean()
    sim.step(5)
    assert sim.positions[:, 2].mean() > before + 1e-3
    sim.wind = [WindSpec(velocity=(1.0, 0.0, 0.0)), {"velocity": [0, 0, -1], "turbulence": 1}]
    assert len(sim.wind) == 2
    sim.wind = None
    assert sim.wind == () and sim._kernel_args.forces == ()
    with pytest.raises(FieldError, match=r"^wind\.drag: must be >= 0, got -1"):
        sim.wind = {"drag": -1}
    with pytest.raises(FieldError, match=r"^wind\[1\]\.velocity\[2\]: "):
        sim.wind = [{}, {"velocity": [0, 0, float("nan")]}]
    assert sim.wind == ()


# -- moving pins -------------------------------------------------------------------------------------
@pytest.mark.parametrize("integrator", INTEGRATORS)
@pytest.mark.parametrize("motion", [{"keyframes": [[0.0, [0, 0, 0]], [0.03, [0.05, -0.02, 0.1]], [0.06, [0, 0, 0]]]},
                                    {"velocity": [0.4, 0.0, -0.3]}])
def test_pinned_points_are_exactly_at_rest_plus_the_offset(integrator, motion):
    data = curtain(integrator=integrator, nw=8, nh=8)
    data["cloth"]["pin_motion"] = motion
    data["simulation"]["simulation_steps"] = 7
    sim = clothsim.Simulation(scene_from_dict(data, "t.json"))
    track = sim.scene.cloth.pin_motion.track()
    rest = sim.initial_positions[sim.pinned]
    for _ in range(40):  # every substep, through and past the keyframes
        sim._run(1)
        assert np.array_equal(sim.positions[sim.pinned], rest + track.at(sim.time))
    free = sim.positions[~sim.pinned]
    assert np.isfinite(free).all() and abs(free - sim.initial_positions[~sim.pinned]).max() > 1e-3


def test_pins_move_the_cloth_and_reset_puts_them_back():
    data = curtain(nw=8, nh=8)
    data["cloth"]["pin_motion"] = {"keyframes": [[0.0, [0.1, 0, 0]], [0.2, [0.3, 0, 0]]]}
    sim = run(data, 0)
    # at time 0 the whole cloth starts moved by offset(0), so the pins do not jump
    assert np.array_equal(sim.positions, sim.initial_positions + [0.1, 0, 0])
    sim.step(30)
    assert sim.positions[~sim.pinned][:, 0].mean() - sim.initial_positions[~sim.pinned][:, 0].mean() > 0.25
    sim.reset()
    assert sim.time == 0.0
    assert np.array_equal(sim.positions, sim.initial_positions + [0.1, 0, 0])


# -- validation --------------------------------------------------------------------------------------
@pytest.mark.parametrize("wind, message", [
    ({"velocity": [1, 2]}, "wind.velocity: expected 3 numbers, got 2"),
    ({"velocity": [1, "x", 0]}, "wind.velocity[1]: expected a number"),
    ({"velocity": [1e9, 0, 0]}, "wind.velocity[0]: must be <= 1000"),
    ({"turbulence": -1}, "wind.turbulence: must be >= 0"),
    ({"turbulence": float("nan")}, "wind.turbulence: must be >= 0, got nan"),
    ({"drag": -0.5}, "wind.drag: must be >= 0"),
    ({"lift": 1000}, "wind.lift: must be <= 100"),
    ({"air_density": -1.2}, "wind.air_density: must be >= 0"),
    ({"seed": -3}, "wind.seed: must be >= 0"),
    ({"seed": 1.5}, "wind.seed: expected an integer"),
    ({"turbulence_scale": 0}, "wind.turbulence_scale: must be > 0"),
    ("strong", "wind: expected an object"),
    ([{}, {"drag": True}], "wind[1].drag: expected a number, got true"),
])
def test_bad_wind_names_the_field(wind, message):
    with pytest.raises(SceneError) as info:
        scene_from_dict(curtain(wind), "s.json")
    assert str(info.value).startswith(f"s.json: {message}"), str(info.value)


@pytest.mark.parametrize("motion, pinned, message", [
    ({"keyframes": [[0, [0, 0, 0]], [0, [1, 0, 0]]]}, True, "cloth.pin_motion.keyframes[1][0]: keyframe times must increase"),
    ({"velocity": [1, 0]}, True, "cloth.pin_motion.velocity: expected 3 numbers"),
    ({}, True, 'cloth.pin_motion: expected exactly one of "keyframes" and "velocity"'),
    ({"velocity": [1, 0, 0]}, False, "cloth.pin_motion: the cloth has no pinned points to move"),
    (3, True, "cloth.pin_motion: expected an object"),
])
def test_bad_pin_motion_names_the_field(motion, pinned, message):
    data = curtain()
    data["cloth"]["pin_motion"] = motion
    if not pinned:
        data["cloth"]["pinned"] = []
    with pytest.raises(SceneError) as info:
        scene_from_dict(data, "s.json")
    assert str(info.value).startswith(f"s.json: {message}"), str(info.value)


def test_unknown_wind_key_is_warned_and_ignored():
    with pytest.warns(UserWarning, match=r"s\.json: wind\.gusts: unknown key, ignored"):
        scene = scene_from_dict(curtain({"velocity": [1, 0, 0], "gusts": 2}), "s.json")
    assert scene.winds == (WindSpec(velocity=(1.0, 0.0, 0.0)),)


def test_cli_refuses_a_bad_wind_in_one_line(tmp_path):
    path = tmp_path / "bad.json"
    path.write_text(json.dumps(curtain({"velocity": [0, 0, 1], "air_density": -1})))
    line = error_line(run_cli("simulate", str(path), "--frames", "1", "--out", str(tmp_path / "s.npz")))
    assert line == f"clothsim: error: {path}: wind.air_density: must be >= 0, got -1"
    assert not (tmp_path / "s.npz").exists()


# -- the commands ------------------------------------------------------------------------------------
def test_resolved_scene_json_round_trips_wind_and_pin_motion():
    from clothsim.sweeps.params import scene_json

    data = curtain([{"velocity": [1, 2, 3], "turbulence": 0.5, "seed": 9}, {"lift": 0.3, "velocity": [0, 0, 1]}])
    for motion in ({"velocity": [0.1, 0, 0]}, {"keyframes": [[0, [0, 0, 0]], [1.5, [0, 0.2, 0]]]}):
        data["cloth"]["pin_motion"] = motion
        scene = scene_from_dict(data, "t.json")
        again = scene_from_dict(json.loads(json.dumps(scene_json(scene))), "t.json")
        assert again.winds == scene.winds and again.cloth == scene.cloth
    assert "wind" not in scene_json(scene_from_dict(curtain(), "t.json"))


def test_flag_from_the_command_line_and_a_wind_sweep(tmp_path):
    small = json.loads((clothsim.scene.resolve_scene_path("flag")).read_text())
    small["cloth"].update(num_width_points=9, num_height_points=6, pinned=[[0, j] for j in range(6)])
    path = tmp_path / "flag.json"
    path.write_text(json.dumps(small))
    r = run_cli("simulate", "flag", "--frames", "2", "--out", str(tmp_path / "f.npz"))
    assert r.returncode == 0, r.stderr
    out = tmp_path / "runs"
    r = run_cli("sweep", str(path), "--set", "wind.velocity.2=3,-3", "--frames", "6", "--workers", "1", "-o", str(out))
    assert r.returncode == 0, r.stderr
    records = [json.loads(line) for line in (out / "manifest.jsonl").read_text().splitlines()]
    assert [r["params"] for r in records] == [{"wind.velocity.2": 3}, {"wind.velocity.2": -3}]
    z = {}
    for rec in records:
        with np.load(out / rec["path"]) as run_file:
            scene = json.loads(str(run_file["scene"]))
            z[rec["params"]["wind.velocity.2"]] = run_file["positions"][-1][:, 2].mean()
            assert scene["wind"][0]["velocity"][2] == rec["params"]["wind.velocity.2"]
    assert z[3] > 0 > z[-3]


def test_profiled_run_gives_the_same_bits_and_names_skipped_passes():
    from clothsim.sim.profile import Profiler

    data = curtain({"velocity": [1.0, 0, 2.0], "turbulence": 3.0}, nw=8, nh=8)
    data["cloth"]["pin_motion"] = {"velocity": [0, 0.2, 0]}
    plain = run(data, 3)
    sim = clothsim.Simulation(scene_from_dict(data, "t.json"))
    prof = Profiler(sim)
    for _ in range(3):
        prof.frame()
    assert np.array_equal(plain.positions, sim.positions)
    assert "wind" not in prof.skipped() and "moving pins" not in prof.skipped()
    skipped = Profiler(run(curtain(), 0)).skipped()
    assert skipped["wind"] == "scene has no wind (or only still air)"
    assert skipped["moving pins"] == "cloth has no pin_motion"


def test_implicit_euler_sees_the_moving_pins_velocity():
    # its stiffness term K v0 uses every point's velocity, the pins' too
    data = curtain(integrator="implicit_euler", nw=6, nh=6)
    data["cloth"]["pin_motion"] = {"velocity": [0.4, 0.0, -0.3]}
    sim = run(data, 2)
    vel = sim.integrator_state.vel[:, sim.pinned]
    np.testing.assert_allclose(vel.T, np.tile([0.4, 0.0, -0.3], (6, 1)), atol=1e-9)
