"""The data channels of a dataset's views, checked against geometry computed here in NumPy.

A cloth draped analytically over a sphere above a floor (render_support.draped_state: no
simulator involved) is drawn at 512 x 512 from cameras drawn around it. Depth is un-projected
through the recorded intrinsics and extrinsics and compared with rays cast against the cloth's
triangles here; flow with the projected motion of the cloth's points; the mask with the cast rays
and the projected triangles' area; normals with area-weighted mesh normals computed here.
"""

from __future__ import annotations

import math

import numpy as np
import pytest

from render_support import draped_state

from clothsim.cloth import cloth_triangles
from clothsim.render.channels import collider_ids
from clothsim.render.views import DISTANCE_RANGE, ELEVATION_RANGE_DEG, ViewCamera, draw_cameras, frame_bounds

SIZE = 512


@pytest.fixture(scope="module")
def drawn():
    """(state, next positions, cameras, channels per camera) at 512 x 512."""
    from clothsim.render.renderer import Renderer

    state = draped_state()
    # The next sampled frame: the drape sinks, turns a little about y and the hem swings out.
    p = state.positions
    c = p.mean(axis=0)
    a = math.radians(4.0)
    rot = np.array([[math.cos(a), 0, math.sin(a)], [0, 1, 0], [-math.sin(a), 0, math.cos(a)]])
    nxt = (p - c) @ rot.T + c + np.array([0.01, -0.03, 0.0])
    nxt[:, 1] -= 0.05 * np.hypot(p[:, 0] - 0.5, p[:, 2] - 0.5)
    centre, radius = frame_bounds(np.stack([p, nxt]))
    cams = draw_cameras((7, 0, 1), 3, centre, radius, 35.0, SIZE, SIZE)
    # A fourth camera below the drape's rim looks up at its underside: the back of the cloth.
    cams.append(ViewCamera((1.3, -0.12, 1.25), (0.5, 0.05, 0.5), 40.0, SIZE, SIZE))
    with Renderer(SIZE, SIZE, samples=0) as r:
        channels = [r.render_channels(state, cam, nxt) for cam in cams]
    return state, nxt, cams, channels


def _triangles(state, positions):
    faces = cloth_triangles(state.nw, state.nh).reshape(-1, 3).astype(np.int64)
    return faces, positions[faces]  # (F, 3, 3)


def _rays(cam: ViewCamera, rows: np.ndarray, cols: np.ndarray):
    """World-space origin and unit directions through pixel centres, from the recorded camera."""
    k = cam.intrinsics()
    c2w = np.linalg.inv(cam.world_to_camera_cv())
    d_cam = np.stack([(cols - k[0, 2]) / k[0, 0], (rows - k[1, 2]) / k[1, 1], np.ones_like(cols, dtype=float)], axis=1)
    d = d_cam @ c2w[:3, :3].T
    return c2w[:3, 3], d / np.linalg.norm(d, axis=1, keepdims=True), d_cam


def _cast(origin, dirs, tris, chunk=256):
    """Nearest hit distance (inf if none) and its triangle, Moeller-Trumbore over every triangle."""
    v0, e1, e2 = tris[:, 0], tris[:, 1] - tris[:, 0], tris[:, 2] - tris[:, 0]
    best = np.full(len(dirs), np.inf)
    which = np.full(len(dirs), -1)
    for s in range(0, len(dirs), chunk):
        d = dirs[s:s + chunk, None, :]
        h = np.cross(d, e2[None])
        det = np.einsum("pfk,fk->pf", h, e1)
        ok = np.abs(det) > 1e-14
        inv = np.where(ok, 1.0 / np.where(ok, det, 1.0), 0.0)
        sv = origin - v0
        u = np.einsum("pfk,fk->pf", h, sv) * inv
        q = np.cross(sv, e1)
        v = np.einsum("pk,fk->pf", dirs[s:s + chunk], q) * inv
        t = np.einsum("fk,fk->f", e2, q)[None] * inv
        hit = ok & (u >= 0) & (v >= 0) & (u + v <= 1) & (t > 0)
        t = np.where(hit, t, np.inf)
        best[s:s + chunk] = t.min(axis=1)
        which[s:s + chunk] = np.where(np.isfinite(t.min(axis=1)), t.argmin(axis=1), -1)
    return best, which


