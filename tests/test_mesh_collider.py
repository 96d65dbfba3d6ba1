"""Triangle-mesh colliders: the OBJ reader and its errors, the shape checks, the grid and the points'
lists against brute force, the lists' separating planes, and cloth kept outside closed meshes and on
its side of open ones."""

from __future__ import annotations

import json

import numpy as np
import pytest

from clothsim import Simulation, load_scene
from clothsim.errors import SceneError
from clothsim.meshcollider import NEAR_PLANES, rotation_matrix
from clothsim.objfile import ObjError, parse_obj
from clothsim.objshapes import TORUS, box_obj, bundled, torus_obj
from clothsim.sim.passes.colliders.mesh import closest_on_triangle, mesh_targets
from clothsim.sim.passes.colliders.meshgrid import INFO_NEAR, INFO_NEAR_OK, PLANE_D, mesh_group

from conftest import SCENES, error_line

THICKNESS = 0.0095


def _cloth(n: int = 14, y: float = 1.0, **extra) -> dict:
    return {"width": 1.0, "height": 1.0, "num_width_points": n, "num_height_points": n, "thickness": THICKNESS,
            "orientation": 0, "damping": 0.2, "density": 150.0, "ks": 5000.0, **extra}


def _scene(tmp_path, obj_text: str, mesh: dict | list | None = None, **top) -> str:
    (tmp_path / "shape.obj").write_text(obj_text)
    data = {"cloth": _cloth(), "simulation": {"self_collision": False}, **top}
    if mesh is not None:
        data["mesh"] = mesh
    path = tmp_path / "scene.json"
    path.write_text(json.dumps(data))
    return str(path)


def _box_depth(points: np.ndarray, center, half, rotation=(0.0, 0.0, 0.0)) -> np.ndarray:
    """Signed distance of each point to an oriented box (negative inside)."""
    q = (points - np.asarray(center)) @ rotation_matrix(rotation)  # into the box frame: R^T p
    d = np.abs(q) - np.asarray(half)
    outside = np.linalg.norm(np.maximum(d, 0.0), axis=1)
    return outside + np.minimum(d.max(axis=1), 0.0)


# -- reading OBJ ---------------------------------------------------------------------------------
def test_reader_fans_polygons_and_reads_every_corner_form():
    obj = parse_obj("# a quad and a triangle\nv 0 0 0\nv 1 0 0\nv 1 1 0\nv 0 1 0 1.0\nvt 0 0\nvn 0 0 1\n"
                    "o thing\ng part\ns off\nusemtl x\nf 1/1/1 2//1 3/1 4\nf -4 -2 -1\n")
    assert obj.vertices.shape == (4, 3)
    assert obj.triangles.tolist() == [[0, 1, 2], [0, 2, 3], [0, 2, 3]]
    assert obj.lines.tolist() == [12, 12, 13]


@pytest.mark.parametrize("text, line, words", [
    ("v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 4\n", 4, "face index 4 out of range"),
    ("v 0 0 0\nv 1 0 nan\nv 0 1 0\nf 1 2 3\n", 2, "must be finite"),
    ("v 0 0 0\nv 1 0 x\n", 2, "expected a number"),
    ("v 0 0\n", 1, "needs 3 coordinates"),
    ("v 0 0 0\nv 1 0 0\nv 0 1 0\nl 1 2\n", 4, "unsupported statement 'l'"),
    ("v 0 0 0\nv 1 0 0\nf 1 2\n", 3, "at least 3 corners"),
    ("v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 2\n", 4, "same vertex twice"),
    ("v 0 0 0\nv 1 0 0\n", 0, "empty mesh: no faces"),
])
def test_reader_errors_name_the_line(text, line, words):
    with pytest.raises(ObjError) as info:
        parse_obj(text)
    assert info.value.line == line
    assert words in str(info.value)


# -- shape checks, through the scene loader -------------------------------------------------------
_TRI = "v 0 0 0\nv 1 0 0\nv 0 0 1\nv 0 1 0\n"


