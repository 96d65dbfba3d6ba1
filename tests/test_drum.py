"""The bundled ``drum`` scene: a towel read from an OBJ tumbling in an open drum (a mesh collider
with baffles) that turns about its axis between two end planes."""

from __future__ import annotations

import json

import numpy as np

from clothsim.objshapes import DRUM
from clothsim.resources import data_dir
from clothsim.scene import load_scene, scene_from_dict
from clothsim.sim import Simulation

SCENE = data_dir("scenes") / "drum.json"
#: Frames of the first baffle pass: the towel falls to the bottom, is carried up past the axis's
#: height and falls off again (at 120 degrees/s a baffle comes by every second, 90 frames).
FRAMES = 150


def drum_scene(degrees_per_second: float):
    data = json.loads(SCENE.read_text(encoding="utf-8"))
    data["mesh"]["motion"]["angular_velocity"] = [0.0, 0.0, degrees_per_second]
    return scene_from_dict(data, str(SCENE))


def run(scene) -> tuple[np.ndarray, Simulation]:
    """The towel's centre of mass at every frame (frame 0 first); asserts at each frame that every
    point is inside the drum: within its radius of the axis and between the end planes."""
    drum = scene.meshes[0]
    axis = np.asarray(drum.translate)[:2]
    ends = sorted(p.point[2] for p in scene.planes)  # the end planes z = const
    sim = Simulation(scene)
    centres = []
    for frame in range(FRAMES + 1):
        if frame:
            sim.step(1)
        p = sim.positions
        r = np.hypot(*(p[:, :2] - axis).T)
        assert r.max() < DRUM[0], f"frame {frame}: a point {r.max():.4f} m from the axis, beyond the drum's wall"
        assert ends[0] <= p[:, 2].min() and p[:, 2].max() <= ends[1], (
            f"frame {frame}: z in [{p[:, 2].min():.4f}, {p[:, 2].max():.4f}], beyond the end planes {ends}")
        centres.append(p.mean(axis=0))
    return np.array(centres), sim


def test_the_drum_is_an_open_mesh_between_two_end_planes():
    scene = load_scene("drum")
    assert len(scene.meshes) == 1 and not scene.meshes[0].closed  # a closed one would push the towel out
    assert scene.meshes[0].motion.angular_velocity == (0.0, 0.0, 120.0)
    assert sorted(p.normal[2] for p in scene.planes) == [-1.0, 1.0]
    assert scene.simulation.self_collision == "contact"


def test_the_turning_drum_carries_the_towel_up_and_drops_it():
    centres, sim = run(drum_scene(120.0))
    still, _ = run(drum_scene(0.0))
    axis_y = load_scene("drum").meshes[0].translate[1]
    top = int(np.argmax(centres[:, 1]))
    # carried round by the wall and the baffles to above the axis (started 0.1 m below it) ...
    assert centres[top, 1] > axis_y + 0.05, f"the towel's centre rose only to {centres[top, 1]:.3f} m"
    assert centres[top, 0] > 0.1  # up the side the drum's floor turns towards (+x for a turn about +z)
    # ... then it falls back off
    assert centres[top:, 1].min() < centres[top, 1] - 0.15, "the towel never fell back"
    # a drum that does not turn leaves it lying at the bottom
    assert still[30:, 1].max() < axis_y - 0.2, f"in a still drum the towel's centre rose to {still[30:, 1].max():.3f} m"
    assert sim.crossings() == 0
