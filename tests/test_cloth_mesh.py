"""Cloth from a mesh (``cloth.mesh``): the OBJ's polygons and texture coordinates, the topology built
from them (welding, springs of three families, areas, render vertices, the planar projection), the
scene keys and their errors (each through the real command), and the grid's surface unchanged."""

from __future__ import annotations

import json
import os
import re
import subprocess
import sys

import numpy as np
import pytest

from clothsim import scene as scene_module
from clothsim.cloth import (SHEARING, STRUCTURAL, BENDING, cloth_surface, cloth_triangles, cloth_uvs,
                            pinned_mask)
from clothsim.clothmesh import build_cloth_mesh, planar_uvs
from clothsim.errors import SceneError
from clothsim.objfile import ObjError, parse_obj, parse_obj_polygons
from clothsim.objshapes import sheet_obj, tube_obj
from clothsim.scene import load_scene, scene_from_dict
from clothsim.sweeps.params import scene_json

from conftest import SCENES, error_line

QUAD = "v 0 0 0\nv 0 0 1\nv 1 0 1\nv 1 0 0\nf 1 2 3 4\n"
TWO_TRIANGLES = "v 0 0 0\nv 0 0 1\nv 1 0 1\nv 1 0 0\nf 1 2 3\nf 1 3 4\n"


def _mesh(text: str, scale: float = 1.0, translate=(0.0, 0.0, 0.0), rotation=(0.0, 0.0, 0.0)):
    return build_cloth_mesh(parse_obj_polygons(text), path="m.obj", file="m.obj", scale=scale,
                            translate=translate, rotation=rotation)


def _families(m) -> list[int]:
    return np.bincount(m.spring_kind, minlength=3).tolist()


def _pairs(m, family: int) -> list[tuple[int, int]]:
    sel = m.spring_kind == family
    return list(zip(m.spring_i[sel].tolist(), m.spring_j[sel].tolist()))


def _cloth(obj: str = "m.obj", **extra) -> dict:
    return {"mesh": {"path": obj}, "thickness": 0.01, "density": 150.0, "ks": 5000.0, "damping": 0.2, **extra}


def _write(tmp_path, text: str, cloth: dict | None = None, name: str = "scene.json") -> str:
    (tmp_path / "m.obj").write_text(text)
    path = tmp_path / name
    path.write_text(json.dumps({"cloth": cloth if cloth is not None else _cloth()}))
    return str(path)


# -- springs, counted by hand ----------------------------------------------------------------------
@pytest.mark.parametrize("text, families", [
    (QUAD, [5, 1, 0]),  # 4 sides + the fan diagonal 1-3; the other diagonal shears; the bend across 1-3 is it
    (TWO_TRIANGLES, [5, 0, 1]),  # the same edges; the bend across 1-3 joins 2 and 4
    (sheet_obj(1.0, 1.0, 3, 3), [16, 4, 4]),  # 12 sides + 4 diagonals; 4 shears; 4 inner sides bend
    (sheet_obj(1.0, 1.0, 3, 3, quads=False), [16, 0, 8]),  # every inner edge (8) bends
    (tube_obj(0.3, 0.5, 8, 3), [80, 24, 40]),  # 32 ring + 24 vertical + 24 diagonal; 24 vertical + 16 ring bend
])
def test_spring_counts(text, families):
    m = _mesh(text)
    assert _families(m) == families
    assert (m.spring_i < m.spring_j).all() and m.spring_i.dtype == np.int32 and m.spring_kind.dtype == np.int8
    assert np.all(np.diff(m.spring_kind) >= 0)  # family by family
    for family in (STRUCTURAL, SHEARING, BENDING):
        pairs = _pairs(m, family)
        assert pairs == sorted(set(pairs))


def test_the_exact_pairs_of_a_quad_and_of_two_triangles():
    quad, tris = _mesh(QUAD), _mesh(TWO_TRIANGLES)
    for m in (quad, tris):
        assert _pairs(m, STRUCTURAL) == [(0, 1), (0, 2), (0, 3), (1, 2), (2, 3)]
        assert m.triangles.tolist() == [[0, 1, 2], [0, 2, 3]]
        assert m.lines.tolist() == ([5, 5] if m is quad else [5, 6])
    assert _pairs(quad, SHEARING) == [(1, 3)] and _pairs(quad, BENDING) == []
    assert _pairs(tris, SHEARING) == [] and _pairs(tris, BENDING) == [(1, 3)]


