"""Scene files load as the course writes them, with spec defaults for the extensions."""

from __future__ import annotations

import json
import warnings

import pytest

from clothsim.errors import SceneError
from clothsim.scene import SceneWarning, bundled_scene_names, load_scene, parse_scene
from conftest import SCENES

COURSE = {"width": 1.0, "height": 1.0, "num_width_points": 50, "num_height_points": 50, "thickness": 0.0095,
          "orientation": 0, "pinned": [[0, 0]], "damping": 0.2, "density": 150.0, "ks": 5000.0,
          "enable_structural": True, "enable_shearing": True, "enable_bending": True}


def test_bundled_scenes_are_the_course_scenes():
    assert set(bundled_scene_names()) >= {"pinned2", "pinned4", "sphere", "plane", "selfCollision"}
    for name in ("pinned2", "pinned4", "sphere", "plane", "selfCollision"):
        c = load_scene(SCENES / f"{name}.json").cloth
        assert (c.num_width_points, c.num_height_points, c.density, c.ks, c.damping, c.thickness) == \
            (50, 50, 150.0, 5000.0, 0.2, 0.0095)


def test_bundled_scene_found_by_name():
    assert load_scene("sphere").spheres[0].radius == 0.08


def test_defaults_of_the_simulation_object():
    s = parse_scene(json.dumps({"cloth": COURSE}))
    sim = s.simulation
    assert (sim.frames_per_sec, sim.simulation_steps, sim.gravity, sim.self_collision, sim.seed) == \
        (90.0, 30, (0.0, -9.8, 0.0), "spec", 0)
    assert (sim.integrator, sim.damping_mode, sim.max_stretch) == ("verlet", "spec", 0.1)


def test_colliders_as_lists_and_normal_normalised():
    s = parse_scene(json.dumps({
        "cloth": COURSE,
        "sphere": [{"origin": [0, 0, 0], "radius": 0.1, "friction": 0.3},
                   {"origin": [1, 0, 0], "radius": 0.2, "friction": 0.0}],
        "plane": {"point": [0, 0, 0], "normal": [0, 2, 0], "friction": 0.5},
    }))
    assert [sp.radius for sp in s.spheres] == [0.1, 0.2]
    assert s.planes[0].normal == (0.0, 1.0, 0.0)


def test_self_collision_values():
    for value, mode in ((True, "spec"), (False, "off"), ("spec", "spec"), ("grid", "grid")):
        s = parse_scene(json.dumps({"cloth": COURSE, "simulation": {"self_collision": value}}))
        assert s.simulation.self_collision == mode


def test_unknown_key_inside_an_object_warns_with_its_name():
    cloth = dict(COURSE, colour="red")
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        parse_scene(json.dumps({"cloth": cloth}), "x.json")
    assert any(issubclass(w.category, SceneWarning) and "cloth.colour" in str(w.message) for w in caught)


def test_unknown_top_level_object_is_an_error():
    with pytest.raises(SceneError, match="breeze: unknown top-level object"):
        parse_scene(json.dumps({"cloth": COURSE, "breeze": {}}))


def test_orientation_names():
    assert parse_scene(json.dumps({"cloth": dict(COURSE, orientation="vertical")})).cloth.orientation == 1
