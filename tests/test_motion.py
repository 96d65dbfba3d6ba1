"""Keyframed and constant-velocity motion: validation and evaluation, in Python and compiled."""

from __future__ import annotations

import numpy as np
import pytest
from numba import njit

from clothsim.errors import SceneError
from clothsim.motion import MOTION, MotionSpec, position_at
from clothsim.validate import At

AT = At("s.json", "sphere.motion")


def test_keyframes_interpolate_linearly_and_hold_at_both_ends():
    track = MOTION({"keyframes": [[0.5, [0, 0, 0]], [1.5, [2, 0, -4]], [2.0, [2, 1, -4]]]}, AT).track()
    assert track.at(0.0).tolist() == [0, 0, 0]  # held before the first
    assert track.at(1.0).tolist() == [1, 0, -2]
    assert track.at(1.75).tolist() == [2, 0.5, -4]
    assert track.at(9.0).tolist() == [2, 1, -4]  # held after the last
    one = MOTION({"keyframes": [[1.0, [3, 2, 1]]]}, AT).track()
    assert one.at(0).tolist() == one.at(5).tolist() == [3, 2, 1]


def test_velocity_moves_from_the_objects_own_position():
    track = MOTION({"velocity": [1, 0, -2]}, AT).track(start=(0.5, 1.0, 0.0))
    assert track.at(0).tolist() == [0.5, 1, 0]
    assert track.at(2).tolist() == [2.5, 1, -4]


def test_compiled_evaluation_matches_python_bit_for_bit():
    rng = np.random.default_rng(3)
    times = np.cumsum(rng.uniform(0.01, 1, 40))
    track = MotionSpec(keyframes=tuple((t, tuple(p)) for t, p in zip(times, rng.normal(size=(40, 3))))).track()
    compiled = njit(position_at)
    a, b = np.empty(3), np.empty(3)
    for t in rng.uniform(-1, times[-1] + 1, 200):
        position_at(track.times, track.points, track.velocity, t, a)
        compiled(track.times, track.points, track.velocity, t, b)
        assert a.tobytes() == b.tobytes()


@pytest.mark.parametrize("value, message", [
    ({}, 'expected exactly one of "keyframes" and "velocity"'),
    ({"keyframes": [[0, [0, 0, 0]]], "velocity": [1, 0, 0]}, 'expected exactly one of "keyframes" and "velocity"'),
    ({"keyframes": []}, "sphere.motion.keyframes: expected a non-empty list of keyframes"),
    ({"keyframes": [[0, [0, 0, 0]], [0, [1, 0, 0]]]}, "sphere.motion.keyframes[1][0]: keyframe times must increase"),
    ({"keyframes": [[1, [0, 0, 0]], [0.5, [1, 0, 0]]]}, "keyframe times must increase: 0.5 follows 1"),
    ({"keyframes": [[-1, [0, 0, 0]]]}, "sphere.motion.keyframes[0][0]:"),
    ({"keyframes": [[0, [0, 0]]]}, "sphere.motion.keyframes[0][1]: expected 3 numbers"),
    ({"keyframes": [[0, [0, "nan", 0]]]}, "sphere.motion.keyframes[0][1][1]:"),
    ({"keyframes": [0.0]}, "sphere.motion.keyframes[0]: expected a keyframe [time, [x, y, z]]"),
    ({"velocity": [float("nan"), 0, 0]}, "sphere.motion.velocity[0]:"),
    ({"velocity": [0, -1001, 0]}, "sphere.motion.velocity[1]: must be >= -1000, got -1001"),
    ({"velocity": [1e300, 0, 0]}, "sphere.motion.velocity[0]: must be <= 1000"),
    ({"keyframes": [[0, [0, 0, 0]], [1, [0, 0, 2e6]]]}, "sphere.motion.keyframes[1][1][2]: must be <= 1e+06"),
    # 1 m in 1e-300 s: a speed whose quotient would overflow, refused without computing it
    ({"keyframes": [[0, [0, 0, 0]], [1e-300, [1, 0, 0]]]},
     "sphere.motion.keyframes[1]: moves 1 m in 1e-300 s after the keyframe before it, faster than 1000 m/s"),
    ({"keyframes": [[0, [0, 0, 0]], [1, [0, 0, 0]], [1.5, [300, 400, 1]]]},
     "sphere.motion.keyframes[2]: moves 500.001 m in 0.5 s"),
    ([1, 2], "sphere.motion: expected an object"),
])
def test_bad_motion_names_the_field(value, message):
    with pytest.raises(SceneError) as info:
        MOTION(value, AT)
    assert message in str(info.value), str(info.value)
    assert str(info.value).startswith("s.json: sphere.motion")


def test_motion_at_the_speed_limit_is_accepted():
    assert MOTION({"velocity": [1000, -1000, 0]}, AT).velocity == (1000.0, -1000.0, 0.0)
    spec = MOTION({"keyframes": [[0, [0, 0, 0]], [0.5, [300, 400, 0]]]}, AT)  # 500 m in 0.5 s
    assert spec.track().at(0.25).tolist() == [150.0, 200.0, 0.0]
