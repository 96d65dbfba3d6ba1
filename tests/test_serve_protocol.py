"""The serve page's messages, its camera and upload names, without a server, GL or a browser."""

from __future__ import annotations

import json
import math

import numpy as np
import pytest

from clothsim.errors import FieldError
from clothsim.render.camera import default_position
from clothsim.render.settings import RenderSettings
from clothsim.serve.engine import upload_label
from clothsim.serve.orbit import MAX_ELEVATION, Orbit
from clothsim.serve.protocol import LOOK_FIELDS, SIM_FIELDS, error_reply, look_overrides, parse_message

SCENES = ("pinned2", "sphere")


def test_every_message_type_parses_to_its_checked_fields():
    assert parse_message('{"type": "set", "field": "ks", "value": 500}') == {"type": "set", "field": "ks", "value": 500}
    assert parse_message(b'{"type": "look", "field": "phong.k_s", "value": 0.2}')["field"] == "phong.k_s"
    for kind in ("toggle_pause", "step", "restart", "reset_camera"):
        assert parse_message(json.dumps({"type": kind})) == {"type": kind}
    assert parse_message('{"type": "rotate", "dx": 3, "dy": -4.5}') == {"type": "rotate", "dx": 3.0, "dy": -4.5}
    assert parse_message('{"type": "zoom", "factor": 1.1}')["factor"] == 1.1
    assert parse_message('{"type": "scene", "name": "sphere"}', SCENES)["name"] == "sphere"
    assert parse_message('{"type": "record", "action": "start"}')["format"] == "mp4"  # the default


@pytest.mark.parametrize("text, message", [
    ("", "message: not valid JSON: Expecting value"),
    ("{", "message: not valid JSON: Expecting property name enclosed in double quotes"),
    (b"\xff\xfe", "message: not UTF-8 text"),
    ("[1, 2]", "message: expected a JSON object, got a list of 2 items"),
    ("{}", "message: type: missing required field"),
    ('{"type": "explode"}', 'message: type: expected one of: set, look, toggle_pause, step, restart, reset_camera, '
                            'rotate, pan, zoom, scene, record; got "explode"'),
    ('{"type": "set", "field": "thickness", "value": 1}', "message: field: expected one of: " + ", ".join(SIM_FIELDS)
     + '; got "thickness"'),
    ('{"type": "set", "field": "ks"}', "message: value: missing required field"),
    ('{"type": "look", "field": "textures.color", "value": "/etc/passwd"}',
     "message: field: expected one of: " + ", ".join(LOOK_FIELDS) + '; got "textures.color"'),
    ('{"type": "step", "extra": 1}', "message: extra: unknown key"),
    ('{"type": "rotate", "dx": "left", "dy": 0}', 'message: dx: expected a number, got "left"'),
    ('{"type": "pan", "dx": 1e300, "dy": 0}', "message: dx: must be <= 100000, got 1e+300"),
    ('{"type": "zoom", "factor": 0}', "message: factor: must be >= 0.01, got 0"),
    ('{"type": "zoom", "factor": NaN}', "message: factor: must be >= 0.01, got nan"),
    ('{"type": "scene", "name": "../../etc/passwd"}', 'message: name: expected one of: pinned2, sphere; '
                                                      'got "../../etc/passwd"'),
    ('{"type": "record", "action": "start", "format": "avi"}', 'message: format: expected one of: mp4, gif; got "avi"'),
    ("[" * 100000 + "]" * 100000, "message: not valid JSON: nested too deeply or too large"),
])
def test_a_malformed_message_is_one_line_naming_the_field(text, message):
    with pytest.raises(FieldError) as err:
        parse_message(text, SCENES)
    assert str(err.value) == message
    assert "\n" not in str(err.value)


def test_look_fields_reach_the_render_rules_as_a_render_object():
    assert look_overrides("phong.k_s", 0.2) == {"phong": {"k_s": 0.2}}
    assert look_overrides("shader", "bump") == {"shader": "bump"}
    base = RenderSettings()
    for field, value, attr in (("phong.k_a", 0.3, "k_a"), ("phong.p", 8, "p"), ("normal_scaling", 4, "normal_scaling"),
                               ("height_scaling", 0.02, "height_scaling"), ("color", "#ff0000", "color"),
                               ("phong.terms", ["specular"], "terms"), ("shader", "wireframe", "shader")):
        assert field in LOOK_FIELDS
        changed = base.with_overrides(look_overrides(field, value), source="message")
        assert getattr(changed, attr) != getattr(base, attr)
    with pytest.raises(FieldError, match=r"^message: phong\.k_s: must be >= 0, got -1$"):
        base.with_overrides(look_overrides("phong.k_s", -1), source="message")
    with pytest.raises(FieldError, match=r"^message: shader: expected one of: wireframe, .*; got \"toon\"$"):
        base.with_overrides(look_overrides("shader", "toon"), source="message")


def test_error_reply_is_json_with_the_line():
    assert json.loads(error_reply("cloth.ks: must be >= 0, got -1")) == {
        "type": "error", "message": "cloth.ks: must be >= 0, got -1"}


def test_the_default_orbit_is_the_renderers_default_camera():
    orbit = Orbit.course_default(1.0, 1.0)
    positions = np.random.default_rng(1).random((20, 3))
    target = orbit.target(positions)
    np.testing.assert_allclose(target, positions.mean(axis=0))
    np.testing.assert_allclose(orbit.position(target), default_position(target, 1.0, 1.0), atol=1e-12)


def test_orbit_rotate_pan_zoom_and_a_scene_camera():
    positions = np.zeros((4, 3))
    orbit = Orbit.course_default(1.0, 1.0)
    d0 = orbit.distance
    orbit.rotate(0, 1e6)  # never over the pole
    assert orbit.elevation == pytest.approx(MAX_ELEVATION)
    orbit.rotate(200, 0)
    assert -math.pi <= orbit.azimuth <= math.pi
    orbit.zoom(0.5)
    assert orbit.distance == pytest.approx(d0 / 2)
    orbit.zoom(1e-9)
    assert orbit.distance > 0
    # a pan moves the target across the view, perpendicular to the view direction
    orbit = Orbit.course_default(1.0, 1.0)
    orbit.pan(100, 0, 35.0, 800)
    moved = orbit.target(positions)
    assert np.linalg.norm(moved) > 0 and abs(moved @ orbit.direction()) < 1e-12
    # a scene's fixed camera is reproduced exactly
    pos, tgt = np.array([1.0, 2.0, 3.0]), np.array([0.5, 0.2, 0.1])
    fixed = Orbit.looking(pos, tgt, fixed=True)
    np.testing.assert_allclose(fixed.position(fixed.target(positions)), pos, atol=1e-12)


@pytest.mark.parametrize("name, label", [
    ("mine.json", "mine.json"), ("../../etc/passwd", "passwd"), ("C:\\Users\\x\\s.json", "s.json"),
    (None, "uploaded scene"), ("", "uploaded scene"), ("a\nb.json", "uploaded scene"), ("x" * 200, "uploaded scene"),
])
def test_an_uploaded_scene_is_named_by_its_base_name_only(name, label):
    assert upload_label(name) == label
