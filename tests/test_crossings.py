"""The crossing counter: hand-made cases, the exact predicate, and agreement with brute force."""

from __future__ import annotations

import json
import re
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from clothsim.cloth import cloth_triangles
from clothsim.sim.crossings import (count_crossings, crossing_pairs, grid_triangles, mesh_crossings, mesh_edges,
                                    orient3d_sign, segment_crosses_triangle)
from clothsim.bench.stress import FLOOR, SQUEEZE_SCENES, STRESS_SCENES, TWIST_APPROACH, StressRun, self_collision_modes
from crossing_support import (STRESS_FRAMES, STRESS_TWIST_SECONDS, _exact_sign, brute_force_pairs,
                              exact_brute_force_pairs, stress_record)

#: Self-collision modes that must keep every stress run free of crossings at the end of every
#: frame (asserted). "off" must show crossings (the run does fold through itself). The other modes
#: (the spec's hash, the grid) are known to leak and are measured, not tested: `clothsim bench
#: selfcollision` prints their crossings (docs/self-collision.md).
NO_CROSSING_MODES: list[str] = ["contact"]
#: (mode, scene) pairs of NO_CROSSING_MODES that do not hold yet, with why: left out of the proof
#: and measured by the bench until they hold.
KNOWN_LEAKS: dict[tuple[str, str], str] = {}
STRESS_CASES = [(mode, scene) for mode in ("off", *NO_CROSSING_MODES) for scene in STRESS_SCENES
                if (mode, scene) not in KNOWN_LEAKS and (mode == "off" or scene not in SQUEEZE_SCENES)]

TRI = np.array([[0.0, 0.0, 0.0], [1.0, 0.0, 0.0], [0.0, 1.0, 0.0]])


def _edge_and_triangle(p: list[float], q: list[float]) -> int:
    """Crossings of the single edge pq with the unit triangle."""
    points = np.vstack([TRI, [p, q]])
    return mesh_crossings(points, np.array([[0, 1, 2]]), edges=np.array([[3, 4]]))


def test_an_edge_through_a_triangle_is_one_crossing() -> None:
    assert _edge_and_triangle([0.2, 0.2, -1.0], [0.2, 0.2, 1.0]) == 1


@pytest.mark.parametrize("p, q, why", [
    ([0.2, 0.2, 0.0], [0.2, 0.2, 1.0], "an endpoint on the triangle"),
    ([0.2, 0.2, -1.0], [0.2, 0.2, 0.0], "the other endpoint on the triangle"),
    ([0.5, 0.0, -1.0], [0.5, 0.0, 1.0], "through a side"),
    ([0.0, 0.0, -1.0], [0.0, 0.0, 1.0], "through a corner"),
    ([0.5, 0.5, -1.0], [0.5, 0.5, 1.0], "through the hypotenuse"),
    ([-0.5, 0.2, 0.0], [2.0, 0.2, 0.0], "lying in the plane across it"),
    ([0.8, 0.8, -1.0], [0.8, 0.8, 1.0], "past the hypotenuse"),
    ([0.2, 0.2, 0.5], [0.2, 0.2, 1.0], "above it"),
])
def test_touching_and_missing_are_not_crossings(p: list[float], q: list[float], why: str) -> None:
    assert _edge_and_triangle(p, q) == 0, why


def test_an_edge_through_a_triangle_it_shares_a_point_with_does_not_count() -> None:
    # the triangle (0, 3, 4) shares point 0 with (0, 1, 2): its edge 3-4 pierces (0, 1, 2) and
    # counts; its edges 0-3 and 0-4 end on it and do not
    points = np.vstack([TRI, [[0.2, 0.2, -1.0], [0.2, 0.2, 1.0]]])
    assert mesh_crossings(points, np.array([[0, 1, 2], [0, 3, 4]])) == 1
    # a neighbour folded right through: every edge of each triangle shares a point with the other
    points = np.vstack([TRI, [[0.2, 0.2, -1.0]]])
    assert mesh_crossings(points, np.array([[0, 1, 2], [1, 2, 3]])) == 0


