"""Workers that write where the data lives: ``--write-in-workers`` into a local folder from
separate worker processes, and an fsspec URL (the in-memory file system, shared by a Dask
cluster's in-process workers). The files are the ones a sweep whose parent writes them has, bit
for bit; resume, failures and the refusal of foreign folders work as they do there.
"""

from __future__ import annotations

import io
import json
from pathlib import Path

import numpy as np
import pytest

from conftest import error_line, run_cli

import clothsim
from clothsim.errors import ClothsimError

SCENE = {
    "cloth": {"width": 1.0, "height": 1.0, "num_width_points": 10, "num_height_points": 10, "thickness": 0.0095,
              "orientation": 0, "pinned": [[0, 9], [9, 9]], "damping": 0.2, "density": 150.0, "ks": 5000.0},
    "sphere": [{"origin": [0.5, -0.3, 0.5], "radius": 0.2, "friction": 0.3},
               {"origin": [0.2, -0.5, 0.2], "radius": 0.1, "friction": 0.3}],
    "simulation": {"simulation_steps": 10},
}
ARGS = ["--set", "cloth.ks=2000,5000,1e9", "--set", "simulation.simulation_steps=1", "--frames", "4", "--every", "2",
        "--views", "2", "--size", "32x32"]


@pytest.fixture
def scene_file(tmp_path: Path) -> Path:
    path = tmp_path / "tiny.json"
    path.write_text(json.dumps(SCENE))
    return path


def _tree(folder: Path) -> dict[str, bytes]:
    return {str(p.relative_to(folder)): p.read_bytes() for p in sorted(folder.rglob("*")) if p.is_file()}


def _lines(text: str) -> list[dict]:
    return [{k: v for k, v in json.loads(x).items() if k not in ("seconds", "render_seconds")} for x in text.splitlines()]


def test_workers_write_a_local_folder_as_the_parent_would(tmp_path: Path, scene_file: Path) -> None:
    parent, direct = tmp_path / "parent", tmp_path / "direct"
    r = run_cli("sweep", str(scene_file), *ARGS, "--workers", "2", "-o", str(parent))
    assert r.returncode == 1 and "2 done, 1 failed" in r.stderr, r.stderr  # ks 1e9 at one substep blows up
    args = ["sweep", str(scene_file), *ARGS, "--workers", "2", "--write-in-workers", "-o", str(direct)]
    r = run_cli(*args)
    assert r.returncode == 1 and "2 done, 1 failed" in r.stderr, r.stderr
    assert _tree(parent / "runs") == _tree(direct / "runs")
    assert sorted(map(json.dumps, _lines((parent / "manifest.jsonl").read_text()))) == \
        sorted(map(json.dumps, _lines((direct / "manifest.jsonl").read_text())))
    assert (parent / "meta.json").read_bytes() == (direct / "meta.json").read_bytes()
    # Resume: a run missing a file is written again by a worker; the others are left alone.
    (direct / "runs" / "run_00001" / "channels.npz").unlink()
    kept = _tree(direct / "runs" / "run_00000")
    r = run_cli(*args)
    assert r.returncode == 1 and "1 done, 0 failed, 2 skipped" in r.stderr, r.stderr  # the failed run stays failed
    assert _tree(direct / "runs") == _tree(parent / "runs") and _tree(direct / "runs" / "run_00000") == kept
    # Another sweep into it, or a folder of someone else's files, is refused as before.
    assert "holds a different sweep" in error_line(run_cli(*[a if a != "32x32" else "16x16" for a in args]))
    foreign = tmp_path / "foreign"
    foreign.mkdir()
    (foreign / "notes.txt").write_text("mine")
    line = error_line(run_cli("sweep", str(scene_file), *ARGS, "--write-in-workers", "-o", str(foreign)))
    assert "not written by clothsim sweep" in line and sorted(p.name for p in foreign.iterdir()) == ["notes.txt"]


def test_an_fsspec_memory_url_from_a_dask_cluster(tmp_path: Path, scene_file: Path) -> None:
    distributed = pytest.importorskip("distributed")
    fsspec = pytest.importorskip("fsspec")
    fs = fsspec.filesystem("memory")
    grid = {"cloth.ks": [2000, 5000, 1e9]}
    kwargs = dict(frames=4, every=2, views=2, size=(32, 32))
    scene = dict(SCENE, simulation={"simulation_steps": 1})
    local = clothsim.sweep(scene, grid, tmp_path / "local", workers=1, **kwargs)
    url = "memory://clothsim-test/ds"
    try:
        # In-process workers share this process's memory file system, as a cluster's machines share a bucket.
        with distributed.LocalCluster(n_workers=2, threads_per_worker=1, processes=False,
                                      dashboard_address=None) as cluster:
            remote = clothsim.sweep(scene, grid, url, scheduler=cluster.scheduler_address, **kwargs)
            assert [r["status"] for r in remote] == [r["status"] for r in local] == ["done", "done", "failed"]
            for rel, data in _tree(tmp_path / "local").items():
                if rel.startswith("runs/") or rel == "meta.json":
                    assert fs.cat_file(f"/clothsim-test/ds/{rel}") == data, rel
            manifest = fs.cat_file("/clothsim-test/ds/manifest.jsonl").decode()
            assert sorted(map(json.dumps, _lines(manifest))) == \
                sorted(map(json.dumps, _lines((tmp_path / "local" / "manifest.jsonl").read_text())))
            with np.load(io.BytesIO(fs.cat_file("/clothsim-test/ds/runs/run_00001.npz"))) as run:
                assert run["positions"].shape == (3, 100, 3)

            # Resume: only the run whose file went missing is done again; a failed run is final.
            fs.rm("/clothsim-test/ds/runs/run_00000/cameras.json")
            again = clothsim.sweep(scene, grid, url, scheduler=cluster.scheduler_address, **kwargs)
            assert [r["skipped"] for r in again] == [False, True, True]
            assert fs.exists("/clothsim-test/ds/runs/run_00000/cameras.json")
            with pytest.raises(ClothsimError, match="holds a different sweep"):
                clothsim.sweep(scene, grid, url, scheduler=cluster.scheduler_address, frames=6, every=2,
                               views=2, size=(32, 32))
            fs.pipe_file("/clothsim-test/other/notes.txt", b"mine")
            with pytest.raises(ClothsimError, match="not written by clothsim sweep"):
                clothsim.sweep(scene, grid, "memory://clothsim-test/other", scheduler=cluster.scheduler_address,
                               **kwargs)
            assert fs.ls("/clothsim-test/other", detail=False) == ["/clothsim-test/other/notes.txt"]
    finally:
        fs.rm("/clothsim-test", recursive=True)
