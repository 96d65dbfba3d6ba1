"""Capsule and box colliders and moving colliders: validation, contacts, friction, tunnelling, skips.

Small grids and few frames; the scenes share three kernel plans (a moving sphere or plane; a static
capsule and box; a capsule and a moving box) so the file compiles each only once.
"""

from __future__ import annotations

import json
import math

import numpy as np
import pytest

from clothsim.errors import SceneError
from clothsim.scene import load_scene, scene_from_dict
from clothsim.sim import Simulation
from clothsim.sim.passes.colliders.moving import posed

from conftest import error_line, run_cli

FLOOR = {"point": [0.0, -5.0, 0.0], "normal": [0.0, 1.0, 0.0], "friction": 0.5}


def _cloth(n: int = 16, size: float = 0.6, orientation: int = 0, pinned: list | None = None) -> dict:
    return {"width": size, "height": size, "num_width_points": n, "num_height_points": n, "thickness": 0.01,
            "orientation": orientation, "pinned": pinned or [], "damping": 0.2, "density": 150.0, "ks": 5000.0}


def _scene(**objects) -> dict:
    objects.setdefault("simulation", {"self_collision": False})
    return {"cloth": _cloth(), **objects}


def _box_distance(box, points: np.ndarray) -> np.ndarray:
    """Signed distance of each point from an oriented box (negative inside)."""
    rot = np.array(box.matrix())
    q = (points - np.array(box.center)) @ rot  # into the box's axes
    d = np.abs(q) - np.array(box.half_extents)
    outside = np.linalg.norm(np.maximum(d, 0.0), axis=1)
    return outside + np.minimum(d.max(axis=1), 0.0)


def _capsule_distance(capsule, points: np.ndarray) -> np.ndarray:
    a, b = np.array(capsule.a), np.array(capsule.b)
    t = np.clip((points - a) @ (b - a) / ((b - a) @ (b - a)), 0.0, 1.0)
    return np.linalg.norm(points - (a + t[:, None] * (b - a)), axis=1) - capsule.radius


# ----------------------------------------------------------------------------------------------
# Validation: one line naming the file, the field and the problem


@pytest.mark.parametrize("objects, message", [
    ({"capsule": {"a": [0, 0, 0], "b": [1, 0, 0], "radius": -0.1, "friction": 0.5}},
     "capsule.radius: must be >= 1e-06, got -0.1"),
    ({"capsule": {"a": [0, "nan", 0], "b": [1, 0, 0], "radius": 0.1, "friction": 0.5}}, "capsule.a[1]:"),
    ({"capsule": {"a": [0, 0, 0], "radius": 0.1, "friction": 0.5}}, "capsule.b:"),
    ({"capsule": [{"a": [0, 0, 0], "b": [1, 0, 0], "radius": 0.1, "friction": 2}]}, "capsule[0].friction:"),
    ({"box": {"center": [0, 0, 0], "half_extents": [0.1, 0, 0.1], "friction": 0.5}},
     "box.half_extents[1]: must be >= 1e-06, got 0"),
    ({"box": {"center": [0, 0, 0], "half_extents": [0.1, 0.1], "friction": 0.5}},
     "box.half_extents: expected 3 numbers, got 2"),
    ({"box": {"center": [0, 0, float("inf")], "half_extents": [0.1, 0.1, 0.1], "friction": 0.5}}, "box.center[2]:"),
    ({"box": {"center": [0, 0, 0], "half_extents": [0.1, 0.1, 0.1], "rotation": [0, "x", 0], "friction": 0.5}},
     "box.rotation[1]:"),
    ({"box": {"center": [0, 0, 0], "half_extents": [0.1, 0.1, 0.1], "friction": -1}}, "box.friction:"),
    ({"sphere": {"origin": [0, 0, 0], "radius": 0.1, "friction": 0.5,
                 "motion": {"keyframes": [[1, [0, 0, 0]], [0.5, [1, 0, 0]]]}}},
     "sphere.motion.keyframes[1][0]: keyframe times must increase: 0.5 follows 1"),
    ({"plane": {"point": [0, 0, 0], "normal": [0, 1, 0], "friction": 0.5,
                "motion": {"keyframes": [[0, [0, 0, 0]]], "velocity": [0, 1, 0]}}},
     'plane.motion: expected one of "keyframes" and "velocity", not both'),
    ({"capsule": {"a": [0, 0, 0], "b": [1, 0, 0], "radius": 0.1, "friction": 0.5,
                  "motion": {"velocity": [0, float("nan"), 0]}}}, "capsule.motion.velocity[1]:"),
    ({"box": [{"center": [0, 0, 0], "half_extents": [0.1, 0.1, 0.1], "friction": 0.5},
              {"center": [0, 0, 0], "half_extents": [0.1, 0.1, 0.1], "friction": 0.5,
               "motion": {"keyframes": [[0, [0, 0]]]}}]}, "box[1].motion.keyframes[0][1]: expected 3 numbers"),
    ({"box": {"center": [0, 0, 0], "half_extents": [0.1, 0.1, 0.1], "friction": 0.5, "motion": []}},
     "box.motion: expected an object"),
])
def test_bad_collider_keys_name_the_field(objects: dict, message: str) -> None:
    with pytest.raises(SceneError) as info:
        scene_from_dict(_scene(**objects), "s.json")
    assert str(info.value).startswith("s.json: "), str(info.value)
    assert message in str(info.value), str(info.value)


