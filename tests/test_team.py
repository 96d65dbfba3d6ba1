"""The frame kernel's thread team: same numbers whatever its size, and no hang when its members
cannot run side by side."""

from __future__ import annotations

import time

import numpy as np
import pytest

import clothsim
from clothsim.scene import load_scene
from clothsim.sim import team
from clothsim.sim.frame import run_substeps
from clothsim.sim.profile import Profiler
from clothsim.sim.selfcollide import count_slots, place_slots, query_share, scatter_slots, sort_by_slot
from clothsim.sim.team import share


def _scene(name: str, n: int = 20, **simulation):
    scene = load_scene(name)
    pins = tuple((x * (n - 1) // 49, y * (n - 1) // 49) for x, y in scene.cloth.pinned)
    scene = scene.with_cloth(num_width_points=n, num_height_points=n, pinned=pins)
    return scene.with_simulation(**simulation) if simulation else scene


def _run(scene, frames: int, size: int) -> tuple[np.ndarray, np.ndarray]:
    sim = clothsim.Simulation(scene)
    args = list(sim._substep_args())
    args[-1] = size
    for _ in range(frames):
        run_substeps(scene.simulation.simulation_steps, *args)
    return sim.positions.copy(), sim._sync.copy()


CASES = [("selfCollision", {}), ("sphere", {}), ("pinned2", {"self_collision": "grid"}),
         ("pinned4", {"self_collision": "off", "max_stretch": None})]


@pytest.mark.parametrize(("name", "simulation"), CASES, ids=[c[0] for c in CASES])
def test_team_size_does_not_change_the_numbers(name: str, simulation: dict) -> None:
    scene = _scene(name, **simulation)
    one, _ = _run(scene, 12, 1)
    two, sync = _run(scene, 12, 2)
    assert np.array_equal(one, two)
    # with two or more threads the two members really did work as a team
    if team.team_size() >= 2:
        assert sync[team.MODE] != team.ALONE


@pytest.mark.parametrize(("name", "simulation"), CASES, ids=[c[0] for c in CASES])
def test_fused_frame_matches_pass_by_pass_profile(name: str, simulation: dict) -> None:
    scene = _scene(name, **simulation)
    fused = clothsim.Simulation(scene)
    fused.step(8)
    profiled = clothsim.Simulation(scene)
    profiler = Profiler(profiled)
    for _ in range(8):
        profiler.frame()
    assert np.array_equal(fused.positions, profiled.positions)


def test_more_members_than_threads_falls_back_to_one() -> None:
    # Members that cannot all run at once (here more of them than threads) must not wait for each
    # other forever: the roll call gives up, one member runs the frame alone, same numbers.
    scene = _scene("selfCollision")
    ref, _ = _run(scene, 3, 1)
    t0 = time.perf_counter()
    got, sync = _run(scene, 3, team.team_size() + 1)
    assert time.perf_counter() - t0 < 30.0
    assert sync[team.MODE] == team.ALONE
    assert np.array_equal(ref, got)


def test_simulation_remembers_a_failed_roll_call(monkeypatch: pytest.MonkeyPatch) -> None:
    threads = team.team_size()
    monkeypatch.setattr(team, "team_size", lambda: threads + 1)
    sim = clothsim.Simulation(_scene("pinned4"))
    assert sim._substep_args()[-1] == threads + 1
    sim.step()
    assert sim._sync[team.MODE] == team.ALONE
    assert sim._team_size == 1
    assert sim._substep_args()[-1] == 1
    ref = clothsim.Simulation(_scene("pinned4"))
    ref._team_size = 1
    ref.step(3)
    sim.step(2)
    assert np.array_equal(sim.positions, ref.positions)



@pytest.mark.parametrize("size", [1, 2, 3, 5])
def test_team_counting_sort_matches_the_serial_sort(size: int) -> None:
    # the members' passes run one after another here, each complete before the next reads it
    rng = np.random.default_rng(size)
    n, table = 500, 64
    slots = rng.integers(0, table, n)
    slots[rng.choice(n, 120, replace=False)] = 7  # one crowded slot
    slots[slots == 9] = 10  # an empty one
    keys = slots * 3 + 1
    pos = rng.random((3, n))
    start0 = np.zeros(table + 1, dtype=np.int64)
    order0 = np.zeros(n, dtype=np.int64)
    busy0 = np.zeros(table, dtype=np.int64)
    nb0 = sort_by_slot(slots, start0, order0, busy0)

    hist = np.zeros((size, table), dtype=np.int32)
    cursor = np.zeros_like(hist)
    tally = np.zeros((size, 2), dtype=np.int64)
    start = np.full(table + 1, -1, dtype=np.int64)
    order = np.full(n, -1, dtype=np.int64)
    busy = np.full(table, -1, dtype=np.int64)
    cum = np.zeros(table, dtype=np.int64)
    xs, ys, zs = np.zeros(n), np.zeros(n), np.zeros(n)
    ks = np.zeros(n, dtype=np.int64)
    for m in range(size):
        count_slots(slots, hist[m], *share(n, m, size))
    for m in range(size):
        tally[m] = place_slots(hist, cursor, start, busy, cum, *share(table, m, size))
    for m in range(size):
        scatter_slots(pos, keys, slots, cursor[m], order, xs, ys, zs, ks, *share(n, m, size))

    assert np.array_equal(start, start0)
    assert np.array_equal(order, order0)
    assert np.array_equal(np.stack([xs, ys, zs]), pos[:, order0]) and np.array_equal(ks, keys[order0])
    ranges = [share(table, m, size) for m in range(size)]
    listed = np.concatenate([busy[t0 : t0 + tally[m, 0]] for m, (t0, _) in enumerate(ranges)])
    assert np.array_equal(listed, busy0[:nb0])

    # every busy slot goes to exactly one member, and the shares' estimated costs are even
    counts = np.diff(start0)
    cost = counts * (counts + 32)
    taken = []
    for m in range(size):
        mine = [t0 + i for r, (t0, _) in enumerate(ranges) for i in range(*query_share(cum, tally, table, r, m, size))]
        taken += mine
        share_cost = cost[busy[mine]].sum()
        assert abs(share_cost - cost[busy0[:nb0]].sum() / size) <= cost.max()
    assert sorted(busy[taken].tolist()) == busy0[:nb0].tolist()
