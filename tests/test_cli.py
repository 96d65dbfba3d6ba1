"""The command line through a real subprocess: output files, and one-line errors for bad input."""

from __future__ import annotations

import json

import numpy as np
import pytest

from conftest import SCENES, run_cli

GOOD = json.loads((SCENES / "sphere.json").read_text())


def test_simulate_writes_the_state(tmp_path):
    out = tmp_path / "state.npz"
    r = run_cli("simulate", str(SCENES / "pinned4.json"), "--frames", "5", "--out", str(out))
    assert r.returncode == 0, r.stderr
    with np.load(out) as z:
        assert z["positions"].shape == (2500, 3) and z["positions"].dtype == np.float64
        assert z["last_positions"].shape == (2500, 3)
        assert z["pinned"].sum() == 4
        assert (int(z["frames"]), int(z["simulation_steps"]), int(z["seed"])) == (5, 30, 0)
    assert list(tmp_path.iterdir()) == [out]  # no temporary left beside it


def test_simulate_is_reproducible_through_the_cli(tmp_path):
    outs = [tmp_path / "a.npz", tmp_path / "b.npz"]
    for out in outs:
        assert run_cli("simulate", "selfCollision", "--frames", "10", "--out", str(out)).returncode == 0
    with np.load(outs[0]) as a, np.load(outs[1]) as b:
        assert a["positions"].tobytes() == b["positions"].tobytes()


def test_help_speaks_the_course_language():
    r = run_cli("simulate", "--help")
    assert r.returncode == 0
    for word in ("--frames", "simulation_steps", "scene"):
        assert word in r.stdout


def test_unknown_key_is_a_one_line_warning(tmp_path):
    scene = dict(GOOD, cloth=dict(GOOD["cloth"], color=[1, 0, 0]))
    path = tmp_path / "extra.json"
    path.write_text(json.dumps(scene))
    r = run_cli("simulate", str(path), "--frames", "1", "--out", str(tmp_path / "s.npz"))
    assert r.returncode == 0
    assert "cloth.color" in r.stderr and "Traceback" not in r.stderr


def cloth(**changes):
    c = dict(GOOD["cloth"])
    for k, v in changes.items():
        if v is ...:
            c.pop(k)
        else:
            c[k] = v
    return dict(GOOD, cloth=c)


BAD = {
    "missing_field": (cloth(ks=...), "cloth.ks"),
    "missing_cloth": ({"sphere": GOOD["sphere"]}, "cloth"),
    "wrong_type": (cloth(num_width_points="fifty"), "cloth.num_width_points"),
    "bool_as_number": (cloth(density=True), "cloth.density"),
    "fractional_count": (cloth(num_height_points=10.5), "cloth.num_height_points"),
    "nan": ('{"cloth": ' + json.dumps(GOOD["cloth"])[:-1] + ', "damping": NaN}}', "cloth.damping"),
    "inf": ('{"cloth": ' + json.dumps(GOOD["cloth"])[:-1] + ', "ks": Infinity}}', "cloth.ks"),
    "count_below_two": (cloth(num_width_points=1), "cloth.num_width_points"),
    "zero_width": (cloth(width=0), "cloth.width"),
    "negative_height": (cloth(height=-1), "cloth.height"),
    "zero_thickness": (cloth(thickness=0.0), "cloth.thickness"),
    "negative_density": (cloth(density=-150), "cloth.density"),
    "zero_radius": (dict(GOOD, sphere=dict(GOOD["sphere"], radius=0)), "sphere.radius"),
    "pin_out_of_range": (cloth(pinned=[[0, 0], [50, 3]]), "cloth.pinned[1][0]"),
    "pin_not_pair": (cloth(pinned=[[0, 0, 0]]), "cloth.pinned[0]"),
    "zero_normal": ({"cloth": GOOD["cloth"], "plane": {"point": [0, 0, 0], "normal": [0, 0, 0], "friction": 0.5}},
                    "plane.normal"),
    "short_vector": (dict(GOOD, sphere=dict(GOOD["sphere"], origin=[0.5, 0])), "sphere.origin"),
    "unknown_orientation": (cloth(orientation=2), "cloth.orientation"),
    "unknown_orientation_name": (cloth(orientation="diagonal"), "cloth.orientation"),
    "truncated_json": (json.dumps(GOOD)[:40], "not valid JSON"),
    "empty_file": ("", "empty"),
    "top_level_list": ([1, 2], "top level"),
    "unknown_top_level": (dict(GOOD, breeze={"speed": 1}), "breeze"),
    "bad_wind": (dict(GOOD, wind={"velocity": [0, 0, "x"]}), "wind.velocity[2]"),
    "bad_pin_motion": (cloth(pin_motion={"keyframes": [[1, [0, 0, 0]], [0.5, [0, 1, 0]]]}), "cloth.pin_motion.keyframes[1][0]"),
    "friction_above_one": (dict(GOOD, sphere=dict(GOOD["sphere"], friction=1.5)), "sphere.friction"),
    "bad_steps": (dict(GOOD, simulation={"simulation_steps": 0}), "simulation.simulation_steps"),
    "bad_self_collision": (dict(GOOD, simulation={"self_collision": "maybe"}), "simulation.self_collision"),
    "sphere_list_item": (dict(GOOD, sphere=[GOOD["sphere"], {"origin": [0, 0, 0], "radius": 1}]),
                         "sphere[1].friction"),
    "grid_too_large": (cloth(num_width_points=1_000_000, num_height_points=1_000_000), "cloth.num_width_points"),
}


