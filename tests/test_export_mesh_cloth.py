"""Exports and datasets of a mesh cloth (an OBJ with a UV seam), and exports resampled to another
frame rate (``--out-fps``).

The cloth is a 7 x 5 sheet of quads written here, its UVs split into two islands along the middle
column, so that 35 points have 40 render vertices. Files go through the real command line and are
read back by plain parsers (OBJ, npz) or ``pxr`` (USD; those tests skip without usd-core).
"""

from __future__ import annotations

import json
from fractions import Fraction
from pathlib import Path

import numpy as np
import pytest

from conftest import error_line, run_cli
from obj_support import parse_obj

import clothsim
from clothsim.cloth import cloth_surface
from clothsim.exporters.geometry import (ClothNormals, cloth_geometry, grid_geometry, point_normals,
                                         surface_geometry)
from clothsim.exporters.timing import exported_samples
from clothsim.render import mesh as render_mesh
from clothsim.sweeps.dataset import mesh_positions, uv_scale

PXR_REASON = "usd-core is not installed (pip install 'clothsim[usd]')"
NX, NZ, STEP = 7, 5, 0.1  # points along x and z, 10 cm apart
UV_SPAN = 0.6  # metres per UV unit (isotropic): mesh_pos must find it


def sheet_obj(uvs: bool = True) -> str:
    """The OBJ text: quads over NX x NZ vertices in the x-z plane; with ``uvs``, u = x / 0.6 and
    v = z / 0.6 on two islands (columns 0..3 and 3..6; the right one moved by 0.05 in u)."""
    lines = [f"v {i * STEP:.3f} 0 {j * STEP:.3f}" for j in range(NZ) for i in range(NX)]
    vt: dict[tuple[int, int, int], int] = {}
    if uvs:
        for side, cols in ((0, range(0, 4)), (1, range(3, 7))):
            for j in range(NZ):
                for i in cols:
                    vt[(side, i, j)] = len(vt) + 1
                    lines.append(f"vt {i * STEP / UV_SPAN + 0.05 * side:.9f} {j * STEP / UV_SPAN:.9f}")
    for j in range(NZ - 1):
        for i in range(NX - 1):
            side = 0 if i < 3 else 1
            corners = [(i, j), (i, j + 1), (i + 1, j + 1), (i + 1, j)]
            if uvs:
                lines.append("f " + " ".join(f"{b * NX + a + 1}/{vt[(side, a, b)]}" for a, b in corners))
            else:
                lines.append("f " + " ".join(f"{b * NX + a + 1}" for a, b in corners))
    return "\n".join(lines) + "\n"


def write_scene(folder: Path, uvs: bool = True, moving: bool = False) -> Path:
    (folder / "sheet.obj").write_text(sheet_obj(uvs))
    sphere = {"origin": [0.3, 0.75, 0.2], "radius": 0.12, "friction": 0.3}
    if moving:
        sphere["motion"] = {"velocity": [0.3, 0.0, 0.0]}
    scene = {"cloth": {"mesh": {"path": "sheet.obj", "translate": [0.0, 1.0, 0.0]}, "thickness": 0.0095,
                       "pinned_vertices": [0, 6], "damping": 0.2, "density": 150.0, "ks": 5000.0},
             "sphere": sphere, "plane": {"point": [0, 0, 0], "normal": [0, 1, 0], "friction": 0.5},
             "simulation": {"frames_per_sec": 60, "seed": 3}}
    path = folder / "sheet.json"
    path.write_text(json.dumps(scene))
    return path


@pytest.fixture(scope="module")
def scene_file(tmp_path_factory) -> Path:
    return write_scene(tmp_path_factory.mktemp("mesh_cloth"), moving=True)


def positions_after(scene_file: Path, frames: int) -> np.ndarray:
    sim = clothsim.Simulation(clothsim.load_scene(scene_file))
    sim.step(frames)
    return sim.positions.copy()


# -- geometry --------------------------------------------------------------------------------------
def test_a_grid_surface_is_the_grid_geometry_written_before():
    scene = clothsim.load_scene("pinned2")
    nw, nh = scene.cloth.num_width_points, scene.cloth.num_height_points
    from_surface = surface_geometry(cloth_surface(scene.cloth), nw * nh)
    grid = grid_geometry(nw, nh)
    for name in ("faces", "uvs", "uv_faces", "uv_point"):
        a, b = getattr(from_surface, name), getattr(grid, name)
        assert a.dtype == b.dtype and np.array_equal(a, b), name
    assert from_surface.shared and grid.shared and grid.grid


