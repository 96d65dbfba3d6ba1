"""``clothsim sweep --views``: the files of a dataset's views, meta.json, loading without clothsim,
the same bits whatever the worker count, resume, splits, and the errors of the new flags.

The channels' values are checked against geometry in test_dataset_channels.py; here the tiny
scene of test_sweep.py (10 x 10 points, two spheres) is drawn at 64 x 48.
"""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest
from PIL import Image

from conftest import error_line, run_cli

from clothsim.datasets import open_dataset

SCENE = {
    "cloth": {"width": 1.0, "height": 1.0, "num_width_points": 10, "num_height_points": 10, "thickness": 0.0095,
              "orientation": 0, "pinned": [[0, 9], [9, 9]], "damping": 0.2, "density": 150.0, "ks": 5000.0},
    "sphere": [{"origin": [0.5, -0.3, 0.5], "radius": 0.2, "friction": 0.3},
               {"origin": [0.2, -0.5, 0.2], "radius": 0.1, "friction": 0.3}],
    "simulation": {"simulation_steps": 10},
}
ARGS = ["--frames", "6", "--every", "2", "--views", "2", "--size", "64x48"]


@pytest.fixture
def scene_file(tmp_path: Path) -> Path:
    path = tmp_path / "tiny.json"
    path.write_text(json.dumps(SCENE))
    return path


def _tree(folder: Path) -> dict[str, bytes]:
    return {str(p.relative_to(folder)): p.read_bytes() for p in sorted(folder.rglob("*")) if p.is_file()}


def test_views_files_meta_and_plain_numpy_loading(tmp_path: Path, scene_file: Path) -> None:
    out = tmp_path / "data"
    r = run_cli("sweep", str(scene_file), "--set", "cloth.ks=2000,5000", *ARGS, "--workers", "2", "-o", str(out))
    assert r.returncode == 0, r.stderr
    meta = json.loads((out / "meta.json").read_text())
    views = meta["views"]
    assert views["count"] == 2 and views["size"] == [64, 48]
    assert views["channels"] == ["rgb", "depth", "normal", "mask", "flow"]
    assert [m["id"] for m in views["mask_ids"]] == [0, 1, 2, 3, 4]
    assert [m.get("kind") for m in views["mask_ids"][3:]] == ["sphere", "sphere"]
    fields = {**meta["run_file"]["fields"], **views["fields"]}
    for name in ("positions", "world_pos", "mesh_pos", "node_type", "cells", "rgb", "depth", "normal", "mask", "flow"):
        assert {"dtype", "shape", "units", "doc"} <= set(fields[name]), name
    assert fields["node_type"]["codes"] == {"NORMAL": 0, "HANDLE": 3}
    splits = meta["splits"]
    assert sorted(sum(splits["runs"].values(), [])) == ["run_00000", "run_00001"]

    # Plain NumPy and Pillow, as docs/datasets.md shows.
    run = out / "runs" / "run_00001"
    with np.load(out / "runs" / "run_00001.npz") as data:
        frames = data["frames"]
        assert list(frames) == [0, 2, 4, 6]
        assert data["mesh_pos"].shape == (100, 2) and data["mesh_pos"].max() == pytest.approx(1.0)
        assert data["node_type"].dtype == np.int32 and sorted(set(data["node_type"])) == [0, 3]
        assert np.array_equal(data["node_type"] == 3, data["pinned"])
        assert np.array_equal(data["cells"], data["faces"])
        positions = data["positions"]
    cameras = json.loads((run / "cameras.json").read_text())
    assert len(cameras) == 2 and np.array(cameras[0]["K"]).shape == (3, 3)
    with np.load(run / "channels.npz") as ch:
        assert ch["depth"].shape == (2, 4, 48, 64) and ch["depth"].dtype == np.float32
        assert ch["normal"].shape == (2, 4, 48, 64, 3) and ch["normal"].dtype == np.float16
        assert ch["mask"].shape == (2, 4, 48, 64) and ch["mask"].dtype == np.uint8
        assert ch["flow"].shape == (2, 3, 48, 64, 2) and ch["flow"].dtype == np.float32
        depth, mask = ch["depth"], ch["mask"]
    rgb = np.asarray(Image.open(run / "rgb_v1_00004.png"))
    assert rgb.shape == (48, 64, 3)
    assert np.isin(mask, (1, 2)).any(axis=(2, 3)).all(), "the cloth is in every view at every frame"
    # The recorded camera maps the cloth's inner points (a hem point is on the outline) into the
    # image where the mask has cloth.
    inner = np.arange(100).reshape(10, 10)[1:-1, 1:-1].ravel()
    for v, cam in enumerate(cameras):
        w2c, k = np.array(cam["world_to_camera_opencv"]), np.array(cam["K"])
        x = positions[2][inner] @ w2c[:3, :3].T + w2c[:3, 3]
        uv = np.rint((x[:, :2] / x[:, 2:]) * [k[0, 0], k[1, 1]] + [k[0, 2], k[1, 2]]).astype(int)
        inside = (uv[:, 0] >= 0) & (uv[:, 0] < 64) & (uv[:, 1] >= 0) & (uv[:, 1] < 48)
        assert inside.all()
        assert np.isin(mask[v, 2][uv[:, 1], uv[:, 0]], (1, 2)).mean() > 0.95
        assert np.all(depth[v, 2][mask[v, 2] == 0] == 0)

    # clothsim.datasets gives the same arrays, with MeshGraphNets' names.
    data = open_dataset(out)
    assert data.ids() == ["run_00000", "run_00001"]
    loaded = data.load("run_00001")
    assert np.array_equal(loaded.arrays["world_pos"], positions)
    assert loaded.views["rgb"].shape == (2, 4, 48, 64, 3)
    assert np.array_equal(loaded.views["rgb"][1, 2], rgb)
    assert np.array_equal(loaded.views["mask"], mask)
    assert loaded.split in ("train", "valid", "test") and loaded.params == {"cloth.ks": 5000}
    assert sum(len(data.ids(s)) for s in ("train", "valid", "test")) == 2

    # One worker writes the same bits as two.
    other = tmp_path / "one"
    assert run_cli("sweep", str(scene_file), "--set", "cloth.ks=2000,5000", *ARGS, "--workers", "1",
                   "-o", str(other)).returncode == 0
    a, b = _tree(out / "runs"), _tree(other / "runs")
    assert a.keys() == b.keys() and all(a[k] == b[k] for k in a), [k for k in a if a[k] != b.get(k)]


