"""``clothsim export``: a USD stage and an OBJ sequence that hold exactly what ``simulate`` computes.

USD files are read back through Pixar's ``pxr`` (usd-core; those tests are skipped without it),
OBJ files through a plain parser written here. Positions are compared for equality with the
``.npz`` of ``clothsim simulate`` at the same frame count and, for an earlier frame, with a
``Simulation`` stepped through the API. Bad outputs go through the real command line.
"""

from __future__ import annotations

import json
import os
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from conftest import error_line, run_cli
from obj_support import parse_obj

import clothsim
from clothsim.render import mesh as render_mesh

PXR_REASON = "usd-core is not installed (pip install 'clothsim[usd]')"

# A small grid, not square (13 x 9, so rows and columns cannot be swapped unnoticed), vertical
# (its z jitter depends on the seed), two corners pinned, one sphere and one tilted plane.
SCENE = {
    "cloth": {"width": 1.2, "height": 0.9, "num_width_points": 13, "num_height_points": 9, "thickness": 0.0095,
              "orientation": 1, "pinned": [[0, 8], [12, 8]], "damping": 0.2, "density": 150.0, "ks": 5000.0},
    "sphere": {"origin": [0.6, 0.3, 0.4], "radius": 0.15, "friction": 0.3},
    "plane": {"point": [0.0, -0.3, 0.0], "normal": [0.0, 1.0, 0.2], "friction": 0.5},
    "simulation": {"frames_per_sec": 60, "seed": 7},
}
NW, NH = 13, 9
FRAMES, EVERY = 7, 3  # 7 is not a multiple of 3: frames 0, 3, 6 and the last one, 7
EXPORTED = [0, 3, 6, 7]


# -- helpers -------------------------------------------------------------------------------------
@pytest.fixture
def scene_file(tmp_path: Path) -> Path:
    path = tmp_path / "both.json"
    path.write_text(json.dumps(SCENE))
    return path



def simulate_npz(scene_file: Path, frames: int, tmp_path: Path) -> np.ndarray:
    """Final positions (N, 3) float64 of ``clothsim simulate`` after ``frames`` frames."""
    out = tmp_path / f"state_{frames}.npz"
    r = run_cli("simulate", str(scene_file), "--frames", str(frames), "--out", str(out))
    assert r.returncode == 0, r.stderr
    with np.load(out) as data:
        return data["positions"]


def api_positions(scene_file: Path, frames: int) -> np.ndarray:
    sim = clothsim.Simulation(clothsim.load_scene(scene_file))
    sim.step(frames)
    return sim.positions.copy()


def renderer_normals(positions: np.ndarray, nw: int = NW, nh: int = NH) -> np.ndarray:
    """Per-vertex normals as the renderer computes them for these positions."""
    out = np.zeros((nw * nh, render_mesh.CLOTH_FLOATS), dtype=np.float32)
    render_mesh.update_cloth_vertices(np.ascontiguousarray(positions, dtype=np.float64), nw, nh, False, out)
    return out[:, 3:6]


def snapshot(folder: Path) -> dict[str, bytes | str]:
    return {str(p.relative_to(folder)): (p.read_bytes() if p.is_file() else "dir") for p in sorted(folder.rglob("*"))}


# -- USD -----------------------------------------------------------------------------------------
@pytest.fixture(scope="module")
def usd_export(tmp_path_factory):
    """One CLI export to .usda, the matching simulate runs, and the scene file."""
    pytest.importorskip("pxr", reason=PXR_REASON)
    tmp = tmp_path_factory.mktemp("usd")
    scene_file = tmp / "both.json"
    scene_file.write_text(json.dumps(SCENE))
    out = tmp / "cloth.usda"
    r = run_cli("export", str(scene_file), "--frames", str(FRAMES), "--every", str(EVERY), "-o", str(out))
    assert r.returncode == 0, r.stderr
    return out, scene_file, tmp


def test_usd_stage_metadata(usd_export):
    from pxr import Usd, UsdGeom

    stage = Usd.Stage.Open(str(usd_export[0]))
    assert stage.GetStartTimeCode() == 0 and stage.GetEndTimeCode() == FRAMES
    assert stage.GetTimeCodesPerSecond() == 60 and stage.GetFramesPerSecond() == 60
    assert UsdGeom.GetStageUpAxis(stage) == UsdGeom.Tokens.y
    assert UsdGeom.GetStageMetersPerUnit(stage) == 1.0
    assert stage.GetDefaultPrim().GetPath() == "/World"