def test_bad_collider_in_a_file_is_one_line_and_exit_2(tmp_path) -> None:
    path = tmp_path / "bad.json"
    path.write_text(json.dumps(_scene(capsule={"a": [0, 0, 0], "b": [1, 0, 0], "radius": -1, "friction": 0.5})))
    line = error_line(run_cli("simulate", str(path), "--frames", "1", "--out", str(tmp_path / "s.npz")))
    assert line == f"clothsim: error: {path}: capsule.radius: must be >= 1e-06, got -1"
    assert not (tmp_path / "s.npz").exists()


def test_box_rotation_is_rz_ry_rx_in_degrees() -> None:
    box = scene_from_dict(_scene(box={"center": [0, 0, 0], "half_extents": [1, 1, 1], "rotation": [90, 0, 0],
                                      "friction": 0})).boxes[0]
    # about x by 90 degrees: y -> z
    assert np.allclose(np.array(box.matrix()) @ [0, 1, 0], [0, 0, 1])
    box = scene_from_dict(_scene(box={"center": [0, 0, 0], "half_extents": [1, 1, 1], "rotation": [90, 0, 90],
                                      "friction": 0})).boxes[0]
    # x first (y -> z), then z (x -> y): the box's y axis ends on z, its x axis on y
    assert np.allclose(np.array(box.matrix()) @ [0, 1, 0], [0, 0, 1])
    assert np.allclose(np.array(box.matrix()) @ [1, 0, 0], [0, 1, 0])


def test_bundled_scenes_load_with_their_colliders() -> None:
    assert load_scene("capsule").capsules and load_scene("tablecloth").boxes[0].motion is not None
    assert load_scene("curtain").spheres[0].motion is not None


# ----------------------------------------------------------------------------------------------
# Moving spheres and planes


