"""``clothsim sweep``: expansion, validation before any run, contact sheets, datasets, resume,
failures, and a Dask cluster giving the same arrays as local processes.

Scenes are tiny (10 x 10 points, a few frames, 48 x 48 images) so the whole file stays quick; the
CLI runs in a subprocess through ``run_cli``. Datasets are compared bit for bit with
``clothsim simulate`` of the same scene, cells pixel for pixel with ``clothsim render``.
"""

from __future__ import annotations

import json
import multiprocessing
import os
import signal
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
import pytest
from PIL import Image

from conftest import child_pids, error_line, run_cli

import clothsim
from clothsim.errors import ClothsimError
from clothsim.sweeps import params as P
from clothsim.sweeps import sheet as S

SCENE = {
    "cloth": {"width": 1.0, "height": 1.0, "num_width_points": 10, "num_height_points": 10, "thickness": 0.0095,
              "orientation": 0, "pinned": [[0, 9], [9, 9]], "damping": 0.2, "density": 150.0, "ks": 5000.0},
    "sphere": [{"origin": [0.5, -0.3, 0.5], "radius": 0.2, "friction": 0.3},
               {"origin": [0.2, -0.5, 0.2], "radius": 0.1, "friction": 0.3}],
    "simulation": {"simulation_steps": 10},
}
GRID = ["--set", "cloth.density=100,150", "--set", "cloth.ks=200,5000"]


@pytest.fixture
def scene_file(tmp_path: Path) -> Path:
    path = tmp_path / "tiny.json"
    path.write_text(json.dumps(SCENE))
    return path



def scene_with(tmp_path: Path, params: dict, name: str) -> Path:
    data = json.loads(json.dumps(SCENE))
    for field, value in params.items():
        P.set_field(data, field, value)
    path = tmp_path / f"{name}.json"
    path.write_text(json.dumps(data))
    return path


def snapshot(folder: Path) -> dict[str, tuple[int, bytes]]:
    return {p.name: (p.stat().st_mtime_ns, p.read_bytes()) for p in sorted(folder.iterdir()) if p.is_file()}


# -- expansion -----------------------------------------------------------------------------------
def test_grid_is_the_cartesian_product_in_order() -> None:
    runs = P.expand({"cloth.density": P.parse_values("d", "1,15,1000"), "cloth.enable_shearing": [True, False]})
    assert [r.id for r in runs] == [f"run_{i:05d}" for i in range(6)]
    assert [tuple(r.params.values()) for r in runs] == [(1, True), (1, False), (15, True), (15, False),
                                                        (1000, True), (1000, False)]
    assert P.parse_set("simulation.self_collision=spec,grid") == ("simulation.self_collision", ["spec", "grid"])
    assert P.parse_set("cloth.enable_bending=true,false")[1] == [True, False]
    assert P.parse_set("cloth.ks=1e3,2.5")[1] == [1000.0, 2.5]


def test_sampling_depends_only_on_seed_and_index() -> None:
    space = {"cloth.ks": P.parse_values("k", "loguniform:10:100000"), "cloth.damping": P.parse_values("d", "uniform:0:1"),
             "cloth.density": P.parse_values("r", "1,15,1000")}
    a = P.expand(space, samples=20, seed=7)
    assert [r.params for r in a] == [r.params for r in P.expand(space, samples=20, seed=7)]
    assert [r.params for r in P.expand(space, samples=5, seed=7)] == [r.params for r in a[:5]]
    assert [r.params for r in P.expand(space, samples=5, seed=8)] != [r.params for r in a[:5]]
    for r in a:
        assert 10 <= r.params["cloth.ks"] <= 100000 and 0 <= r.params["cloth.damping"] <= 1
        assert r.params["cloth.density"] in (1, 15, 1000)
    assert len({r.params["cloth.density"] for r in a}) > 1
    with pytest.raises(ClothsimError, match="needs --samples"):
        P.expand(space)


def test_dotted_paths_reach_list_colliders_and_create_objects() -> None:
    data = json.loads(json.dumps(SCENE))
    P.set_field(data, "sphere.1.radius", 0.3)
    P.set_field(data, "render.light.intensity", [1, 1, 1])
    assert data["sphere"][1]["radius"] == 0.3 and data["sphere"][0]["radius"] == 0.2
    assert data["render"] == {"light": {"intensity": [1, 1, 1]}}
    with pytest.raises(ClothsimError, match="no item 5"):
        P.set_field(data, "sphere.5.radius", 1.0)
    with pytest.raises(ClothsimError, match="is a list"):
        P.set_field(data, "sphere.radius", 1.0)