def test_usd_points_equal_simulate_at_every_exported_frame(usd_export):
    from pxr import Usd, UsdGeom

    out, scene_file, tmp = usd_export
    stage = Usd.Stage.Open(str(out))  # kept referenced: prims die with their stage
    cloth = UsdGeom.Mesh(stage.GetPrimAtPath("/World/cloth"))
    points = cloth.GetPointsAttr()
    assert points.GetTimeSamples() == EXPORTED
    assert cloth.GetNormalsAttr().GetTimeSamples() == EXPORTED
    for frame in EXPORTED:
        got = np.array(points.Get(Usd.TimeCode(frame)))
        assert got.dtype == np.float32 and got.shape == (NW * NH, 3)
        expected = simulate_npz(scene_file, FRAMES, tmp) if frame == FRAMES else api_positions(scene_file, frame)
        np.testing.assert_array_equal(got, expected.astype(np.float32), err_msg=f"frame {frame}")
        extent = np.array(cloth.GetExtentAttr().Get(Usd.TimeCode(frame)))
        np.testing.assert_array_equal(extent, [got.min(axis=0), got.max(axis=0)])
    assert not np.array_equal(np.array(points.Get(Usd.TimeCode(0))), np.array(points.Get(Usd.TimeCode(FRAMES))))


def test_usd_topology_uvs_and_normals(usd_export):
    from pxr import Usd, UsdGeom

    out, scene_file, _ = usd_export
    stage = Usd.Stage.Open(str(out))  # kept referenced: prims die with their stage
    cloth = UsdGeom.Mesh(stage.GetPrimAtPath("/World/cloth"))
    counts = np.array(cloth.GetFaceVertexCountsAttr().Get())
    indices = np.array(cloth.GetFaceVertexIndicesAttr().Get())
    assert counts.tolist() == [3] * (2 * (NW - 1) * (NH - 1))
    np.testing.assert_array_equal(indices, render_mesh.cloth_triangles(NW, NH))
    assert cloth.GetSubdivisionSchemeAttr().Get() == UsdGeom.Tokens.none
    st = UsdGeom.PrimvarsAPI(cloth.GetPrim()).GetPrimvar("st")
    assert st.GetInterpolation() == UsdGeom.Tokens.vertex
    uv = np.array(st.Get())
    np.testing.assert_array_equal(uv, render_mesh.cloth_uvs(NW, NH))
    assert uv[NW - 1].tolist() == [1.0, 0.0] and uv[NW].tolist() == [0.0, pytest.approx(1 / (NH - 1))]
    assert cloth.GetNormalsInterpolation() == UsdGeom.Tokens.vertex
    for frame in (0, 3):
        normals = np.array(cloth.GetNormalsAttr().Get(Usd.TimeCode(frame)))
        positions = api_positions(scene_file, frame)
        np.testing.assert_array_equal(normals, renderer_normals(positions))
        np.testing.assert_allclose(np.linalg.norm(normals, axis=1), 1.0, rtol=1e-6)
    # The cloth starts flat (a 1 mm jitter): every normal points to the side its triangles'
    # counter-clockwise winding faces (USD's rightHanded orientation).
    points0 = np.array(cloth.GetPointsAttr().Get(Usd.TimeCode(0)), dtype=np.float64)
    i0, i1, i2 = indices[:3]
    face = np.cross(points0[i1] - points0[i0], points0[i2] - points0[i0])
    normals0 = np.array(cloth.GetNormalsAttr().Get(Usd.TimeCode(0)))
    assert cloth.GetOrientationAttr().Get() == UsdGeom.Tokens.rightHanded
    assert (normals0 @ (face / np.linalg.norm(face)) > 0.99).all()