def test_a_flat_and_a_hanging_cloth_have_none() -> None:
    n = 12
    u, v = np.meshgrid(np.linspace(0, 1, n), np.linspace(0, 1, n))
    flat = np.column_stack([u.ravel(), np.ones(n * n), v.ravel()])
    assert count_crossings(flat, n, n) == 0
    wavy = flat.copy()
    wavy[:, 1] += 0.1 * np.sin(7 * u.ravel()) * np.cos(5 * v.ravel())
    assert count_crossings(wavy, n, n) == 0


def folded_cloth(n: int, depth: float) -> np.ndarray:
    """An n x n cloth folded in two along its middle row, the folded half waving 0.05 about a plane
    that reaches ``-depth`` at its far edge: it lies on the bottom half for depth < -0.05 and
    passes through it for |depth| < 0.05."""
    u, v = np.meshgrid(np.linspace(0, 1, n), np.linspace(0, 1, n))
    pts = np.column_stack([u.ravel(), np.zeros(n * n), v.ravel()])
    top = pts[:, 2] > 0.5
    r = pts[top, 2] - 0.5
    pts[top, 2] = 0.5 - r
    pts[top, 1] = r / 0.5 * (-depth + 0.05 * np.sin(9 * pts[top, 0]))
    return pts


def test_a_fold_lying_on_itself_has_none_and_pushed_through_has_some() -> None:
    n = 16
    assert count_crossings(folded_cloth(n, -0.06), n, n) == 0
    through = folded_cloth(n, 0.01)
    count = count_crossings(through, n, n)
    assert count > 0
    assert count == len(brute_force_pairs(through, grid_triangles(n, n)))


def test_the_mesh_is_the_renderers() -> None:
    tris = grid_triangles(4, 3)
    assert np.array_equal(tris.ravel(), cloth_triangles(4, 3).astype(np.int64))
    edges = mesh_edges(tris)
    # rows, columns and one diagonal per quad
    assert len(edges) == 3 * 3 + 4 * 2 + 3 * 2


def test_orientation_is_exact_for_nearly_coplanar_points() -> None:
    rng = np.random.default_rng(3)
    wrong_in_float = 0
    for _ in range(3000):
        a, b, c = rng.uniform(-1, 1, (3, 3)) * 10.0 ** rng.integers(-3, 4)
        s, t = rng.uniform(-1, 2, 2)
        d = a + s * (b - a) + t * (c - a)  # on the plane, up to rounding
        if rng.integers(2):
            d = d + rng.choice([-1, 1]) * np.spacing(d) * rng.integers(0, 3)
        exact = _exact_sign(a, b, c, d)
        assert orient3d_sign(a, b, c, d) == exact
        u, v, w = a - d, b - d, c - d
        wrong_in_float += int(np.sign(np.dot(u, np.cross(v, w)))) != exact
    assert wrong_in_float > 100  # these cases did need the exact path


def test_orientation_of_exactly_coplanar_points_is_zero() -> None:
    a, b, c = np.array([0.1, 1.0, 0.3]), np.array([0.7, 1.0, 0.2]), np.array([0.4, 1.0, 0.9])
    assert orient3d_sign(a, b, c, np.array([0.3, 1.0, 0.31])) == 0
    assert orient3d_sign(a, b, c, np.array([0.3, 1.0 + 2.0 ** -52, 0.31])) == -orient3d_sign(
        a, b, c, np.array([0.3, 1.0 - 2.0 ** -53, 0.31]))
    assert segment_crosses_triangle(np.array([0.4, 1.0 - 2.0 ** -53, 0.4]), np.array([0.4, 1.0 + 2.0 ** -52, 0.4]), a, b, c)


def test_random_meshes_agree_with_brute_force() -> None:
    rng = np.random.default_rng(0)
    for trial in range(20):
        nw, nh = rng.integers(2, 9, 2)
        pts = rng.uniform(0, 1, (nw * nh, 3)) * [1.0, 1.0, rng.uniform(0.05, 1.0)]
        tris = grid_triangles(nw, nh)
        want = brute_force_pairs(pts, tris)
        got = mesh_crossings(pts, tris, pairs=True)
        assert {tuple(r) for r in got.tolist()} == want, trial
        assert mesh_crossings(pts, tris) == len(want)