# -- validation before any run -------------------------------------------------------------------
@pytest.mark.parametrize("args, expected", [
    (["--set", "cloth.kss=1,2"], "--set cloth.kss: unknown field cloth.kss"),
    (["--set", "cloth.ks=10,-5"], "cloth.ks: must be >= 0, got -5 (run_00001: cloth.ks=-5)"),
    (["--set", "sphere.2.radius=0.1"], "--set sphere.2.radius: no item 2"),
    (["--set", "cloth.ks=uniform:1:2"], "needs --samples"),
    (["--set", "cloth.ks"], "expected FIELD=VALUES"),
])
def test_bad_field_or_value_fails_first_and_writes_nothing(tmp_path: Path, scene_file: Path, args, expected) -> None:
    for out in (tmp_path / "sheet.png", tmp_path / "data"):
        r = run_cli("sweep", str(scene_file), *args, "--frames", "2", "-o", str(out))
        assert expected in error_line(r)
        assert not out.exists()


def test_missing_dask_names_the_extra(tmp_path: Path, scene_file: Path) -> None:
    fake = tmp_path / "fake"
    (fake / "distributed").mkdir(parents=True)
    (fake / "distributed" / "__init__.py").write_text("raise ImportError('no distributed here')\n")
    env = dict(os.environ, PYTHONPATH=str(fake))
    r = subprocess.run([sys.executable, "-m", "clothsim", "sweep", str(scene_file), "--set", "cloth.ks=10",
                        "--scheduler", "tcp://127.0.0.1:1", "-o", str(tmp_path / "d")],
                       capture_output=True, text=True, env=env, timeout=120)
    assert "pip install 'clothsim[cluster]'" in error_line(r)
    assert not (tmp_path / "d").exists()


# -- contact sheet -------------------------------------------------------------------------------
def test_contact_sheet_layout_labels_and_cells_equal_render(tmp_path: Path, scene_file: Path) -> None:
    out = tmp_path / "sheet.png"
    r = run_cli("sweep", str(scene_file), *GRID, "--frames", "30", "--size", "48x48", "--workers", "1", "-o", str(out))
    assert r.returncode == 0, r.stderr
    sheet = np.asarray(Image.open(out).convert("RGB"))
    runs = P.expand({"cloth.density": [100, 150], "cloth.ks": [200, 5000]})
    spec = S.plan(runs, {"cloth.density": [100, 150], "cloth.ks": [200, 5000]}, [30], 90.0, False)
    assert spec.row_labels == ["density = 100", "density = 150"]
    assert spec.col_labels == ["ks = 200", "ks = 5000"]
    geo = S.layout(spec, (48, 48))
    assert (geo.rows, geo.cols) == (2, 2)
    assert sheet.shape == (geo.size[1], geo.size[0], 3)
    assert geo.left > S.PAD and geo.top > S.PAD  # labels sit outside the cells
    # The margins hold dark label text; the gaps between cells stay background.
    assert (sheet[:geo.top, :] < 100).any() and (sheet[:, :geo.left] < 100).any()
    # One cell is exactly what clothsim render draws of that run's scene.
    render_png = tmp_path / "cell.png"
    r = run_cli("render", str(scene_with(tmp_path, runs[3].params, "r3")), "--frames", "30", "--size", "48x48",
                "-o", str(render_png))
    assert r.returncode == 0, r.stderr
    expected = np.asarray(Image.open(render_png).convert("RGB"))
    x0, y0, x1, y1 = geo.cell_box(1, 1)
    assert np.array_equal(sheet[y0:y1, x0:x1], expected)
    x0, y0, x1, y1 = geo.cell_box(0, 0)
    assert not np.array_equal(sheet[y0:y1, x0:x1], expected)  # another run: another image