def _project(cam: ViewCamera, points: np.ndarray) -> np.ndarray:
    w2c = cam.world_to_camera_cv()
    x = points @ w2c[:3, :3].T + w2c[:3, 3]
    k = cam.intrinsics()
    return np.stack([k[0, 0] * x[:, 0] / x[:, 2] + k[0, 2], k[1, 1] * x[:, 1] / x[:, 2] + k[1, 2]], axis=1)


def _mesh_normals(state) -> np.ndarray:
    faces, tris = _triangles(state, state.positions)
    n = np.cross(tris[:, 1] - tris[:, 0], tris[:, 2] - tris[:, 0])
    acc = np.zeros_like(state.positions)
    for k in range(3):
        np.add.at(acc, faces[:, k], n)
    return acc / np.linalg.norm(acc, axis=1, keepdims=True)


def test_depth_unprojects_onto_the_cloth_within_a_millimetre(drawn) -> None:
    state, _, cams, channels = drawn
    _, tris = _triangles(state, state.positions)
    rng = np.random.default_rng(0)
    for cam, ch in zip(cams, channels):
        rows, cols = np.nonzero(ch.mask == 1) if (ch.mask == 1).sum() > 0 else (np.array([]), np.array([]))
        rows2, cols2 = np.nonzero(ch.mask == 2)
        rows, cols = np.concatenate([rows, rows2]), np.concatenate([cols, cols2])
        assert len(rows) > 2000, "the cloth fills a good part of every view"
        pick = rng.choice(len(rows), 1500, replace=False)
        rows, cols = rows[pick].astype(float), cols[pick].astype(float)
        origin, dirs, d_cam = _rays(cam, rows, cols)
        z = ch.depth[rows.astype(int), cols.astype(int)].astype(np.float64)
        # Un-project: x_cam = z K^-1 (u, v, 1), then camera -> world with the recorded extrinsics.
        c2w = np.linalg.inv(cam.world_to_camera_cv())
        world = (d_cam * z[:, None]) @ c2w[:3, :3].T + c2w[:3, 3]
        t, _ = _cast(origin, dirs, tris)
        # A pixel centre right on the silhouette can miss every triangle by a rounding error.
        hit = np.isfinite(t)
        assert hit.mean() > 0.995
        surface = origin + dirs[hit] * t[hit, None]
        err = np.linalg.norm(world[hit] - surface, axis=1)
        assert err.max() < 1e-3, f"un-projected depth off the cloth by up to {err.max() * 1000:.3f} mm"


def _cast_colliders(state, origin, dirs):
    """Nearest hit of the sphere (drawn at SPHERE_DRAW_SCALE of its radius: a facetted UV sphere,
    taken as round here) and of the plane (a square of half-extent 2, as mesh.plane_mesh draws it)."""
    from clothsim.render.renderer import SPHERE_DRAW_SCALE

    sphere, plane = state.scene.spheres[0], state.scene.planes[0]
    c, r = np.array(sphere.origin), sphere.radius * SPHERE_DRAW_SCALE
    oc = origin - c
    b = dirs @ oc
    disc = b * b - (oc @ oc - r * r)
    t_sphere = np.where(disc > 0, -b - np.sqrt(np.maximum(disc, 0)), np.inf)
    t_sphere = np.where(t_sphere > 0, t_sphere, np.inf)
    n, p0 = np.array(plane.normal), np.array(plane.point)
    denom = dirs @ n
    t_plane = np.where(np.abs(denom) > 1e-12, ((p0 - origin) @ n) / np.where(denom == 0, 1, denom), np.inf)
    q = origin + dirs * t_plane[:, None] - p0
    inside = (np.abs(q[:, 0]) <= 2.0) & (np.abs(q[:, 2]) <= 2.0)  # the y-up plane's square
    t_plane = np.where((t_plane > 0) & inside, t_plane, np.inf)
    return t_sphere, t_plane