@settings(max_examples=150, deadline=None)
@given(st.integers(2, 4), st.integers(2, 4), st.data())
def test_integer_lattice_meshes_agree_with_exact_brute_force(nw: int, nh: int, data: st.DataObject) -> None:
    # coordinates from a few integers: ties everywhere (coplanar, through corners and sides), and
    # the int64 brute force is exact
    coords = data.draw(st.lists(st.integers(-2, 2), min_size=3 * nw * nh, max_size=3 * nw * nh))
    ints = np.array(coords, dtype=np.int64).reshape(-1, 3)
    tris = grid_triangles(nw, nh)
    want = brute_force_pairs(ints, tris)
    got = mesh_crossings(ints.astype(np.float64), tris, pairs=True)
    assert {tuple(r) for r in got.tolist()} == want


@settings(max_examples=40, deadline=None)
@given(st.integers(3, 10), st.floats(-0.2, 0.3), st.floats(0, 1e3), st.integers(0, 2 ** 32 - 1))
def test_folded_meshes_agree_with_brute_force(n: int, depth: float, offset: float, seed: int) -> None:
    pts = folded_cloth(n, depth) + offset
    pts += np.random.default_rng(seed).normal(0, 0.02, pts.shape)
    tris = grid_triangles(n, n)
    assert count_crossings(pts, n, n) == len(brute_force_pairs(pts, tris))


def test_a_simulated_heap_agrees_with_brute_force() -> None:
    from clothsim import load_scene
    from clothsim.sim import Simulation

    n = 20
    scene = load_scene("selfCollision").with_cloth(num_width_points=n, num_height_points=n)
    sim = Simulation(scene.with_simulation(self_collision="off"))
    sim.step(70)
    pts = sim.positions.copy()
    want = brute_force_pairs(pts, grid_triangles(n, n))
    assert len(want) > 10  # it did pass through itself
    rows = crossing_pairs(pts, n, n)
    edges = mesh_edges(grid_triangles(n, n))
    assert {(int(np.flatnonzero((edges == r[:2]).all(axis=1))[0]), int(r[2])) for r in rows} == want
    assert count_crossings(pts, n, n) == len(want)


def test_an_exploded_mesh_still_counts() -> None:
    # one point thrown far away: triangles a billion cells long (the hash's cell grows), and
    # determinants that float64 gets wrong (the exact reference is needed here)
    n = 7
    pts = folded_cloth(n, 0.1)
    pts[5] = [1e9, -3e8, 2e9]
    tris = grid_triangles(n, n)
    got = {tuple(r) for r in mesh_crossings(pts, tris, pairs=True).tolist()}
    assert got == exact_brute_force_pairs(pts, tris)
    assert got != brute_force_pairs(pts, tris)


@pytest.mark.parametrize("positions, message", [
    (np.zeros((8, 3)), r"positions: expected shape \(9, 3\)"),
    (np.full((9, 3), np.nan), "positions: not every coordinate is finite"),
])
def test_bad_positions_are_named(positions: np.ndarray, message: str) -> None:
    with pytest.raises(ValueError, match=message):
        count_crossings(positions, 3, 3)


# ----------------------------------------------------------------------------------------------
# The stress set, proved (or recorded) frame by frame


@pytest.mark.parametrize("mode, scene", STRESS_CASES)
def test_stress_crossings_frame_by_frame(mode: str, scene: str, record_property) -> None:  # noqa: ANN001
    rec = stress_record(scene, mode)
    record_property("crossings", rec.counts)
    record_property("blew_up", rec.blew_up)
    assert rec.blew_up is None, rec.summary()
    if mode == "off":
        # without self-collision the cloth does pass through itself: the run is a real stress
        assert max(rec.counts) > 0, rec.summary()
    else:
        assert len(rec.counts) == STRESS_FRAMES and not any(rec.counts), rec.summary()