def test_usd_colliders(usd_export):
    from pxr import Gf, Usd, UsdGeom

    stage = Usd.Stage.Open(str(usd_export[0]))
    sphere = UsdGeom.Sphere(stage.GetPrimAtPath("/World/colliders/sphere_0"))
    assert sphere, [str(p.GetPath()) for p in stage.Traverse()]
    assert sphere.GetRadiusAttr().Get() == pytest.approx(0.15)
    world = sphere.ComputeLocalToWorldTransform(Usd.TimeCode.Default())
    assert world.ExtractTranslation() == Gf.Vec3d(0.6, 0.3, 0.4)
    np.testing.assert_allclose(np.array(sphere.GetExtentAttr().Get()), [[-0.15] * 3, [0.15] * 3], rtol=1e-6)
    plane = UsdGeom.Mesh(stage.GetPrimAtPath("/World/colliders/plane_0"))
    assert plane
    assert list(plane.GetFaceVertexCountsAttr().Get()) == [4]
    assert list(plane.GetFaceVertexIndicesAttr().Get()) == [0, 1, 2, 3]
    corners = np.array(plane.GetPointsAttr().Get(), dtype=np.float64)
    n = np.array([0.0, 1.0, 0.2]) / np.linalg.norm([0.0, 1.0, 0.2])
    np.testing.assert_allclose((corners - [0.0, -0.3, 0.0]) @ n, 0.0, atol=1e-6)  # on the plane
    assert np.ptp(corners[:, 0]) >= 2.0  # large: wider than the cloth
    # Counter-clockwise seen from the normal's side: the quad's own normal is the plane's.
    quad_normal = np.cross(corners[1] - corners[0], corners[2] - corners[0])
    np.testing.assert_allclose(quad_normal / np.linalg.norm(quad_normal), n, atol=1e-6)
    np.testing.assert_allclose(np.array(plane.GetNormalsAttr().Get()), np.tile(n, (4, 1)), atol=1e-6)


def test_usd_crate_and_usdc_open_and_are_deterministic(scene_file, tmp_path):
    pytest.importorskip("pxr", reason=PXR_REASON)
    from pxr import Usd

    for name in ("a.usd", "b.usd", "c.usdc", "a.usda", "b.usda"):
        clothsim.export(scene_file, tmp_path / name, frames=FRAMES, every=EVERY)
    assert (tmp_path / "a.usd").read_bytes().startswith(b"PXR-USDC")  # .usd is written binary
    assert (tmp_path / "c.usdc").read_bytes().startswith(b"PXR-USDC")
    assert Usd.Stage.Open(str(tmp_path / "c.usdc")).GetEndTimeCode() == FRAMES
    assert (tmp_path / "a.usd").read_bytes() == (tmp_path / "b.usd").read_bytes()
    assert (tmp_path / "a.usda").read_bytes() == (tmp_path / "b.usda").read_bytes()
    assert b"#usda 1.0" in (tmp_path / "a.usda").read_bytes()[:20]
    assert sorted(p.name for p in tmp_path.iterdir()) == ["a.usd", "a.usda", "b.usd", "b.usda", "both.json", "c.usdc"]


def test_missing_usd_extra_is_one_line_and_writes_nothing(tmp_path):
    # A fresh interpreter in which `import pxr` fails, as without usd-core.
    block = ("import sys; sys.modules['pxr'] = None; from clothsim.cli import main; "
             "sys.exit(main(sys.argv[1:]))")
    env = {k: v for k, v in os.environ.items() if k != "DISPLAY"}
    for out in ("stage.usda", "sub/stage.usd", "stage.usdc"):
        r = subprocess.run([sys.executable, "-c", block, "export", "pinned2", "--frames", "1", "-o", out],
                           cwd=tmp_path, capture_output=True, text=True, env=env, timeout=300)
        suffix = Path(out).suffix
        assert error_line(r) == (f"clothsim: error: {out}: writing {suffix} needs the 'usd' extra (usd-core): "
                                 "pip install 'clothsim[usd]'")
    assert list(tmp_path.iterdir()) == []
    # The OBJ sequence needs no extra.
    r = subprocess.run([sys.executable, "-c", block, "export", "pinned2", "--frames", "1", "-o", "seq/"],
                       cwd=tmp_path, capture_output=True, text=True, env=env, timeout=300)
    assert r.returncode == 0, r.stderr
    assert sorted(p.name for p in (tmp_path / "seq").iterdir()) == ["cloth_00000.obj", "cloth_00001.obj"]


