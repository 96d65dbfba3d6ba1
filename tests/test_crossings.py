"""The crossing counter: hand-made cases, the exact predicate, and agreement with brute force."""

from __future__ import annotations

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from clothsim.cloth import cloth_triangles
from clothsim.sim.crossings import (count_crossings, crossing_pairs, grid_triangles, mesh_crossings, mesh_edges,
                                    orient3d_sign, segment_crosses_triangle)
from crossing_support import _exact_sign, brute_force_pairs, exact_brute_force_pairs

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
