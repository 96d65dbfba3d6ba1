"""Colliders that turn: the convention of a motion's turn (orientation keyframes, angular velocity),
posing from the one clock, a turning box, plane and mesh carrying and holding the cloth, and the
errors of bad turns."""

from __future__ import annotations

import json
import math

import numpy as np
import pytest

from clothsim.errors import ClothsimError
from clothsim.motion import COLLIDER_MOTION
from clothsim.resources import data_dir
from clothsim.scene import scene_from_dict
from clothsim.sim import Simulation
from clothsim.sim.passes.colliders.moving import placement, turn
from clothsim.validate import At

AT = At("m.json", "motion")


def rx(a: float) -> np.ndarray:
    c, s = math.cos(math.radians(a)), math.sin(math.radians(a))
    return np.array([[1, 0, 0], [0, c, -s], [0, s, c]])


def ry(a: float) -> np.ndarray:
    c, s = math.cos(math.radians(a)), math.sin(math.radians(a))
    return np.array([[c, 0, s], [0, 1, 0], [-s, 0, c]])


def rz(a: float) -> np.ndarray:
    c, s = math.cos(math.radians(a)), math.sin(math.radians(a))
    return np.array([[c, -s, 0], [s, c, 0], [0, 0, 1]])


def euler(a: tuple[float, float, float]) -> np.ndarray:
    """The static ``rotation``'s convention: R = Rz . Ry . Rx."""
    return rz(a[2]) @ ry(a[1]) @ rx(a[0])


def axis_angle(axis: np.ndarray, degrees: float) -> np.ndarray:
    k = np.asarray(axis, dtype=np.float64) / np.linalg.norm(axis)
    kx = np.array([[0, -k[2], k[1]], [k[2], 0, -k[0]], [-k[1], k[0], 0]])
    a = math.radians(degrees)
    return np.eye(3) + math.sin(a) * kx + (1 - math.cos(a)) * kx @ kx


CLOTH = {"width": 0.6, "height": 0.6, "num_width_points": 16, "num_height_points": 16, "thickness": 0.01,
         "orientation": "horizontal", "damping": 0.2, "density": 150, "ks": 5000}


def scene(**objects) -> object:
    return scene_from_dict({"cloth": CLOTH, "simulation": {"self_collision": False}, **objects}, "<test>")


def box(motion: dict, rotation=(0, 0, 0), **extra) -> dict:
    return {"center": [0.6, 0.8, 0.3], "half_extents": [0.9, 0.05, 0.9], "rotation": list(rotation),
            "friction": 1.0, "motion": motion, **extra}


# -- the convention -----------------------------------------------------------------------------

def test_angular_velocity_turns_about_its_world_axis_after_the_static_rotation():
    spec = scene(box=box({"angular_velocity": [30, 0, 40]}, rotation=(20, 0, 0))).boxes[0]
    for t in (0.0, 0.5, 1.7):
        # |w| = 50 degrees a second about (0.6, 0, 0.8)
        expected = axis_angle([0.6, 0, 0.8], 50 * t)
        assert np.allclose(turn(spec, t), expected, atol=1e-12)
        # the box's orientation: the static rotation first, then the turn
        assert np.allclose(turn(spec, t) @ np.array(spec.matrix()), expected @ euler((20, 0, 0)), atol=1e-12)