def test_a_polygon_is_a_fan_and_only_quads_shear():
    m = _mesh("v 0 0 0\nv 1 0 0\nv 2 0 1\nv 1 0 2\nv 0 0 1\nf 1 2 3 4 5\n")
    assert m.triangles.tolist() == [[0, 1, 2], [0, 2, 3], [0, 3, 4]]
    assert _families(m) == [7, 0, 2]
    assert _pairs(m, BENDING) == [(1, 3), (2, 4)]


# -- areas -----------------------------------------------------------------------------------------
def test_point_areas_sum_to_the_placed_area():
    sheet = _mesh(sheet_obj(2.0, 1.0, 5, 5), scale=1.5, rotation=(30.0, 10.0, 0.0), translate=(1.0, 2.0, 3.0))
    assert sheet.point_area.sum() == pytest.approx(2.0 * 1.0 * 1.5**2, rel=1e-12)
    assert sheet.point_area.shape == (25,) and (sheet.point_area > 0).all()
    # a cell is 0.5 x 0.25 before scaling; its fan's first corner is in both triangles (a third of
    # each), the corner at the end of its first row in one
    cell = 0.5 * 0.25 * 1.5**2
    assert sheet.point_area[0] == pytest.approx(cell / 3, rel=1e-12)
    assert sheet.point_area[4] == pytest.approx(cell / 2 / 3, rel=1e-12)
    tube = _mesh(tube_obj(0.3, 0.5, 8, 3))
    assert tube.point_area.sum() == pytest.approx(8 * 2 * 0.3 * np.sin(np.pi / 8) * 0.5, rel=1e-5)


def test_placement_is_the_mesh_colliders():
    from clothsim.meshcollider import rotation_matrix

    parsed = parse_obj_polygons(QUAD).vertices
    m = _mesh(QUAD, scale=2.0, translate=(1.0, -2.0, 0.5), rotation=(10.0, 20.0, 30.0))
    assert np.array_equal(m.points, (parsed * 2.0) @ rotation_matrix((10.0, 20.0, 30.0)).T + [1.0, -2.0, 0.5])


# -- welding ---------------------------------------------------------------------------------------
def test_a_seam_is_welded_for_the_simulation_and_kept_for_the_texture():
    plain, seamed = _mesh(sheet_obj(1.0, 1.0, 5, 4)), _mesh(sheet_obj(1.0, 1.0, 5, 4, seam=True))
    for name in ("points", "triangles", "spring_i", "spring_j", "spring_kind", "point_area"):
        assert np.array_equal(getattr(plain, name), getattr(seamed, name)), name
    assert plain.uvs.shape[0] == plain.points.shape[0] == 20
    assert seamed.uvs.shape[0] == 24 > seamed.points.shape[0]
    # the duplicates (v lines 21..24) are the middle column's points
    assert seamed.vertex_point[20:].tolist() == [2, 7, 12, 17]
    assert np.array_equal(np.unique(seamed.uv_point), np.arange(20))
    assert np.array_equal(seamed.uv_point[seamed.uv_triangles], seamed.triangles)
    # every render vertex keeps its own vt
    assert np.allclose(seamed.uvs, seamed.points[seamed.uv_point][:, [0, 2]], atol=1e-6)


def test_points_are_numbered_by_first_appearance_and_unused_vertices_dropped():
    text = "v 5 5 5\nv 0 0 0\nv 1 0 0\nv 0 0 0\nv 1 0 1\nf 4 3 5\n"
    m = _mesh(text)
    assert m.vertex_point.tolist() == [-1, 0, 1, 0, 2]  # v 2 and v 4 are one point, v 1 is unused
    assert m.triangles.tolist() == [[0, 1, 2]]
    assert m.points.tolist() == [[0, 0, 0], [1, 0, 0], [1, 0, 1]]


def test_pinned_vertices_go_through_the_weld(tmp_path):
    obj = sheet_obj(1.0, 1.0, 5, 4, seam=True)
    by_copy = load_scene(_write(tmp_path, obj, _cloth(pinned_vertices=[22, 0, 0]), "a.json"))
    by_original = load_scene(_write(tmp_path, obj, _cloth(pinned_vertices=[12, 0]), "b.json"))
    mask = pinned_mask(by_copy.cloth)
    assert np.flatnonzero(mask).tolist() == [0, 12]
    assert np.array_equal(mask, pinned_mask(by_original.cloth))
    assert by_copy.cloth.pinned_vertices == (22, 0, 0)