def test_mask_matches_the_rasterised_cloth_front_back_and_colliders(drawn) -> None:
    state, _, cams, channels = drawn
    faces, tris = _triangles(state, state.positions)
    normals = np.cross(tris[:, 1] - tris[:, 0], tris[:, 2] - tris[:, 0])
    assert [(c["id"], c["kind"]) for c in collider_ids(state.scene)] == [(3, "sphere"), (4, "plane")]
    saw_back = False
    for cam, ch in zip(cams, channels):
        assert set(np.unique(ch.mask)) <= {0, 1, 2, 3, 4}
        # Cast a ray through every 6th pixel centre: the id of what it meets first is the mask's.
        rows, cols = np.mgrid[1:SIZE:6, 2:SIZE:6]
        rows, cols = rows.ravel().astype(float), cols.ravel().astype(float)
        origin, dirs, _ = _rays(cam, rows, cols)
        t_cloth, tri = _cast(origin, dirs, tris)
        t_sphere, t_plane = _cast_colliders(state, origin, dirs)
        first = np.argmin(np.stack([np.full_like(t_cloth, np.inf), t_cloth, t_sphere, t_plane]), axis=0)
        none = ~np.isfinite(np.minimum(np.minimum(t_cloth, t_sphere), t_plane))
        want = np.where(none, 0, np.where(first == 1, 1, np.where(first == 2, 3, 4)))
        on_cloth = want == 1
        front = np.einsum("pk,pk->p", normals[tri[on_cloth]], -dirs[on_cloth]) > 0
        want[np.nonzero(on_cloth)[0][~front]] = 2
        got = ch.mask[rows.astype(int), cols.astype(int)]
        # Pixel centres right on an outline (the cloth's hem, the sphere's facets) may go either way.
        assert np.mean(got == want) > 0.995, np.mean(got == want)
        cloth_got, cloth_want = np.isin(got, (1, 2)).sum(), np.isin(want, (1, 2)).sum()
        assert cloth_want > 250 and abs(int(cloth_got) - int(cloth_want)) <= 0.005 * cloth_want
        saw_back |= bool((got == 2).sum() > 100)
    assert saw_back


def _visible_points(cam, ch, points, depth_tol=2e-3):
    """Points whose pixel (nearest centre) shows them: the cloth there, at their depth."""
    uv = _project(cam, points)
    col, row = np.rint(uv[:, 0]).astype(int), np.rint(uv[:, 1]).astype(int)
    inside = (col >= 1) & (col < SIZE - 1) & (row >= 1) & (row < SIZE - 1)
    w2c = cam.world_to_camera_cv()
    z = points @ w2c[2, :3] + w2c[2, 3]
    ok = inside.copy()
    ok[inside] = np.isin(ch.mask[row[inside], col[inside]], (1, 2)) & \
        (np.abs(ch.depth[row[inside], col[inside]] - z[inside]) < depth_tol)
    return ok, uv, row, col


def test_flow_is_the_projected_motion_of_the_cloth(drawn) -> None:
    state, nxt, cams, channels = drawn
    for cam, ch in zip(cams, channels):
        ok, uv, _, _ = _visible_points(cam, ch, state.positions)
        assert ok.sum() > 200
        want = _project(cam, nxt) - uv
        # Flow at the point's exact sub-pixel place: bilinear between the four pixel centres
        # around it, all four on the same layer of cloth (at the point's depth, not a fold
        # behind or in front of it).
        w2c = cam.world_to_camera_cv()
        z = state.positions @ w2c[2, :3] + w2c[2, 3]
        x0, y0 = np.floor(uv[:, 0]).astype(int), np.floor(uv[:, 1]).astype(int)
        fx, fy = uv[:, 0] - x0, uv[:, 1] - y0
        good = ok.copy()
        for dy in (0, 1):
            for dx in (0, 1):
                r, c = np.clip(y0 + dy, 0, SIZE - 1), np.clip(x0 + dx, 0, SIZE - 1)
                good &= np.isin(ch.mask[r, c], (1, 2)) & (np.abs(ch.depth[r, c] - z) < 0.01)
        i = np.nonzero(good)[0]
        f = sum(ch.flow[y0[i] + dy, x0[i] + dx] * (((1 - fx[i]) if dx == 0 else fx[i]) * ((1 - fy[i]) if dy == 0 else fy[i]))[:, None]
                for dy in (0, 1) for dx in (0, 1))
        err = np.linalg.norm(f - want[i], axis=1)
        mag = np.linalg.norm(want[i], axis=1)
        assert mag.mean() > 2.0, "the motion is several pixels"
        assert np.percentile(err, 99) < 0.05 + 0.01 * mag.max(), (err.max(), mag.max())
        assert np.all(ch.flow[ch.mask == 0] == 0) and np.all(ch.flow[ch.mask >= 3] == 0)