# -- OBJ -----------------------------------------------------------------------------------------
def test_obj_sequence_round_trip(scene_file, tmp_path):
    out = tmp_path / "seq"
    r = run_cli("export", str(scene_file), "--frames", str(FRAMES), "--every", str(EVERY), "-o", f"{out}/")
    assert r.returncode == 0, r.stderr
    assert sorted(p.name for p in out.iterdir()) == [f"cloth_{f:05d}.obj" for f in EXPORTED] + ["colliders.obj"]
    final = simulate_npz(scene_file, FRAMES, tmp_path)
    triangles = render_mesh.cloth_triangles(NW, NH).reshape(-1, 3).astype(np.int64)
    for frame in EXPORTED:
        objects = parse_obj(out / f"cloth_{frame:05d}.obj")
        assert list(objects) == ["cloth"]
        cloth = objects["cloth"]
        expected = final if frame == FRAMES else api_positions(scene_file, frame)
        np.testing.assert_array_equal(cloth["v"], expected.astype(np.float32), err_msg=f"frame {frame}")
        np.testing.assert_array_equal(cloth["vt"], render_mesh.cloth_uvs(NW, NH))
        np.testing.assert_array_equal(cloth["vn"], renderer_normals(expected))
        faces = cloth["f"]
        assert faces.shape == (len(triangles), 3, 3)
        np.testing.assert_array_equal(faces[:, :, 0], triangles + 1)  # 1-based
        np.testing.assert_array_equal(faces[:, :, 1], faces[:, :, 0])
        np.testing.assert_array_equal(faces[:, :, 2], faces[:, :, 0])
    text = (out / "cloth_00007.obj").read_text()
    assert text.startswith("# clothsim ") and "frame 7" in text.splitlines()[0]


def test_obj_colliders(scene_file, tmp_path):
    clothsim.export(scene_file, tmp_path / "seq", frames=1)
    objects = parse_obj(tmp_path / "seq" / "colliders.obj")
    assert list(objects) == ["sphere_0", "plane_0"]
    sphere = objects["sphere_0"]
    distance = np.linalg.norm(sphere["v"].astype(np.float64) - [0.6, 0.3, 0.4], axis=1)
    np.testing.assert_allclose(distance, 0.15, rtol=1e-6)
    assert len(sphere["v"]) == len(sphere["vt"]) == len(sphere["vn"])
    assert sphere["f"].min() == 1 and sphere["f"].max() == len(sphere["v"])
    plane = objects["plane_0"]
    assert plane["f"].shape == (1, 4, 3)
    first = len(sphere["v"]) + 1  # OBJ indices count over the whole file
    assert plane["f"][0, :, 0].tolist() == [first, first + 1, first + 2, first + 3]


def test_obj_is_deterministic_and_static_scene_has_no_colliders_file(tmp_path):
    for name in ("a", "b"):
        clothsim.export("pinned2", tmp_path / name, frames=4, every=2)
    assert snapshot(tmp_path / "a") == snapshot(tmp_path / "b")
    assert sorted(snapshot(tmp_path / "a")) == ["cloth_00000.obj", "cloth_00002.obj", "cloth_00004.obj"]


# -- the API -------------------------------------------------------------------------------------
def test_api_continues_a_simulation_and_is_the_package_function(scene_file, tmp_path):
    import clothsim.exporters.obj  # noqa: F401  (loading the package must not hide the function)

    assert "export" in clothsim.__all__ and callable(clothsim.export)
    sim = clothsim.Simulation(clothsim.load_scene(scene_file))
    sim.step(2)
    assert clothsim.export(sim, tmp_path / "seq", frames=5, every=2) == [2, 4, 6, 7]
    assert sim.frame == 7
    assert sorted(p.name for p in (tmp_path / "seq").iterdir()) == [
        "cloth_00002.obj", "cloth_00004.obj", "cloth_00006.obj", "cloth_00007.obj", "colliders.obj"]
    last = parse_obj(tmp_path / "seq" / "cloth_00007.obj")["cloth"]["v"]
    np.testing.assert_array_equal(last, sim.positions.astype(np.float32))
    with pytest.raises(clothsim.ClothsimError, match=r"^frames: must be >= 0, got -1$"):
        clothsim.export(sim, tmp_path / "x.usda", frames=-1)
    with pytest.raises(clothsim.ClothsimError, match=r"^every: must be >= 1, got 0$"):
        clothsim.export(sim, tmp_path / "x.usda", every=0)
    assert sim.frame == 7