# -- texture coordinates ---------------------------------------------------------------------------
def test_the_vt_of_each_corner_and_negative_vt_indices():
    m = _mesh("v 0 0 0\nv 1 0 0\nv 1 0 1\nvt 0.25 0.5\nvt 1 0\nvt 0.75\nf 1/-3 2/-2 3/-1\n")
    assert m.has_uvs and m.uvs.dtype == np.float32
    assert m.uvs.tolist() == [[0.25, 0.5], [1.0, 0.0], [0.75, 0.0]]


def _without_vt(text: str) -> str:
    return re.sub(r"(\d+)/\d+", r"\1", "".join(l for l in text.splitlines(True) if not l.startswith("vt ")))


@pytest.mark.parametrize("drop_vt", [True, False])
def test_the_planar_projection_when_uvs_are_missing(drop_vt):
    text = sheet_obj(2.0, 1.0, 5, 3)
    # no vt at all; or one corner without its vt: every point is projected
    text = _without_vt(text) if drop_vt else text.replace("f 1/1 ", "f 1 ")
    m = _mesh(text, rotation=(40.0, 25.0, -15.0), translate=(3.0, 1.0, 0.0))
    assert not m.has_uvs
    assert m.uvs.shape == (15, 2) and np.array_equal(m.uv_point, np.arange(15))
    assert np.array_equal(m.uv_triangles, m.triangles)
    # the rectangle comes back whatever its placement (up to a mirror), scaled alike on both axes
    # so that its long side spans [0, 1]
    flat = parse_obj_polygons(text).vertices[:, [0, 2]] / 2.0
    gaps = lambda xy: np.linalg.norm(xy[:, None, :] - xy[None, :, :], axis=2)  # noqa: E731
    assert np.allclose(gaps(m.uvs.astype(np.float64)), gaps(flat), atol=1e-6)
    assert m.uvs.min(axis=0) == pytest.approx([0.0, 0.0], abs=1e-6)
    assert sorted(m.uvs.max(axis=0)) == pytest.approx([0.5, 1.0])
    again = _mesh(text, rotation=(40.0, 25.0, -15.0), translate=(3.0, 1.0, 0.0))
    assert np.array_equal(again.uvs, m.uvs)


def test_a_square_sheets_projection_follows_the_world_axes():
    m = _mesh(_without_vt(sheet_obj(1.0, 1.0, 4, 4)))
    assert not m.has_uvs
    assert np.allclose(m.uvs, m.points[:, [0, 2]], atol=1e-6)
    assert planar_uvs(m.points).dtype == np.float32


# -- the reader: the collider's reading unchanged --------------------------------------------------
def test_the_colliders_reading_ignores_texture_indices_as_before():
    text = "v 0 0 0\nv 1 0 0\nv 0 1 0\nvt 0 0\nf 1/9 2/9 3/x\n"
    assert parse_obj(text).triangles.tolist() == [[0, 1, 2]]
    with pytest.raises(ObjError, match=r"line 5: face vt index 9 out of range \(1\.\.1, "):
        parse_obj_polygons(text)


# -- the scene -------------------------------------------------------------------------------------
def test_a_mesh_cloth_in_the_scene(tmp_path):
    scene = load_scene(_write(tmp_path, tube_obj(0.3, 0.5, 8, 3), _cloth(pinned_vertices=[27])))
    cloth = scene.cloth
    assert cloth.is_mesh and cloth.num_points == 32
    assert (cloth.width, cloth.height, cloth.num_width_points, cloth.num_height_points, cloth.pinned) == (0.0, 0.0, 0, 0, ())
    assert cloth.orientation == scene_module.HORIZONTAL
    assert cloth.mesh.file == str(tmp_path / "m.obj")
    grid = load_scene(SCENES / "pinned2.json").cloth
    assert not grid.is_mesh and grid.mesh is None and grid.pinned_vertices == ()