def test_normals_agree_with_the_mesh_normals(drawn) -> None:
    state, _, cams, channels = drawn
    mesh_n = _mesh_normals(state)
    for cam, ch in zip(cams, channels):
        ok, _, row, col = _visible_points(cam, ch, state.positions)
        seen = ch.normal[row[ok], col[ok]].astype(np.float64)
        side = np.where(ch.mask[row[ok], col[ok]] == 1, 1.0, -1.0)
        cos = np.einsum("pk,pk->p", seen, mesh_n[ok] * side[:, None])
        assert np.percentile(cos, 1) > 0.99 and cos.min() > 0.95, (cos.min(), np.percentile(cos, 1))
        lengths = np.linalg.norm(ch.normal[ch.mask > 0], axis=1)
        assert np.allclose(lengths, 1.0, atol=1e-5)
        assert np.all(ch.normal[ch.mask == 0] == 0) and np.all(ch.depth[ch.mask == 0] == 0)
        # The side seen faces the camera.
        _, dirs, _ = _rays(cam, row[ok].astype(float), col[ok].astype(float))
        assert np.mean(np.einsum("pk,pk->p", seen, -dirs) > 0) > 0.99


def test_a_camera_drawn_from_a_seed_is_the_same_every_time() -> None:
    centre, radius = np.array([0.5, 0.1, 0.5]), 0.8
    a = draw_cameras((3, 12, 1), 4, centre, radius, 35.0, 256, 192)
    b = draw_cameras((3, 12, 1), 2, centre, radius, 35.0, 256, 192)
    assert a[:2] == b  # camera k does not depend on how many are drawn
    assert a != draw_cameras((3, 13, 1), 4, centre, radius, 35.0, 256, 192)
    draws = np.random.default_rng([3, 12, 1]).random((4, 3))
    for cam, (u_az, u_el, u_d) in zip(a, draws):
        offset = np.array(cam.position) - centre
        dist = np.linalg.norm(offset)
        el = math.degrees(math.asin(offset[1] / dist))
        assert el == pytest.approx(ELEVATION_RANGE_DEG[0] + (ELEVATION_RANGE_DEG[1] - ELEVATION_RANGE_DEG[0]) * u_el)
        assert math.atan2(offset[0], offset[2]) % (2 * math.pi) == pytest.approx(2 * math.pi * u_az)
        half = math.atan(math.tan(math.radians(17.5)) * 256 / 192)
        assert dist == pytest.approx(radius / math.sin(min(half, math.radians(17.5))) *
                                     (DISTANCE_RANGE[0] + (DISTANCE_RANGE[1] - DISTANCE_RANGE[0]) * u_d))
        assert cam.target == tuple(centre)


def test_opencv_and_opengl_conventions_agree() -> None:
    cam = ViewCamera((1.0, 1.2, 2.0), (0.4, 0.1, 0.3), 40.0, 320, 200)
    points = np.random.default_rng(1).uniform(-0.3, 0.3, (50, 3)) + np.array(cam.target)
    # OpenCV pixel coordinates ...
    uv = _project(cam, points)
    # ... equal OpenGL's: clip -> NDC -> window (y up, pixel centres at +0.5) -> rows from the top.
    clip = np.c_[points, np.ones(len(points))] @ (cam.projection_gl() @ cam.view_gl()).T
    ndc = clip[:, :3] / clip[:, 3:]
    gl_u = (ndc[:, 0] + 1) / 2 * cam.width - 0.5
    gl_v = (1 - ndc[:, 1]) / 2 * cam.height - 0.5
    np.testing.assert_allclose(uv, np.c_[gl_u, gl_v], atol=1e-9)
    d = cam.as_dict()
    np.testing.assert_allclose(np.array(d["world_to_camera_opencv"]) @ np.array(d["camera_to_world_opencv"]), np.eye(4),
                               atol=1e-12)
    np.testing.assert_allclose(np.diag([1, -1, -1, 1]) @ np.array(d["view_opengl"]), d["world_to_camera_opencv"])