def test_rotation_keyframes_replace_the_static_rotation_interpolate_the_angles_and_hold():
    frames = {"rotation_keyframes": [[1.0, [10, 0, 0]], [3.0, [10, 40, 90]]]}
    spec = scene(box=box(frames, rotation=(10, 0, 0))).boxes[0]
    static = np.array(spec.matrix())
    # before the first keyframe: held there (here the static orientation itself)
    assert np.allclose(turn(spec, 0.0), np.eye(3), atol=1e-12)
    # between: each angle linear in time (linear in Euler angles, not slerp), the orientation E(angles)
    for t, angles in ((2.0, (10, 20, 45)), (2.5, (10, 30, 67.5)), (1.5, (10, 10, 22.5))):
        assert np.allclose(turn(spec, t) @ static, euler(angles), atol=1e-12)
    # after the last: held
    for t in (3.0, 7.5):
        assert np.allclose(turn(spec, t) @ static, euler((10, 40, 90)), atol=1e-12)
    # one axis: a steady turn (45 degrees a second about z here)
    spec = scene(plane={"point": [0, 0, 0], "normal": [0, 1, 0], "friction": 0.5,
                        "motion": {"rotation_keyframes": [[0, [0, 0, 0]], [2, [0, 0, 90]]]}}).planes[0]
    assert np.allclose(turn(spec, 1.0), rz(45), atol=1e-12)
    assert np.allclose(turn(spec, 1.0) @ spec.normal, [-math.sqrt(0.5), math.sqrt(0.5), 0], atol=1e-12)


def test_a_turn_combines_with_the_translation_about_the_moving_anchor():
    spec = scene(capsule={"a": [0, 0, 0], "b": [1, 0, 0], "radius": 0.1, "friction": 0.5,
                          "motion": {"velocity": [0, 1, 0], "angular_velocity": [0, 0, 90]}}).capsules[0]
    place = placement(spec, 1.0)
    # the midpoint (the anchor) moved 1 m up, the segment turned 90 degrees about z through it
    a = place[:3, :3] @ np.array(spec.a) + place[:3, 3]
    b = place[:3, :3] @ np.array(spec.b) + place[:3, 3]
    assert np.allclose(a, [0.5, 0.5, 0], atol=1e-12) and np.allclose(b, [0.5, 1.5, 0], atol=1e-12)


def test_a_turning_box_is_posed_from_the_one_clock():
    spec = box({"rotation_keyframes": [[0, [0, 0, 0]], [0.2, [0, 90, 0]]], "velocity": [0.5, 0, 0]},
               rotation=(0, 30, 0))
    sim = Simulation(scene(box=spec))
    group = next(g for g in sim._colliders if type(g).__name__ == "Boxes")
    for frames in (3, 5, 20):
        sim.step(frames)
        t = sim.time
        row = group.rows[0]
        matrix = row[6:15].reshape(3, 3)
        s = sim.scene.boxes[0]
        assert np.allclose(matrix, turn(s, t) @ np.array(s.matrix()), atol=1e-12)
        assert np.allclose(row[:3], np.array(s.center) + [0.5 * t, 0, 0], atol=1e-12)


# -- the physics --------------------------------------------------------------------------------

def test_a_turning_box_carries_a_resting_cloth_round_its_axis():
    # a 1.8 m board under the cloth, turning at 90 degrees a second about the vertical axis through
    # (0.6, 0.8, 0.3): the cloth's centroid, off the axis, turns with it (friction 1)
    sim = Simulation(scene(box=box({"angular_velocity": [0, 90, 0]})))
    sim.step(30)
    angles = []
    for _ in range(3):
        sim.step(30)
        c = sim.positions.mean(axis=0)
        assert abs(c[1] - 0.85) < 1e-3  # resting on the top face
        angles.append(math.degrees(math.atan2(-(c[2] - 0.3), c[0] - 0.6)))
    # a third of a second between the two: 30 degrees, counter-clockwise seen from above (+y)
    steps = np.diff(angles)
    assert np.allclose(steps, 30.0, atol=0.2), angles
    radius = np.hypot(*(sim.positions.mean(axis=0)[[0, 2]] - [0.6, 0.3]))
    assert abs(radius - 0.3) < 0.01


