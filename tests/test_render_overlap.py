"""Frames drawn without the depth test where the cloth's image covers no sample twice
(clothsim.render.overlap) and lies in front of the scene's one plane, if any: the test that
decides it, against a brute-force overlap check, and the images, which must be the bytes the
depth test gives."""

from __future__ import annotations

import numpy as np
import pytest

from clothsim.render.overlap import SLACK, covers_once

SIZE = 100.0  # pixels, square


def _to_window() -> np.ndarray:
    """A view-projection that puts (x, y, z) at window (x, y) of a SIZE x SIZE image."""
    m = np.zeros((4, 4))
    m[0, 0] = m[1, 1] = 2.0 / SIZE
    m[0, 3] = m[1, 3] = -1.0
    m[2, 2] = 0.001
    m[3, 3] = 1.0
    return m


def _grid(xy: np.ndarray) -> np.ndarray:
    """The renderer's vertex stream (N, 9) float32 for window positions xy (nh, nw, 2)."""
    nh, nw = xy.shape[:2]
    v = np.zeros((nw * nh, 9), dtype=np.float32)
    v[:, :2] = xy.reshape(-1, 2)
    return v


def _plain(nw: int, nh: int, spacing: float = 8.0, origin: float = 10.0) -> np.ndarray:
    x, y = np.meshgrid(np.arange(nw) * spacing + origin, np.arange(nh) * spacing + origin)
    return np.stack([x, y], axis=-1).astype(np.float64)


def _once(xy: np.ndarray) -> bool:
    nh, nw = xy.shape[:2]
    return bool(covers_once(_grid(xy), nw, nh, _to_window(), int(SIZE), int(SIZE)))


def test_a_flat_grid_seen_from_either_side_covers_once():
    xy = _plain(6, 5)
    assert _once(xy)
    assert _once(xy[:, ::-1].copy() * [-1, 1] + [100, 0])  # mirrored: every winding turned over


def test_a_grid_folded_over_itself_does_not():
    xy = _plain(8, 4)
    xy[:, 5:, 0] = 2 * xy[:, 4:5, 0] - xy[:, 5:, 0] + 1.0  # the last columns folded back
    assert not _once(xy)


def test_one_triangle_turned_over_is_enough_to_answer_no():
    xy = _plain(6, 6)
    xy[3, 3] = xy[3, 2] - [2.0, 0.0]  # pulled across its left neighbour
    assert not _once(xy)


def test_a_strip_wound_past_a_full_turn_answers_no_though_every_triangle_keeps_its_winding():
    # An annulus sector of 400 degrees: each triangle is fine, the border crosses itself.
    angles = np.radians(np.linspace(0.0, 400.0, 40))
    radii = np.array([25.0, 35.0])
    xy = np.stack([50 + radii[:, None] * np.cos(angles), 50 + radii[:, None] * np.sin(angles)], axis=-1)
    assert not _once(xy)
    assert _once(xy[:, :30].copy())  # 300 degrees: a simple border


def test_a_triangle_within_the_slack_of_turning_over_answers_no():
    # The middle corner pulled towards the line through two of its neighbours (26, 18)-(18, 26):
    # the triangle between them keeps its winding, with 16 x e of twice its area left.
    def pulled(e: float) -> np.ndarray:
        xy = _plain(5, 5)
        xy[2, 2] = [22.0 + e, 22.0 + e]
        return xy

    assert _once(pulled(1.0))
    assert not _once(pulled(0.01))  # a driver's snapping could turn it over
    assert not _once(_plain(4, 4) * [1.0, SLACK / 16.0])  # the whole grid a sliver


def test_corners_behind_the_camera_or_far_outside_the_image_answer_no():
    xy = _plain(4, 4)
    v = _grid(xy)
    behind = _to_window()
    behind[3] = [0.0, 0.0, 0.0, -1.0]
    assert not covers_once(v, 4, 4, behind, 100, 100)
    far = xy + [10 * SIZE, 0.0]
    assert not _once(far)


def _tri_overlap(a: np.ndarray, b: np.ndarray) -> bool:
    """Whether two 2-D triangles' interiors overlap (separating axis test on their six edges)."""
    for tri in (a, b):
        for k in range(3):
            e = tri[(k + 1) % 3] - tri[k]
            n = np.array([-e[1], e[0]])
            pa, pb = a @ n, b @ n
            if pa.max() <= pb.min() + 1e-9 or pb.max() <= pa.min() + 1e-9:
                return False
    return True


def _triangles(xy: np.ndarray) -> tuple[np.ndarray, list[set[int]]]:
    nh, nw = xy.shape[:2]
    p = xy.reshape(-1, 2)
    tris, corners = [], []
    for y in range(nh - 1):
        for x in range(nw - 1):
            a = y * nw + x
            for t in ((a, a + nw, a + 1), (a + 1, a + nw, a + nw + 1)):
                tris.append(p[list(t)])
                corners.append(set(t))
    return np.array(tris), corners


