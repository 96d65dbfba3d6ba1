"""Mesh kernels, render settings validation, textures and output-format choice."""

from __future__ import annotations

import numpy as np
import pytest

from clothsim.errors import ClothsimError, SceneError
from clothsim.render import mesh, textures
from clothsim.render.settings import RenderSettings
from clothsim.scene import scene_from_dict

CLOTH = {"width": 1, "height": 1, "num_width_points": 5, "num_height_points": 4, "thickness": 0.01,
         "orientation": 0, "damping": 0.2, "density": 150, "ks": 5000}


def _reference_normals(pos: np.ndarray, nw: int, nh: int) -> np.ndarray:
    tris = mesh.cloth_triangles(nw, nh).reshape(-1, 3)
    face = np.cross(pos[tris[:, 1]] - pos[tris[:, 0]], pos[tris[:, 2]] - pos[tris[:, 0]])
    acc = np.zeros_like(pos)
    for k in range(3):
        np.add.at(acc, tris[:, k], face)
    return acc / np.linalg.norm(acc, axis=1, keepdims=True)


def test_flat_horizontal_cloth_faces_up_with_u_tangent():
    nw, nh = 5, 4
    u, v = np.meshgrid(np.linspace(0, 1, nw), np.linspace(0, 1, nh))
    pos = np.stack([u.ravel(), np.ones(nw * nh), v.ravel()], axis=1)
    out = np.empty((nw * nh, 9), np.float32)
    mesh.update_cloth_vertices(pos, nw, nh, True, out)
    assert np.allclose(out[:, 3:6], [0, 1, 0])
    assert np.allclose(out[:, 6:9], [1, 0, 0])


def test_normals_match_area_weighted_reference():
    nw, nh = 7, 6
    rng = np.random.default_rng(1)
    u, v = np.meshgrid(np.linspace(0, 1, nw), np.linspace(0, 1, nh))
    pos = np.stack([u.ravel(), 0.2 * rng.random(nw * nh), v.ravel()], axis=1)
    out = np.empty((nw * nh, 9), np.float32)
    mesh.update_cloth_vertices(pos, nw, nh, True, out)
    assert np.allclose(out[:, 3:6], _reference_normals(pos, nw, nh), atol=1e-5)
    assert np.allclose((out[:, 3:6] * out[:, 6:9]).sum(axis=1), 0.0, atol=1e-5)  # t is orthogonal to n
    mesh.update_cloth_vertices(pos, nw, nh, False, out)
    assert np.all(out[:, 6:9] == 0.0)  # no tangent work unless asked


def test_sphere_mesh_is_unit_and_outward():
    verts, idx = mesh.sphere_mesh(8, 12)
    assert np.allclose(np.linalg.norm(verts[:, :3], axis=1), 1.0, atol=1e-6)
    tri = verts[idx.reshape(-1, 3), :3]
    n = np.cross(tri[:, 1] - tri[:, 0], tri[:, 2] - tri[:, 0])
    centre = tri.mean(axis=1)
    big = np.linalg.norm(n, axis=1) > 1e-9  # pole triangles are degenerate
    assert np.all((n[big] * centre[big]).sum(axis=1) > 0)


def test_render_settings_defaults_and_errors(tmp_path):
    s = RenderSettings.from_scene(scene_from_dict({"cloth": CLOTH}, "a.json"))
    assert s.size == (800, 800) and s.normal_scaling == 2.0 and s.height_scaling == 0.1
    assert s.light_position == (0.5, 2.0, 2.0) and s.sphere_resolution == (40, 40)
    s = RenderSettings.from_scene(scene_from_dict(
        {"cloth": CLOTH, "render": {"size": "320x200", "color": "#ff0000", "phong": {"terms": ["specular"]}}}, "a.json"))
    assert s.size == (320, 200) and s.color == (1.0, 0.0, 0.0) and s.terms == ("specular",)
    for bad, field in (({"size": [0, 1]}, "render.size[0]"), ({"shader": "toon"}, "render.shader"),
                       ({"camera": {"fov": 0}}, "render.camera.fov"), ({"phong": {"terms": ["glow"]}}, "render.phong.terms"),
                       ({"textures": {"color": "nope.png"}}, "render.textures.color"), ("x", "render")):
        with pytest.raises(SceneError) as info:
            RenderSettings.from_scene(scene_from_dict({"cloth": CLOTH, "render": bad}, str(tmp_path / "a.json")))
        assert field in str(info.value) and "a.json" in str(info.value)


def test_default_textures_are_deterministic():
    assert np.array_equal(textures.default_height_map(), textures.default_height_map())
    faces = textures.default_cubemap(16)
    assert len(faces) == 6 and all(f.shape == (16, 16, 4) for f in faces)
    up, down = faces[2][..., :3].mean(), faces[3][..., :3].mean()
    assert faces[2][..., 2].mean() > faces[2][..., 0].mean()  # the sky is blue
    assert up != down


def test_output_format_by_suffix(tmp_path):
    from clothsim.output import output_format

    assert output_format("a.png") == "png" and output_format("a.GIF") == "gif"
    assert output_format("a.mp4") == "mp4" and output_format("frames") == "dir"
    assert output_format(str(tmp_path) + "/x.d/") == "dir" and output_format(tmp_path) == "dir"
    with pytest.raises(ClothsimError):
        output_format("a.jpg")
