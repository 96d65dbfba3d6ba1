"""The render CLI through a real subprocess, output formats, atomic output and error lines."""

from __future__ import annotations

import os
import subprocess
import sys

import numpy as np
import pytest
from conftest import run_cli

pytest.importorskip("moderngl")


@pytest.fixture(scope="module")
def egl_available():
    from clothsim.errors import ClothsimError
    from clothsim.render.context import create_context

    try:
        create_context().release()
    except ClothsimError as exc:
        pytest.skip(str(exc))


def test_info(egl_available):
    r = run_cli("info")
    assert r.returncode == 0, r.stderr
    assert "GL renderer:" in r.stdout and "GL version:" in r.stdout


@pytest.mark.parametrize("name", ["out.png", "out.gif", "out.mp4", "frames/"])
def test_render_formats(tmp_path, name, egl_available):
    out = tmp_path / name
    r = run_cli("render", "sphere", "--frames", "4", "--every", "2", "--size", "96x64",
                 "--shader", "phong", "-o", str(out))
    assert r.returncode == 0, r.stderr
    from PIL import Image

    if name.endswith("/"):
        files = sorted(out.iterdir())
        assert [f.name for f in files] == ["frame_00000.png", "frame_00001.png", "frame_00002.png"]
        assert Image.open(files[0]).size == (96, 64)
    elif name.endswith(".mp4"):
        assert out.stat().st_size > 0 and b"ftyp" in out.read_bytes()[:64]
    else:
        with Image.open(out) as im:
            assert im.size == (96, 64)
            if name.endswith(".gif"):
                assert im.n_frames == 3
            else:
                assert np.asarray(im.convert("RGB")).std() > 1.0  # not a blank picture
    assert list(tmp_path.iterdir()) == [out]  # no temporaries left, whatever their names


def test_failed_render_leaves_no_file(tmp_path, egl_available):
    out = tmp_path / "odd.mp4"
    r = run_cli("render", "sphere", "--frames", "1", "--size", "63x64", "-o", str(out))
    assert r.returncode == 2
    assert "even width and height" in r.stderr
    assert len(r.stderr.strip().splitlines()) == 1
    assert list(tmp_path.iterdir()) == []


def test_bad_render_setting_names_field(tmp_path):
    scene = tmp_path / "s.json"
    scene.write_text('{"cloth": {"width": 1, "height": 1, "num_width_points": 4, "num_height_points": 4,'
                     ' "thickness": 0.01, "orientation": 0, "damping": 0.2, "density": 150, "ks": 5000},'
                     ' "render": {"size": [0, 10]}}')
    r = run_cli("render", str(scene), "-o", str(tmp_path / "x.png"))
    assert r.returncode == 2
    assert "render.size" in r.stderr and str(scene) in r.stderr
    assert not (tmp_path / "x.png").exists()


def test_simulation_commands_do_not_load_gl():
    code = ("import sys, clothsim.cli as c; c.build_parser(); import clothsim.cli.render; "
            "print('moderngl' in sys.modules, 'glcontext' in sys.modules)")
    r = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=120)
    assert r.returncode == 0, r.stderr
    assert r.stdout.split() == ["False", "False"]


def test_missing_egl_gives_one_line(monkeypatch):
    import moderngl

    from clothsim.errors import ClothsimError
    from clothsim.render import context

    def no_egl(*args, **kwargs):
        raise Exception("libEGL.so: cannot open shared object file:\n No such file or directory")

    monkeypatch.setattr(moderngl, "create_standalone_context", no_egl)
    with pytest.raises(ClothsimError) as info:
        context.create_context()
    message = str(info.value)
    assert "\n" not in message
    for package in ("libegl1", "libegl-mesa0", "libgl1-mesa-dri"):
        assert package in message


def test_bench_render_ends_with_a_clip_end_to_end(egl_available):
    r = run_cli("bench", "render", "pinned2", "--shaders", "normal,phong", "--frames", "4", "--repeats", "1",
                 "--warmup", "0", "--size", "64x64")
    assert r.returncode == 0, r.stderr
    lines = r.stdout.splitlines()
    assert [line.split()[0] for line in lines[3:5]] == ["normal", "phong"]
    assert lines[5] == "" and lines[6].startswith("end to end: pinned2, phong, 64x64, ")
    assert "a clip of 4 frames from the start, every 1 drawn (5 images)" in lines[7]
    rows = {line[:14].strip(): line[14:].split() for line in lines[9:]}
    assert set(rows) == {"overlapped", "serial", "render only", "driver limit"}
    assert all(float(v[0]) > 0 for v in rows.values())  # images per second
    assert rows["render only"][3] == "100%" and rows["driver limit"][4] == "100%"
    # the process's CPU ms per image and the cores it kept busy (CPU time per wall time)
    assert all(len(v) == 7 and float(v[5]) > 0 and 0 < float(v[6]) <= (os.cpu_count() or 1) + 0.5
               for v in rows.values())