@pytest.mark.parametrize("obj, words", [
    (_TRI + "f 1 2 3\nf 1 2 4\n", "wound the same way"),  # both run 1 -> 2
    (_TRI + "f 1 2 3\nf 2 1 4\nf 1 2 4\n", "shared by 3 faces"),
    ("v 0 0 0\nv 1 0 0\nv 2 0 0\nf 1 2 3\n", "zero area"),
    ("v 0 0 0\nv 1 0 0\nv 0 0 1\nv 1 0 1\nf 1 2 3\nf 2 4 3\nf 3 2 4\n", "non-manifold: the edge between vertices"),
])
def test_bad_shapes_are_one_line_errors(tmp_path, obj, words):
    path = _scene(tmp_path, obj, {"path": "shape.obj", "friction": 0.2})
    with pytest.raises(SceneError) as info:
        load_scene(path)
    text = str(info.value)
    assert text.startswith(f"{path}: mesh.path: shape.obj: line ")
    assert words in text and "\n" not in text


def test_missing_obj_and_bad_fields_are_errors_naming_the_field(tmp_path):
    path = _scene(tmp_path, box_obj(), [{"path": "shape.obj", "friction": 0.2}, {"path": "nope.obj", "friction": 0}])
    with pytest.raises(SceneError, match=r"mesh\[1\]\.path: nope.obj: no such OBJ file"):
        load_scene(path)
    for mesh, match in (({"path": "shape.obj", "friction": 2}, r"mesh.friction: must be <= 1"),
                        ({"path": "shape.obj", "friction": 0, "scale": 0}, r"mesh.scale: must be > 0"),
                        ({"path": "shape.obj", "friction": 0, "rotation": [0, "x", 0]}, r"mesh.rotation\[1\]"),
                        ({"path": 3, "friction": 0}, r"mesh.path: expected the path of an OBJ file"),
                        ({"path": "shape.obj", "friction": 0, "motion": {"keyframes": [[1, [0, 0, 0]], [0.5, [1, 0, 0]]]}},
                         r"mesh.motion.keyframes\[1\]\[0\]: keyframe times must increase")):
        path = _scene(tmp_path, box_obj(), mesh)
        with pytest.raises(SceneError, match=match):
            load_scene(path)


def test_cli_reports_a_bad_obj_in_one_line(tmp_path, cli):
    path = _scene(tmp_path, box_obj() + "f 1 2 99\n", {"path": "shape.obj", "friction": 0.2})
    line = error_line(cli("simulate", path, "--frames", "1", "--out", str(tmp_path / "s.npz")))
    assert line == (f"clothsim: error: {path}: mesh.path: shape.obj: line 16: face index 99 out of range "
                    f"(1..8, or -1..-8, vertices read so far)")


def test_closed_and_open_meshes_are_told_apart_and_inside_out_is_turned(tmp_path):
    path = _scene(tmp_path, box_obj(), {"path": "shape.obj", "friction": 0})
    assert load_scene(path).meshes[0].closed
    path = _scene(tmp_path, box_obj(drop_top=True), {"path": "shape.obj", "friction": 0})
    assert not load_scene(path).meshes[0].closed
    # every face reversed: the loader turns it back, so the normals point out again
    flipped = "\n".join(" ".join(["f", *reversed(line.split()[1:])]) if line.startswith("f ") else line
                        for line in box_obj().splitlines())
    spec = load_scene(_scene(tmp_path, flipped, {"path": "shape.obj", "friction": 0})).meshes[0]
    v = spec.vertices
    a, b, c = (v[spec.triangles[:, k]] for k in range(3))
    assert (np.einsum("ij,ij->i", np.cross(b - a, c - a), (a + b + c) / 3) > 0).all()


def test_bundled_torus_is_what_the_generator_writes():
    assert (SCENES / "torus.obj").read_text() == torus_obj(*TORUS)
    for name, text in bundled().items():  # every shipped OBJ (the skirt's cloth too)
        assert (SCENES / name).read_text() == text, name
    spec = load_scene("mesh").meshes[0]
    assert spec.closed and spec.triangles.shape == (2 * TORUS[2] * TORUS[3], 3)


# -- the grid against brute force -----------------------------------------------------------------
def _without_planes(group):
    """The group with room for no separating plane: every listed point is decided by the tests."""
    return group._replace(near_pl=np.zeros(group.near_pl.shape[:2] + (0,) + group.near_pl.shape[3:]))