# -- bad outputs ---------------------------------------------------------------------------------
def test_bad_output_paths_fail_before_simulating(tmp_path):
    (tmp_path / "afile").write_bytes(b"a regular file")
    (tmp_path / "stage.usda").mkdir()
    huge = ("--frames", "100000000")  # would run for hours if the check came after the simulation
    cases = [
        ("x.fbx", "x.fbx: unsupported output type '.fbx' (use .usd, .usda, .usdc, or a folder for an OBJ sequence)"),
        ("x.obj", "x.obj: unsupported output type '.obj' (use .usd, .usda, .usdc, or a folder for an OBJ sequence)"),
        ("afile/x.usda", "afile/x.usda: afile is a file, not a folder"),
        ("afile/seq/", "afile/seq: afile is a file, not a folder"),
        ("afile", "afile: exists and is not a folder (a frames folder needs a folder)"),
        ("stage.usda", "stage.usda: is a folder, not a file; choose a file name "
                       "(or write stage.usda/ for an OBJ sequence in that folder)"),
    ]
    if os.path.isdir("/proc/self"):
        cases += [("/proc/x.usda", "/proc/x.usda: cannot write in /proc: No such file or directory"),
                  ("/proc/seq/", "/proc/seq: cannot write in /proc: No such file or directory")]
    before = snapshot(tmp_path)
    for out, message in cases:
        r = run_cli("export", "pinned2", *huge, "-o", out, cwd=tmp_path, timeout=120)
        assert error_line(r) == f"clothsim: error: {message}", out
    r = run_cli("export", "pinned2", "--every", "0", "-o", "x.usda", cwd=tmp_path)
    assert error_line(r) == "clothsim: error: --every: must be >= 1, got 0"
    assert snapshot(tmp_path) == before


def test_existing_folder_with_a_users_files_is_untouched(tmp_path):
    out = tmp_path / "seq"
    out.mkdir()
    (out / "notes.txt").write_bytes(b"do not lose me\n")
    (out / "cloth_00000.obj").write_bytes(b"an earlier frame")  # ours, but the folder is still refused
    (out / "cloth_0001.obj").write_bytes(b"four digits: not a name clothsim writes")
    (out / "frame_00000.png").write_bytes(b"a render's frame: not part of an OBJ sequence")
    before = snapshot(out)
    r = run_cli("export", "pinned2", "--frames", "100000000", "-o", "seq", cwd=tmp_path, timeout=120)
    assert error_line(r) == ("clothsim: error: seq: folder is not empty (3 files not written by clothsim); "
                             "choose another or empty it")
    assert snapshot(out) == before
    assert snapshot(tmp_path) == {**{f"seq/{k}": v for k, v in before.items()}, "seq": "dir"}


def test_existing_sequence_is_replaced_and_stale_frames_removed(scene_file, tmp_path):
    out = tmp_path / "seq"
    out.mkdir()
    for name in ("cloth_00000.obj", "cloth_00003.obj", "cloth_00009.obj", "colliders.obj"):
        (out / name).write_bytes(b"an earlier export")
    r = run_cli("export", "pinned2", "--frames", "2", "--every", "2", "-o", str(out))
    assert r.returncode == 0, r.stderr
    # pinned2 has no colliders: the earlier colliders.obj goes with the earlier frames.
    assert sorted(p.name for p in out.iterdir()) == ["cloth_00000.obj", "cloth_00002.obj"]
    assert (out / "cloth_00000.obj").read_bytes().startswith(b"# clothsim ")


def test_sequence_names():
    from clothsim.atomic import is_frame_name
    from clothsim.exporters.obj import cloth_name, is_sequence_name

    assert cloth_name(12) == "cloth_00012.obj" and cloth_name(123456) == "cloth_123456.obj"
    for name in ("cloth_00000.obj", "cloth_123456.obj", "colliders.obj"):
        assert is_sequence_name(name), name
    for name in ("cloth_0001.obj", "cloth_000001.obj", "cloth_00001.OBJ", "cloth_00001.obj.bak",
                 "frame_00000.png", "Colliders.obj", ".cloth_00000.obj"):
        assert not is_sequence_name(name), name
    assert is_frame_name("frame_00000.png") and not is_frame_name("cloth_00000.obj")  # renders unchanged