@pytest.mark.parametrize("case", sorted(BAD))
def test_bad_scene_gives_one_line_exit_2_and_no_file(tmp_path, case):
    content, field = BAD[case]
    path = tmp_path / "bad.json"
    path.write_text(content if isinstance(content, str) else json.dumps(content))
    out = tmp_path / "out.npz"
    r = run_cli("simulate", str(path), "--frames", "1", "--out", str(out))
    assert r.returncode == 2, r.stderr
    lines = r.stderr.strip().splitlines()
    assert len(lines) == 1, r.stderr
    assert "Traceback" not in r.stderr
    assert str(path) in lines[0] and field in lines[0], lines[0]
    if case == "grid_too_large":
        assert "would need" in lines[0] and "TiB" in lines[0]
    assert not out.exists()
    assert list(tmp_path.iterdir()) == [path]


def test_missing_scene_file(tmp_path):
    r = run_cli("simulate", str(tmp_path / "nope.json"), "--out", str(tmp_path / "o.npz"))
    assert r.returncode == 2 and "no such scene file" in r.stderr and "Traceback" not in r.stderr


def test_bad_option_value(tmp_path):
    r = run_cli("simulate", "sphere", "--frames", "2", "--out", str(tmp_path / "o.txt"))
    assert r.returncode == 2 and "--out" in r.stderr


def test_simulation_commands_do_not_load_egl(tmp_path):
    # `simulate` must never create a GL context: libEGL stays out of the process.
    code = ("import sys, clothsim.cli as c; rc = c.main(['simulate', 'pinned4', '--frames', '1', '--out', "
            f"{str(tmp_path / 's.npz')!r}]); maps = open('/proc/self/maps').read(); "
            "sys.exit(3 if 'libEGL' in maps or 'moderngl' in sys.modules else rc)")
    import subprocess
    import sys

    r = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True)
    assert r.returncode == 0, r.stderr


def test_python_dash_m_and_version():
    r = run_cli("--version")
    assert r.returncode == 0 and "clothsim" in r.stdout


def test_until_rest_stops_and_reports_the_frame(tmp_path):
    out = tmp_path / "rest.npz"
    r = run_cli("simulate", "pinned4", "--frames", "900", "--until-rest", "--out", str(out))
    assert r.returncode == 0, r.stderr
    assert "at rest after frame" in r.stdout
    with np.load(out) as z:
        frames = int(z["frames"])
    assert 30 < frames < 900
    assert f"frame {frames}" in r.stdout


def test_profile_lists_passes_and_what_was_skipped(tmp_path):
    r = run_cli("simulate", "pinned4", "--frames", "3", "--profile", "--self-collision", "off",
                "--out", str(tmp_path / "p.npz"))
    assert r.returncode == 0, r.stderr
    for name in ("forces", "integrate", "provot"):
        assert name in r.stdout
    assert "self-collision: simulation.self_collision is false" in r.stdout
    assert "colliders: scene has no sphere, plane, capsule, box or mesh" in r.stdout
    r = run_cli("simulate", "sphere", "--frames", "20", "--profile", "--out", str(tmp_path / "s.npz"))
    assert r.returncode == 0, r.stderr
    assert "colliders" in r.stdout and "self-collision" in r.stdout and "bounding-box" in r.stdout