def test_point_normals_are_the_renderers_on_a_grid():
    nw, nh = 9, 6
    rng = np.random.default_rng(1)
    x, z = np.meshgrid(np.linspace(0, 1, nw), np.linspace(0, 0.7, nh))
    pos = np.stack([x.ravel(), 0.2 * np.sin(3 * x.ravel()) + 0.05 * rng.standard_normal(nw * nh), z.ravel()], axis=1)
    out = np.zeros((nw * nh, render_mesh.CLOTH_FLOATS), dtype=np.float32)
    render_mesh.update_cloth_vertices(pos, nw, nh, False, out)
    mine = point_normals(pos, grid_geometry(nw, nh).faces)
    assert np.allclose(mine, out[:, 3:6], atol=2e-7)
    assert np.array_equal(ClothNormals(grid_geometry(nw, nh))(pos), out[:, 3:6])  # the kernel itself


def test_a_surface_that_does_not_fit_is_one_line():
    from clothsim.errors import ClothsimError

    surface = cloth_surface(clothsim.load_scene("pinned2").cloth)
    with pytest.raises(ClothsimError, match="outside"):
        surface_geometry(surface, 10)


# -- OBJ and USD of a mesh cloth -------------------------------------------------------------------
@pytest.fixture(scope="module")
def obj_export(scene_file, tmp_path_factory):
    out = tmp_path_factory.mktemp("obj") / "seq"
    r = run_cli("export", str(scene_file), "--frames", "6", "--every", "3", "-o", f"{out}/")
    assert r.returncode == 0, r.stderr
    return out


def test_obj_of_a_mesh_cloth_keeps_its_seam(scene_file, obj_export):
    sim = clothsim.Simulation(clothsim.load_scene(scene_file))
    surface = sim.surface
    n, r = len(sim.positions), len(surface.uvs)
    assert (n, r) == (35, 40)
    assert sorted(p.name for p in obj_export.iterdir()) == [
        "cloth_00000.obj", "cloth_00003.obj", "cloth_00006.obj", "colliders.obj"]
    objs = parse_obj(obj_export / "cloth_00006.obj")
    cloth = objs["cloth"]
    assert cloth["v"].shape == (n, 3) and cloth["vt"].shape == (r, 2) and cloth["vn"].shape == (r, 3)
    sim.step(6)
    assert np.array_equal(cloth["v"], sim.positions.astype(np.float32))
    assert np.array_equal(cloth["vt"], surface.uvs)
    f = cloth["f"]
    assert np.array_equal(f[:, :, 0] - 1, surface.triangles)
    assert np.array_equal(f[:, :, 1] - 1, surface.uv_triangles) and np.array_equal(f[:, :, 2], f[:, :, 1])
    # a render vertex's normal is its point's: the two sides of the seam match
    normals = point_normals(sim.positions, surface.triangles)
    assert np.array_equal(cloth["vn"], normals[surface.uv_point])
    # the moving sphere follows in the same file, numbered after the cloth's points and render vertices
    sphere = objs["sphere_0"]
    sf = sphere["f"]
    assert sf[:, :, 0].min() == n + 1 and sf[:, :, 1].min() == r + 1
    assert sf[:, :, 0].max() == n + len(sphere["v"]) and sf[:, :, 1].max() == r + len(sphere["vt"])
    assert "plane_0" in parse_obj(obj_export / "colliders.obj")


def test_usd_of_a_mesh_cloth_has_indexed_face_varying_uvs(scene_file, tmp_path):
    pytest.importorskip("pxr", reason=PXR_REASON)
    from pxr import Usd, UsdGeom

    out = tmp_path / "sheet.usda"
    r = run_cli("export", str(scene_file), "--frames", "4", "--every", "2", "-o", str(out))
    assert r.returncode == 0, r.stderr
    stage = Usd.Stage.Open(str(out))
    mesh = UsdGeom.Mesh(stage.GetPrimAtPath("/World/cloth"))
    sim = clothsim.Simulation(clothsim.load_scene(scene_file))
    surface = sim.surface
    assert np.array_equal(np.array(mesh.GetFaceVertexIndicesAttr().Get()), surface.triangles.ravel())
    st = UsdGeom.PrimvarsAPI(mesh.GetPrim()).GetPrimvar("st")
    assert st.GetInterpolation() == UsdGeom.Tokens.faceVarying and st.IsIndexed()
    assert np.array_equal(np.array(st.Get(), dtype=np.float32), surface.uvs)
    assert np.array_equal(np.array(st.GetIndices()), surface.uv_triangles.ravel())
    assert mesh.GetNormalsInterpolation() == UsdGeom.Tokens.vertex
    for frame in (0, 2, 4):
        points = np.array(mesh.GetPointsAttr().Get(frame), dtype=np.float32)
        assert np.array_equal(points, sim.positions.astype(np.float32)), frame
        normals = np.array(mesh.GetNormalsAttr().Get(frame), dtype=np.float32)
        assert np.array_equal(normals, point_normals(sim.positions, surface.triangles))
        sim.step(2)