@pytest.mark.xdist_group("mesh_targets")  # one worker compiles the brute-force query (5 s), not both
def test_grid_gives_the_same_contacts_as_brute_force(tmp_path):
    rng = np.random.default_rng(7)
    for obj, mesh in ((torus_obj(*TORUS), {"translate": [0.5, 0.3, 0.5], "rotation": [20, 35, -10]}),
                      (box_obj(0.2, 0.1, 0.3, drop_top=True), {"translate": [0.5, 0.5, 0.5], "scale": 1.5})):
        scene = load_scene(_scene(tmp_path, obj, {"path": "shape.obj", "friction": 0.25, **mesh}))
        group = _without_planes(mesh_group(scene))
        lo = group.verts.min(axis=0) + group.pose[0, :3] - 0.05
        hi = group.verts.max(axis=0) + group.pose[0, :3] + 0.05
        n = 20000
        last = rng.uniform(lo, hi, (n, 3))
        pos = last + rng.normal(0.0, 0.01, (n, 3))
        pos_t, last_t = np.ascontiguousarray(pos.T), np.ascontiguousarray(last.T)
        grid = mesh_targets(pos_t, last_t, group, False)
        brute = mesh_targets(pos_t, last_t, group, True)
        assert grid.tobytes() == brute.tobytes()
        moved = np.any(grid != pos_t, axis=0).sum()
        assert moved > 500, moved  # the points met the mesh: the comparison is not vacuous


def _near_surface(group, rng, n: int, spread: float) -> np.ndarray:
    """(3, n) points within ``spread`` of the mesh's surface, at random corners of its triangles."""
    t = rng.integers(0, group.tris.shape[0], n)
    w = rng.dirichlet((1.0, 1.0, 1.0), n)
    p = np.einsum("nk,nkc->nc", w, group.verts[group.tris[t]])
    p += group.fnorm[t] * rng.uniform(-spread, spread, (n, 1)) + group.pose[0, :3]
    return np.ascontiguousarray(p.T)


@pytest.mark.xdist_group("mesh_targets")  # one worker compiles the brute-force query (5 s), not both
@pytest.mark.parametrize("thickness, crowded", [(THICKNESS, False), (0.03, True)])
def test_each_points_list_holds_what_the_tests_need_and_its_planes_keep_the_thickness_as_the_points_move(
        tmp_path, thickness, crowded):
    # A finely tessellated torus (20,000 triangles) and a cloth of as many points as the test moves,
    # so that each keeps its own list. The points take small steps (most lists are kept), larger
    # ones (gathered afresh) and steps wider than a list reaches (the grid); with a thick cloth
    # many points have more triangles near them than a list holds, and ask the grid every time.
    # Each step runs twice from the same lists: without room for planes, the tests decide every
    # point and must give the brute-force answer bit for bit (the lists hold every triangle within
    # reach); with the planes, a point they hold must keep the thickness and cross nothing wherever
    # the tests' own answer does, and end near where the tests put it.
    n = 900
    text = _scene(tmp_path, torus_obj(TORUS[0], TORUS[1], 100, 100),
                  {"path": "shape.obj", "friction": 0.0, "translate": [0.5, 0.3, 0.5], "rotation": [10, 0, 25]},
                  cloth=_cloth(30, thickness=thickness))
    group = mesh_group(load_scene(text))
    assert group.tris.shape[0] == 20000 and group.near_n.shape == (1, n)
    lists = ("near_at", "near_n", "near_tris", "near_d", "near_ref", "near_first", "near_pl")
    rng = np.random.default_rng(3)
    last = _near_surface(group, rng, n, 2.0 * thickness)
    moved = held = checked = 0
    for step, spread in enumerate((0.2, 0.01, 0.01, 0.3, 0.01, 3.0, 0.01, 0.05)):
        pos = last + rng.normal(0.0, spread * thickness, last.shape)
        anchors = group.near_at.copy()
        saved = [getattr(group, name).copy() for name in lists]
        tests = mesh_targets(pos, last, _without_planes(group), False)
        brute = mesh_targets(pos, last, group, True)
        assert tests.tobytes() == brute.tobytes(), step
        for name, array in zip(lists, saved):
            getattr(group, name)[...] = array
        out = mesh_targets(pos, last, group, False)
        by_planes = np.any(out != brute, axis=0)
        held += int(by_planes.sum())
        # where the tests leave their own answer in place (it crosses nothing from the last position
        # and is the thickness clear of every triangle, to rounding), they must leave the planes' too
        held_out, held_last, held_tests = (np.ascontiguousarray(a[:, by_planes]) for a in (out, last, brute))
        clear = np.all(np.abs(mesh_targets(held_tests, held_last, group, True) - held_tests) <= 1e-9 * thickness,
                       axis=0)
        again = mesh_targets(held_out, held_last, group, True)
        assert np.all(np.abs(again - held_out)[:, clear] <= 1e-9 * thickness), step
        checked += int(clear.sum())
        assert np.all(np.linalg.norm(out - brute, axis=0) <= 0.5 * thickness), step
        moved += int(np.any(out != pos, axis=0).sum())
        if step == 2:  # after two small steps most lists were kept
            assert np.all(group.near_at == anchors, axis=2).sum() > n // 2
        last = out
    assert moved > n  # the points met the mesh: the comparison is not vacuous
    listed = group.near_n[0] >= 0
    too_many = np.isfinite(group.near_at[0, :, 0]) & ~listed  # gathered, and more than a list holds
    if crowded:
        assert too_many.sum() > n // 4
    else:
        assert listed.sum() > n // 2
        assert held > n // 4 and checked > held // 2  # the planes decided many points, most of them checked