def test_bench_passes_times_each_pass_member_by_member(tmp_path):
    r = run_cli("bench", "passes", "pinned4", "--frames", "2", "--warmup", "1", "--self-collision", "off")
    assert r.returncode == 0, r.stderr
    assert "waiting" in r.stdout and "gather and Verlet" in r.stdout and "Provot: bands" in r.stdout
    assert "hash: query" not in r.stdout  # no self-collision: no such pass
    r = run_cli("bench", "passes", "pinned4", "--frames", "0")
    assert r.returncode == 2 and "--frames" in r.stderr and "Traceback" not in r.stderr
    assert len(r.stderr.strip().splitlines()) == 1
    other = tmp_path / "xpbd.json"
    other.write_text(json.dumps({**GOOD, "simulation": {"integrator": "xpbd"}}))
    r = run_cli("bench", "passes", str(other), "--frames", "1", "--warmup", "0")
    assert r.returncode == 0, r.stderr
    assert "does not run the frame kernel" in r.stdout


@pytest.mark.parametrize("profile", [[], ["--profile"]], ids=["plain", "profiled"])
def test_a_blow_up_stops_the_run_with_or_without_profile(tmp_path, profile):
    # ks 1e7 at one substep a frame is far past the explicit step bound: the guard must end the run
    # with its one-line error and write nothing, whether the frame runs fused or pass by pass.
    scene = tmp_path / "stiff.json"
    scene.write_text(json.dumps({"cloth": dict(GOOD["cloth"], ks=1e7, density=15, orientation=1, pinned=[[0, 0]],
                                                   num_width_points=20, num_height_points=20),
                                 "simulation": {"simulation_steps": 1}}))
    out = tmp_path / "s.npz"
    r = run_cli("simulate", str(scene), "--frames", "200", *profile, "--out", str(out))
    assert r.returncode == 2, r.stderr
    assert "Traceback" not in r.stderr
    errors = [line for line in r.stderr.splitlines() if line.startswith("clothsim: error:")]
    assert len(errors) == 1 and "blew up" in errors[0], r.stderr
    assert not out.exists() and sorted(p.name for p in tmp_path.iterdir()) == ["stiff.json"]


def test_render_of_a_rested_cloth_reuses_its_image(tmp_path):
    out = tmp_path / "rest.gif"
    r = run_cli("render", "pinned4", "--frames", "600", "--every", "30", "--size", "64x64", "--profile",
                "-o", str(out))
    assert r.returncode == 0, r.stderr
    assert "at rest after frame" in r.stderr
    reused = [line for line in r.stdout.splitlines() if line.startswith("reused")]
    assert reused and int(reused[0].split()[1]) > 0
    assert out.exists()


@pytest.mark.parametrize("bench", [
    ["bench", "stability", "--quick", "--integrators", "verlet"],
    ["bench", "accuracy", "--quick", "--integrators", "verlet", "--max-substeps", "4", "--reference-substeps", "16",
     "--no-spec-model"],
])
def test_analysis_benchmarks_do_not_load_egl(tmp_path, bench):
    import subprocess
    import sys

    args = [*bench, "--png", str(tmp_path / "plot.png"), "--json", str(tmp_path / "out.json")]
    code = (f"import sys, clothsim.cli as c; rc = c.main({args!r}); maps = open('/proc/self/maps').read(); "
            "sys.exit(3 if 'libEGL' in maps or 'moderngl' in sys.modules else rc)")
    r = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=300)
    assert r.returncode == 0, r.stdout + r.stderr
    assert (tmp_path / "plot.png").exists() and (tmp_path / "out.json").exists()


def test_building_the_parser_does_not_load_numba():
    # Every command pays the parser: --help, --version, a usage error and a sweep's parent answer
    # without the third of a second Numba's import costs.
    import subprocess
    import sys

    code = ("import sys, clothsim.cli as c; c.build_parser(); "
            "sys.exit(3 if 'numba' in sys.modules or 'clothsim.sim' in sys.modules else 0)")
    r = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=120)
    assert r.returncode == 0, r.stdout + r.stderr
