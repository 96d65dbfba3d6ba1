"""The contact self-collision mode: no crossings at the end of any frame, with every integrator,
on the stress scenes scaled down; pinned points untouched; the same bits twice; a cloth that
starts crossed is warned about and gains no crossings.

Crossings are counted by the project's exact counter (:mod:`clothsim.sim.crossings`, itself checked
against brute force in tests/test_crossings.py), independently of the pass.
"""

from __future__ import annotations

import json
import warnings
from pathlib import Path

import numba
from numba import njit
import numpy as np
import pytest

from clothsim.errors import SceneError
from clothsim.scene import load_scene, scene_from_dict
from clothsim.sim import Simulation
from clothsim.sim.profile import Profiler
from clothsim.sim.solvers.frame import PASS_ALL

from clothsim.jit import BORROWED, EXACT
from clothsim.sim.crossings import count_crossings
from clothsim.sim.passes.contactsearch import _edge_edge, _point_triangle

SCENES = Path(__file__).resolve().parents[1] / "scenes"
INTEGRATIONS = [("verlet", "spec"), ("verlet", "rate"), ("symplectic_euler", "spec"), ("implicit_euler", "spec"),
                ("xpbd", "spec")]


def self_collision_scene(n: int = 22, integrator: str = "verlet", damping: str = "spec", mode: str = "contact"):
    return load_scene(SCENES / "selfCollision.json").with_cloth(num_width_points=n, num_height_points=n) \
        .with_simulation(self_collision=mode, integrator=integrator, damping_mode=damping)


def rest_of(sim: Simulation) -> np.ndarray:
    """The cloth's rest positions (3, N), from which the simulation made its contact group (its
    query radius depends on the rest edges)."""
    return np.ascontiguousarray(sim.initial_positions.T)


def folded_cloth(frames: int = 70) -> Simulation:
    """The 20 x 20 cloth folded on the floor: from frame ``frames`` on, the first frame from whose
    positions a rebuild stores more than 10 point-triangle and 10 edge-edge pairs (which frame that
    is depends on the contact mode's bits; the tests below need pairs of both kinds to check)."""
    from clothsim.sim.passes.contactgroup import contact_group
    from clothsim.sim.passes.contactsearch import rebuild

    sim = Simulation(self_collision_scene(20))
    sim.step(frames)
    for _ in range(60):
        x = np.ascontiguousarray(sim.positions.T)
        c = sim._kernel_args.contact
        probe = contact_group(rest_of(sim), c.tris, c.movable, sim.scene.cloth.thickness)
        rebuild(x, probe)
        if probe.meta[1] > 10 and probe.meta[2] > 10:
            return sim
        sim.step(1)
    raise AssertionError(f"the 20 x 20 cloth had no frame from {frames} to {frames + 59} with pairs of both kinds")


def with_pair_arrays(make, columns: int):  # noqa: ANN001, ANN201
    """``make`` (``contact_group``) giving groups whose pair arrays have ``columns`` columns."""
    def short(*args, **kwargs):  # noqa: ANN002, ANN003, ANN202
        c = make(*args, **kwargs)
        return c._replace(pt=np.zeros((2, columns), np.int64), ptf=np.zeros((6, columns)),
                          ee=np.zeros((2, columns), np.int64), eef=np.zeros((5, columns)))
    return short


def flag_scene(nw: int = 27, nh: int = 18, mode: str = "contact", pin_motion: dict | None = None):
    raw = {"cloth": {"width": 1.5, "height": 1.0, "num_width_points": nw, "num_height_points": nh, "thickness": 0.01,
                     "orientation": "vertical", "pinned": [[0, j] for j in range(nh)], "damping": 0.05,
                     "density": 0.5, "ks": 300.0, **({} if pin_motion is None else {"pin_motion": pin_motion})},
           "wind": {"velocity": [6.0, 0.0, 0.0], "turbulence": 3.0, "drag": 1.0, "lift": 0.3, "air_density": 1.2,
                    "seed": 7, "turbulence_scale": 2.0},
           "simulation": {"self_collision": mode}}
    return scene_from_dict(raw)


def crossings_per_frame(sim: Simulation, frames: int) -> tuple[list[int], int]:
    """Crossings at the end of each frame, and the most contact pairs the pass stored."""
    out = []
    pairs = 0
    for _ in range(frames):
        sim.step(1)
        out.append(count_crossings(sim.positions, sim.nw, sim.nh))
        c = sim._kernel_args.contact
        pairs = max(pairs, int(c.meta[1] + c.meta[2]))
    return out, pairs


@pytest.mark.parametrize("integrator,damping", INTEGRATIONS)
def test_self_collision_scene_never_crosses(integrator: str, damping: str) -> None:
    sim = Simulation(self_collision_scene(22, integrator, damping))
    counts, pairs = crossings_per_frame(sim, 75)
    assert counts == [0] * len(counts)
    assert pairs > 0  # the cloth did fold onto itself
    assert np.isfinite(sim.positions).all()
    assert sim.positions[:, 1].min() > -1e-3  # and stays on the floor