@pytest.mark.parametrize("max_stretch, depth", [(None, 1e-6), (0.1, 1e-3)])
def test_a_sphere_keyframed_through_a_hanging_cloth_leaves_no_point_inside(max_stretch, depth) -> None:
    # A pinned curtain 0.6 m wide; a sphere of radius 0.1 crosses its plane (z = 0) at 1.2 m/s.
    # The collision leaves every point on or outside the sphere; Provot's limit, which the spec
    # runs after the colliders, then pulls some back in by a fraction of a millimetre (0.45 mm
    # measured).
    top = [[i, 15] for i in range(16)]
    keys = [[0.0, [0.3, 0.25, -0.3]], [0.1, [0.3, 0.25, -0.3]], [0.6, [0.3, 0.25, 0.3]]]
    data = {"cloth": _cloth(orientation=1, pinned=top),
            "simulation": {"self_collision": False, "max_stretch": max_stretch},
            "sphere": {"origin": [0.3, 0.25, -0.3], "radius": 0.1, "friction": 0.3, "motion": {"keyframes": keys}}}
    sim = Simulation(scene_from_dict(data))
    deepest = -np.inf
    for _ in range(60):
        sim.step()
        sphere = posed(sim.scene.spheres[0], sim.time)
        assert np.allclose(sim.plan.colliders[0].rows[0, :3], sphere.origin)  # the kernel's pose is the drawn one
        inside = sphere.radius - np.linalg.norm(sim.positions - sphere.origin, axis=1)
        deepest = max(deepest, inside.max())
    assert sim.time == pytest.approx(60 / 90)
    assert sim.scene.spheres[0].motion.track().at(sim.time)[2] == pytest.approx(0.3)
    # pushed along: the cloth's middle went forward with the sphere (it started at z ~ 0)
    assert sim.positions[:, 2].max() > 0.3
    assert deepest < depth, deepest


def _cloth_above_a_plane(velocity: float, size: int = 12) -> Simulation:
    # A horizontal cloth at y = 1, a floor plane starting 5 cm below and rising at `velocity` m/s
    # (keyframes) for 0.2 s, then holding.
    rise = velocity * 0.2
    keys = [[0.0, [0.3, 0.95, 0.3]], [0.2, [0.3, 0.95 + rise, 0.3]]]
    data = {"cloth": _cloth(n=size), "simulation": {"self_collision": False},
            "plane": {"point": [0.3, 0.95, 0.3], "normal": [0, 1, 0], "friction": 0.5, "motion": {"keyframes": keys}}}
    return Simulation(scene_from_dict(data))


@pytest.mark.parametrize("velocity", [2.0, 60.0])
def test_a_fast_moving_plane_does_not_tunnel_through_the_cloth(velocity: float) -> None:
    # 60 m/s is 22 mm a substep, more than twice the cloth's thickness: a test that only looked at
    # where the plane ends each substep would let every point through.
    sim = _cloth_above_a_plane(velocity)
    for _ in range(24):
        sim.step()
        plane_y = posed(sim.scene.planes[0], sim.time).point[1]
        assert sim.positions[:, 1].min() >= plane_y, (sim.frame, sim.positions[:, 1].min(), plane_y)
    assert plane_y == pytest.approx(0.95 + velocity * 0.2)
    assert sim.positions[:, 1].min() > 0.95 + velocity * 0.2 - 1e-9  # carried up, on top


# ----------------------------------------------------------------------------------------------
# Capsules and boxes: contact, far skip


def _dropped(capsule: dict, box: dict, frames: int = 90) -> Simulation:
    sim = Simulation(scene_from_dict({"cloth": _cloth(n=20, size=0.8), "simulation": {"self_collision": False},
                                      "capsule": capsule, "box": box}))
    sim.step(frames)
    return sim


FAR_BOX = {"center": [5.0, 0.0, 5.0], "half_extents": [0.2, 0.2, 0.2], "friction": 0.5}
#: The tests that compile the capsule's and the moving box's plans run on one worker, one after
#: another: on two workers the second waited for the first's compile (up to 11 s) on a cold cache.
SHARED_PLANS = pytest.mark.xdist_group("capsule and moving box plans")


FAR_CAPSULE = {"a": [-5.0, 0.0, 0.0], "b": [-5.0, 1.0, 0.0], "radius": 0.1, "friction": 0.5}


@SHARED_PLANS
def test_cloth_dropped_on_a_capsule_ends_outside_it() -> None:
    capsule = {"a": [-0.1, 0.6, 0.4], "b": [0.9, 0.7, 0.4], "radius": 0.08, "friction": 0.3}
    sim = _dropped(capsule, FAR_BOX)
    dist = _capsule_distance(sim.scene.capsules[0], sim.positions)
    assert dist.min() > -2e-3, dist.min()  # within 2 mm of the surface at worst
    assert dist.min() < 0.02  # it lies on it
    assert sim.positions[:, 1].min() < 0.45  # draped over, both sides hang down
    # the far box never came within the cloth's reach: ruled out at every substep
    assert sim.colliders_skipped >= 90 * 30


