"""Mesh colliders that deform (a ``sequence`` of OBJ frames): the frames' rule in time, the posed
vertices the kernels use, a growing sphere pushing a resting cloth outwards, and bad sequences."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest

from obj_support import parse_obj

from clothsim.meshsequence import frame_name
from clothsim.objshapes import breathing_frames, bundled, sphere_obj
from clothsim.resources import data_dir
from clothsim.scene import load_scene, scene_from_dict
from clothsim.sim import Simulation

CLOTH = {"width": 0.6, "height": 0.6, "num_width_points": 16, "num_height_points": 16, "thickness": 0.01,
         "orientation": "horizontal", "damping": 0.2, "density": 150, "ks": 5000}
CENTRE = np.array([0.3, 0.6, 0.3])


def growing(folder: Path, frames: int = 11, start: int = 0) -> str:
    """Frames of a sphere whose radius grows from 0.2 by 1 cm a frame; returns the pattern."""
    for k in range(frames):
        (folder / f"g_{start + k:03d}.obj").write_text(sphere_obj(0.2 + 0.01 * k, 12, 24))
    return str(folder / "g_###.obj")


def mesh(pattern: str, **extra) -> dict:
    return {"sequence": pattern, "fps": 10, "translate": CENTRE.tolist(), "friction": 0.5, **extra}


def scene(**mesh_keys) -> object:
    return scene_from_dict({"cloth": CLOTH, "simulation": {"self_collision": False}, "mesh": mesh_keys}, "<test>")


def inradius(verts: np.ndarray, tris: np.ndarray) -> float:
    """The distance from the origin to the nearest face plane of a convex mesh around it: the
    radius of the largest ball about the origin inside it."""
    a, b, c = (verts[tris[:, k]] for k in range(3))
    n = np.cross(b - a, c - a)
    n /= np.linalg.norm(n, axis=1, keepdims=True)
    return float(np.abs(np.einsum("ij,ij->i", a, n)).min())


# -- the frames' rule ---------------------------------------------------------------------------

def test_frames_are_numbered_from_the_first_that_exists_and_end_at_the_first_missing(tmp_path):
    growing(tmp_path, frames=4, start=1)
    (tmp_path / "g_006.obj").write_text(sphere_obj(0.5, 12, 24))  # after a gap: not a frame
    spec = scene(**mesh(str(tmp_path / "g_###.obj"))).meshes[0]
    assert spec.sequence.first == 1
    assert [Path(f).name for f in spec.sequence.files] == ["g_001.obj", "g_002.obj", "g_003.obj", "g_004.obj"]
    assert frame_name("a_##_b_####.obj", 7) == "a_07_b_0007.obj"
    assert frame_name("a_#.obj", 123) == "a_123.obj"


def test_the_shape_between_frames_is_linear_held_after_the_last_or_looped(tmp_path):
    spec = scene(**mesh(growing(tmp_path, frames=3), scale=2.0, rotation=[0, 30, 0])).meshes[0]
    frames = spec.local_frames()
    for t, expected in ((0.0, frames[0]), (0.025, frames[0] + 0.25 * (frames[1] - frames[0])),
                        (0.15, frames[1] + 0.5 * (frames[2] - frames[1])), (0.2, frames[2]), (5.0, frames[2])):
        assert np.allclose(spec.local_vertices_at(t), expected, rtol=0, atol=1e-12), t
    # the placement applies to each frame as to a fixed mesh
    assert np.allclose(frames[0], spec.local_vertices(), rtol=0, atol=1e-15)
    looped = scene(**mesh(str(tmp_path / "g_###.obj"), loop=True)).meshes[0]
    f = looped.local_frames()
    # frame 2 at 0.2 s, back to frame 0 over the next 0.1 s, then round again
    assert np.allclose(looped.local_vertices_at(0.25), f[2] + 0.5 * (f[0] - f[2]), atol=1e-12)
    assert np.allclose(looped.local_vertices_at(0.3 + 0.15), f[1] + 0.5 * (f[2] - f[1]), atol=1e-12)


def test_the_kernels_pose_the_vertices_the_rule_gives(tmp_path):
    from clothsim.sim.passes.colliders.meshgrid import MeshGroup

    sim = Simulation(scene(**mesh(growing(tmp_path), rotation=[10, 0, 0])))
    spec = sim.scene.meshes[0]
    for frames in (1, 4, 13):  # 1/90 s a frame: between the sequence's frames (1/10 s apart)
        sim.step(frames)
        group = next(g for g in sim._colliders if isinstance(g, MeshGroup))
        # the group holds the shape at the end of the last substep, which is now
        assert np.allclose(group.verts, spec.local_vertices_at(sim.time), rtol=0, atol=1e-9), sim.time
        assert group.deform.moved[0] > 0.0


# -- the physics --------------------------------------------------------------------------------

def test_a_growing_sphere_pushes_the_cloth_resting_on_it_outwards(tmp_path):
    # the cloth falls onto a sphere of radius 0.2 m that grows to 0.3 m over its first second
    sim = Simulation(scene(**mesh(growing(tmp_path))))
    spec = sim.scene.meshes[0]
    th = CLOTH["thickness"]
    landed = None
    for frame in range(120):
        sim.step(1)
        inner = inradius(spec.local_vertices_at(sim.time), spec.triangles)
        dist = np.linalg.norm(sim.positions - CENTRE, axis=1)
        # never inside: every point at least (about) the thickness outside the current faces
        assert dist.min() >= inner + 0.5 * th, (sim.time, dist.min(), inner)
        if frame == 40:  # landed (0.45 s: radius 0.245)
            landed = dist.mean()
    # carried outwards with the surface (5.5 cm of growth after it landed), all of it
    dist = np.linalg.norm(sim.positions - CENTRE, axis=1)
    assert dist.mean() > landed + 0.035 and dist.min() > 0.3, (landed, dist.mean(), dist.min())


def sliding_sheet(folder: Path, frames: int = 6) -> str:
    """Frames of an open 2 m square sheet (4 x 4 quads, y = 0) whose vertices move 0.1 m along +x a
    frame: a surface moving within itself, which only friction can see."""
    for k in range(frames):
        verts = [f"v {-1 + 0.5 * i + 0.1 * k:.6f} 0 {-1 + 0.5 * j:.6f}" for j in range(5) for i in range(5)]
        faces = [f"f {j * 5 + i + 1} {(j + 1) * 5 + i + 1} {(j + 1) * 5 + i + 2} {j * 5 + i + 2}"
                 for j in range(4) for i in range(4)]
        (folder / f"s_{k}.obj").write_text("\n".join(verts + faces) + "\n")
    return str(folder / "s_#.obj")


@pytest.mark.parametrize("friction, carried", [(1.0, 0.1), (0.0, 0.0)])
def test_friction_acts_on_the_motion_relative_to_the_deforming_surface(tmp_path, friction, carried):
    # the sheet's surface slides along +x at 0.2 m/s (2 frames a second) under a resting cloth
    keys = {"sequence": sliding_sheet(tmp_path), "fps": 2, "translate": [0.3, 0.8, 0.3], "friction": friction}
    sim = Simulation(scene(**keys))
    sim.step(45)  # landed by 0.5 s
    before = sim.positions.mean(axis=0)
    sim.step(45)  # half a second more
    after = sim.positions.mean(axis=0)
    assert abs(after[0] - before[0] - carried) < 0.01, (before, after)
    assert abs(after[1] - 0.81) < 2e-3  # resting on it, the thickness above


# -- the bundled scene --------------------------------------------------------------------------

def test_the_bundled_breathing_frames_are_what_the_generator_writes(tmp_path):
    shipped = sorted((data_dir("scenes") / "breathing").glob("breath_*.obj"))
    written = {name: text for name, text in bundled().items() if name.startswith("breathing/")}
    assert [f"breathing/{p.name}" for p in shipped] == sorted(written)
    assert all(p.read_text() == written[f"breathing/{p.name}"] for p in shipped)
    assert len(breathing_frames(0.2, 0.05, 4, 6, 8)) == 4
    spec = load_scene("breathing").meshes[0]
    assert spec.sequence.loop and spec.closed


def test_a_sequence_round_trips_through_scene_json(tmp_path):
    from clothsim.colliders import KINDS

    spec = scene(**mesh(growing(tmp_path, frames=3), loop=True, scale=1.5)).meshes[0]
    data = next(k for k in KINDS if k.key == "mesh").to_json(spec)
    assert data["sequence"] == str(tmp_path / "g_###.obj") and data["fps"] == 10 and data["loop"] is True
    again = scene(**data).meshes[0]
    assert again.sequence.files == spec.sequence.files and again.scale == 1.5
    assert np.array_equal(again.local_frames(), spec.local_frames())


def _usd_stage(path: Path, radii: list[float]) -> None:
    """A stage with one mesh whose points are time-sampled: a sphere of each radius in turn."""
    from pxr import Usd, UsdGeom

    from clothsim.objfile import parse_obj

    stage = Usd.Stage.CreateNew(str(path))
    mesh = UsdGeom.Mesh.Define(stage, "/body")
    shapes = [parse_obj(sphere_obj(r, 8, 12)) for r in radii]
    mesh.GetFaceVertexCountsAttr().Set([3] * shapes[0].triangles.shape[0])
    mesh.GetFaceVertexIndicesAttr().Set(shapes[0].triangles.reshape(-1).tolist())
    for k, shape in enumerate(shapes):
        mesh.GetPointsAttr().Set([tuple(p) for p in shape.vertices.tolist()], 10.0 * k)
    stage.GetRootLayer().Save()


def test_a_usd_meshs_time_samples_are_the_frames(tmp_path):
    pytest.importorskip("pxr")
    _usd_stage(tmp_path / "grow.usda", [0.2, 0.25, 0.3])
    spec = scene(**mesh(str(tmp_path / "grow.usda"))).meshes[0]
    assert spec.sequence.frames.shape[0] == 3 and spec.closed
    radius = np.linalg.norm(spec.local_vertices_at(0.05), axis=1)
    assert np.allclose(radius, 0.225)  # half way between the first two samples (10 fps)


def test_a_usd_sequence_without_usd_core_names_the_extra(tmp_path, monkeypatch):
    import sys

    from clothsim.errors import ClothsimError

    monkeypatch.setitem(sys.modules, "pxr", None)
    (tmp_path / "a.usda").write_text("#usda 1.0\n")
    with pytest.raises(ClothsimError, match=r"needs the 'usd' extra \(pip install 'clothsim\[usd\]'\)"):
        scene(**mesh(str(tmp_path / "a.usda")))


# -- bad input ----------------------------------------------------------------------------------

def _fails(tmp_path: Path, keys: dict) -> list[str]:
    from conftest import run_cli

    path = tmp_path / "seq.json"
    path.write_text(json.dumps({"cloth": CLOTH, "mesh": keys}))
    done = run_cli("simulate", str(path), "--frames", "1", "--out", str(tmp_path / "s.npz"))
    assert done.returncode == 2, done.stderr
    lines = done.stderr.strip().splitlines()
    assert len(lines) == 1, lines
    return [lines[0], str(path)]


def test_bad_sequences_are_one_line_and_exit_code_2(tmp_path):
    pattern = growing(tmp_path, frames=3)
    # frame 2 with one face written the other way round
    text = (tmp_path / "g_002.obj").read_text().splitlines()
    first_face = next(i for i, line in enumerate(text) if line.startswith("f "))
    corners = text[first_face].split()[1:]
    text[first_face] = "f " + " ".join(reversed(corners))
    (tmp_path / "g_002.obj").write_text("\n".join(text) + "\n")
    line, scene_path = _fails(tmp_path, mesh(pattern))
    assert line == (f"clothsim: error: {scene_path}: mesh.sequence: {tmp_path / 'g_002.obj'}: line {first_face + 1}: "
                    f"face differs from the first frame's ({tmp_path / 'g_000.obj'} line {first_face + 1}); every "
                    f"frame needs the first frame's faces")

    line, scene_path = _fails(tmp_path, mesh(str(tmp_path / "none_##.obj")))
    assert line == (f"clothsim: error: {scene_path}: mesh.sequence: no first frame: neither "
                    f"{tmp_path / 'none_00.obj'} nor {tmp_path / 'none_01.obj'} is a file")

    line, scene_path = _fails(tmp_path, mesh(str(tmp_path / "g_000.obj")))
    assert line.startswith(f"clothsim: error: {scene_path}: mesh.sequence: {tmp_path / 'g_000.obj'}: the pattern "
                           f"has no '#'")

    for fps in (0, -5):
        line, scene_path = _fails(tmp_path, mesh(pattern, fps=fps))
        assert line == f"clothsim: error: {scene_path}: mesh.fps: must be > 0, got {fps}", line


@pytest.mark.parametrize("keys, message", [
    ({"path": "a.obj", "sequence": "a_#.obj", "fps": 10}, "mesh.sequence: give either path"),
    ({"sequence": "a_#.obj"}, "mesh.fps: missing required field"),
    ({"path": "a.obj", "fps": 10}, "mesh.fps: applies only to a sequence"),
    ({}, "mesh.path: missing required field (or sequence"),
])
def test_the_keys_of_a_sequence_name_the_field(keys, message):
    from clothsim.errors import ClothsimError

    with pytest.raises(ClothsimError) as info:
        scene_from_dict({"cloth": CLOTH, "mesh": {"friction": 0.5, **keys}}, "s.json")
    assert message in str(info.value), str(info.value)


@pytest.mark.parametrize("fmt", ["obj", "usda"])
def test_exports_carry_the_deforming_mesh_frame_by_frame(tmp_path, fmt):
    # the sphere grows 1 cm every 0.1 s (a frame of the sequence); frames 0, 9 and 18 at 90 a
    # second are 0, 0.1 and 0.2 s: radii 0.20, 0.21, 0.22 about the mesh's place
    import clothsim

    sc = scene(**mesh(growing(tmp_path)))
    out = tmp_path / ("seq/" if fmt == "obj" else "clip.usda")
    written = clothsim.export(sc, str(out), frames=18, every=9)
    assert written == [0, 9, 18]
    for frame, radius in zip(written, (0.20, 0.21, 0.22)):
        if fmt == "obj":
            points = parse_obj(out / f"cloth_{frame:05d}.obj")["mesh_0"]["v"].astype(np.float64)
        else:
            pytest.importorskip("pxr", reason="the usd extra (usd-core) is not installed")
            from pxr import Usd, UsdGeom

            stage = Usd.Stage.Open(str(out))  # kept: a prim is valid while its stage lives
            prim = UsdGeom.Mesh(stage.GetPrimAtPath("/World/colliders/mesh_0"))
            points = np.array(prim.GetPointsAttr().Get(Usd.TimeCode(frame)), dtype=np.float64)
        assert np.abs(np.linalg.norm(points - CENTRE, axis=1) - radius).max() < 1e-6
    if fmt == "obj":
        assert not (out / "colliders.obj").exists()  # the one collider is not static
