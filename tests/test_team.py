"""The frame kernel's thread team: same numbers whatever its size, no hang when its members
cannot run side by side or one of them never comes, and recovery afterwards."""

from __future__ import annotations

import sys
import time

import numba
import numpy as np
import pytest

import clothsim
from clothsim.scene import load_scene
from clothsim.sim import team
from clothsim.sim.solvers import frame
from clothsim.sim.solvers.frame import PASS_ALL
from clothsim.jit import CHUNKS
from clothsim.sim.profile import FrameLaps, Profiler
from clothsim.sim.passes.selfcollide import count_slots, place_slots, query_share, scatter_slots, sort_by_slot
from clothsim.sim.team import share


def _scene(name: str, n: int = 20, **simulation):
    scene = load_scene(name)
    pins = tuple((x * (n - 1) // 49, y * (n - 1) // 49) for x, y in scene.cloth.pinned)
    scene = scene.with_cloth(num_width_points=n, num_height_points=n, pinned=pins)
    return scene.with_simulation(**simulation) if simulation else scene


def _run(scene, frames: int, size: int) -> tuple[np.ndarray, list[int]]:
    """Positions after ``frames`` kernel calls with a team of ``size``, and each call's MODE."""
    sim = clothsim.Simulation(scene)
    modes = []
    for _ in range(frames):
        assert sim.run_kernel(scene.simulation.simulation_steps, PASS_ALL, size)
        modes.append(int(sim._sync[team.MODE]))
    return sim.positions.copy(), modes


CASES = [("selfCollision", {}), ("sphere", {}), ("pinned2", {"self_collision": "grid"}),
         ("pinned4", {"self_collision": "off", "max_stretch": None}), ("heap", {"self_collision": "contact"})]

needs_two_threads = pytest.mark.skipif(numba.config.NUMBA_NUM_THREADS < 2,
                                       reason="Numba has one thread here: a team of two would be one member alone")


@needs_two_threads
@pytest.mark.parametrize(("name", "simulation"), CASES, ids=[f"{c[0]}-{c[1].get('self_collision', 'own')}" for c in CASES])
def test_team_size_does_not_change_the_numbers(name: str, simulation: dict, all_threads: int) -> None:
    scene = _scene(name, **simulation)
    one, _ = _run(scene, 12, 1)
    two, modes = _run(scene, 12, 2)
    assert np.array_equal(one, two)
    # the two members really did work as a team (a frame's roll call may fail on a loaded machine)
    assert modes.count(team._TEAM) >= 6


@pytest.mark.parametrize(("name", "simulation"), CASES, ids=[f"{c[0]}-{c[1].get('self_collision', 'own')}" for c in CASES])
def test_fused_frame_matches_pass_by_pass_profile(name: str, simulation: dict) -> None:
    scene = _scene(name, **simulation)
    fused = clothsim.Simulation(scene)
    fused.step(8)
    profiled = clothsim.Simulation(scene)
    profiler = Profiler(profiled)
    for _ in range(8):
        profiler.frame()
    assert np.array_equal(fused.positions, profiled.positions)


TIMED = [("selfCollision", {}, ("springs and forces", "gather and Verlet", "hash: query", "colliders", "Provot: bands")),
         ("pinned2", {"self_collision": "contact"}, ("contact: stale?", "contact: join, moves, response",
                                                     "contact: bound")),
         ("pinned4", {"self_collision": "off", "max_stretch": None}, ("gather and Verlet",))]
ABSENT = {"selfCollision": ("contact: bound", "grid self-collision"), "pinned2": ("hash: query", "colliders"),
          "pinned4": ("hash: query", "colliders", "Provot: bands")}


@pytest.mark.parametrize(("name", "simulation", "present"), TIMED, ids=[c[0] for c in TIMED])
def test_timed_frames_give_the_same_numbers_and_time_each_pass_the_scene_runs(name: str, simulation: dict,
                                                                             present: tuple, all_threads: int) -> None:
    scene = _scene(name, **simulation)
    plain = clothsim.Simulation(scene)
    plain.step(6)
    timed = clothsim.Simulation(scene)
    laps = FrameLaps(timed)
    began = time.perf_counter()
    for _ in range(6):
        laps.frame()
    took = time.perf_counter() - began
    assert np.array_equal(plain.positions, timed.positions)
    assert laps.frames == 6 and laps.substeps == 6 * scene.simulation.simulation_steps
    # the laps follow each other inside the calls; the members wait no longer than they are there
    spent = laps.ns[:, 0].sum() * 1e-9
    assert 0 < spent <= took
    assert (laps.ns[:, 1] <= laps.members * laps.ns[:, 0]).all()
    report = laps.report()
    for lap in present:
        assert lap in report
        assert laps.ns[frame.LAP_NAMES.index(lap), 0] > 0
    for lap in ABSENT[name]:
        assert lap not in report and not laps.ns[frame.LAP_NAMES.index(lap)].any()


def test_laps_fit_the_teams_counters() -> None:
    assert len(frame.LAP_NAMES) <= team.MOST_LAPS
    assert team.SYNC_SIZE == team.LAPS + 2 * team.MOST_LAPS


def test_only_the_spec_verlet_is_timed_inside_its_frame() -> None:
    with pytest.raises(ValueError, match="verlet"):
        FrameLaps(clothsim.Simulation(_scene("pinned4", integrator="xpbd")))


def test_more_members_than_threads_falls_back_to_one() -> None:
    # Members that cannot all run at once (here more of them than threads) must not wait for each
    # other forever: the roll call gives up after 10 ms, one member runs the frame alone.
    scene = _scene("selfCollision")
    ref, _ = _run(scene, 3, 1)
    t0 = time.perf_counter()
    got, modes = _run(scene, 3, numba.get_num_threads() + 1)
    assert time.perf_counter() - t0 < 30.0
    assert modes == [team.ALONE] * 3
    assert np.array_equal(ref, got)


def test_a_member_that_never_comes_ends_the_wait_in_bounded_time() -> None:
    # Member 0 of a team of two, run without member 1 after a roll call that (as if) succeeded:
    # it must give up at its first barrier after BARRIER_NS, raise ABORT and return.
    sim = clothsim.Simulation(_scene("pinned2"))
    sim.step(1)  # compiled before the clock starts
    # the kernel's state groups (the collider kinds' go by address: none here)
    groups = sim.plan._replace(colliders=0)
    sync = team.new_sync()
    sync[team.MODE] = team._TEAM
    t0 = time.perf_counter()
    frame._member(0, 2, 3, *groups, sync, PASS_ALL)
    waited = time.perf_counter() - t0
    assert sync[team.ABORT] == 1
    assert team.BARRIER_NS / 1e9 <= waited < team.BARRIER_NS / 1e9 + 20.0


def test_a_frame_given_up_half_way_is_restored_and_run_alone(monkeypatch: pytest.MonkeyPatch) -> None:
    # A team call that aborts half-way (member 1 never comes) leaves the state half-updated; the
    # simulation must restore the frame's start, run it alone, and try the team again later.
    real = frame.run_substeps

    def lost_member(steps, plan, sync, size, passes, *addresses):  # noqa: ANN001, ANN202
        if size == 1:
            return real(steps, plan, sync, size, passes, *addresses)
        sync[:] = 0
        sync[team.MODE] = team._TEAM
        frame._member(0, size, steps, *plan._replace(colliders=0), sync, passes)  # (no colliders)
        return 0

    scene = _scene("pinned4")
    ref = clothsim.Simulation(scene)
    ref.step(3)
    monkeypatch.setattr(team, "team_size", lambda: 2)
    import clothsim.sim.simulation as simulation_module

    monkeypatch.setattr(simulation_module, "run_substeps", lost_member)
    sim = clothsim.Simulation(scene)
    sim.step(3)
    assert sim.team.aborted_frames == 1
    assert sim.team.alone_for == team.FIRST_BACKOFF - 2
    assert np.array_equal(sim.positions, ref.positions)


def test_simulation_recovers_after_a_failed_roll_call(monkeypatch: pytest.MonkeyPatch) -> None:
    threads = numba.get_num_threads()
    monkeypatch.setattr(team, "team_size", lambda: threads + 1)
    sim = clothsim.Simulation(_scene("pinned4"))
    assert sim.team.size() == threads + 1
    sim.team.after(np.array([0] * team.MODE + [team.ALONE] + [0] * (team.SYNC_SIZE - team.MODE - 1)), threads + 1)
    # after a failed roll call: FIRST_BACKOFF frames alone, then the team again; failures in a
    # row double the wait, a frame the team ran resets it
    assert [sim.team.size() for _ in range(team.FIRST_BACKOFF + 1)] == [1] * team.FIRST_BACKOFF + [threads + 1]
    sim.step()
    assert sim._sync[team.MODE] == team.ALONE
    assert sim.team.backoff == 2 * team.FIRST_BACKOFF
    ref = clothsim.Simulation(_scene("pinned4"))
    ref.step(3)
    sim.step(2)
    assert np.array_equal(sim.positions, ref.positions)
    ok = team.new_sync()
    sim.team.alone_for = 0
    sim.team.after(ok, 2)
    assert sim.team.backoff == 0


def test_team_is_capped_at_the_useful_size(monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.setattr(numba, "get_num_threads", lambda: 64)
    assert team.team_size() == min(CHUNKS, team.available_cores())
    monkeypatch.setattr(team, "available_cores", lambda: 3)
    assert team.team_size() == 3
    monkeypatch.setattr(numba, "get_num_threads", lambda: 1)
    assert team.team_size() == 1


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


def test_groups_handed_by_address_reach_every_thread_of_a_parallel_loop_whole(all_threads: int) -> None:
    # The collider pass hands a parallel loop's threads its tuple of groups by address (a
    # parallel loop takes no tuple of groups); every thread must see the same groups, arrays
    # shared, not copied, and a write through them must survive Numba's dead-code pass.
    from collections import namedtuple

    from numba import njit, prange

    from clothsim.jit.internals import load_value, stack_address, type_ref

    Inner = namedtuple("Inner", ["a", "k", "gone"])
    Outer = namedtuple("Outer", ["inner", "b", "x"])

    @njit(parallel=True)
    def each_thread_reads(groups: tuple, out: np.ndarray) -> None:
        at = stack_address(groups)
        proto = type_ref(groups)
        for m in prange(out.shape[0]):
            g = load_value(at, proto)
            o = g[1]
            o.inner.a[m] = m  # the caller's array itself
            out[m] = o.inner.k + o.b.sum() + o.x + (1.0 if o.inner.gone is None else 0.0) + g[0][0]

    a = np.zeros(all_threads * 2)
    groups = ((5.0,), Outer(Inner(a, 2.0, None), np.array([1.0, 2.0]), 0.5))
    out = np.zeros(all_threads * 2)
    refs = sys.getrefcount(a)
    each_thread_reads(groups, out)
    assert np.array_equal(out, np.full(out.shape, 2.0 + 3.0 + 0.5 + 1.0 + 5.0))
    assert sys.getrefcount(a) == refs
    assert np.array_equal(a, np.arange(a.size))


def test_a_plan_packed_in_python_reads_back_as_the_stack_copy_does() -> None:
    # packed_value lays a value out as stack_address does (arrays detached): a kernel reading the
    # address back sees the same arrays, scalars, flags and missing passes, and writes the caller's arrays
    import ctypes
    from collections import namedtuple

    from numba import njit

    from numba import types

    from clothsim.jit.internals import load_value, packed_value

    Inner = namedtuple("Inner", ["a", "k", "gone", "on", "n"])
    Outer = namedtuple("Outer", ["inner", "b", "x", "pair"])

    @njit
    def read(at: int, proto, out: np.ndarray) -> None:  # noqa: ANN001
        g = load_value(at, proto)
        o = g[1]
        o.inner.a[:] = 7.0
        out[0] = o.inner.k + o.b.sum() + o.x + g[0][0]
        out[1] = 1.0 if o.inner.gone is None else 0.0
        out[2] = 1.0 if o.inner.on else 0.0
        out[3] = o.inner.n + o.pair[0] + o.pair[1] + o.b.shape[1] + o.b.strides[0]

    a = np.zeros(5)
    b = np.arange(6.0).reshape(2, 3)
    value = ((5.0,), Outer(Inner(a, 2.0, None, True, np.int64(3)), b, 0.5, (np.int64(4), np.int64(6))))
    ty = numba.typeof(value)
    buffer = packed_value(value, ty)
    out = np.zeros(4)
    read(ctypes.addressof(buffer), types.TypeRef(ty), out)
    assert out.tolist() == [2.0 + 15.0 + 0.5 + 5.0, 1.0, 1.0, 3 + 4 + 6 + 3 + 24]
    assert np.array_equal(a, np.full(5, 7.0))
    with pytest.raises(TypeError, match="cannot lay out"):
        packed_value(("text",), numba.typeof(("text",)))