@pytest.mark.parametrize("integrator", ["verlet", "symplectic_euler"])
def test_a_squeeze_keeps_the_cloth_between_the_colliders_and_counts_what_it_lets_through(integrator: str) -> None:
    # The squeeze's plane comes down to 5 mm over the floor on a heap of layers that each keep the
    # contact distance (16 mm at 30 x 30): the colliders keep every point between them (before, the
    # bound pulled points back to references the plane had passed, and 414 of 900 points ended on
    # top of it), and the cloth crosses itself only in substeps that are counted, none before.
    from crossing_support import STRESS_DRIVEN_GRID

    from clothsim.sim import Simulation

    run = StressRun("squeeze", "contact", STRESS_DRIVEN_GRID)
    if integrator != "verlet":
        # (the integrators other than the spec's Verlet run the corrections outside the thread team)
        run.sim = Simulation(run.sim.scene.with_simulation(integrator=integrator))
    lid = run.sim.scene.planes[1].motion.keyframes
    times = [t for t, _ in lid]
    heights = [p[1] for _, p in lid]
    first_squeeze = None
    for f in range(1, STRESS_FRAMES + 1):
        run.frame()
        y = run.sim.positions[:, 1]
        top = float(np.interp(run.sim.time, times, heights))
        assert y.max() <= top + 1e-9, f"frame {f}: {int((y > top).sum())} points over the plane at {top - FLOOR:.4f} m"
        assert y.min() >= FLOOR - 1e-9, f"frame {f}: a point under the floor"
        crossings = run.crossings()
        if run.sim.squeezed_substeps == 0:
            assert crossings == 0, f"frame {f}: {crossings} crossings and no substep counted"
        elif first_squeeze is None:
            first_squeeze = f
    assert first_squeeze is not None and top - FLOOR < 0.006, "the plane never squeezed the heap"
    assert run.sim.unsafe_substeps == 0


def test_simulate_says_when_colliders_squeezed_the_cloth(tmp_path: Path) -> None:
    from clothsim.bench.stress import driven_scene_data
    from conftest import run_cli

    scene = dict(driven_scene_data("squeeze", 16), simulation={"self_collision": "contact"})
    path = tmp_path / "squeeze.json"
    path.write_text(json.dumps(scene))
    done = run_cli("simulate", str(path), "--frames", "120", "--out", str(tmp_path / "out.npz"))
    assert done.returncode == 0, done.stderr
    warned = [line for line in done.stderr.splitlines() if "warning" in line]
    assert len(warned) == 1 and "a moving collider pressed the cloth thinner than the bound allows" in warned[0], \
        done.stderr
    assert re.search(r"in \d+ substeps", warned[0]) and (tmp_path / "out.npz").exists()


def test_the_modes_are_the_validators() -> None:
    from clothsim.scene import SELF_COLLISION_MODES

    assert set(SELF_COLLISION_MODES) <= set(self_collision_modes())
    assert {"off", "spec", "grid"} <= set(self_collision_modes())
    assert set(NO_CROSSING_MODES) <= set(self_collision_modes())


def test_the_twist_turns_each_edge_a_full_turn() -> None:
    from clothsim.bench.stress import TWIST_START, StressRun, twist_pose

    run = StressRun("twist", "off", 8, twist_seconds=STRESS_TWIST_SECONDS)
    pins = np.flatnonzero(run.sim.pinned)
    rest = run.sim.positions[pins].copy()
    top = rest[:, 1] > 0.5
    ends = [np.flatnonzero(top)[[0, -1]], np.flatnonzero(~top)[[0, -1]]]
    times = np.linspace(0.0, TWIST_START + STRESS_TWIST_SECONDS + 0.1, 2001)
    for edge, sign in zip(ends, (1.0, -1.0)):
        d = np.array([np.subtract(*twist_pose(rest, top, t, STRESS_TWIST_SECONDS)[edge[::-1]]) for t in times])
        turned = np.sum(np.angle(np.exp(1j * np.diff(np.arctan2(d[:, 2], d[:, 0])))))
        assert turned == pytest.approx(sign * 2 * np.pi, abs=1e-9)
    last = twist_pose(rest, top, times[-1], STRESS_TWIST_SECONDS)
    assert last[:, [0, 2]] == pytest.approx(rest[:, [0, 2]], abs=1e-12)
    assert last[:, 1] == pytest.approx(rest[:, 1] + np.where(top, -TWIST_APPROACH, TWIST_APPROACH))
    # the run holds its pins where the pose puts them at the start of each substep
    for _ in range(20):
        run.frame()
    t = run.sim.time - run.sim.dt
    assert run.sim.positions[pins] == pytest.approx(twist_pose(rest, top, t, STRESS_TWIST_SECONDS), abs=1e-12)
    assert run.frames == 20