def test_cloth_dropped_on_a_rotated_box_ends_outside_it() -> None:
    box = {"center": [0.4, 0.45, 0.4], "half_extents": [0.25, 0.1, 0.15], "rotation": [10, 30, 5], "friction": 0.3}
    sim = _dropped(FAR_CAPSULE, box)
    dist = _box_distance(sim.scene.boxes[0], sim.positions)
    assert dist.min() > -2e-3, dist.min()
    assert dist.min() < 0.02
    assert sim.positions[:, 1].min() < 0.3
    assert sim.colliders_skipped >= 90 * 30  # the far capsule


@SHARED_PLANS
def test_far_capsule_and_box_are_skipped_and_cost_nothing() -> None:
    # Both far away: every test is ruled out by the bounding box, and the cloth falls freely,
    # bit for bit as with no capsule or box.
    sim = _dropped(FAR_CAPSULE, FAR_BOX, frames=10)
    assert sim.colliders_skipped == 10 * 30 * 2
    free = Simulation(scene_from_dict({"cloth": _cloth(n=20, size=0.8), "simulation": {"self_collision": False}}))
    free.step(10)
    assert np.array_equal(sim.positions, free.positions)


def test_profile_reports_capsule_and_box_tests_skipped() -> None:
    from clothsim.sim.profile import Profiler

    sim = Simulation(scene_from_dict({"cloth": _cloth(n=20, size=0.8), "simulation": {"self_collision": False},
                                      "capsule": FAR_CAPSULE, "box": FAR_BOX}))
    prof = Profiler(sim)
    prof.frame()
    assert prof.collider_tests == 60 and prof.collider_skips == 60


# ----------------------------------------------------------------------------------------------
# Moving boxes: friction carries the cloth


def _on_a_moving_box(friction: float) -> Simulation:
    # A cloth dropped 5 cm onto a box top (landed by 0.15 s); from 0.3 s the box slides 0.3 m
    # along +x in 0.6 s (0.5 m/s).
    keys = [[0.0, [0.4, 0.75, 0.4]], [0.3, [0.4, 0.75, 0.4]], [0.9, [0.7, 0.75, 0.4]]]
    box = {"center": [0.4, 0.75, 0.4], "half_extents": [0.6, 0.2, 0.6], "friction": friction,
           "motion": {"keyframes": keys}}
    sim = Simulation(scene_from_dict({"cloth": _cloth(n=20, size=0.8), "simulation": {"self_collision": False},
                                      "capsule": FAR_CAPSULE, "box": box}))
    return sim


@SHARED_PLANS
def test_the_pass_by_pass_profile_gives_the_same_bits_with_a_moving_box() -> None:
    # --profile runs each pass of a substep as its own call; every pass must see the substep's time
    from clothsim.sim.profile import Profiler

    plain, profiled = _on_a_moving_box(0.3), _on_a_moving_box(0.3)
    plain.step(45)  # through the start of the slide at 0.3 s
    profiler = Profiler(profiled)
    for _ in range(45):
        profiler.frame()
    assert profiled.time == plain.time
    assert plain.positions.tobytes() == profiled.positions.tobytes()


@SHARED_PLANS
def test_cloth_on_a_moving_box_is_carried_along_by_friction() -> None:
    sims = {f: _on_a_moving_box(f) for f in (0.0, 0.3, 0.9)}
    moved = {}
    for f, sim in sims.items():
        sim.step(27)  # 0.3 s: landed, box not moving yet
        start = sim.positions[:, 0].mean()
        sim.step(63)  # the slide, and 0.1 s more
        moved[f] = sim.positions[:, 0].mean() - start
        top = posed(sim.scene.boxes[0], sim.time)
        assert _box_distance(top, sim.positions).min() > -1e-3  # still on top, not inside
    # A point resting on the box touches it every few substeps (it sits SURFACE_OFFSET above the
    # face and falls back in), and each touch keeps 1 - friction of its velocity relative to the box.
    assert moved[0.9] == pytest.approx(0.3, abs=0.03)  # moved with the box
    assert 0.1 < moved[0.3] < moved[0.9]
    assert abs(moved[0.0]) < 0.005  # no friction: the box slides away under it