def test_spec_mode_crosses_on_the_same_scene() -> None:
    """The scene is a real stress test: the spec's hash lets the same cloth cross itself."""
    sim = Simulation(self_collision_scene(30, mode="spec"))
    sim.step(60)
    assert count_crossings(sim.positions, sim.nw, sim.nh) > 0


@pytest.mark.parametrize("integrator,damping", [INTEGRATIONS[0], INTEGRATIONS[3]])
def test_flag_never_crosses_and_pins_stay(integrator: str, damping: str) -> None:
    scene = flag_scene()
    scene = scene.with_simulation(integrator=integrator, damping_mode=damping)
    sim = Simulation(scene)
    pinned = sim.pinned.copy()
    start = sim.positions[pinned].copy()
    counts, _ = crossings_per_frame(sim, 60)
    assert counts == [0] * len(counts)
    assert np.array_equal(sim.positions[pinned], start)


def test_moving_pins_follow_their_track() -> None:
    """The pass never moves a pinned point: with contact on, pins end exactly where the track puts
    them (the same bits as with self-collision off)."""
    scene = load_scene(SCENES / "shake.json").with_cloth(num_width_points=16, num_height_points=16,
                                                         pinned=tuple((i, 0) for i in range(16)))
    sim = Simulation(scene.with_simulation(self_collision="contact"))
    track = scene.cloth.pin_motion.track()
    rest = sim.initial_positions[sim.pinned]
    for _ in range(20):
        sim.step(1)
        offset = track.at(sim.time)
        assert np.allclose(sim.positions[sim.pinned], rest + offset, rtol=0, atol=1e-12)


def test_same_bits_twice() -> None:
    a, b = (Simulation(self_collision_scene(20)) for _ in range(2))
    a.step(50)
    b.step(25)
    b.step(25)
    assert np.array_equal(a.positions, b.positions) and np.array_equal(a.last_positions, b.last_positions)