def test_contact_sheet_frame_list_adds_time_columns(tmp_path: Path, scene_file: Path) -> None:
    out = tmp_path / "times.png"
    r = run_cli("sweep", str(scene_file), "--set", "cloth.ks=2000,5000", "--frames", "0,2,4", "--size", "48x48",
                "--workers", "1", "-o", str(out))
    assert r.returncode == 0, r.stderr
    space = {"cloth.ks": [2000, 5000]}
    spec = S.plan(P.expand(space), space, [0, 2, 4], 90.0, False)
    assert len(spec.slots) == 2 and len(spec.slots[0]) == 3
    assert spec.col_labels[2] == "t = 0.04 s (frame 4)"
    geo = S.layout(spec, (48, 48))
    sheet = np.asarray(Image.open(out).convert("RGB"))
    assert sheet.shape == (geo.size[1], geo.size[0], 3)
    first = [sheet[b[1]:b[3], b[0]:b[2]] for b in (geo.cell_box(0, c) for c in range(3))]
    assert not np.array_equal(first[0], first[2])  # the cloth moved between frame 0 and frame 4


# -- datasets ------------------------------------------------------------------------------------
def test_dataset_matches_simulate_bit_for_bit(tmp_path: Path, scene_file: Path) -> None:
    out = tmp_path / "data"
    r = run_cli("sweep", str(scene_file), *GRID, "--set", "sphere.1.radius=0.15", "--frames", "5", "--every", "2",
                "--workers", "2", "-o", str(out))
    assert r.returncode == 0, r.stderr
    records = [json.loads(line) for line in (out / "manifest.jsonl").read_text().splitlines()]
    assert sorted(rec["id"] for rec in records) == [f"run_{i:05d}" for i in range(4)]
    for rec in records:
        assert set(rec) == {"id", "params", "seed", "status", "error", "path", "frames", "seconds", "split"}
        assert rec["status"] == "done" and rec["error"] is None and rec["frames"] == 5
        with np.load(out / rec["path"]) as data:
            pos = data["positions"]
            assert pos.dtype == np.float32 and pos.shape == (4, 100, 3)  # frames 0, 2, 4, 5
            assert list(data["frames"]) == [0, 2, 4, 5]
            assert data["faces"].dtype == np.int32 and data["faces"].shape == (2 * 9 * 9, 3)
            assert data["uv"].dtype == np.float32 and data["uv"].shape == (100, 2)
            assert data["pinned"].dtype == bool and data["pinned"].sum() == 2
            scene = json.loads(str(data["scene"]))
        assert scene["cloth"]["ks"] == rec["params"]["cloth.ks"]
        assert scene["sphere"][1]["radius"] == 0.15
        path = scene_with(tmp_path, rec["params"], rec["id"])
        sim_out = tmp_path / f"{rec['id']}.npz"
        assert run_cli("simulate", str(path), "--frames", "5", "--out", str(sim_out)).returncode == 0
        with np.load(sim_out) as ref:
            assert np.array_equal(pos[-1], ref["positions"].astype(np.float32))
        sim = clothsim.Simulation(clothsim.load_scene(path))
        sim.step(2)
        assert np.array_equal(pos[1], sim.positions.astype(np.float32))


def test_failing_run_is_recorded_and_others_go_on(tmp_path: Path, scene_file: Path) -> None:
    out = tmp_path / "data"
    r = run_cli("sweep", str(scene_file), "--set", "cloth.ks=5000,1e9", "--set", "simulation.simulation_steps=1",
                "--frames", "3", "--workers", "1", "-o", str(out))
    assert r.returncode == 1, r.stderr
    assert "1 done, 1 failed" in r.stderr and "Traceback" not in r.stderr
    records = {rec["id"]: rec for rec in map(json.loads, (out / "manifest.jsonl").read_text().splitlines())}
    assert records["run_00000"]["status"] == "done"
    bad = records["run_00001"]
    assert bad["status"] == "failed" and "blew up" in bad["error"] and "\n" not in bad["error"]
    assert bad["path"] is None and not (out / "runs" / "run_00001.npz").exists()


def test_resume_redoes_only_missing_or_broken_runs(tmp_path: Path, scene_file: Path) -> None:
    out = tmp_path / "data"
    args = ["sweep", str(scene_file), *GRID, "--frames", "3", "--workers", "1", "-o", str(out)]
    assert run_cli(*args).returncode == 0
    runs = out / "runs"
    (runs / "run_00001.npz").unlink()
    broken = runs / "run_00002.npz"
    broken.write_bytes(broken.read_bytes()[:300])  # a half-written file
    before = snapshot(runs)
    manifest = (out / "manifest.jsonl").read_bytes()
    definition = snapshot(out)["sweep.json"]
    r = run_cli(*args)
    assert r.returncode == 0, r.stderr
    assert "2 done, 0 failed, 2 skipped" in r.stderr
    after = snapshot(runs)
    for name in ("run_00000.npz", "run_00003.npz"):
        assert after[name] == before[name]  # neither rewritten nor touched
    assert after["run_00002.npz"][1] != before["run_00002.npz"][1]
    assert "run_00001.npz" in after
    assert (out / "manifest.jsonl").read_bytes().startswith(manifest)  # appended, not rewritten
    assert snapshot(out)["sweep.json"] == definition
    with np.load(runs / "run_00002.npz") as data:
        assert data["positions"].shape == (4, 100, 3)
    # Everything complete: a third run does nothing.
    r = run_cli(*args)
    assert r.returncode == 0 and "0 done, 0 failed, 4 skipped" in r.stderr
    assert snapshot(runs) == after