def test_the_kernel_pose_follows_the_track_and_reset_puts_it_back() -> None:
    sim = _on_a_moving_box(0.3)
    sim.step(60)
    boxes = [g for g in sim.plan.colliders if type(g).__name__ == "Boxes"][0].rows
    assert np.allclose(boxes[0, :3], posed(sim.scene.boxes[0], sim.time).center)
    assert boxes[0, 0] == pytest.approx(0.4 + 0.5 * (sim.time - 0.3))
    sim.reset()
    assert sim.time == 0.0 and boxes[0, 0] == 0.4
    again = _on_a_moving_box(0.3)
    sim.step(60)
    again.step(60)
    assert np.array_equal(sim.positions, again.positions)


def test_a_scene_plans_only_the_collider_kinds_it_has_and_no_motion_when_nothing_moves() -> None:
    # what keeps the other kinds' code, and the moving code, out of the compiled kernel; the
    # course's kinds are always there (a plane-less sphere scene shares the course's plan)
    sim = Simulation(load_scene("sphere"))
    assert [type(g).__name__ for g in sim.plan.colliders] == ["Spheres", "Planes"]
    assert [len(g.rows) for g in sim.plan.colliders] == [1, 0]
    assert all(g.tracks is None and g.carry is None for g in sim.plan.colliders)
    assert Simulation(load_scene("pinned2")).plan.colliders == ()
    assert math.isclose(sim.time, 0.0)


# ----------------------------------------------------------------------------------------------
# Export


def test_export_writes_capsules_and_boxes_and_animates_the_moving_ones(tmp_path) -> None:
    pxr = pytest.importorskip("pxr")
    import clothsim

    clothsim.export(_on_a_moving_box(0.3), str(tmp_path / "m.usda"), frames=60, every=30)
    stage = pxr.Usd.Stage.Open(str(tmp_path / "m.usda"))
    box = pxr.UsdGeom.Mesh(stage.GetPrimAtPath("/World/colliders/box_0"))
    assert len(box.GetPointsAttr().Get()) == 24
    (op,) = box.GetOrderedXformOps()
    # the box rests until 0.3 s, then moves at 0.5 m/s along x
    assert list(op.Get(pxr.Usd.TimeCode(0))) == [0, 0, 0]
    assert op.Get(pxr.Usd.TimeCode(60))[0] == pytest.approx(0.5 * (60 / 90 - 0.3))
    capsule = pxr.UsdGeom.Mesh(stage.GetPrimAtPath("/World/colliders/capsule_0"))
    assert not capsule.GetOrderedXformOps()  # static: written where it is
    points = np.array(capsule.GetPointsAttr().Get())
    # the segment (-5, 0, 0)-(-5, 1, 0) with radius 0.1
    assert np.allclose(points.min(axis=0), [-5.1, -0.1, -0.1], atol=1e-6)
    assert np.allclose(points.max(axis=0), [-4.9, 1.1, 0.1], atol=1e-6)

    clothsim.export(_on_a_moving_box(0.3), str(tmp_path / "obj/"), frames=60, every=30)
    static = (tmp_path / "obj" / "colliders.obj").read_text()
    assert "o capsule_0" in static and "o box_0" not in static
    last = (tmp_path / "obj" / "cloth_00060.obj").read_text()
    box_part = last.split("o box_0\n")[1]
    xs = [float(line.split()[1]) for line in box_part.splitlines() if line.startswith("v ")]
    assert len(xs) == 24 and (min(xs) + max(xs)) / 2 == pytest.approx(0.4 + 0.5 * (60 / 90 - 0.3), abs=1e-6)
