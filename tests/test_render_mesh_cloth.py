"""Drawing a cloth from its surface (a mesh cloth): the surface kernel, the renderer's surface path,
its wireframe, channels, camera and the warning for a mesh without UVs.

Surfaces here are made by hand from a grid (the same triangles, or a seam column split into two
render vertices a point) and a tube, so that the surface path is compared with the grid path it
must reproduce and a seam is checked for a crease.
"""

from __future__ import annotations

import dataclasses
import math
import warnings
from dataclasses import dataclass
from typing import Any

import numpy as np
import pytest

from clothsim.cloth import Springs, Surface
from clothsim.errors import ClothsimError
from clothsim.render import mesh
from clothsim.render.camera import cloth_size
from clothsim.render.drawn import surface_geometry
from clothsim.scene import Scene

from render_support import GOLDEN_SIZE, draped_state, golden_renderer, image_difference, images_match


# -- surfaces made by hand ---------------------------------------------------------------------
def grid_surface(nw: int, nh: int, has_uvs: bool = True) -> Surface:
    """The grid's own surface: one render vertex a point, the grid's triangles and uvs."""
    tris = mesh.cloth_triangles(nw, nh).reshape(-1, 3).astype(np.int64)
    return Surface(triangles=tris, uv_point=np.arange(nw * nh, dtype=np.int64), uvs=mesh.cloth_uvs(nw, nh),
                   uv_triangles=tris.copy(), has_uvs=has_uvs)


def seamed_surface(nw: int, nh: int, column: int, shift: float = 0.0) -> Surface:
    """The grid with its points of ``column`` split into two render vertices each: the quads left
    of the column use the points' own vertices, those right of it copies (render vertices N + y)
    whose u is moved by ``shift`` (0: the same uvs, an invisible seam)."""
    n = nw * nh
    tris = mesh.cloth_triangles(nw, nh).reshape(-1, 3).astype(np.int64)
    uv_tris = tris.copy()
    x = tris % nw
    right_of_seam = (x.max(axis=1) > column)[:, None] & (x == column)
    uv_tris[right_of_seam] = n + tris[right_of_seam] // nw
    uv_point = np.concatenate([np.arange(n), np.arange(nh) * nw + column]).astype(np.int64)
    base = mesh.cloth_uvs(nw, nh)
    uvs = base[uv_point].copy()
    uvs[n:, 0] += np.float32(shift)
    return Surface(triangles=tris, uv_point=uv_point, uvs=uvs, uv_triangles=uv_tris, has_uvs=True)


def tube_surface(around: int, along: int) -> tuple[Surface, np.ndarray]:
    """A closed tube (radius 0.25, length 0.8, axis x): ``around`` x ``along`` points, its UV seam
    where u wraps from 1 to 0 (the first point of every ring has a second render vertex at u = 1).
    Front faces point outwards. Returns the surface and its points (N, 3)."""
    phi = 2.0 * math.pi * np.arange(around) / around
    xs = np.linspace(0.1, 0.9, along)
    pts = np.stack([np.repeat(xs, around), 0.5 + 0.25 * np.tile(np.cos(phi), along),
                    0.5 + 0.25 * np.tile(np.sin(phi), along)], axis=1)
    ring = around + 1  # render vertices a ring
    uv_point = (np.arange(along)[:, None] * around + np.arange(ring)[None, :] % around).ravel().astype(np.int64)
    u = np.tile(np.arange(ring) / around, along)
    v = np.repeat(np.arange(along) / (along - 1), ring)
    uvs = np.stack([u, v], axis=1).astype(np.float32)
    quads = [(j * ring + i, j * ring + i + 1, (j + 1) * ring + i, (j + 1) * ring + i + 1)
             for j in range(along - 1) for i in range(around)]
    uv_tris = np.array([t for a, b, c, d in quads for t in ((a, b, c), (b, d, c))], dtype=np.int64)
    surface = Surface(triangles=uv_point[uv_tris], uv_point=uv_point, uvs=uvs, uv_triangles=uv_tris, has_uvs=True)
    return surface, pts