# ----------------------------------------------------------------------------------------------
# The command


def _cli(*args: str, cwd: Path) -> subprocess.CompletedProcess:
    return subprocess.run([sys.executable, "-m", "clothsim", *args], cwd=cwd, capture_output=True, text=True,
                          timeout=300)


def test_check_intersections_of_a_simulate_output(tmp_path: Path) -> None:
    done = _cli("simulate", "selfCollision", "--frames", "40", "--self-collision", "off", "-o", "run.npz",
                cwd=tmp_path)
    assert done.returncode == 0, done.stderr
    with np.load(tmp_path / "run.npz") as data:
        want = count_crossings(data["positions"], 50, 50)
    assert want > 0
    out = _cli("check-intersections", "run.npz", cwd=tmp_path)
    assert out.returncode == 0, out.stderr
    lines = out.stdout.splitlines()
    assert lines[0] == "run.npz: 2500 points, 4802 triangles, 7301 edges, 1 frame"
    assert lines[2].split() == ["40", str(want)]
    assert lines[3].startswith(f"max {want} (frame 40), final {want}")
    strict = _cli("check-intersections", "run.npz", "--fail-on-crossings", cwd=tmp_path)
    assert strict.returncode == 1 and strict.stdout == out.stdout


def test_check_intersections_of_a_sweep_run_counts_every_frame(tmp_path: Path) -> None:
    # the arrays a sweep dataset's runs/<id>.npz holds (clothsim.sweeps.api): float32 positions
    n = 10
    frames = [folded_cloth(n, d) for d in (-0.06, 0.01, 0.02)]
    np.savez(tmp_path / "run_00000.npz", positions=np.array(frames, dtype=np.float32),
             faces=cloth_triangles(n, n).astype(np.int32).reshape(-1, 3), frames=np.array([0, 5, 10]),
             uv=np.zeros((n * n, 2), np.float32), pinned=np.zeros(n * n, bool), scene=np.array("{}"))
    out = _cli("check-intersections", "run_00000.npz", cwd=tmp_path)
    assert out.returncode == 0, out.stderr
    rows = [line.split() for line in out.stdout.splitlines()[2:5]]
    want = [count_crossings(f.astype(np.float32).astype(np.float64), n, n) for f in frames]
    assert rows == [[str(f), str(c)] for f, c in zip((0, 5, 10), want)]
    assert want[0] == 0 and want[1] > 0


@pytest.mark.parametrize("arrays, message", [
    ({"last_positions": np.zeros((4, 3))}, "bad.npz: positions: missing"),
    ({"positions": np.zeros((4, 2))}, r"bad.npz: positions: expected floats of shape \(N, 3\) or \(T, N, 3\)"),
    ({"positions": np.zeros((9, 3), np.int64)}, "bad.npz: positions: expected floats"),
    ({"positions": np.zeros((9, 3))}, "bad.npz: faces: missing, and no num_width_points"),
    ({"positions": np.zeros((9, 3)), "num_width_points": np.int64(3), "num_height_points": np.int64(4)},
     r"bad.npz: positions: 9 points, but num_width_points x num_height_points is 3 x 4 = 12"),
    ({"positions": np.zeros((9, 3)), "num_width_points": np.float64(3), "num_height_points": np.int64(3)},
     "bad.npz: num_width_points: expected an integer >= 2"),
    ({"positions": np.zeros((9, 3)), "faces": np.array([[0, 1, 9]])}, r"bad.npz: faces: point indices must be in 0..8"),
    ({"positions": np.zeros((9, 3)), "faces": np.zeros((2, 4), int)}, r"bad.npz: faces: expected integers of shape"),
    ({"positions": np.full((2, 9, 3), np.nan), "faces": np.array([[0, 1, 2]]), "frames": np.array([3, 6])},
     r"bad.npz: positions: not every coordinate is finite \(frame 3\)"),
    ({"positions": np.zeros((2, 9, 3)), "faces": np.array([[0, 1, 2]]), "frames": np.array([3])},
     r"bad.npz: frames: expected 2 integer frame numbers"),
])
def test_check_intersections_names_the_bad_field(tmp_path: Path, arrays: dict, message: str) -> None:
    np.savez(tmp_path / "bad.npz", **arrays)
    out = _cli("check-intersections", "bad.npz", cwd=tmp_path)
    assert out.returncode == 2 and out.stdout == ""
    assert len(out.stderr.splitlines()) == 1 and re.search("^clothsim: error: " + message, out.stderr), out.stderr