def test_scene_json_round_trips_a_mesh_cloth_and_keeps_a_grids(tmp_path):
    cloth = _cloth(pinned_vertices=[3, 5], pin_motion={"velocity": [0, 0.1, 0]}, enable_bending=False)
    cloth["mesh"].update(scale=2.0, translate=[0, 1, 0], rotation=[90, 0, 0])
    scene = load_scene(_write(tmp_path, sheet_obj(1.0, 1.0, 3, 3), cloth))
    data = json.loads(json.dumps(scene_json(scene)))
    again = scene_from_dict(data, str(tmp_path / "elsewhere" / "x.json"))
    assert data["cloth"]["mesh"] == {"path": str(tmp_path / "m.obj"), "scale": 2.0, "translate": [0.0, 1.0, 0.0],
                                     "rotation": [90.0, 0.0, 0.0]}
    assert np.array_equal(again.cloth.mesh.points, scene.cloth.mesh.points)
    assert again.cloth.pinned_vertices == (3, 5) and again.cloth.pin_motion == scene.cloth.pin_motion
    assert again.cloth.enable_bending is False
    # a grid's JSON: exactly what the sweeps wrote before mesh cloths (the fields in order)
    import dataclasses

    for name in ("pinned2", "flag"):
        grid = load_scene(SCENES / f"{name}.json")
        old = dataclasses.asdict(grid.cloth)
        del old["mesh"], old["pinned_vertices"]
        old["pinned"] = [list(p) for p in grid.cloth.pinned]
        m = grid.cloth.pin_motion
        if m is None:
            del old["pin_motion"]
        else:
            old["pin_motion"] = ({"velocity": list(m.velocity)} if m.velocity is not None else
                                 {"keyframes": [[t, list(p)] for t, p in m.keyframes]})
        assert json.dumps(grid.cloth.as_json()) == json.dumps(old)


def test_a_mesh_too_large_for_the_memory_is_refused(tmp_path, monkeypatch):
    monkeypatch.setattr(scene_module, "available_memory", lambda: 10_000)
    with pytest.raises(SceneError) as err:
        load_scene(_write(tmp_path, tube_obj(0.3, 0.5, 8, 3)))
    assert str(err.value) == (f"{tmp_path / 'scene.json'}: cloth.mesh.path: m.obj: a cloth of 32 points, 144 "
                              f"springs and 48 triangles would need about 65.0 KiB of memory; only 9.8 KiB is "
                              f"available")


def test_the_grids_surface_is_the_grid_functions():
    cloth = load_scene(SCENES / "pinned2.json").cloth
    s = cloth_surface(cloth)
    nw, nh = cloth.num_width_points, cloth.num_height_points
    assert s.triangles.dtype == np.int64 and np.array_equal(s.triangles, cloth_triangles(nw, nh).reshape(-1, 3))
    assert s.uv_triangles is s.triangles and s.has_uvs
    assert np.array_equal(s.uv_point, np.arange(nw * nh)) and np.array_equal(s.uvs, cloth_uvs(nw, nh))


def test_a_mesh_cloths_surface_is_its_mesh(tmp_path):
    m = load_scene(_write(tmp_path, sheet_obj(1.0, 1.0, 4, 3, seam=True))).cloth.mesh
    s = cloth_surface(load_scene(str(tmp_path / "scene.json")).cloth)
    assert s.triangles.shape == m.triangles.shape and s.uvs.shape == (15, 2) and s.has_uvs