# -- resampling: --out-fps -------------------------------------------------------------------------
def test_exported_samples_rules():
    same = exported_samples(0, 7, 3, 60.0)
    assert [(s.code, s.frame, s.weight) for s in same] == [(0, 0, 0.0), (3, 3, 0.0), (6, 6, 0.0), (7, 7, 0.0)]
    assert exported_samples(0, 7, 3, 60.0, 60.0) == same
    third = exported_samples(0, 90, 1, 90.0, 30.0)  # 90 -> 30: every third frame exactly
    assert [s.code for s in third] == list(range(31)) and all(s.weight == 0 and s.frame == 3 * s.code for s in third)
    blender = exported_samples(0, 100, 1, 90.0, 24.0)  # 100 frames = 1.11 s: 24 fps frames 0..26
    assert blender[-1].code == 26 and len(blender) == 27
    for s in blender:
        at = Fraction(s.code) * 90 / 24
        assert s.frame == int(at) and s.weight == float(at - int(at))
    assert [s.code for s in exported_samples(0, 100, 10, 90.0, 24.0)] == [0, 10, 20, 26]
    assert [s.code for s in exported_samples(5, 10, 1, 60.0, 24.0)] == [2, 3, 4, 5, 6]  # from frame 5 (2.0) to 15 (6.0)


def test_out_fps_interpolates_between_simulated_frames(tmp_path):
    scene = write_scene(tmp_path)
    out = tmp_path / "seq"
    r = run_cli("export", str(scene), "--frames", "7", "--out-fps", "24", "-o", f"{out}/")
    assert r.returncode == 0, r.stderr
    assert "exported 3 frames at 24 fps (0..2)" in r.stderr
    # 60 -> 24 fps: frame k is simulated frame 2.5 k
    assert sorted(p.name for p in out.iterdir()) == ["cloth_00000.obj", "cloth_00001.obj", "cloth_00002.obj",
                                                     "colliders.obj"]
    sim = clothsim.Simulation(clothsim.load_scene(scene))
    states = [sim.positions.copy()]
    for _ in range(5):
        sim.step()
        states.append(sim.positions.copy())
    want = {0: states[0], 1: states[2] + 0.5 * (states[3] - states[2]), 2: states[5]}
    for k, pos in want.items():
        got = parse_obj(out / f"cloth_{k:05d}.obj")["cloth"]["v"]
        assert np.array_equal(got, pos.astype(np.float32)), k


def test_out_fps_stage_says_its_rate(tmp_path):
    pytest.importorskip("pxr", reason=PXR_REASON)
    from pxr import Usd

    scene = write_scene(tmp_path, moving=True)
    out = tmp_path / "clip.usda"
    r = run_cli("export", str(scene), "--frames", "15", "--every", "2", "--out-fps", "24", "-o", str(out))
    assert r.returncode == 0, r.stderr
    stage = Usd.Stage.Open(str(out))
    assert stage.GetTimeCodesPerSecond() == 24 and stage.GetFramesPerSecond() == 24
    assert (stage.GetStartTimeCode(), stage.GetEndTimeCode()) == (0, 6)  # 15 frames at 60 fps = 0.25 s = 6 at 24
    times = stage.GetPrimAtPath("/World/cloth").GetAttribute("points").GetTimeSamples()
    assert list(times) == [0, 2, 4, 6]
    moving = stage.GetPrimAtPath("/World/colliders/sphere_0").GetAttribute("xformOp:translate")
    # the moving sphere is where it is at k / 24 s (0.3 m/s along x)
    assert moving.Get(4)[0] == pytest.approx(0.3 + 0.3 * 4 / 24, abs=1e-9)


def test_out_fps_at_the_simulations_rate_changes_no_byte(tmp_path):
    scene = write_scene(tmp_path)
    a, b = tmp_path / "a", tmp_path / "b"
    assert run_cli("export", str(scene), "--frames", "5", "--every", "2", "-o", f"{a}/").returncode == 0
    r = run_cli("export", str(scene), "--frames", "5", "--every", "2", "--out-fps", "60", "-o", f"{b}/")
    assert r.returncode == 0, r.stderr
    names = sorted(p.name for p in a.iterdir())
    assert names == sorted(p.name for p in b.iterdir())
    for name in names:
        assert (a / name).read_bytes() == (b / name).read_bytes(), name