def test_resume_redoes_a_run_missing_a_view_file(tmp_path: Path, scene_file: Path) -> None:
    out = tmp_path / "data"
    args = ["sweep", str(scene_file), "--set", "cloth.ks=2000,5000", *ARGS, "--channels", "rgb,mask",
            "--workers", "1", "-o", str(out)]
    assert run_cli(*args).returncode == 0
    with np.load(out / "runs" / "run_00000" / "channels.npz") as ch:
        assert ch.files == ["mask"]
    (out / "runs" / "run_00001" / "rgb_v0_00002.png").unlink()
    kept = _tree(out / "runs" / "run_00000")
    meta = (out / "meta.json").read_bytes()
    r = run_cli(*args)
    assert r.returncode == 0 and "1 done, 0 failed, 1 skipped" in r.stderr, r.stderr
    assert (out / "runs" / "run_00001" / "rgb_v0_00002.png").is_file()
    assert _tree(out / "runs" / "run_00000") == kept
    assert (out / "meta.json").read_bytes() == meta
    # Other views or channels are another sweep.
    line = error_line(run_cli(*[a if a != "rgb,mask" else "rgb,depth" for a in args]))
    assert "holds a different sweep" in line and "channels differs" in line


def test_split_is_stable_when_a_sampled_sweep_grows(tmp_path: Path, scene_file: Path) -> None:
    def splits(n: int, folder: str) -> dict[str, str]:
        out = tmp_path / folder
        r = run_cli("sweep", str(scene_file), "--set", "cloth.ks=uniform:2000:6000", "--samples", str(n), "--seed", "4",
                    "--frames", "1", "--split", "0.5,0.25,0.25", "--split-seed", "9", "--workers", "1", "-o", str(out))
        assert r.returncode == 0, r.stderr
        meta = json.loads((out / "meta.json").read_text())
        assert meta["splits"]["fractions"] == {"train": 0.5, "valid": 0.25, "test": 0.25} and meta["splits"]["seed"] == 9
        assert "views" not in meta  # positions only
        records = [json.loads(x) for x in (out / "manifest.jsonl").read_text().splitlines()]
        by_meta = {rid: s for s, ids in meta["splits"]["runs"].items() for rid in ids}
        assert all(rec["split"] == by_meta[rec["id"]] for rec in records)
        return by_meta

    small, large = splits(6, "small"), splits(12, "large")
    assert all(large[k] == v for k, v in small.items())
    assert set(large.values()) == {"train", "valid", "test"}


def test_scene_listed_cameras_are_the_views(tmp_path: Path) -> None:
    scene = json.loads(json.dumps(SCENE))
    scene["render"] = {"views": [{"position": [0.5, 0.5, 3.0], "target": [0.5, 0.0, 0.5], "fov": 30},
                                 {"position": [3.0, 1.0, 0.5], "target": [0.5, 0.0, 0.5]}]}
    path = tmp_path / "listed.json"
    path.write_text(json.dumps(scene))
    out = tmp_path / "data"
    r = run_cli("sweep", str(path), "--set", "cloth.ks=5000", "--frames", "2", "--views", "2", "--size", "32x32",
                "--channels", "depth", "--workers", "1", "-o", str(out))
    assert r.returncode == 0, r.stderr
    cams = json.loads((out / "runs" / "run_00000" / "cameras.json").read_text())
    assert cams[0]["position"] == [0.5, 0.5, 3.0] and cams[0]["fov_y_deg"] == 30
    assert cams[1]["position"] == [3.0, 1.0, 0.5] and cams[1]["fov_y_deg"] == 35.0
    assert json.loads((out / "meta.json").read_text())["views"]["cameras_from"] == "render.views"
    line = error_line(run_cli("sweep", str(path), "--set", "cloth.ks=5000", "--frames", "2", "--views", "3",
                              "-o", str(tmp_path / "more")))
    assert "--views 3: render.views lists only 2 cameras" in line
    assert not (tmp_path / "more").exists()


@pytest.mark.parametrize("args, expected", [
    (["--views", "2", "--channels", "rgb,heat"], "--channels: unknown channel 'heat'"),
    (["--channels", "rgb"], "--channels: goes with --views N"),
    (["--views", "-1"], "--views"),
    (["--views", "2", "--split", "0.5,0.5"], "--split: expected three fractions"),
])
def test_bad_view_flags_are_one_line_and_write_nothing(tmp_path: Path, scene_file: Path, args, expected) -> None:
    out = tmp_path / "data"
    line = error_line(run_cli("sweep", str(scene_file), "--set", "cloth.ks=5000", "--frames", "2", *args, "-o", str(out)))
    assert expected in line
    assert not out.exists()


def test_views_need_a_dataset(tmp_path: Path, scene_file: Path) -> None:
    line = error_line(run_cli("sweep", str(scene_file), "--set", "cloth.ks=5000", "--frames", "2", "--views", "2",
                              "-o", str(tmp_path / "sheet.png")))
    assert "--views: needs a dataset folder" in line