@pytest.mark.parametrize("make, message", [
    (lambda p: None, "nope.npz: no such file"),
    (lambda p: p.write_text("hello"), "nope.npz: not a NumPy .npz file"),
    (lambda p: p.mkdir(), "nope.npz: is a folder"),
])
def test_check_intersections_of_no_npz(tmp_path: Path, make, message: str) -> None:  # noqa: ANN001
    make(tmp_path / "nope.npz")
    out = _cli("check-intersections", "nope.npz", cwd=tmp_path)
    assert out.returncode == 2 and out.stderr.startswith(f"clothsim: error: {message}")
    assert len(out.stderr.splitlines()) == 1


def test_the_api_names() -> None:
    import clothsim
    from clothsim.sim import Simulation

    assert "count_crossings" in clothsim.__all__ and clothsim.count_crossings is count_crossings
    sim = Simulation(clothsim.load_scene("selfCollision").with_simulation(self_collision="off"))
    assert sim.crossings() == 0
    sim.step(40)
    assert sim.crossings() == count_crossings(sim.positions, 50, 50) > 0


def test_bench_selfcollision_prints_a_row_per_scene_and_mode(tmp_path: Path) -> None:
    from clothsim.bench.selfcollision import measure

    out = _cli("bench", "selfcollision", "--grid", "10", "--frames", "40", "--every", "20", "--scenes", "selfCollision",
               "twist", "--modes", "off", "spec", cwd=tmp_path)
    assert out.returncode == 0, out.stderr
    rows = [line.split() for line in out.stdout.splitlines()[1:5]]
    assert [r[:2] for r in rows] == [["selfCollision", "off"], ["selfCollision", "spec"], ["twist", "off"],
                                     ["twist", "spec"]]
    want = measure("selfCollision", "off", 40, 20, 10)
    assert [int(x) for x in rows[0][3:6]] == [want.worst[1], want.worst[0], want.samples[-1][1]]
    assert [f for f, _ in want.samples] == [20, 40] and len(want.ms) == 40
    assert rows[0][6:8] == ["-", "-"]
    bad = _cli("bench", "selfcollision", "--modes", "nosuch", cwd=tmp_path)
    assert bad.returncode == 2 and bad.stderr.startswith("clothsim: error: --modes: unknown self-collision mode 'nosuch'")


def test_bench_selfcollision_gives_the_contact_modes_rebuilds_and_their_cost() -> None:
    # timed frames give the same numbers as plain ones; the rebuilds are the group's counter
    from clothsim.bench.selfcollision import measure
    from clothsim.bench.stress import StressRun
    from clothsim.sim.passes.contactgroup import REBUILDS

    got = measure("selfCollision", "contact", 30, 30, 12)
    plain = StressRun("selfCollision", "contact", 12)
    for _ in range(30):
        plain.frame()
    assert got.samples == [(30, plain.crossings())]
    assert got.rebuilds == plain.sim._kernel_args.contact.meta[REBUILDS] > 0
    assert got.search_ms is not None and 0.0 < got.search_ms < sum(got.ms)
    twist = measure("twist", "contact", 2, 2, 8)
    assert twist.rebuilds > 0 and twist.search_ms is None