def folded(sim: Simulation, layers: int, gap: float, tilt: float = 0.0) -> None:
    """Lay a horizontal cloth in ``layers`` stacked folds ``gap`` apart (rows shared out), the
    layer above each tilted by ``tilt`` (a slope along x, to make them pierce each other), with a
    seeded jitter of 0.1 mm so that no point lies exactly on another element."""
    nw, nh = sim.nw, sim.nh
    x0 = sim.initial_positions.reshape(nh, nw, 3)
    per = nh // layers
    pos = x0.copy()
    spacing = x0[1, 0, 2] - x0[0, 0, 2]
    for j in range(nh):
        layer = min(j // per, layers - 1)
        k = j - layer * per
        z = k * spacing if layer % 2 == 0 else (per - 1 - k) * spacing
        pos[j, :, 2] = z
        pos[j, :, 1] = 0.3 + layer * gap + tilt * layer * (x0[j, :, 0] - 0.5)
    pos += np.random.default_rng(3).uniform(-1e-4, 1e-4, pos.shape)
    sim.positions[:] = pos.reshape(-1, 3)
    sim.last_positions[:] = pos.reshape(-1, 3)


def heap_scene(n: int = 24):
    raw = {"cloth": {"width": 1.0, "height": 1.0, "num_width_points": n, "num_height_points": n, "thickness": 0.0095,
                     "orientation": "horizontal", "damping": 0.2, "density": 150.0, "ks": 5000.0},
           "plane": {"point": [0.5, 0.0, 0.5], "normal": [0.0, 1.0, 0.0], "friction": 0.5},
           "simulation": {"self_collision": "contact"}}
    return scene_from_dict(raw)


def test_heap_of_folds_dropped_on_a_plane() -> None:
    sim = Simulation(heap_scene())
    folded(sim, 4, 0.03)
    assert count_crossings(sim.positions, sim.nw, sim.nh) == 0
    counts, pairs = crossings_per_frame(sim, 60)
    assert counts == [0] * len(counts)
    assert pairs > 0
    assert sim.positions[:, 1].min() > -1e-3
    assert sim.positions[:, 1].max() < 0.3  # it fell and lies in folds


def test_a_cloth_that_starts_crossed_is_warned_about_and_gains_none() -> None:
    sim = Simulation(heap_scene())
    folded(sim, 3, 0.03, tilt=0.2)
    start = count_crossings(sim.positions, sim.nw, sim.nh)
    assert start > 0
    with pytest.warns(RuntimeWarning, match=rf"starts with {start} self-crossings"):
        sim.step(1)
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        counts, _ = crossings_per_frame(sim, 40)  # warned once only
    assert max(counts) <= start
    assert np.isfinite(sim.positions).all() and np.abs(sim.positions).max() < 5.0


def test_scene_rule_accepts_contact_and_names_it() -> None:
    raw = json.loads((SCENES / "selfCollision.json").read_text())
    assert scene_from_dict({**raw, "simulation": {"self_collision": "contact"}}).simulation.self_collision == "contact"
    with pytest.raises(SceneError, match='simulation.self_collision.*"contact"'):
        scene_from_dict({**raw, "simulation": {"self_collision": "touch"}})


@pytest.mark.skipif(numba.config.NUMBA_NUM_THREADS < 2, reason="Numba has one thread here: no team of two")
def test_team_size_does_not_change_the_numbers(all_threads: int) -> None:
    scene = self_collision_scene(20)
    out = []
    for size in (1, 2):
        sim = Simulation(scene)
        for _ in range(40):
            sim._forget_contacts()
            assert sim.run_kernel(scene.simulation.simulation_steps, PASS_ALL, size)
        out.append(sim.positions.copy())
    assert np.array_equal(out[0], out[1])


def test_fused_frame_matches_pass_by_pass_profile() -> None:
    scene = self_collision_scene(20)
    fused = Simulation(scene)
    fused.step(40)
    profiled = Simulation(scene)
    profiler = Profiler(profiled)
    for _ in range(40):
        profiler.frame()
    assert np.array_equal(fused.positions, profiled.positions)
    assert profiler.calls["contact bound"] == 40 * scene.simulation.simulation_steps


def test_the_pass_by_pass_profile_gives_moving_colliders_the_last_word_too() -> None:
    # (its frames match the fused frame's to rounding only where colliders move, as they did
    # before: 1e-16 m apart from frame 17 of a 16 x 16 driven run, in the spec mode too; 30 x 30
    # as in tests/test_crossings.py: on a cloth as coarse as 16 x 16 the box and the plane between
    # them leave points over the plane in every mode)
    from clothsim.bench.stress import FLOOR, SQUEEZE_GAP, driven_scene

    sim = Simulation(driven_scene("squeeze", 30).with_simulation(self_collision="contact"))
    profiler = Profiler(sim)
    for _ in range(120):
        profiler.frame()
    assert sim.squeezed_substeps > 0
    assert sim.positions[:, 1].max() <= FLOOR + SQUEEZE_GAP + 1e-9


@pytest.mark.parametrize("n, thickness, radius, nearest", [(20, 0.0095, 0.69 / 19, None),
                                                            (50, 0.0095, 1.5 * 0.0095, None),
                                                            (20, 0.05, 1.5 * 0.5 / 19, 1 / 19 / np.sqrt(2))])
def test_the_query_radius_reaches_to_just_short_of_the_sheets_own_neighbours(n: int, thickness: float, radius: float,
                                                                             nearest: float | None) -> None:
    # 1.5 x the contact distance, or 0.69 x the shortest rest edge where that is more (a cloth thin
    # against its edges). The flat cloth's nearest elements that share no point lie 1/sqrt(2) edge
    # apart: within a radius of 0.69 edge there is no pair at rest and every ball is the largest;
    # a contact distance of half an edge reaches them (0.75 edge), and they bound every ball
    from clothsim.sim.passes.contactgroup import FLOOR, GAMMA
    from clothsim.sim.passes.contactsearch import rebuild

    sim = Simulation(self_collision_scene(n).with_cloth(thickness=thickness))
    c = sim._kernel_args.contact
    assert c.radius == pytest.approx(radius, rel=1e-9)
    rebuild(rest_of(sim), c)
    assert int(c.meta[1]) == int(c.meta[2]) == 0  # (none within the contact distance)
    if nearest is None:
        assert np.allclose(np.sqrt(c.rho2), GAMMA * (c.radius - FLOOR * c.thickness), rtol=1e-9, atol=0)
    else:  # (the scene's grid is jittered by up to a millimetre out of its plane)
        assert np.allclose(np.sqrt(c.rho2), GAMMA * (nearest - FLOOR * c.thickness), rtol=1e-3, atol=0)


def test_no_pair_is_held_closer_than_the_floor() -> None:
    # Two triangles, the upper one driven straight down onto the lower one, still, at every
    # rebuild: the gap shrinks by GAMMA x (gap - floor) each time, towards FLOOR x the contact
    # distance and never below it (without the floor: 0.02 x 0.55^60, 5e-18 m).
    from clothsim.sim.passes.contactgroup import FLOOR, GAMMA, contact_group
    from clothsim.sim.passes.contactsearch import rebuild
    from clothsim.sim.passes.contactresponse import bound

    lower = [[0.0, 0.0, 0.0], [1.0, 0.0, 0.0], [0.0, 1.0, 0.0]]
    upper = [[0.1, 0.1, 0.02], [1.1, 0.1, 0.02], [0.1, 1.1, 0.02]]
    x = np.ascontiguousarray(np.array(lower + upper).T)
    c = contact_group(x, np.array([[0, 3], [1, 4], [2, 5]]), np.ones(6, dtype=np.bool_), 0.05)
    floor = FLOOR * c.thickness
    gaps = []
    for _ in range(60):
        rebuild(x, c)
        x[2, 3:] = -1.0
        bound(x, c)
        gaps.append(float(x[2, 3:].min() - x[2, :3].max()))
    assert gaps[0] == pytest.approx(0.02 - GAMMA * (0.02 - floor), rel=1e-8)
    assert all(b < a for a, b in zip(gaps, gaps[1:]) if a > 2 * floor)
    assert floor <= min(gaps) < 1.01 * floor


@njit(**EXACT)
def _every_pair(x: np.ndarray, c) -> np.ndarray:  # noqa: ANN001
    """The reference by brute force: every point-triangle and edge-edge pair tested, in order, in
    IEEE order (as the rebuild's tests are compiled)."""
    dmin = np.full(x.shape[1], c.radius)
    _every_pair_into(x, c, dmin)
    return dmin


@pytest.mark.parametrize("frames", [35, 70])
def test_the_broad_phase_finds_every_pair_brute_force_finds(frames: int) -> None:
    # landing (35: points within the query radius, none yet within the contact distance) and folded
    # on the floor (70): the same pairs stored, with the same weights, normals and balls as testing
    # every pair
    from clothsim.sim.passes.contactgroup import FLOOR, GAMMA, contact_group
    from clothsim.sim.passes.contactsearch import rebuild

    if frames == 70:
        sim = folded_cloth(frames)
    else:
        sim = Simulation(self_collision_scene(20))
        sim.step(frames)
    x = np.ascontiguousarray(sim.positions.T)
    c = sim._kernel_args.contact
    rebuild(x, c)
    want = contact_group(rest_of(sim), c.tris, c.movable, sim.scene.cloth.thickness)
    dmin = _every_pair(x, want)
    npt, nee = int(c.meta[1]), int(c.meta[2])
    assert (npt, nee) == (int(want.meta[1]), int(want.meta[2]))
    # (falling, no pair is within the contact distance yet, but some within the query radius)
    assert np.sum(dmin < c.radius) > 10 and ((npt > 10 and nee > 10) if frames == 70 else True)
    for got_ids, got_f, want_ids, want_f, k, width in ((c.pt, c.ptf, want.pt, want.ptf, npt, c.tris.shape[1]),
                                                      (c.ee, c.eef, want.ee, want.eef, nee, c.edges.shape[1])):
        # (pairs in the order brute force finds them)
        order = np.argsort(got_ids[0, :k] * width + got_ids[1, :k])
        assert np.array_equal(got_ids[:, :k][:, order], want_ids[:, :k])
        assert np.allclose(got_f[:, :k][:, order], want_f[:, :k], rtol=0, atol=1e-12)
    r = GAMMA * np.maximum(dmin - FLOOR * c.thickness, 0.0)
    assert np.allclose(c.rho2, r * r, rtol=1e-9, atol=0)



def test_the_batched_tests_give_the_one_at_a_time_tests_bits() -> None:
    # the rebuild tests its pairs in vectorised batches: on a folded cloth, every stored pair's
    # weights and normal and every ball equal bit for bit to the scalar tests' in the same order
    from clothsim.sim.passes.contactgroup import FLOOR, GAMMA, contact_group
    from clothsim.sim.passes.contactsearch import rebuild

    sim = folded_cloth()
    x = np.ascontiguousarray(sim.positions.T)
    c = sim._kernel_args.contact
    rebuild(x, c)
    want = contact_group(rest_of(sim), c.tris, c.movable, sim.scene.cloth.thickness)
    dmin = _every_pair(x, want)
    npt, nee = int(c.meta[1]), int(c.meta[2])
    assert (npt, nee) == (int(want.meta[1]), int(want.meta[2])) and npt > 10 and nee > 10
    for got_ids, got_f, want_ids, want_f, k, width in ((c.pt, c.ptf, want.pt, want.ptf, npt, c.tris.shape[1]),
                                                      (c.ee, c.eef, want.ee, want.eef, nee, c.edges.shape[1])):
        order = np.argsort(got_ids[0, :k] * width + got_ids[1, :k])
        assert np.array_equal(got_ids[:, :k][:, order], want_ids[:, :k])
        assert np.array_equal(got_f[:, :k][:, order], want_f[:, :k])
    r = GAMMA * np.maximum(dmin - FLOOR * c.thickness, 0.0)
    assert np.array_equal(c.rho2, r * r)


def _joined(x: np.ndarray, c, members: int) -> tuple:  # noqa: ANN001
    """A rebuild searched by ``members`` members, each its parts, then joined: what it stored, and
    whether a part found more pairs than its share of the arrays holds."""
    from clothsim.sim.passes.contact import contact_stale
    from clothsim.sim.passes.contactgroup import CUT, DROPPED, FLAG, N_EE, N_PT, SIZE
    from clothsim.sim.passes.contactsearch import contact_search, fall_back, join, overflowed

    flags = [np.zeros(FLAG, np.int64) for _ in range(members)]
    c.meta[0] = 0  # no reference (as at a frame's start): stale for every member
    for m, flag in enumerate(flags):  # every member decides before any searches (as in the team)
        contact_stale(x, x, c, flag, m, members)
    assert all(flag[0] == 1 and flag[3] == members for flag in flags)
    assert flags[0][1] == 0 and flags[-1][2] == len(c.cost)
    assert all(a[2] == b[1] for a, b in zip(flags, flags[1:]))  # each part searched once
    for m, flag in enumerate(flags):
        contact_search(x, c, flag, m)
    parts = len(c.cost)
    over = any(c.found[k, 0] > (k + 1) * c.pt.shape[1] // parts - k * c.pt.shape[1] // parts
               or c.found[k, 1] > (k + 1) * c.ee.shape[1] // parts - k * c.ee.shape[1] // parts for k in range(parts))
    assert overflowed(c, parts) == over
    flag = flags[0]  # the first member's, as in the team
    if over:
        fall_back(flag)
        contact_search(x, c, flag, 0)
    join(x, c, flag[CUT], flag[SIZE])
    npt, nee = int(c.meta[N_PT]), int(c.meta[N_EE])
    return (c.pt[:, :npt].copy(), c.ptf[:, :npt].copy(), c.ee[:, :nee].copy(), c.eef[:, :nee].copy(),
            c.rho2.copy(), int(c.meta[DROPPED])), over


def test_a_part_over_its_share_has_the_first_member_search_the_rebuild_again_in_the_frame(monkeypatch) -> None:
    # the frame kernel's own fall-back: pair arrays too short for a part's pairs in its share (but
    # long enough for all of a rebuild's pairs) have the first member search the whole rebuild again
    # as one part, and the cloth moves as it does with arrays of the usual length, bit for bit
    from clothsim.sim import simulation as simulation_module
    from clothsim.sim.passes.contactgroup import DROPPED, PARTS
    from clothsim.sim.passes.contactsearch import overflowed

    want = Simulation(self_collision_scene(20))
    monkeypatch.setattr(simulation_module, "contact_group", with_pair_arrays(simulation_module.contact_group, 200))
    got = Simulation(self_collision_scene(20))
    fell_back = 0
    for _ in range(60):
        want.step(1)
        got.step(1)
        fell_back += overflowed(got._kernel_args.contact, PARTS)  # the last rebuild was searched again
        assert np.array_equal(got.positions, want.positions)
    assert fell_back > 0 and got._kernel_args.contact.meta[DROPPED] == 0


def test_a_frame_that_finds_more_pairs_than_the_arrays_hold_is_run_again_with_longer_ones(monkeypatch) -> None:
    # pair arrays of 8 columns: a frame whose rebuilds find more pairs is run again from its start
    # with arrays twice as long, until none is dropped; the cloth moves as with arrays of the usual
    # length, bit for bit, on the fast path and on another integrator's
    from clothsim.sim import simulation as simulation_module
    from clothsim.sim.passes.contactgroup import DROPPED

    usual = simulation_module.contact_group
    short = with_pair_arrays(usual, 8)
    for integrator in ("verlet", "xpbd"):
        monkeypatch.setattr(simulation_module, "contact_group", usual)
        want = Simulation(self_collision_scene(16, integrator=integrator))
        monkeypatch.setattr(simulation_module, "contact_group", short)
        got = Simulation(self_collision_scene(16, integrator=integrator))
        for _ in range(55):
            want.step(1)
            got.step(1)
            assert np.array_equal(got.positions, want.positions), integrator
        c = got._kernel_args.contact
        assert c.pt.shape[1] > 8 and c.meta[DROPPED] == 0 and want._kernel_args.contact.meta[DROPPED] == 0


@pytest.mark.parametrize("room", ["shares", "all", "half"])
def test_a_rebuild_searched_in_parts_by_the_team_stores_what_one_sweep_stores(room: str) -> None:
    # the team's members search their parts of a rebuild side by side and the first joins them:
    # the same pairs in the same order, the same balls, bit for bit, as one sweep over every
    # part, for one to three members and with the parts shared out by the last rebuild's costs;
    # with pair arrays that hold all the pairs but not a part's in its share (the whole rebuild
    # searched again as one part), or half the pairs (the rest dropped, as one sweep drops them)
    from clothsim.sim.passes.contactsearch import join, search

    sim = folded_cloth()
    x = np.ascontiguousarray(sim.positions.T)
    c = sim._kernel_args.contact
    if room != "shares":
        search(x, c, 0, 1, 1, 0)
        join(x, c, 1, 1)
        npt, nee = (int(c.meta[1]), int(c.meta[2])) if room == "all" else (int(c.meta[1]) // 2, int(c.meta[2]) // 2)
        c = c._replace(pt=np.zeros((2, npt), np.int64), ptf=np.zeros((6, npt)), ee=np.zeros((2, nee), np.int64),
                       eef=np.zeros((5, nee)))

    def fresh():  # noqa: ANN202
        return c._replace(meta=np.zeros_like(c.meta), found=np.zeros_like(c.found), cost=np.zeros_like(c.cost),
                          dmins=np.zeros_like(c.dmins))

    one = fresh()
    search(x, one, 0, 1, 1, 0)
    join(x, one, 1, 1)
    want = (one.pt[:, :one.meta[1]], one.ptf[:, :one.meta[1]], one.ee[:, :one.meta[2]], one.eef[:, :one.meta[2]],
            one.rho2, int(one.meta[4]))
    assert want[0].shape[1] > 5 and want[2].shape[1] > 10
    assert (want[5] > 0) == (room == "half")
    for members in (1, 2, 3):
        team = fresh()
        for _ in range(2):  # equal shares of the parts, then shares by the first rebuild's costs
            got, over = _joined(x, team, members)
            assert over == (room != "shares")
            for a, b in zip(got, want):
                assert np.array_equal(a, b)
            team.meta[4] = 0


def test_a_pin_that_leaves_a_small_ball_is_counted_in_that_substep() -> None:
    # A pin 1 mm above a free triangle (a ball of 0.45 mm, far below ROOMY's) driven 2 mm down in
    # one substep: the pass must rebuild then and count the substep unsafe, not wait for the next
    # frame (a free point with a small ball may wait, clamped; a pin is never clamped).
    from clothsim.sim.passes.contact import contact_respond
    from clothsim.sim.passes.contactgroup import GAMMA, REBUILDS, ROOMY, UNSAFE, contact_group
    from clothsim.sim.passes.contactsearch import rebuild

    lower = [[0.0, 0.0, 0.0], [1.0, 0.0, 0.0], [0.0, 1.0, 0.0]]
    upper = [[0.2, 0.2, 0.001], [1.2, 0.2, 0.001], [0.2, 1.2, 0.001]]
    x = np.ascontiguousarray(np.array(lower + upper).T)
    movable = np.array([True, True, True, False, True, True])
    c = contact_group(x, np.array([[0, 3], [1, 4], [2, 5]]), movable, 0.05)
    rebuild(x, c)
    assert c.rho2[3] < (ROOMY * GAMMA * c.radius) ** 2
    pos = x.copy()
    pos[2, 3] -= 0.002
    contact_respond(pos, x.copy(), c)
    assert (c.meta[REBUILDS], c.meta[UNSAFE]) == (2, 1)


def test_a_pin_put_out_of_its_ball_through_the_api_is_counted() -> None:
    # a pin moved between frames through the API jumps there in no substep, so no pass bounds
    # it: out of its ball it is counted unsafe once, inside it (or with no reference) not at all
    from clothsim.sim.passes.contactgroup import UNSAFE

    scene = self_collision_scene(12)
    scene = scene.with_cloth(pinned=[[0, 0]])
    sim = Simulation(scene)
    sim.step(2)
    c = sim._kernel_args.contact
    pin = int(np.flatnonzero(sim.pinned)[0])
    ball = float(np.sqrt(c.rho2[pin]))
    assert ball > 0.0 and c.meta[UNSAFE] == 0
    sim.positions[pin, 0] += 0.5 * ball
    sim.step(1)
    assert c.meta[UNSAFE] == 0
    sim.positions[pin, 0] += 3.0 * float(np.sqrt(c.rho2[pin])) + 1e-6
    sim.step(1)
    assert c.meta[UNSAFE] == 1 and sim.unsafe_substeps == 1
    sim.reset()
    sim.positions[pin, 0] += 0.02
    sim.step(1)
    assert c.meta[UNSAFE] == 1  # (no reference after reset: a fresh one from where the pin is)


@pytest.mark.parametrize("sweeps", [1, 4])
def test_the_response_pushes_an_isolated_pair_by_its_sweeps(sweeps: int) -> None:
    # A free point 0.05 above a pinned triangle, contact distance 0.1, not moving: each sweep
    # removes PUSH (one sweep) or PUSH_MOVING (SWEEPS_MOVING sweeps, while pins move) of the
    # overlap left, so 1 - (1 - push)^sweeps of it goes.
    from clothsim.sim.passes.contactgroup import MOVING, PUSH, PUSH_MOVING, SWEEPS_MOVING, contact_group
    from clothsim.sim.passes.contactsearch import rebuild
    from clothsim.sim.passes.contactresponse import respond

    x = np.ascontiguousarray(np.array([[0.0, 0.0, 0.0], [1.0, 0.0, 0.0], [0.0, 0.0, 1.0], [0.2, 0.05, 0.2]]).T)
    c = contact_group(x, np.array([[0], [1], [2]]), np.array([False, False, False, True]), 0.1)
    rebuild(x, c)
    assert c.meta[1] == 1  # the one point-triangle pair
    c.meta[MOVING] = sweeps > 1
    pos = x.copy()
    respond(pos, x.copy(), c)
    push = PUSH_MOVING if sweeps > 1 else PUSH
    n = SWEEPS_MOVING if sweeps > 1 else 1
    assert pos[1, 3] == pytest.approx(0.1 - 0.05 * (1.0 - push) ** n, abs=1e-15)
    assert np.array_equal(pos[:, :3], x[:, :3])  # pinned
    assert pos[[0, 2], 3] == pytest.approx(x[[0, 2], 3], abs=1e-15)  # pushed along the normal only


def test_the_response_sweeps_while_pins_move() -> None:
    # One sweep while the pins stay; SWEEPS_MOVING in a frame whose pins were put elsewhere through
    # the API, and in every frame of a scene whose pins follow a track.
    from clothsim.sim.passes.contactgroup import MOVING

    sim = Simulation(flag_scene(9, 6))
    meta = sim._kernel_args.contact.meta
    sim.step(1)
    assert meta[MOVING] == 0
    pins = np.flatnonzero(sim.pinned)
    sim.positions[pins] += [0.0, 0.0, 0.01]
    sim.step(1)
    assert meta[MOVING] == 1
    sim.step(1)
    assert meta[MOVING] == 0
    tracked = Simulation(flag_scene(9, 6, pin_motion={"keyframes": [[0.0, [0.0, 0.0, 0.0]], [1.0, [0.0, 0.1, 0.0]]]}))
    tracked.step(1)
    assert tracked._kernel_args.contact.meta[MOVING] == 1


@njit(**BORROWED)
def _every_pair_into(x: np.ndarray, c, dmin: np.ndarray) -> None:  # noqa: ANN001
    # (_every_pair's tests, compiled, without reference counting: it would count the group's
    # arrays up and down at every pair)
    npt = 0
    for p in range(x.shape[1]):
        for t in range(c.tris.shape[1]):
            npt = _point_triangle(x, c, p, t, dmin, npt, c.pt.shape[1])
    nee = 0
    for e1 in range(c.edges.shape[1]):
        for e2 in range(e1 + 1, c.edges.shape[1]):
            nee = _edge_edge(x, c, e1, e2, dmin, nee, c.ee.shape[1])
    c.meta[1] = npt
    c.meta[2] = nee


def test_the_references_moved_point_by_point_hold_what_a_rebuild_from_them_would_find() -> None:
    # Between whole rebuilds the points about to leave their balls (and those the bound held back)
    # get their references moved one by one, their pairs found again through the cells of the
    # points and elements. After every frame of a folding cloth whose substeps moved references
    # and rebuilt nothing, the mixed reference this leaves must store exactly the pairs brute
    # force finds in it, once each, every ball must be no larger than brute force gives it, every
    # point must lie in its ball, and the cells must list every point, triangle and edge once, in
    # the cell of its reference position or of its box's lower corner.
    from clothsim.sim.passes.contactgroup import FLOOR, GAMMA, LOCALS, MOVED, REBUILDS, contact_group
    from clothsim.sim.passes.nearby import key_of

    sim = Simulation(self_collision_scene(20))
    c = sim._kernel_args.contact
    nb = c.near
    inv = 1.0 / nb.cell
    sim.step(45)
    checked = 0
    in_contact = 0

    def check() -> None:
        nonlocal checked, in_contact
        x = c.ref.copy()
        want = contact_group(rest_of(sim), c.tris, c.movable, sim.scene.cloth.thickness)
        dmin = _every_pair(x, want)
        for ids, k, width, wants, wk in ((c.pt, int(c.meta[1]), c.tris.shape[1], want.pt, int(want.meta[1])),
                                         (c.ee, int(c.meta[2]), c.edges.shape[1], want.ee, int(want.meta[2]))):
            got = np.sort(ids[0, :k] * width + ids[1, :k])
            assert np.array_equal(got, np.sort(wants[0, :wk] * width + wants[1, :wk]))  # (each pair once)
            in_contact += k
        r = GAMMA * np.maximum(dmin - FLOOR * c.thickness, 0.0)
        assert np.all(c.rho2 <= r * r)
        d2 = ((np.ascontiguousarray(sim.positions.T) - c.ref) ** 2).sum(axis=0)
        assert np.all(d2 <= c.rho2 * (1 + 1e-9) + 1e-28)
        for cells, m, lo in ((nb.points, x.shape[1], x), (nb.tris, c.tris.shape[1], nb.tri_box),
                             (nb.edges, c.edges.shape[1], nb.edge_box)):
            listed = []
            for s in range(cells.head.shape[0]):
                q = cells.head[s]
                while q >= 0:
                    listed.append(q)
                    q = cells.nxt[q]
            assert sorted(listed) == list(range(m))
            assert all(cells.key[i] == key_of(lo[0, i], lo[1, i], lo[2, i], inv) for i in range(m))
        assert np.array_equal(nb.tri_box[:3], x[:, c.tris].min(axis=1) - c.radius)
        assert np.array_equal(nb.edge_box[3:], x[:, c.edges].max(axis=1) + 0.5 * c.radius)
        checked += 1

    def substeps(steps: int, saved: tuple | None) -> None:
        for _ in range(steps):  # (one at a time, on one member: the state after each is looked at)
            before = (int(c.meta[REBUILDS]), int(c.meta[LOCALS]))
            sim.run_kernel(1)
            if int(c.meta[REBUILDS]) == before[0] and int(c.meta[LOCALS]) > before[1] and checked < 20:
                check()

    while checked < 20 and sim.frame < 90:
        sim._advance_frame(substeps)
    assert checked == 20 and in_contact > 50 and c.meta[MOVED] > c.meta[LOCALS] > 0


def _nbytes(x) -> int:  # noqa: ANN001
    return x.nbytes if isinstance(x, np.ndarray) else sum(_nbytes(y) for y in x) if isinstance(x, tuple) else 0


def test_the_memory_check_counts_the_contact_modes_arrays_and_a_rebuilds_tables(monkeypatch) -> None:
    # the pass's group and a rebuild's tables (built here as the search builds them, on the folded
    # cloth) fit in what the check counts a point; a grid that fits in the spec's mode but not with
    # the contact mode's arrays is refused, naming the grid
    import clothsim.scene as scene_module
    from clothsim.jit import CHUNKS
    from clothsim.sim.passes.celltables import box_table, corner_table, grid_over
    from clothsim.sim.passes.contactsearch import EDGE_SPLIT, GRID_CELLS, _element_boxes
    from clothsim.sim.passes.nearby import extent

    sim = folded_cloth()
    c = sim._kernel_args.contact
    n = sim.positions.shape[0]
    assert _nbytes(c) / n * 1.25 <= scene_module.CONTACT_BYTES_PER_POINT
    x = np.ascontiguousarray(sim.positions.T)
    tbox = _element_boxes(x, c.tris, c.radius)
    grid, tcell = grid_over(tbox, c.cell, GRID_CELLS * tbox.shape[1] + 64)
    tables = [tbox, *box_table(tbox, grid, tcell), tbox]  # (the boxes, by triangle again)
    ebox = _element_boxes(x, c.edges, 0.5 * c.radius)
    eext = max(extent(ebox, e) for e in range(ebox.shape[1]))
    egrid, ecell = grid_over(ebox, eext / EDGE_SPLIT, GRID_CELLS * ebox.shape[1] + 64)
    # (the edges' boxes, their table, the boxes in table order, each entry's place, the hits)
    tables += [ebox, *corner_table(ebox, egrid, ecell), ebox, np.empty(2 * ebox.shape[1], np.int64)]
    assert _nbytes(tuple(tables)) / n * 1.25 <= scene_module.CONTACT_SEARCH_BYTES_PER_POINT
    assert scene_module.MOST_MEMBERS == CHUNKS
    spec, contact = self_collision_scene(40, mode="spec"), self_collision_scene(40)
    need = scene_module.bytes_per_point(spec.simulation) * 1600
    monkeypatch.setattr(scene_module, "available_memory", lambda: need + 100)
    scene_module.check_memory(spec)
    with pytest.raises(SceneError, match="40x40 grid would need about"):
        scene_module.check_memory(contact)


def test_simulate_says_when_a_pin_outran_the_bound(tmp_path: Path) -> None:
    # a pin track that jumps 0.4 m in 2 ms (0.15 m a substep, several balls): the contact mode
    # cannot bound those substeps; the command counts them on stderr and still writes its file
    from conftest import run_cli

    scene = {"cloth": {"width": 1.0, "height": 1.0, "num_width_points": 12, "num_height_points": 12,
                       "thickness": 0.02, "orientation": "horizontal", "damping": 0.2, "density": 15.0, "ks": 5000.0,
                       "pinned": [[0, 0]],
                       "pin_motion": {"keyframes": [[0.0, [0, 0, 0]], [0.05, [0, 0, 0]], [0.052, [0.0, 0.0, 0.4]]]}},
             "simulation": {"self_collision": "contact"}}
    path = tmp_path / "fast.json"
    path.write_text(json.dumps(scene))
    done = run_cli("simulate", str(path), "--frames", "10", "--out", str(tmp_path / "out.npz"))
    assert done.returncode == 0, done.stderr
    warned = [line for line in done.stderr.splitlines() if "warning" in line]
    assert len(warned) == 1 and "a pin moved farther than the bound allows" in warned[0], done.stderr
    assert (tmp_path / "out.npz").exists()
    quiet = dict(scene, cloth=dict(scene["cloth"], pin_motion={"velocity": [0.0, 0.0, 0.1]}))
    path.write_text(json.dumps(quiet))
    done = run_cli("simulate", str(path), "--frames", "10", "--out", str(tmp_path / "out.npz"))
    assert done.returncode == 0 and "warning" not in done.stderr, done.stderr