def test_video_per_run_and_a_missing_video_is_redone(tmp_path: Path, scene_file: Path) -> None:
    import imageio_ffmpeg

    out = tmp_path / "data"
    args = ["sweep", str(scene_file), "--set", "cloth.ks=2000,5000", "--frames", "6", "--every", "3", "--video",
            "--size", "64x48", "--workers", "1", "-o", str(out)]
    assert run_cli(*args).returncode == 0
    reader = imageio_ffmpeg.read_frames(str(out / "runs" / "run_00001.mp4"))
    meta = next(reader)
    assert meta["size"] == (64, 48) and sum(1 for _ in reader) == 3  # frames 0, 3, 6
    (out / "runs" / "run_00001.mp4").unlink()
    kept = snapshot(out / "runs")
    r = run_cli(*args)
    assert r.returncode == 0 and "1 done, 0 failed, 1 skipped" in r.stderr
    assert (out / "runs" / "run_00001.mp4").stat().st_size > 0
    assert snapshot(out / "runs")["run_00000.mp4"] == kept["run_00000.mp4"]


def test_same_folder_other_sweep_or_foreign_files_refused(tmp_path: Path, scene_file: Path) -> None:
    out = tmp_path / "data"
    assert run_cli("sweep", str(scene_file), "--set", "cloth.ks=2000", "--frames", "2", "--workers", "1",
                   "-o", str(out)).returncode == 0
    before = snapshot(out)
    r = run_cli("sweep", str(scene_file), "--set", "cloth.ks=3000", "--frames", "2", "-o", str(out))
    assert "holds a different sweep" in error_line(r)
    r = run_cli("sweep", str(scene_file), "--set", "cloth.ks=2000", "--frames", "3", "-o", str(out))
    assert "frames 2 there, 3 here" in error_line(r)
    assert snapshot(out) == before
    mine = tmp_path / "mine"
    mine.mkdir()
    (mine / "notes.txt").write_text("keep me")
    r = run_cli("sweep", str(scene_file), "--set", "cloth.ks=2000", "--frames", "2", "-o", str(mine))
    assert "folder is not empty" in error_line(r)
    assert os.listdir(mine) == ["notes.txt"] and (mine / "notes.txt").read_text() == "keep me"


