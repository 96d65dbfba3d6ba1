"""A clip's frames with the simulation run ahead in a thread: the same states, images and bytes as
the serial loop, errors in order, and the thread stopped when the drawing stops."""

from __future__ import annotations

import threading

import numpy as np
import pytest

from clothsim.errors import ClothsimError
from clothsim.render.pipeline import ClipStats, clip_frames
from clothsim.scene import load_scene, scene_from_dict
from clothsim.sim.rest import RestDetector
from clothsim.sim.simulation import Simulation

SMALL = {"cloth": {"width": 1, "height": 1, "num_width_points": 12, "num_height_points": 10, "thickness": 0.01,
                   "orientation": 0, "damping": 0.2, "density": 150, "ks": 5000},
         "plane": {"point": [0.5, 0.95, 0.5], "normal": [0, 1, 0], "friction": 0.5}}


def _clip(scene, frames: int, every: int, ahead: int, rest: bool = False):
    sim = Simulation(scene)
    detector = None
    if rest:
        s = scene.simulation
        detector = RestDetector(s.rest_tolerance, s.rest_frames)
        detector.update(sim._pos)
    stats = ClipStats()
    states = [None if s is None else (s.frame, s.time, s.positions.copy())
              for s in clip_frames(sim, frames, every, False, detector, stats, ahead=ahead)]
    return states, stats


@pytest.mark.parametrize("every", [1, 3])
def test_threaded_clip_draws_the_serial_clips_states(every):
    scene = scene_from_dict(SMALL)
    serial, s_stats = _clip(scene, 20, every, ahead=0)
    threaded, t_stats = _clip(scene, 20, every, ahead=2)
    assert len(serial) == len(threaded) == 20 // every + 1
    for a, b in zip(serial, threaded):
        assert a[0] == b[0] and a[1] == b[1]
        assert np.array_equal(a[2], b[2])  # bit for bit
    assert [s[0] for s in serial] == list(range(0, 21, every))
    assert s_stats.simulated == t_stats.simulated == 20


def test_threaded_clip_reuses_the_image_at_rest_where_the_serial_one_does():
    # A low rest tolerance on a short, stiff drop: the cloth comes to rest within the clip.
    scene = scene_from_dict({**SMALL, "simulation": {"rest_tolerance": 1e-3, "rest_frames": 3}})
    serial, s_stats = _clip(scene, 240, 2, ahead=0, rest=True)
    threaded, t_stats = _clip(scene, 240, 2, ahead=2, rest=True)
    assert s_stats.rested_at is not None and s_stats.rested_at == t_stats.rested_at
    assert s_stats.simulated == t_stats.simulated < 240
    assert [s is None for s in serial] == [s is None for s in threaded]
    assert serial[-1] is None  # later frames reuse the image
    for a, b in zip(serial, threaded):
        if a is not None:
            assert np.array_equal(a[2], b[2])


def test_an_error_in_the_simulation_thread_reaches_the_drawing_thread_after_the_frames_before_it():
    sim = Simulation(scene_from_dict(SMALL))
    real_step = sim.step

    def step(frames: int = 1) -> None:
        if sim.frame == 5:
            raise ClothsimError("the simulation blew up at frame 5")
        real_step(frames)

    sim.step = step
    seen = []
    with pytest.raises(ClothsimError, match="frame 5"):
        for s in clip_frames(sim, 10, 1, False, None, ClipStats(), ahead=2):
            seen.append(s.frame)
    assert seen == [0, 1, 2, 3, 4, 5]


def test_the_simulation_thread_ends_when_the_drawing_stops():
    sim = Simulation(load_scene("pinned2"))
    frames = clip_frames(sim, 1_000_000, 1, False, None, ClipStats(), ahead=2)
    next(frames)
    frames.close()  # what a failed sink or Ctrl-C does to the loop
    assert not [t for t in threading.enumerate() if t.name == "clothsim-simulate"]
    assert sim.frame < 100


def test_the_drawings_kernels_are_loaded_before_the_simulation_thread_starts(monkeypatch):
    # Numba's compiling and cache loading is not thread-safe: the drawing's first kernel call must
    # not load its kernel while the simulation thread loads the frame kernel (seen once in CI:
    # "generator already executing" in Numba's typing registry).
    from clothsim.render import pipeline

    events = []
    warm = pipeline.warm_side_kernels
    start = threading.Thread.start

    def warming() -> None:
        events.append("kernels loaded")
        warm()

    def starting(self):  # noqa: ANN001, ANN202
        events.append(f"{self.name} started")
        return start(self)

    monkeypatch.setattr(pipeline, "warm_side_kernels", warming)
    monkeypatch.setattr(threading.Thread, "start", starting)
    _clip(scene_from_dict(SMALL), 2, 1, ahead=2)
    assert events[:2] == ["kernels loaded", "clothsim-simulate started"]