@pytest.mark.xdist_group("mesh_targets")  # one worker compiles the brute-force query (5 s), not both
def test_each_list_is_nearest_first_with_each_triangles_distance_from_where_it_was_measured(tmp_path):
    # The pass reads a list only while a triangle's distance from the list's reference point (less
    # the slack), less the point's distance from it, is within r: the distances must be those of the
    # triangles, in order, from that point: the anchor when the list is gathered, and where the
    # point is once it has drifted REFRESH thicknesses from there (the list itself kept). The first
    # NEAR_PLANES triangles carry their separating planes from the same point: the unit vector from
    # the triangle's closest point to it, offset by the corner furthest along it; none for a point
    # inside the (closed) torus.
    text = _scene(tmp_path, torus_obj(*TORUS), {"path": "shape.obj", "translate": [0.5, 0.3, 0.5], "friction": 0.3},
                  cloth=_cloth(30))
    group = mesh_group(load_scene(text))
    rng = np.random.default_rng(5)
    pos = _near_surface(group, rng, 900, 1.5 * THICKNESS)
    slack = group.info[0, INFO_NEAR] - group.info[0, INFO_NEAR_OK]
    shift = group.pose[0, :3]
    ring, tube, _, sides = TORUS
    sag = tube * (1.0 - np.cos(np.pi / sides))  # the faces lie within this of the smooth torus, inside it
    sides_seen = set()

    def check(points):
        for p in points:
            k = group.near_n[0, p]
            tris, dist = group.near_tris[0, p, :k], group.near_d[0, p, :k]
            assert np.all(np.diff(dist) >= 0.0)
            ref = group.near_ref[0, p]
            exact = [np.linalg.norm(ref - np.array(closest_on_triangle(*ref, *group.verts[group.tris[t]].reshape(-1))[:3]))
                     for t in tris]
            assert np.allclose(dist, np.array(exact) - slack, rtol=0.0, atol=1e-12)
            assert group.near_first[0, p] == (dist[0] if k else np.inf)
            smooth = np.hypot(np.hypot(ref[0], ref[2]) - ring, ref[1]) - tube  # signed, the smooth torus's
            planes = group.near_pl[0, p, :min(k, NEAR_PLANES)]
            assert np.array_equal(planes[:, PLANE_D], dist[:planes.shape[0]])  # each plane's bound, copied to be read with it
            if smooth < -sag - 1e-4:  # surely inside the faces
                assert np.all(planes[:, 3] == np.inf), p
                sides_seen.add("inside")
            elif smooth > 0.0:  # surely outside
                normal, offset = planes[:, :3], planes[:, 3]
                corners = group.verts[group.tris[tris[:normal.shape[0]]]]  # (P, 3, 3)
                assert np.allclose(np.linalg.norm(normal, axis=1), 1.0, rtol=0.0, atol=1e-12)
                assert np.allclose(offset, np.einsum("pc,pkc->pk", normal, corners).max(axis=1), rtol=0.0, atol=1e-15)
                assert np.allclose(normal @ ref - offset, dist[:normal.shape[0]] + slack, rtol=0.0, atol=1e-12)
                sides_seen.add("outside")

    mesh_targets(pos, pos, group, False)
    listed = np.flatnonzero(group.near_n[0] > 1)
    assert listed.size > 300, listed.size
    assert np.array_equal(group.near_ref[0, listed], group.near_at[0, listed])
    check(listed[:80])
    # most lists hold triangles the pass need not read at the reference itself: the order matters
    assert np.mean(group.near_d[0, listed, 0] > THICKNESS) > 0.2
    # a drift of 0.25 thicknesses along the normal keeps the lists and measures them again
    anchors = group.near_at.copy()
    step = 0.25 * THICKNESS * group.fnorm[group.near_tris[0, :, 0]].T
    moved = pos + step
    mesh_targets(moved, moved, group, False)
    kept = listed[np.all(group.near_at[0, listed] == anchors[0, listed], axis=1)]
    assert kept.size > 100, kept.size
    remeasured = kept[np.all(group.near_ref[0, kept] != anchors[0, kept], axis=1)]
    assert remeasured.size > 50, remeasured.size
    assert np.allclose(group.near_ref[0, remeasured], (moved[:, remeasured] - shift[:, None]).T, rtol=0.0, atol=0.0)
    check(remeasured[:80])
    assert sides_seen == {"inside", "outside"}