def _wavy_grid(nw: int, nh: int, seed: int = 3) -> np.ndarray:
    rng = np.random.default_rng(seed)
    u, v = np.meshgrid(np.linspace(0, 1, nw), np.linspace(0, 1, nh))
    y = 0.1 * np.sin(4 * u) * np.cos(3 * v) + 0.01 * rng.random(u.shape)
    return np.stack([u.ravel(), y.ravel(), v.ravel()], axis=1)


def _fill(surface: Surface, pos: np.ndarray, tangents: bool = True) -> np.ndarray:
    g = surface_geometry(surface, pos.shape[0])
    out = np.empty((g.vertex_count, mesh.CLOTH_FLOATS), np.float32)
    g.fill(np.ascontiguousarray(pos, dtype=np.float64), tangents, out)
    return out


# -- the surface kernel --------------------------------------------------------------------------
def test_a_grid_given_as_a_surface_gets_the_grid_kernels_vertices():
    nw, nh = 9, 7
    pos = _wavy_grid(nw, nh)
    grid = np.empty((nw * nh, mesh.CLOTH_FLOATS), np.float32)
    mesh.update_cloth_vertices(pos, nw, nh, True, grid)
    surf = _fill(grid_surface(nw, nh), pos)
    assert np.array_equal(surf[:, :6], grid[:, :6])  # the same sums in the same order
    # tangents from the float32 uvs rather than the grid's exact steps
    assert np.allclose(surf[:, 6:], grid[:, 6:], atol=1e-5)
    assert np.all(_fill(grid_surface(nw, nh), pos, tangents=False)[:, 6:] == 0.0)


def test_a_seam_splits_uvs_but_not_normals():
    nw, nh, column = 9, 7, 4
    pos = _wavy_grid(nw, nh)
    plain = _fill(grid_surface(nw, nh), pos)
    seamed = _fill(seamed_surface(nw, nh, column), pos)
    n = nw * nh
    assert seamed.shape == (n + nh, mesh.CLOTH_FLOATS)
    copies = np.arange(nh) * nw + column
    # every render vertex has its point's position and normal: the seam's two sides agree exactly
    assert np.array_equal(seamed[:n, :6], plain[:, :6])
    assert np.array_equal(seamed[n:, :6], plain[copies, :6])
    # each side's tangent sums its own triangles only, both still along +u where u is continuous
    assert np.allclose((seamed[:, 3:6] * seamed[:, 6:]).sum(axis=1), 0.0, atol=1e-6)
    assert np.all(seamed[:, 6] > 0.9)


def test_a_tube_faces_outwards_and_its_seam_is_smooth():
    surface, pts = tube_surface(16, 5)
    out = _fill(surface, pts)
    radial = out[:, :3].astype(np.float64) - np.array([0.0, 0.5, 0.5])
    radial[:, 0] = 0.0
    radial /= np.linalg.norm(radial, axis=1, keepdims=True)
    # radial up to the grid's diagonals, which weigh a point's two sides a little differently
    assert np.all((out[:, 3:6] * radial).sum(axis=1) > 0.99)
    seam = np.flatnonzero(np.arange(surface.uv_point.size) % 17 == 16)
    assert np.array_equal(out[seam, 3:6], out[seam - 16, 3:6])  # u = 1 and u = 0 share their normal
    # tangents run around the tube (+u), on both sides of the seam
    around = np.cross(np.array([1.0, 0.0, 0.0]), radial)
    assert np.all((out[:, 6:] * around).sum(axis=1) > 0.99)


@pytest.mark.parametrize("change, field", [
    (lambda s: dataclasses.replace(s, uv_point=s.uv_point + 100), "uv_point"),
    (lambda s: dataclasses.replace(s, uv_triangles=s.uv_triangles + 1000), "uv_triangles"),
    (lambda s: dataclasses.replace(s, triangles=-s.triangles - 1), "triangles"),
    (lambda s: dataclasses.replace(s, uvs=s.uvs[:-1]), "uvs"),
    (lambda s: dataclasses.replace(s, uv_triangles=s.uv_triangles[:-1]), "uv_triangles"),
    (lambda s: dataclasses.replace(s, uv_triangles=s.uv_triangles[:, ::-1].copy()), "uv_triangles"),
    (lambda s: dataclasses.replace(s, uv_point=s.uv_point.astype(np.float64)), "uv_point"),
])
def test_a_surface_whose_arrays_disagree_is_refused_with_one_line(change, field):
    with pytest.raises(ClothsimError) as err:
        surface_geometry(change(grid_surface(4, 3)), 12)
    message = str(err.value)
    assert "\n" not in message and message.startswith("cloth surface: ") and field in message