def test_a_turning_plane_tilts_a_resting_cloth_with_it():
    plane = {"point": [0.3, 0.9, 0.3], "normal": [0, 1, 0], "friction": 1.0,
             "motion": {"rotation_keyframes": [[0.3, [0, 0, 0]], [0.8, [0, 0, 20]]]}}
    sim = Simulation(scene(plane=plane))
    sim.step(90)
    n = rz(20) @ np.array([0.0, 1.0, 0.0])
    height = (sim.positions - [0.3, 0.9, 0.3]) @ n
    # on the tilted plane, on its side, and not slid off (friction 1 held it)
    assert height.min() > 0.0 and height.max() < 1e-4
    assert np.allclose(sim.positions.mean(axis=0), [0.3, 0.9, 0.3], atol=2e-3)


def _winding(points: np.ndarray, verts: np.ndarray, tris: np.ndarray) -> np.ndarray:
    """The generalised winding number of each point about a closed mesh (1 inside, 0 outside)."""
    a, b, c = (verts[tris[:, k]][None] - points[:, None] for k in range(3))
    la, lb, lc = (np.linalg.norm(x, axis=2) for x in (a, b, c))
    det = np.einsum("ijk,ijk->ij", a, np.cross(b, c))
    den = (la * lb * lc + np.einsum("ijk,ijk->ij", a, b) * lc + np.einsum("ijk,ijk->ij", b, c) * la
           + np.einsum("ijk,ijk->ij", c, a) * lb)
    return (2 * np.arctan2(det, den)).sum(axis=1) / (4 * np.pi)


def test_a_turning_mesh_leaves_no_point_inside():
    # the torus turning at 120 degrees a second about x under a falling cloth: the cloth lands on
    # it, is dragged along +z by its top surface, and no point ever ends up inside it
    cloth = dict(CLOTH, width=1.0, height=1.0, num_width_points=20, num_height_points=20)
    data = {"cloth": cloth, "simulation": {"self_collision": False},
            "mesh": {"path": str(data_dir("scenes") / "torus.obj"), "translate": [0.5, 0.5, 0.5], "friction": 0.3,
                     "motion": {"angular_velocity": [120, 0, 0]}}}
    sim = Simulation(scene_from_dict(data, "<test>"))
    spec = sim.scene.meshes[0]
    verts, tris = spec.local_vertices(), spec.triangles
    for _ in range(10):
        sim.step(10)
        place = placement(spec, sim.time)
        q = place[:3, :3]
        local = (sim.positions - (place[:3, 3] + q @ np.array(spec.translate))) @ q
        assert _winding(local, verts, tris).max() < 0.5, sim.time
    assert sim.positions.mean(axis=0)[2] > 0.52  # carried along +z by the turning surface


# -- bad input ----------------------------------------------------------------------------------

@pytest.mark.parametrize("motion, message", [
    ({}, 'motion: expected "keyframes" or "velocity" (a translation), "rotation_keyframes" or "angular_velocity" '
         '(a turn), or one of each'),
    ({"rotation_keyframes": [[0, [0, 0, 0]]], "angular_velocity": [0, 1, 0]},
     'motion: expected one of "rotation_keyframes" and "angular_velocity", not both'),
    ({"angular_velocity": [0, 40000, 0]}, "motion.angular_velocity[1]: must be <= 36000, got 40000"),
    ({"angular_velocity": [30000, 30000, 0]},
     "motion.angular_velocity: turns at 42426.4 degrees/s, faster than 36000 degrees/s"),
    ({"angular_velocity": [0, "x", 0]}, "motion.angular_velocity[1]:"),
    ({"rotation_keyframes": [[0, [0, 0, 0]], [0.001, [0, 90, 0]]]},
     "motion.rotation_keyframes[1]: turns 90 degrees (|d rx| + |d ry| + |d rz|) in 0.001 s after the keyframe "
     "before it, faster than 36000 degrees/s"),
    ({"rotation_keyframes": [[1, [0, 0, 0]], [0.5, [0, 1, 0]]]},
     "motion.rotation_keyframes[1][0]: keyframe times must increase: 0.5 follows 1"),
    ({"rotation_keyframes": [[0, [0, 0]]]}, "motion.rotation_keyframes[0][1]: expected 3 numbers"),
    ({"rotation_keyframes": [[0, [0, 0, 1e9]]]}, "motion.rotation_keyframes[0][1][2]: must be <= 36000"),
    ({"rotation_keyframes": []}, "motion.rotation_keyframes:"),
])
def test_bad_turns_name_the_field(motion, message):
    with pytest.raises(ClothsimError) as info:
        COLLIDER_MOTION(motion, AT)
    assert str(info.value).startswith(f"m.json: {message}"), str(info.value)