@pytest.mark.xdist_group("mesh_targets")  # one worker compiles the brute-force query (5 s), not both
def test_a_point_that_jumps_through_a_sheet_in_one_substep_is_put_back_on_its_side(tmp_path):
    # 10 cm in one substep, ten times the thickness: only the swept (crossing) test can see it
    sheet = "v 0 0 0\nv 1 0 0\nv 1 0 1\nv 0 0 1\nf 1 2 3 4\n"
    group = mesh_group(load_scene(_scene(tmp_path, sheet, {"path": "shape.obj", "friction": 0.0})))
    last = np.array([[0.3, 0.05, 0.6], [0.7, -0.05, 0.2]]).T.copy()
    pos = np.array([[0.32, -0.05, 0.6], [0.7, 0.05, 0.25]]).T.copy()
    out = mesh_targets(pos, last, group, False)
    assert np.allclose(out.T, [[0.32, THICKNESS, 0.6], [0.7, -THICKNESS, 0.25]])


# -- cloth against meshes -------------------------------------------------------------------------
@pytest.mark.parametrize("rotation", [(0.0, 0.0, 0.0), (0.0, 30.0, 10.0)])
def test_cloth_dropped_on_a_box_obj_ends_outside_it(tmp_path, rotation):
    center, half = (0.5, 0.55, 0.5), (0.15, 0.15, 0.15)
    path = _scene(tmp_path, box_obj(*half), {"path": "shape.obj", "translate": list(center),
                                             "rotation": list(rotation), "friction": 0.3})
    sim = Simulation(load_scene(path))
    for _ in range(4):
        sim.step(30)
        depth = _box_depth(sim.positions, center, half, rotation)
        assert depth.min() > -0.003, depth.min()  # nothing more than 3 mm inside, at any checked frame
    # it rests on the box: the points above the top face lie about a thickness above it
    assert np.isclose(np.percentile(depth, 1), THICKNESS, atol=0.003)
    assert sim.positions[:, 1].min() < center[1] - half[1]  # and the rest hangs down its sides


def test_an_open_mesh_keeps_the_cloth_on_the_side_it_came_from(tmp_path):
    # One square sheet, wound to face down (-y): the side rule must not depend on the winding.
    # The cloth starts at y = 1 and falls onto a sheet below it, or rises (gravity up) against one above.
    sheet = "v 0 0 0\nv 1 0 0\nv 1 0 1\nv 0 0 1\nf 1 4 3 2\n"
    for gravity, height in ((-9.8, 0.5), (9.8, 1.5)):
        path = _scene(tmp_path, sheet, {"path": "shape.obj", "translate": [-0.5, height, -0.5], "scale": 2.0,
                                        "friction": 0.2})
        scene = load_scene(path)
        assert not scene.meshes[0].closed
        sim = Simulation(scene.with_simulation(gravity=(0.0, gravity, 0.0)))
        sim.step(60)
        y = sim.positions[:, 1]
        if gravity < 0:
            assert y.min() > height + THICKNESS - 0.002, y.min()
        else:
            assert y.max() < height - THICKNESS + 0.002, y.max()
        assert abs(np.median(y) - height) < 2 * THICKNESS  # it did reach the sheet