@pytest.mark.parametrize("value, expected", [
    ("0", "--out-fps: must be > 0, got 0"),
    ("-24", "--out-fps: must be > 0, got -24"),
    ("nan", "--out-fps: must be > 0"),
    ("1e9", "--out-fps: must be <= 10000"),
])
def test_bad_out_fps_is_one_line_and_writes_nothing(tmp_path, value, expected):
    scene = write_scene(tmp_path)
    out = tmp_path / "seq"
    r = run_cli("export", str(scene), "--frames", "2", "--out-fps", value, "-o", f"{out}/")
    assert expected in error_line(r)
    assert not out.exists()


def test_out_fps_with_no_frame_in_the_span_is_one_line(tmp_path):
    scene = write_scene(tmp_path)
    sim = clothsim.Simulation(clothsim.load_scene(scene))
    sim.step(1)
    from clothsim.errors import ClothsimError

    with pytest.raises(ClothsimError, match="no frame at that rate falls between simulated frames 1 and 2"):
        clothsim.export(sim, tmp_path / "seq", frames=1, out_fps=24)
    assert not (tmp_path / "seq").exists()


# -- datasets --------------------------------------------------------------------------------------
def test_mesh_pos_scale_is_the_least_squares_one():
    scene = clothsim.load_scene(write_scene_tmp(uvs=True))
    surface = cloth_surface(scene.cloth)
    rest = scene.cloth.mesh.points
    assert uv_scale(surface, rest) == pytest.approx(UV_SPAN, rel=1e-6)
    first = np.unique(surface.uv_point, return_index=True)[1]
    assert np.allclose(mesh_positions(surface, rest), surface.uvs[first] * UV_SPAN, atol=1e-6)
    no_uv = clothsim.load_scene(write_scene_tmp(uvs=False))
    pos = mesh_positions(cloth_surface(no_uv.cloth), no_uv.cloth.mesh.points)
    assert pos.shape == (35, 3) and np.array_equal(pos, no_uv.cloth.mesh.points.astype(np.float32))


def write_scene_tmp(uvs: bool) -> Path:
    import tempfile

    return write_scene(Path(tempfile.mkdtemp(prefix="clothsim-meshpos.")), uvs=uvs)


def test_sweep_of_a_mesh_cloth_writes_its_triangles_node_types_and_mesh_pos(tmp_path):
    scene_file = write_scene(tmp_path)
    out = tmp_path / "data"
    r = run_cli("sweep", str(scene_file), "--set", "cloth.ks=3000,6000", "--frames", "4", "--every", "2",
                "--workers", "1", "-o", str(out))
    assert r.returncode == 0, r.stderr
    from clothsim.datasets import open_dataset

    data = open_dataset(out)
    meta = data.meta
    assert "grid" not in meta and meta["cloth"]["N"] == 35 and meta["cloth"]["render_vertices"] == 40
    fields = meta["run_file"]["fields"]
    for name in ("faces", "cells", "node_type", "mesh_pos", "uv", "uv_vertex", "uv_faces", "uv_point"):
        assert name in fields, name
    scene = clothsim.load_scene(scene_file)
    surface = cloth_surface(scene.cloth)
    runs = list(data.runs())
    assert len(runs) == 2
    for run in runs:
        a = run.arrays
        assert a["positions"].shape == (3, 35, 3) and a["positions"].dtype == np.float32
        assert a["faces"].dtype == np.int32 and np.array_equal(a["faces"], surface.triangles)
        assert np.array_equal(a["cells"], a["faces"])
        assert np.array_equal(a["uv_faces"], surface.uv_triangles) and np.array_equal(a["uv_point"], surface.uv_point)
        assert np.array_equal(a["uv_vertex"], surface.uvs)
        pinned = np.zeros(35, dtype=bool)
        pinned[[0, 6]] = True  # the two corners of the first row
        assert np.array_equal(a["pinned"], pinned) and np.array_equal(a["node_type"], np.where(pinned, 3, 0))
        assert a["mesh_pos"].shape == (35, 2)
        assert np.allclose(a["mesh_pos"], a["uv"] * UV_SPAN, atol=1e-6)
        assert np.array_equal(a["positions"][0], scene.cloth.mesh.points.astype(np.float32))  # frame 0: at rest