def test_a_mesh_cloths_view_distance_follows_its_rest_points():
    @dataclass
    class _Mesh:
        points: np.ndarray

    @dataclass
    class _Cloth:
        mesh: _Mesh
        width: float = 0.0
        height: float = 0.0
        is_mesh: bool = True

    pts = np.array([[0.0, 0.0, 0.0], [0.3, 1.2, -0.1], [0.2, 0.5, 0.4]])
    assert cloth_size(_Cloth(_Mesh(pts))) == pytest.approx(1.2)
    grid = draped_state().scene.cloth
    assert cloth_size(grid) == max(grid.width, grid.height)


# -- the renderer --------------------------------------------------------------------------------
@dataclass
class SurfaceState:
    """A mesh cloth's state as the renderer reads it: no grid (nw = nh = 0), a surface."""

    scene: Scene
    positions: np.ndarray
    springs: Springs
    surface: Any
    nw: int = 0
    nh: int = 0
    time: float = 0.0
    frame: int = 0

    @property
    def live_springs(self) -> Springs:
        return self.springs


renderer = pytest.fixture(scope="module", name="renderer")(golden_renderer)


@pytest.fixture(scope="module")
def draped():
    return draped_state()


def _as_surface(state: Any, surface: Surface) -> SurfaceState:
    return SurfaceState(scene=state.scene, positions=state.positions, springs=state.springs, surface=surface)


def _camera(renderer: Any, state: Any) -> Any:
    return renderer.camera(state, renderer.settings_for(state.scene))


LOOKS = ("wireframe", "normal", "diffuse", "phong", "texture", "bump", "displacement", "mirror", "custom")


@pytest.mark.parametrize("look", LOOKS)
def test_a_grid_drawn_as_a_surface_looks_like_the_grid(renderer, draped, look):
    cam = _camera(renderer, draped)
    grid = renderer.render(draped, look, camera=cam)
    surf = renderer.render(_as_surface(draped, grid_surface(48, 48)), look, camera=cam)
    d = image_difference(surf, grid)
    assert d.mean < 0.05 and d.pct <= 1.0, f"{look}: {d}"


@pytest.mark.parametrize("look", ("normal", "diffuse", "phong", "bump", "displacement"))
def test_a_seamed_sheet_draws_as_the_sheet(renderer, draped, look):
    """A seam down the middle of the draped cloth (uvs continuous across it) draws as the plain grid."""
    cam = _camera(renderer, draped)
    grid = renderer.render(draped, look, camera=cam)
    drawn = renderer.render(_as_surface(draped, seamed_surface(48, 48, 23)), look, camera=cam)
    d = image_difference(drawn, grid)
    assert d.mean < 0.05 and d.pct <= 1.0, f"{look}: {d}"


@pytest.mark.parametrize("look", ("normal", "diffuse", "phong"))
def test_a_tubes_uv_seam_shows_no_crease(renderer, draped, look):
    """A coarse tube (12 sides) drawn with its UV seam is the same image as the tube without one
    (one render vertex a point: these looks read no uvs), while the seam's copies made points of
    their own (each side's normal from its own triangles: what a seam must not do) crease it."""
    surface, pts = tube_surface(12, 6)
    n = pts.shape[0]
    none = np.zeros(0, np.int32)
    springs = Springs(none, none, np.zeros(0), np.zeros(0, np.int8))
    seamed = SurfaceState(scene=draped.scene, positions=pts, springs=springs, surface=surface)
    cam = _camera(renderer, seamed)
    welded = Surface(triangles=surface.triangles, uv_point=np.arange(n, dtype=np.int64),
                     uvs=np.zeros((n, 2), np.float32), uv_triangles=surface.triangles, has_uvs=True)
    split = Surface(triangles=surface.uv_triangles, uv_point=np.arange(surface.uv_point.size, dtype=np.int64),
                    uvs=surface.uvs, uv_triangles=surface.uv_triangles, has_uvs=True)
    plain = renderer.render(dataclasses.replace(seamed, surface=welded), look, camera=cam)
    assert np.array_equal(renderer.render(seamed, look, camera=cam), plain)
    creased = renderer.render(dataclasses.replace(seamed, positions=pts[surface.uv_point], surface=split), look,
                              camera=cam)
    assert (np.abs(creased.astype(int) - plain.astype(int)).max(axis=2) > 8).sum() > 500, look