def test_a_far_mesh_is_skipped_and_changes_nothing(tmp_path):
    far = _scene(tmp_path, box_obj(0.2, 0.2, 0.2), {"path": "shape.obj", "translate": [5, 0, 5], "friction": 0.3})
    near = load_scene(far)
    plain = load_scene(_scene(tmp_path, box_obj(), None))
    a, b = Simulation(near), Simulation(plain)
    a.step(20)
    b.step(20)
    assert a.colliders_skipped == 20 * 30  # the mesh was ruled out by the bounding box every substep
    assert a.positions.tobytes() == b.positions.tobytes()


def test_a_keyframed_box_lifts_the_cloth_without_leaving_points_inside(tmp_path):
    # up through the cloth at 1.33 m/s (faster trips the blow-up guard's energy bound, which counts
    # only the work of gravity)
    center0, half = (0.5, 0.6, 0.5), (0.12, 0.12, 0.12)
    motion = {"keyframes": [[0.0, list(center0)], [0.6, [0.5, 1.4, 0.5]]]}
    path = _scene(tmp_path, box_obj(*half), {"path": "shape.obj", "translate": list(center0), "friction": 0.5,
                                             "motion": motion})
    # The cloth is free: pinned corners would stretch it over the box, and Provot's limit, which runs
    # after the collisions in the spec's order, then pulls points back into the box by millimetres.
    scene = load_scene(path)
    track = scene.meshes[0].track()
    sim = Simulation(scene)
    lifted = 0.0
    for _ in range(60):
        sim.step(1)
        center = track.at(sim.time)
        assert _box_depth(sim.positions, center, half).min() > -0.003
        lifted = max(lifted, sim.positions[:, 1].max())
    assert lifted > 1.4  # the cloth was carried up, not passed through


def test_other_integrators_collide_with_meshes_too(tmp_path):
    center, half = (0.5, 0.55, 0.5), (0.15, 0.15, 0.15)
    path = _scene(tmp_path, box_obj(*half), {"path": "shape.obj", "translate": list(center), "friction": 0.3})
    scene = load_scene(path).with_simulation(integrator="xpbd")
    sim = Simulation(scene)
    sim.step(90)
    assert _box_depth(sim.positions, center, half).min() > -0.003
    assert sim.positions[:, 1].min() < center[1] - half[1]


def test_export_writes_the_mesh_where_it_is(tmp_path):
    import clothsim

    center, half = (0.5, 0.55, 0.5), (0.15, 0.1, 0.2)
    path = _scene(tmp_path, box_obj(*half), {"path": "shape.obj", "translate": list(center), "friction": 0.3})
    clothsim.export(path, tmp_path / "seq", frames=1)
    written = parse_obj((tmp_path / "seq" / "colliders.obj").read_text())
    assert "o mesh_0" in (tmp_path / "seq" / "colliders.obj").read_text()
    assert written.triangles.shape == (12, 3)
    corners = np.abs(written.vertices - center)
    np.testing.assert_allclose(corners, np.broadcast_to(half, corners.shape), rtol=1e-6)