def test_pins_do_not_turn(tmp_path):
    data = {"cloth": dict(CLOTH, pinned=[[0, 0]], pin_motion={"angular_velocity": [0, 10, 0]})}
    path = tmp_path / "pins.json"
    path.write_text(json.dumps(data))
    from clothsim.scene import load_scene

    with pytest.raises(ClothsimError, match='pins.json: cloth.pin_motion: expected exactly one of "keyframes"'):
        load_scene(path)


def test_a_bad_turn_is_one_line_and_exit_code_2(tmp_path):
    from conftest import run_cli

    data = {"cloth": CLOTH, "box": box({"angular_velocity": [0, 0, 100000]})}
    path = tmp_path / "spin.json"
    path.write_text(json.dumps(data))
    done = run_cli("simulate", str(path), "--frames", "1", "--out", str(tmp_path / "s.npz"))
    assert done.returncode == 2
    assert done.stderr.strip().splitlines() == [
        f"clothsim: error: {path}: box.motion.angular_velocity[2]: must be <= 36000, got 100000"]


def test_a_turning_collider_round_trips_through_scene_json():
    from clothsim.colliders import KINDS

    spec = scene(box=box({"keyframes": [[0, [0.6, 0.8, 0.3]]], "rotation_keyframes": [[0, [0, 0, 0]],
                                                                                    [1, [0, 45, 0]]]})).boxes[0]
    again = scene(box=next(k for k in KINDS if k.key == "box").to_json(spec)).boxes[0]
    assert again == spec
    assert spec.motion.ends == 1.0 and spec.motion.turns


def test_a_scene_without_turns_packs_none_so_its_kernels_are_the_ones_it_had():
    from clothsim.scene import load_scene
    from clothsim.sim.passes.colliders import plan_colliders

    for name in ("tablecloth", "curtain", "mesh", "capsule"):
        scene = load_scene(name)
        groups = plan_colliders(scene, np.zeros(2), 1 / 2700)
        assert groups and all(g.turns is None for g in groups), name
    # one turning box: its kind's group turns, the others' (the course's sphere and plane) do not
    groups = plan_colliders(scene_from_dict({"cloth": CLOTH, "box": box({"angular_velocity": [0, 10, 0]}),
                                             "plane": {"point": [0, 0, 0], "normal": [0, 1, 0], "friction": 0.5}},
                                            "<test>"), np.zeros(2), 1 / 2700)
    assert [type(g).__name__ for g in groups if g.turns is not None] == ["Boxes"]


def test_a_turning_sphere_carries_a_cloth_draped_over_it_round():
    # a sphere keeps its shape as it turns, but with friction it carries what rests on it round
    sphere = {"origin": [0.3, 0.6, 0.3], "radius": 0.25, "friction": 1.0, "motion": {"angular_velocity": [0, 90, 0]}}
    sim = Simulation(scene(sphere=sphere))
    sim.step(60)
    corner = sim.positions[0] - [0.3, 0.6, 0.3]
    before = math.degrees(math.atan2(-corner[2], corner[0]))
    sim.step(30)
    corner = sim.positions[0] - [0.3, 0.6, 0.3]
    after = math.degrees(math.atan2(-corner[2], corner[0]))
    assert abs((after - before) % 360 - 30.0) < 3.0, (before, after)