def test_a_seam_in_the_uvs_moves_the_texture_on_one_side_only(renderer, draped):
    cam = _camera(renderer, draped)
    grid = renderer.render(draped, "texture", camera=cam)
    moved = renderer.render(_as_surface(draped, seamed_surface(48, 48, 23, shift=0.37)), "texture", camera=cam)
    assert not images_match(moved, grid)


def test_a_wireframe_draws_the_springs_between_points_across_a_seam(renderer, draped):
    cam = _camera(renderer, draped)
    grid = renderer.render(draped, "wireframe", camera=cam)
    seamed = renderer.render(_as_surface(draped, seamed_surface(48, 48, 23)), "wireframe", camera=cam)
    assert np.array_equal(seamed, grid)


def test_channels_of_a_surface_are_the_grids(renderer, draped):
    from clothsim.render.views import ViewCamera

    cam = _camera(renderer, draped)
    view = ViewCamera(tuple(map(float, cam.position)), tuple(map(float, cam.target)), 35.0, GOLDEN_SIZE, GOLDEN_SIZE)
    nxt = draped.positions + np.array([0.01, 0.02, 0.0])
    grid = renderer.render_channels(draped, view, nxt)
    surf = renderer.render_channels(_as_surface(draped, seamed_surface(48, 48, 23)), view, nxt)
    assert np.array_equal(surf.mask, grid.mask)
    assert np.allclose(surf.depth, grid.depth, atol=1e-6)
    assert np.allclose(surf.flow, grid.flow, atol=1e-4)  # the seam's copies move with their points
    assert np.allclose(surf.normal, grid.normal, atol=1e-6)


def test_a_tube_draws_with_its_default_camera(renderer, draped):
    surface, pts = tube_surface(32, 12)
    springs = Springs(np.zeros(0, np.int32), np.zeros(0, np.int32), np.zeros(0), np.zeros(0, np.int8))
    state = SurfaceState(scene=draped.scene, positions=pts, springs=springs, surface=surface)
    cam = _camera(renderer, state)
    for look in LOOKS:
        image = renderer.render(state, look, camera=cam)
        assert (image != image[0, 0]).any(axis=2).mean() > 0.02, look


def test_a_mesh_without_uvs_is_warned_about_once_per_renderer(draped):
    pytest.importorskip("moderngl")
    from clothsim.render.renderer import Renderer

    try:
        r = Renderer(64, 64, samples=0)
    except ClothsimError as exc:
        pytest.skip(f"no OpenGL: {exc}")
    try:
        plain = _as_surface(draped, grid_surface(48, 48, has_uvs=False))
        with warnings.catch_warnings(record=True) as caught:
            warnings.simplefilter("always")
            for look in ("phong", "texture"):
                r.render(plain, look)
            r.render(draped, "phong")  # another cloth in between: its buffers are rebuilt
            r.render(_as_surface(draped, grid_surface(48, 48, has_uvs=False)), "bump")
        texts = [str(w.message) for w in caught if "UV" in str(w.message)]
        assert len(texts) == 1 and "no UVs" in texts[0] and "planar projection" in texts[0], texts
        with warnings.catch_warnings(record=True) as caught:
            warnings.simplefilter("always")
            r.render(_as_surface(draped, grid_surface(48, 48)), "phong")
        assert not [w for w in caught if "UV" in str(w.message)]
    finally:
        r.release()