def test_export_animates_a_moving_mesh(tmp_path):
    import clothsim

    # keyframes that do not start at translate: at time 0 the mesh is already 0.1 m above it
    center, half = (0.5, 0.5, 0.5), (0.15, 0.1, 0.2)
    motion = {"keyframes": [[0.0, [0.5, 0.6, 0.5]], [1.0, [0.5, 0.6, 1.5]]]}
    path = _scene(tmp_path, box_obj(*half), {"path": "shape.obj", "translate": list(center), "friction": 0.3,
                                             "motion": motion})
    track = load_scene(path).meshes[0].track()
    offsets = {f: track.at(f / 90.0) - np.asarray(center) for f in (0, 9, 18)}

    pxr = pytest.importorskip("pxr")
    clothsim.export(path, str(tmp_path / "m.usda"), frames=18, every=9)
    stage = pxr.Usd.Stage.Open(str(tmp_path / "m.usda"))
    mesh = pxr.UsdGeom.Mesh(stage.GetPrimAtPath("/World/colliders/mesh_0"))
    corners = np.abs(np.array(mesh.GetPointsAttr().Get(), dtype=np.float64) - center)  # at the scene pose
    np.testing.assert_allclose(corners, np.broadcast_to(half, corners.shape), rtol=1e-6)
    (op,) = mesh.GetOrderedXformOps()
    for frame, offset in offsets.items():
        np.testing.assert_allclose(np.array(op.Get(pxr.Usd.TimeCode(frame))), offset, atol=1e-12)
    assert offsets[18][2] == pytest.approx(0.2)  # it moved along z

    clothsim.export(path, tmp_path / "seq", frames=18, every=9)
    assert not (tmp_path / "seq" / "colliders.obj").exists()  # the only collider moves
    for frame, offset in offsets.items():
        text = (tmp_path / "seq" / f"cloth_{frame:05d}.obj").read_text()
        part = text.split("o mesh_0\n")[1]
        points = np.array([[float(c) for c in line.split()[1:4]] for line in part.splitlines()
                           if line.startswith("v ")])
        corners = np.abs(points - (np.asarray(center) + offset))
        np.testing.assert_allclose(corners, np.broadcast_to(half, corners.shape), rtol=1e-5, atol=1e-6)


def test_a_runs_resolved_scene_keeps_its_meshes_and_loads_from_anywhere(tmp_path):
    from clothsim.scene import scene_from_dict
    from clothsim.sweeps.params import scene_json

    scene = load_scene("mesh")
    data = json.loads(json.dumps(scene_json(scene)))
    again = scene_from_dict(data, str(tmp_path / "elsewhere.json"))  # the OBJ path is absolute there
    (a,), (b,) = scene.meshes, again.meshes
    assert (a.translate, a.rotation, a.scale, a.friction, a.closed) == (b.translate, b.rotation, b.scale, b.friction,
                                                                       b.closed)
    assert np.array_equal(a.vertices, b.vertices) and np.array_equal(a.triangles, b.triangles)


def test_the_pass_by_pass_profile_gives_the_same_bits_with_a_moving_mesh(tmp_path):
    from clothsim.sim.profile import Profiler

    motion = {"keyframes": [[0.0, [0.5, 0.6, 0.5]], [0.3, [0.5, 0.9, 0.5]]]}
    path = _scene(tmp_path, box_obj(0.12, 0.12, 0.12), {"path": "shape.obj", "translate": [0.5, 0.6, 0.5],
                                                        "friction": 0.4, "motion": motion})
    plain, profiled = Simulation(load_scene(path)), Simulation(load_scene(path))
    plain.step(40)
    profiler = Profiler(profiled)
    for _ in range(40):
        profiler.frame()
    assert profiled.time == plain.time
    assert plain.positions.tobytes() == profiled.positions.tobytes()
    assert plain.positions[:, 1].max() > 1.0  # the box did lift the cloth


def test_motion_moves_the_translation_and_holds_off_rest(tmp_path):
    path = _scene(tmp_path, box_obj(), {"path": "shape.obj", "translate": [1, 2, 3], "friction": 0,
                                        "motion": {"velocity": [0.5, 0, -1]}})
    scene = load_scene(path)
    assert scene.meshes[0].track().at(2.0).tolist() == [2.0, 2.0, 1.0]
    assert Simulation(scene).colliders_still_after == float("inf")
    keyed = load_scene(_scene(tmp_path, box_obj(), {"path": "shape.obj", "friction": 0,
                                                    "motion": {"keyframes": [[0.5, [0, 0, 0]], [1.25, [0, 1, 0]]]}}))
    assert Simulation(keyed).colliders_still_after == 1.25
    static = load_scene(_scene(tmp_path, box_obj(), {"path": "shape.obj", "translate": [1, 2, 3], "friction": 0}))
    assert static.meshes[0].track().at(7.0).tolist() == [1.0, 2.0, 3.0]