def test_a_yes_is_never_given_to_a_grid_whose_triangles_overlap():
    # Random bends of a small grid: wherever two triangles that share no corner overlap (or two
    # neighbours fold over each other), the answer must be no; it must also be yes often.
    rng = np.random.default_rng(7)
    yes = overlapping = 0
    for trial in range(300):
        xy = _plain(5, 4, spacing=6.0, origin=30.0)
        xy += rng.normal(scale=rng.choice([0.5, 2.0, 5.0]), size=xy.shape)
        if trial % 3 == 0:  # a bend that can bring the far edge back over the grid
            bend = rng.uniform(0.5, 3.5)
            xy[..., 0], xy[..., 1] = (30 + (xy[..., 0] - 30) * np.cos(bend * (xy[..., 1] - 30) / 20),
                                      30 + (xy[..., 0] - 30) * np.sin(bend * (xy[..., 1] - 30) / 20))
        tris, corners = _triangles(xy)
        u, v = tris[:, 1] - tris[:, 0], tris[:, 2] - tris[:, 0]
        area = u[:, 0] * v[:, 1] - u[:, 1] * v[:, 0]
        overlap = bool((area > 0).any() and (area < 0).any())
        for i in range(len(tris)):
            for j in range(i + 1, len(tris)):
                if not overlap and len(corners[i] & corners[j]) == 0 and _tri_overlap(tris[i], tris[j]):
                    overlap = True
        once = _once(xy)
        yes += once
        overlapping += overlap
        assert not (once and overlap), f"trial {trial}: answered yes for overlapping triangles"
    assert yes > 60 and overlapping > 60, (yes, overlapping)


@pytest.fixture(scope="module")
def renderers():
    pytest.importorskip("moderngl")
    from clothsim.render.renderer import Renderer

    try:
        pair = (Renderer(160, 160), Renderer(160, 160))
    except Exception as exc:  # no EGL / GL on this machine
        pytest.skip(f"no OpenGL: {exc}")
    yield pair
    for r in pair:
        r.release()


@pytest.mark.parametrize("scene_name", ["pinned2", "plane"])
@pytest.mark.parametrize("look", ["phong", "texture", "mirror"])
def test_frames_drawn_without_the_depth_test_are_the_bytes_drawn_with_it(renderers, monkeypatch, scene_name, look):
    from clothsim.render.camera import Camera
    from clothsim.render.pipeline import Snapshot
    from clothsim.render.renderer import Renderer
    from clothsim.scene import load_scene
    from clothsim.sim.simulation import Simulation

    sim = Simulation(load_scene(scene_name))
    states = []
    for frame in range(90):
        sim.step(1)
        if frame % 6 == 0:
            states.append(Snapshot.of(sim))
    rng = np.random.default_rng(3)
    answers: list[bool] = []
    real = Renderer._without_depth

    def recorded(self, *args):
        answers.append(bool(real(self, *args)))
        return answers[-1]

    plain, skipping = renderers
    settings = plain.settings_for(states[0].scene)
    for k, state in enumerate(states):
        camera = None
        if k % 2:  # and from anywhere around it, near and far (below the plane too)
            centre = state.positions.mean(axis=0)
            away = rng.normal(size=3)
            camera = Camera(centre + away / np.linalg.norm(away) * rng.uniform(0.5, 5.0), centre, 40.0, 0.01, 100.0)
        monkeypatch.setattr(Renderer, "_without_depth", lambda self, *args: False)
        with_depth = plain.render(state, look, settings, camera=camera)
        monkeypatch.setattr(Renderer, "_without_depth", recorded)
        without = skipping.render(state, look, settings, camera=camera)
        assert np.array_equal(with_depth, without), f"frame {k}: {int((with_depth != without).any(-1).sum())} pixels"
    assert len(answers) == len(states) and sum(answers) >= len(states) // 3, answers


def test_a_camera_beyond_the_plane_keeps_the_depth_test(renderers, monkeypatch):
    # From below the floor the plane hides the cloth: drawn after it without the test, the
    # cloth would show (its texture differs from the plane's).
    from clothsim.render import renderer as renderer_module
    from clothsim.render.camera import Camera
    from clothsim.scene import load_scene
    from clothsim.sim.simulation import Simulation

    sim = Simulation(load_scene("plane"))
    sim.step(60)
    centre = sim.positions.mean(axis=0)
    below = Camera(centre + np.array([0.3, -1.5, 0.4]), centre, 40.0, 0.01, 100.0)
    above = Camera(centre + np.array([0.3, 1.5, 0.4]), centre, 40.0, 0.01, 100.0)
    asked: list[int] = []
    real = renderer_module.covers_once
    monkeypatch.setattr(renderer_module, "covers_once", lambda *args: asked.append(1) or real(*args))
    renderers[1].render(sim, "texture", camera=below)
    assert asked == []  # answered no before the overlap test
    renderers[1].render(sim, "texture", camera=above)
    assert asked == [1]


def test_a_scene_with_a_collider_keeps_the_depth_test(renderers, monkeypatch):
    from clothsim.render import renderer as renderer_module
    from clothsim.scene import load_scene
    from clothsim.sim.simulation import Simulation

    asked: list[int] = []
    monkeypatch.setattr(renderer_module, "covers_once", lambda *args: asked.append(1) or True)
    renderers[1].render(Simulation(load_scene("sphere")), "phong")
    renderers[1].render(Simulation(load_scene("tablecloth")), "phong")  # a plane and a box
    renderers[1].render(Simulation(load_scene("pinned2")), "wireframe")
    assert asked == []


def test_only_looks_whose_vertex_stage_leaves_the_positions_are_tested():
    from clothsim.render.programs import Programs, read_source

    plain = Programs(None)
    assert plain.places_as_given("phong") and plain.places_as_given("mirror")
    assert not any(plain.places_as_given(look) for look in ("wireframe", "displacement", "custom"))
    vertex = read_source("mesh.vert")
    assert Programs(None, {"phong": (vertex, "a fragment stage")}).places_as_given("phong")
    moved = vertex.replace("gl_Position = ", "gl_Position = 0.5 * ")
    assert moved != vertex and not Programs(None, {"phong": (moved, "a fragment stage")}).places_as_given("phong")
