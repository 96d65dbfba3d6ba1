"""The registry of collider kinds drives every per-kind table, and every kind moves by one pose
update read from the simulation's one clock."""

from __future__ import annotations

import numpy as np
import pytest

from clothsim.colliders import BY_KEY, KINDS, scene_colliders
from clothsim.errors import SceneError
from clothsim.scene import scene_from_dict
from conftest import SCENES

KEYS = ["sphere", "plane", "capsule", "box", "mesh"]


def _groups(sim) -> dict:  # noqa: ANN001
    """The plan's collider groups by kind key."""
    from clothsim.sim.passes.colliders import KIND_MODULES

    by_group = {m.Group: kind.key for m, kind in zip(KIND_MODULES, KINDS)}
    return {by_group[type(g)]: g for g in sim.plan.colliders}


def _scene(moving: bool) -> dict:
    motion = {"keyframes": [[0.0, [0.0, 0.0, 0.0]], [0.05, [0.02, 0.01, 0.0]]]}

    def moved(obj: dict, at: list[float]) -> dict:
        if moving:
            obj["motion"] = {"keyframes": [[t, [a + d for a, d in zip(at, p)]] for t, p in motion["keyframes"]]}
        return obj

    return {
        "cloth": {"width": 1.0, "height": 1.0, "num_width_points": 8, "num_height_points": 8, "thickness": 0.01,
                  "orientation": "horizontal", "damping": 0.2, "density": 150.0, "ks": 5000.0, "pinned": []},
        "sphere": moved({"origin": [0.5, -2.0, 0.5], "radius": 0.2, "friction": 0.3}, [0.5, -2.0, 0.5]),
        "plane": moved({"point": [0.0, -3.0, 0.0], "normal": [0, 1, 0], "friction": 0.5}, [0.0, -3.0, 0.0]),
        "capsule": moved({"a": [0.2, -2.0, 0.2], "b": [0.8, -2.0, 0.2], "radius": 0.05, "friction": 0.2},
                         [0.5, -2.0, 0.2]),
        "box": moved({"center": [0.5, -2.5, 0.5], "half_extents": [0.1, 0.1, 0.1], "friction": 0.1},
                     [0.5, -2.5, 0.5]),
        "mesh": moved({"path": str(SCENES / "torus.obj"), "scale": 0.2, "translate": [0.5, -2.0, 0.8],
                       "friction": 0.3}, [0.5, -2.0, 0.8]),
        "simulation": {"simulation_steps": 7},
    }


def test_the_registry_lists_every_kind_once_in_scene_order() -> None:
    assert [k.key for k in KINDS] == KEYS
    assert set(BY_KEY) == set(KEYS)


def test_every_per_kind_table_covers_exactly_the_registry() -> None:
    from clothsim.exporters.geometry import COLLIDER_KINDS
    from clothsim.render.renderer import Renderer
    from clothsim.sim.passes.colliders import KIND_MODULES

    assert list(COLLIDER_KINDS) == KEYS
    for key in KEYS:
        assert callable(getattr(Renderer, f"_draw_{key}")), key
    # the simulator's side: one pass module per kind, in registry order, each with the whole interface
    assert [m.__name__.rsplit(".", 1)[1] for m in KIND_MODULES] == [k.pass_module for k in KINDS]
    for module in KIND_MODULES:
        for name in ("Group", "pack", "pose", "reach", "collide"):
            assert hasattr(module, name), (module.__name__, name)
        assert {"on", "tracks"} <= set(module.Group._fields), module.__name__


def test_a_plan_holds_the_groups_of_the_kinds_its_scene_has_in_registry_order() -> None:
    from clothsim.sim import Simulation

    data = _scene(False)
    del data["capsule"], data["sphere"]
    sim = Simulation(scene_from_dict(data, "k.json"))
    # the course's kinds are in every plan with colliders, empty when the scene has none of them
    assert list(_groups(sim)) == ["sphere", "plane", "box", "mesh"]
    assert len(_groups(sim)["sphere"].rows) == 0
    assert all(g.tracks is None for g in sim.plan.colliders)