def test_a_box_and_an_obj_of_that_box_give_nearly_the_same_drape(tmp_path):
    # The analytic box and a 12-triangle mesh of it, under the same rotation (R = Rz . Ry . Rx for
    # both). Each run is checked against the box's own distance function, so a mesh turned by
    # another convention would leave points inside the box or hovering off it. The drapes then
    # agree in the large; point by point they drift apart as the cloth slides and swings (the box
    # keeps SURFACE_OFFSET, the mesh the cloth's thickness: about a centimetre of difference that
    # the folds amplify): after 1 s, 3.8 cm median apart, centroids 2.3 cm apart, 30 % and 28 % of
    # the points lying on the box.
    center, half, rotation = [0.5, 0.55, 0.5], [0.2, 0.1, 0.15], [10.0, 30.0, 5.0]
    path = _scene(tmp_path, box_obj(*half), {"path": "shape.obj", "translate": center, "rotation": rotation,
                                             "friction": 0.3})
    as_mesh = load_scene(path)
    data = json.loads((tmp_path / "scene.json").read_text())
    del data["mesh"]
    data["box"] = {"center": center, "half_extents": half, "rotation": rotation, "friction": 0.3}
    (tmp_path / "box.json").write_text(json.dumps(data))
    as_box = load_scene(str(tmp_path / "box.json"))
    drapes, resting = [], []
    for scene in (as_box, as_mesh):
        sim = Simulation(scene)
        sim.step(90)
        depth = _box_depth(sim.positions, center, half, rotation)
        assert depth.min() > -0.003, depth.min()  # outside, within 3 mm
        assert depth.min() < THICKNESS + 0.003  # resting on it
        drapes.append(sim.positions.copy())
        resting.append((depth < 0.02).mean())
    box, mesh = drapes
    assert np.linalg.norm(box.mean(axis=0) - mesh.mean(axis=0)) < 0.04
    assert abs(resting[0] - resting[1]) < 0.06 and min(resting) > 0.15, resting
    assert np.median(np.linalg.norm(box - mesh, axis=1)) < 0.06


def test_the_collider_bench_times_the_mesh_scene_without_its_mesh_and_with_a_fine_torus():
    from clothsim.bench.colliders import FAR, fine_mesh, variants

    scene = load_scene("mesh")
    v = variants(scene)
    assert set(v) == {"as is", "far away", "none"}
    assert v["none"].meshes == () and v["none"].planes == scene.planes
    assert v["far away"].meshes[0].translate == (scene.meshes[0].translate[0] + FAR, *scene.meshes[0].translate[1:])
    fine = fine_mesh(scene).meshes[0]
    assert fine.closed and fine.triangles.shape == (20000, 3) and fine.translate == scene.meshes[0].translate
    assert np.ptp(fine.vertices, axis=0) == pytest.approx(np.ptp(scene.meshes[0].vertices, axis=0), rel=0.01)


def test_the_memory_check_counts_each_meshs_lists_per_point(tmp_path, monkeypatch):
    # a mesh keeps a list of near triangles for every cloth point: the check must count it
    import clothsim.scene as scene_module
    from clothsim.meshcollider import MESH_BYTES_PER_POINT
    from clothsim.scene import BYTES_PER_POINT

    mesh = {"path": "shape.obj", "translate": [0.5, 0.3, 0.5], "friction": 0.3}
    group = mesh_group(load_scene(_scene(tmp_path, torus_obj(*TORUS), mesh, cloth=_cloth(30))))
    lists = (group.near_at, group.near_n, group.near_tris, group.near_d, group.near_ref, group.near_first,
             group.near_pl)
    assert MESH_BYTES_PER_POINT >= 1.25 * sum(a.nbytes for a in lists) / 900
    monkeypatch.setattr(scene_module, "available_memory", lambda: 900 * BYTES_PER_POINT + 100)
    load_scene(_scene(tmp_path, torus_obj(*TORUS), None, cloth=_cloth(30)))  # fits without the mesh
    with pytest.raises(SceneError, match="30x30 grid would need about"):
        load_scene(_scene(tmp_path, torus_obj(*TORUS), mesh, cloth=_cloth(30)))


def test_the_lists_rows_are_not_a_power_of_two_bytes_long():
    # rows a power of two bytes apart fall in a fraction of the caches' sets, where two arrays can
    # evict each other (docs/performance-meshes.md, "The lists' rows")
    group = mesh_group(load_scene("mesh"))
    for rows in (group.near_d, group.near_pl):
        stride = rows.strides[1]
        assert stride & (stride - 1) != 0, rows.shape
    assert np.array_equal(group.near_first, np.full(group.near_n.shape, np.inf))  # nothing listed yet