# -- every refusal: one line naming the file and field; exit 2 through the real command -------------------------------------
V4 = "v 0 0 0\nv 1 0 0\nv 1 0 1\nv 0 0 1\n"
BAD = [
    ("no faces", V4, None, "cloth.mesh.path: m.obj: empty mesh: no faces (4 vertices)"),
    ("index", V4 + "f 1 2 9\n", None,
     "cloth.mesh.path: m.obj: line 5: face index 9 out of range (1..4, or -1..-4, vertices read so far)"),
    ("vt index", V4 + "vt 0 0\nf 1/1 2/1 3/2\n", None,
     "cloth.mesh.path: m.obj: line 6: face vt index 2 out of range (1..1, or -1..-1, vt lines read so far)"),
    ("three at an edge", V4 + "v 0 1 0\nf 1 2 3\nf 2 1 4\nf 1 2 5\n", None,
     "cloth.mesh.path: m.obj: line 6: non-manifold: the edge between vertices 1 and 2 is shared by 3 triangles "
     "(faces on lines 6, 7, 8); an edge of a cloth may belong to at most 2"),
    ("collinear", "v 0 0 0\nv 1 0 0\nv 2 0 0\nf 1 2 3\n", None,
     "cloth.mesh.path: m.obj: line 4: degenerate face: a triangle of area 0 m^2 (at most 1e-12 x the squared "
     "bounding-box diagonal, 4 m^2)"),
    ("tiny", V4 + "v 0.5 0 1e-13\nf 1 2 3 4\nf 1 5 2\n", None,
     "cloth.mesh.path: m.obj: line 7: degenerate face: a triangle of area 5e-14 m^2 (at most 1e-12 x the squared "
     "bounding-box diagonal, 2 m^2)"),
    ("repeat", V4 + "f 1 2 1\n", None, "cloth.mesh.path: m.obj: line 5: degenerate face: it names vertex 1 twice"),
    ("welded", V4 + "v 1 0 0\nf 1 2 5\n", None,
     "cloth.mesh.path: m.obj: line 6: degenerate face: vertices 2 and 5 are at the same position (welded into one point)"),
    ("missing", None, None, "cloth.mesh.path: nothere.obj: no such OBJ file"),
    ("pin range", V4 + "f 1 2 3 4\n", {"pinned_vertices": [0, 4]},
     "cloth.pinned_vertices[1]: vertex index 4 out of range 0..3 (the OBJ has 4 vertices)"),
    ("pin unused", V4 + "v 5 5 5\nf 1 2 3 4\n", {"pinned_vertices": [4]},
     "cloth.pinned_vertices[0]: vertex 4 is not part of the cloth: no face uses it"),
    ("width", V4 + "f 1 2 3 4\n", {"width": 1.0},
     "cloth.width: not allowed with cloth.mesh (the mesh gives the shape)"),
    ("pinned", V4 + "f 1 2 3 4\n", {"pinned": [[0, 0]]},
     "cloth.pinned: not allowed with cloth.mesh (pin OBJ vertices with cloth.pinned_vertices)"),
    ("pin motion", V4 + "f 1 2 3 4\n", {"pin_motion": {"velocity": [0, 1, 0]}},
     "cloth.pin_motion: the cloth has no pinned points to move (cloth.pinned_vertices is empty)"),
    ("grid pins", None, "grid", "cloth.pinned_vertices: only with cloth.mesh (a grid cloth pins [x, y] index pairs "
                                "with cloth.pinned)"),
]


def _bad_scene(folder, k: int) -> str:
    name, obj, extra, words = BAD[k]
    if extra == "grid":
        cloth = {**json.loads((SCENES / "pinned2.json").read_text())["cloth"], "pinned_vertices": [0]}
    else:
        cloth = _cloth("nothere.obj" if obj is None else "m.obj", **(extra or {}))
    return _write(folder, obj or "", cloth)


@pytest.mark.parametrize("k", range(len(BAD)), ids=[b[0] for b in BAD])
def test_every_refusal_is_one_line(tmp_path, k):
    path = _bad_scene(tmp_path, k)
    with pytest.raises(SceneError) as err:
        load_scene(path)
    text = str(err.value)
    assert "\n" not in text and text.startswith(f"{path}: {BAD[k][3]}"), text


def test_refusals_through_the_command(tmp_path):
    # The command prints the loader's message (the test above checks each); three kinds here, an
    # OBJ's line, a scene field and a missing file, all at once: each is a whole interpreter starting
    # (about 1 s on two busy cores), and every case this way took 24 s.
    runs = []
    env = {k: v for k, v in os.environ.items() if k != "DISPLAY"}
    for k in (3, 9, 8):
        folder = tmp_path / str(k)
        folder.mkdir()
        path = _bad_scene(folder, k)
        runs.append((path, BAD[k][3], subprocess.Popen(
            [sys.executable, "-m", "clothsim", "simulate", path, "--frames", "0", "-o", str(folder / "out.npz")],
            stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True, env=env)))
    for path, words, proc in runs:
        out, err = proc.communicate(timeout=120)
        line = error_line(subprocess.CompletedProcess(proc.args, proc.returncode, out, err))
        assert line.startswith(f"clothsim: error: {path}: {words}"), line
        assert not os.path.exists(os.path.join(os.path.dirname(path), "out.npz"))


def test_a_grid_written_with_every_field_loads_as_a_grid():
    data = json.loads((SCENES / "pinned2.json").read_text())
    data["cloth"].update(mesh=None, pinned_vertices=[])
    assert scene_from_dict(data, "g.json").cloth == load_scene(SCENES / "pinned2.json").cloth