def test_the_loader_reads_every_kind_and_names_them_for_an_unknown_key() -> None:
    scene = scene_from_dict(_scene(True), "k.json")
    assert [k.key for k, _, _ in scene_colliders(scene)] == KEYS
    assert len(scene.colliders) == 5 and scene.moving
    with pytest.raises(SceneError) as err:
        scene_from_dict({**_scene(False), "cylinder": {}}, "k.json")
    assert "expected one of: cloth, sphere, plane, capsule, box, mesh, wind, simulation, render" in str(err.value)


def test_the_scene_writer_round_trips_every_kind() -> None:
    from clothsim.sweeps.params import scene_json

    scene = scene_from_dict(_scene(True), "k.json")
    again = scene_from_dict(scene_json(scene), "again.json")
    for kind in KINDS:
        a, b = getattr(scene, kind.attr), getattr(again, kind.attr)
        assert [kind.to_json(x) for x in a] == [kind.to_json(x) for x in b], kind.key


# (on one worker, one after another: the verlet plans share their member, and on two workers one
# waited for the other's compile on a cold cache)
@pytest.mark.xdist_group("one plan per kind")
@pytest.mark.parametrize("integrator, kinds", [*(("verlet", (k,)) for k in KEYS), ("symplectic_euler", ("sphere",))])
def test_every_kind_is_posed_from_the_one_clock(integrator: str, kinds: tuple[str, ...]) -> None:
    # After a frame every moving collider stands where its track puts it at the simulation's
    # time, bit for bit: the kernels' clock and the Python one are the same clock. Every kind on
    # the thread team's path; the other integrators' collider pass calls the same pose functions
    # with its own substep count, checked with one kind. (One kind a plan: each compiles its
    # kind's passes, 1-4 s on a cold cache, and two small kernels for the plan's set of kinds.)
    from clothsim.sim import Simulation

    data = {k: v for k, v in _scene(True).items() if k not in KEYS or k in kinds}
    data["simulation"].update(integrator=integrator, self_collision="off")  # (less to compile)
    sim = Simulation(scene_from_dict(data, "k.json"))
    sim.step(2)
    t = sim.time
    scene = sim.scene
    groups = _groups(sim)
    for spec, key in ((s, k) for k in ("sphere", "plane", "box") if k in kinds for s in getattr(scene, BY_KEY[k].attr)):
        anchor = np.asarray(spec.anchor)
        assert np.array_equal(groups[key].rows[0, :3], anchor + (spec.motion.track(spec.anchor).at(t) - anchor))
    if "capsule" in kinds:
        capsule = scene.capsules[0]
        shift = capsule.motion.track(capsule.anchor).at(t) - np.asarray(capsule.anchor)
        assert np.array_equal(groups["capsule"].rows[0, :3], np.asarray(capsule.a) + shift)
    if "mesh" in kinds:
        mesh = scene.meshes[0]
        assert np.array_equal(groups["mesh"].pose[0, 3:], mesh.track().at(t))
        before = scene.meshes[0].track().at(t - sim.dt)
        assert np.allclose(groups["mesh"].pose[0, :3], before, rtol=0, atol=1e-15)


def test_static_colliders_are_posed_once_and_stay() -> None:
    from clothsim.sim import Simulation

    # the kinds of the bundled mesh scene's plan, which `clothsim compile` compiles: capsules and
    # boxes add nothing to what is checked here but a compile of their own
    data = _scene(False)
    del data["capsule"], data["box"]
    sim = Simulation(scene_from_dict(data, "k.json"))
    groups = _groups(sim)
    pose = groups["mesh"].pose.copy()
    rows = groups["sphere"].rows.copy()
    sim.step(1)
    assert all(g.tracks is None for g in sim.plan.colliders)
    assert groups["sphere"].carry is None  # nothing moves: the spec's static sphere test
    assert np.array_equal(groups["mesh"].pose, pose) and np.array_equal(pose[0, :3], [0.5, -2.0, 0.8])
    assert np.array_equal(groups["sphere"].rows, rows)