def test_killed_worker_then_resume_completes(tmp_path: Path, scene_file: Path) -> None:
    if not Path(f"/proc/{os.getpid()}/task").exists():
        pytest.skip("needs /proc")
    out = tmp_path / "data"
    big = dict(SCENE, cloth=dict(SCENE["cloth"], num_width_points=24, num_height_points=24, pinned=[[0, 23]]),
               simulation={"simulation_steps": 30})
    path = tmp_path / "big.json"
    path.write_text(json.dumps(big))
    args = ["-m", "clothsim", "sweep", str(path), "--set", "cloth.ks=3000,4000,5000,6000,7000,8000",
            "--frames", "600", "--workers", "1", "-o", str(out)]
    proc = subprocess.Popen([sys.executable, *args], stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    try:
        deadline = time.monotonic() + 120
        manifest = out / "manifest.jsonl"
        while time.monotonic() < deadline and not (manifest.exists() and manifest.read_text().count("\n") >= 1):
            time.sleep(0.05)
        assert manifest.exists(), "no run finished in time"
        workers = [k for k in child_pids(proc.pid)
                   if b"spawn_main" in Path(f"/proc/{k}/cmdline").read_bytes()]
        assert workers, "no worker process found"
        os.kill(workers[0], signal.SIGKILL)
        _, err = proc.communicate(timeout=120)
    finally:
        if proc.poll() is None:
            proc.kill()
            proc.wait()
    assert proc.returncode == 1, err
    assert "lost with a worker that died" in err and "Traceback" not in err
    done_before = [json.loads(x)["id"] for x in manifest.read_text().splitlines()]
    assert 1 <= len(done_before) < 6
    r = run_cli(*args[2:])
    assert r.returncode == 0, r.stderr
    assert f"{6 - len(done_before)} done, 0 failed, {len(done_before)} skipped" in r.stderr
    for i in range(6):
        with np.load(out / "runs" / f"run_{i:05d}.npz") as data:
            assert data["positions"].shape == (601, 24 * 24, 3)
    assert not [p for p in out.rglob("*") if ".tmp" in p.name]


# -- API and Dask --------------------------------------------------------------------------------
def test_sweep_is_the_function_even_after_its_package_loads() -> None:
    import clothsim.sweeps.api  # noqa: F401

    assert "sweep" in clothsim.__all__ and callable(clothsim.sweep)


def test_unreachable_scheduler_writes_nothing(tmp_path: Path, scene_file: Path, monkeypatch) -> None:
    distributed = pytest.importorskip("distributed")

    def refuse(*args, **kwargs):
        raise OSError("Timed out trying to connect to tcp://10.0.0.1:8786 after 20 s")

    monkeypatch.setattr(distributed, "Client", refuse)
    with pytest.raises(ClothsimError, match="--scheduler tcp://10.0.0.1:8786: cannot connect: Timed out"):
        clothsim.sweep(scene_file, {"cloth.ks": [10]}, tmp_path / "d", frames=1, scheduler="tcp://10.0.0.1:8786")
    assert not (tmp_path / "d").exists()


def test_api_and_local_dask_cluster_give_identical_arrays(tmp_path: Path, scene_file: Path) -> None:
    distributed = pytest.importorskip("distributed")
    grid = {"cloth.ks": [2000, 5000], "cloth.damping": "0.1,0.3"}
    local = clothsim.sweep(scene_file, grid, tmp_path / "local", frames=4, every=2, workers=2)
    assert [r["status"] for r in local] == ["done"] * 4
    assert [r["id"] for r in local] == [f"run_{i:05d}" for i in range(4)]
    # The workers are ended once every result is in, and reaped: none is left running.
    assert multiprocessing.active_children() == []
    with distributed.LocalCluster(n_workers=2, threads_per_worker=1, processes=True,
                                  dashboard_address=None) as cluster:
        remote = clothsim.sweep(scene_file, grid, tmp_path / "dask", frames=4, every=2,
                                scheduler=cluster.scheduler_address)
    assert [r["params"] for r in remote] == [r["params"] for r in local]
    for rec in local:
        with np.load(tmp_path / "local" / rec["path"]) as a, np.load(tmp_path / "dask" / rec["path"]) as b:
            assert a.files == b.files
            for key in a.files:
                assert np.array_equal(a[key], b[key]), key


def test_script_without_main_guard_gets_one_clear_error(tmp_path: Path, scene_file: Path) -> None:
    # Workers are spawned and import the caller's script: unguarded, each would start a sweep.
    script = tmp_path / "unguarded.py"
    script.write_text(f"import clothsim\nclothsim.sweep({str(scene_file)!r}, {{'cloth.ks': [1, 2]}}, "
                      f"{str(tmp_path / 'out')!r}, frames=1, workers=1)\n")
    r = subprocess.run([sys.executable, str(script)], capture_output=True, text=True, timeout=300)
    assert r.returncode == 1
    last = r.stderr.strip().splitlines()[-1]
    assert last.startswith("clothsim.errors.ClothsimError: the sweep's worker processes stopped while starting"), last
    assert "unguarded.py must call clothsim.sweep under 'if __name__ == \"__main__\":'" in last
    assert not (tmp_path / "out").exists()


def test_bench_sweep_prints_every_variant(tmp_path: Path, scene_file: Path) -> None:
    r = run_cli("bench", "sweep", str(scene_file), "--runs", "2", "--frames", "3", "--workers", "1")
    assert r.returncode == 0, r.stderr
    rows = {line.split("  ")[0]: line for line in r.stdout.splitlines()}
    for name in ("plain API loop (script), 1 Numba thread", "clothsim sweep --workers 1",
                 "plain loop in this process (kernels loaded), 1 Numba thread"):
        assert name in rows, r.stdout
    assert rows["clothsim sweep --workers 1"].rstrip().endswith("1.00x"), r.stdout  # its own "vs 1 worker"