def test_the_grid_path_is_untouched_by_a_surface_drawn_before(renderer, draped):
    cam = _camera(renderer, draped)
    before = renderer.render(draped, "phong", camera=cam)
    renderer.render(_as_surface(draped, seamed_surface(48, 48, 10)), "phong", camera=cam)
    assert np.array_equal(renderer.render(draped, "phong", camera=cam), before)


# -- a simulated mesh cloth ------------------------------------------------------------------------
def _skirt_scene(tmp_path: Any, uvs: bool = True) -> Any:
    """A skirt (an open tube with a UV seam, clothsim.objshapes) pinned by its top ring over a ball."""
    from clothsim.objshapes import tube_obj
    from clothsim.scene import scene_from_dict

    obj = tube_obj(0.3, 0.5, 16, 6)
    if not uvs:  # the same OBJ without its vt: a corner names its v only
        obj = "\n".join(" ".join(w.split("/")[0] for w in ln.split()) for ln in obj.splitlines()
                        if not ln.startswith("vt ")) + "\n"
    name = "skirt.obj" if uvs else "bare.obj"
    (tmp_path / name).write_text(obj)
    top = [k for k, ln in enumerate(ln for ln in obj.splitlines() if ln.startswith("v "))
           if float(ln.split()[2]) >= 0.5 - 1e-9]
    scene = {"cloth": {"mesh": {"path": name, "translate": [0.0, 0.45, 0.0]}, "thickness": 0.01, "damping": 0.2,
                       "density": 150.0, "ks": 5000.0, "pinned_vertices": top},
             "sphere": {"origin": [0.0, 0.5, 0.0], "radius": 0.2, "friction": 0.3},
             "plane": {"point": [0.0, 0.0, 0.0], "normal": [0.0, 1.0, 0.0], "friction": 0.5},
             "simulation": {"self_collision": "off"}}
    path = tmp_path / ("skirt.json" if uvs else "bare.json")
    import json

    path.write_text(json.dumps(scene))
    return path


def test_a_simulated_skirt_draws_in_every_look(tmp_path, renderer):
    from clothsim.render.pipeline import Snapshot
    from clothsim.scene import load_scene
    from clothsim.sim import Simulation

    sim = Simulation(load_scene(str(_skirt_scene(tmp_path))))
    sim.step(5)
    shot = Snapshot.of(sim)
    assert shot.nw == 0 and shot.surface is sim.surface
    assert sim.surface.uv_point.size > sim.positions.shape[0]  # the seam's render vertices
    # the default camera: 2 * 0.9 * the rest points' largest extent (the skirt's 0.6 m across)
    cam = _camera(renderer, shot)
    assert np.linalg.norm(cam.position - cam.target) == pytest.approx(1.8 * 0.6, rel=1e-6)
    away = dataclasses.replace(shot, positions=shot.positions + 1e4)
    for look in LOOKS:
        image = renderer.render(shot, look, camera=cam)
        changed = (image != renderer.render(away, look, camera=cam)).any(axis=2).mean()
        assert changed > 0.2, f"{look}: the skirt covers {changed:.1%} of the image"


def test_the_render_command_warns_once_about_a_mesh_without_uvs(tmp_path, capsys):
    pytest.importorskip("moderngl")
    from clothsim.cli import main

    out = tmp_path / "frames"
    assert main(["render", str(_skirt_scene(tmp_path, uvs=False)), "-o", str(out), "--frames", "4", "--every", "2",
                 "--size", "48x48", "--shader", "texture"]) == 0
    err = capsys.readouterr().err
    lines = [ln for ln in err.splitlines() if "UVs" in ln]
    assert lines == ["clothsim: warning: bare.obj: the cloth mesh has no UVs (texture coordinates); its textures "
                     "use a planar projection"], err
    assert len(list(out.iterdir())) == 3
    assert main(["render", str(_skirt_scene(tmp_path)), "-o", str(tmp_path / "uv.png"), "--frames", "2",
                 "--size", "48x48"]) == 0
    assert "UVs" not in capsys.readouterr().err
