"""Part 1 of the spec: the grid of point masses and the three spring families."""

from __future__ import annotations

import dataclasses
import itertools

import numpy as np
import pytest

from clothsim.cloth import (BENDING, SHEARING, STRUCTURAL, all_springs, grid_positions, pinned_mask,
                            spring_blocks, spring_count)
from clothsim.scene import load_scene
from clothsim.sim import Simulation


def brute_force_springs(nw, nh, families):
    """Springs by the spec's words, one point at a time."""
    out = set()
    for y, x in itertools.product(range(nh), range(nw)):
        p = y * nw + x
        cand = []
        if "structural" in families:
            cand += [(x - 1, y), (x, y - 1)]
        if "shearing" in families:
            cand += [(x - 1, y - 1), (x + 1, y - 1)]
        if "bending" in families:
            cand += [(x - 2, y), (x, y - 2)]
        for qx, qy in cand:
            if 0 <= qx < nw and 0 <= qy < nh:
                out.add(frozenset((p, qy * nw + qx)))
    return out


@pytest.mark.parametrize("nw,nh", [(2, 2), (3, 5), (50, 50), (7, 2)])
@pytest.mark.parametrize("flags", list(itertools.product([True, False], repeat=3)))
def test_spring_count_matches_closed_form_and_brute_force(nw, nh, flags):
    scene = load_scene("pinned4")
    cloth = dict(num_width_points=nw, num_height_points=nh, pinned=(),
                 enable_structural=flags[0], enable_shearing=flags[1], enable_bending=flags[2])
    sim = Simulation(scene.with_cloth(**cloth))
    expected = (nw - 1) * nh * flags[0] + nw * (nh - 1) * flags[0] + 2 * (nw - 1) * (nh - 1) * flags[1] \
        + ((nw - 2) * nh + nw * (nh - 2)) * flags[2]
    assert len(sim.springs) == expected == spring_count(nw, nh, *flags)
    fams = {n for n, on in zip(("structural", "shearing", "bending"), flags) if on}
    got = {frozenset((int(a), int(b))) for a, b in zip(sim.springs.i, sim.springs.j)}
    assert got == brute_force_springs(nw, nh, fams)


def test_blocks_describe_the_spring_arrays():
    nw, nh = 6, 5
    cloth = dataclasses.replace(load_scene("pinned4").cloth, num_width_points=nw, num_height_points=nh, pinned=())
    pos = grid_positions(cloth, 0)
    springs = all_springs(nw, nh, pos)
    blocks, families = spring_blocks(nw, nh)
    for (dx, dy, x0, x1, first, rows), fam in zip(blocks, families):
        for r in range(rows):
            for t in range(x1 - x0):
                s = first + r * (x1 - x0) + t
                assert springs.i[s] == r * nw + x0 - dx + t
                assert springs.j[s] == (r + dy) * nw + x0 + t
                assert springs.kind[s] == fam


def test_rest_lengths_and_kinds():
    sim = Simulation(load_scene("pinned4"))
    d = 1.0 / 49
    rest = {STRUCTURAL: d, SHEARING: d * np.sqrt(2), BENDING: 2 * d}
    for kind, length in rest.items():
        assert np.allclose(sim.springs.rest[sim.springs.kind == kind], length)


def test_grid_corners_and_orientation():
    horizontal = load_scene("pinned4").cloth
    pos = grid_positions(horizontal, 0)
    assert np.array_equal(pos[0], [0, 1, 0]) and np.array_equal(pos[-1], [1, 1, 1])
    assert np.all(pos[:, 1] == 1.0)
    vertical = load_scene("selfCollision").cloth
    pos = grid_positions(vertical, 0)
    assert pos[0, :2].tolist() == [0, 0] and pos[-1, :2].tolist() == [1, 1]
    assert np.all(np.abs(pos[:, 2]) <= 1e-3) and np.std(pos[:, 2]) > 1e-4
    # row-major: index = row * nw + col
    assert pos[1, 0] > pos[0, 0] and pos[50, 1] > pos[0, 1]


def test_jitter_is_seeded():
    vertical = load_scene("selfCollision").cloth
    assert np.array_equal(grid_positions(vertical, 3), grid_positions(vertical, 3))
    assert not np.array_equal(grid_positions(vertical, 3), grid_positions(vertical, 4))


def test_pins_are_x_y_index_pairs():
    cloth = load_scene("pinned2").cloth
    mask = pinned_mask(cloth)
    assert mask.sum() == 2
    for x, y in cloth.pinned:
        assert mask[y * cloth.num_width_points + x]


def test_mass_per_point():
    sim = Simulation(load_scene("pinned4"))
    assert sim.mass == pytest.approx(1.0 * 1.0 * 150.0 / 2500)
