"""The registry of forces drives every per-force table: the scene loader, the memory check, the
guard, serve's cost model, the sweeps' writer, the profiler and the simulator's passes."""

from __future__ import annotations

import dataclasses
import inspect

import numpy as np
import pytest

from clothsim.errors import SceneError
from clothsim.forces import FORCES, scene_forces
from clothsim.scene import Scene, scene_from_dict
from clothsim.wind import WindSpec


def _scene(**extra) -> dict:
    return {"cloth": {"width": 1.0, "height": 1.0, "num_width_points": 6, "num_height_points": 6,
                      "thickness": 0.01, "orientation": "vertical", "damping": 0.2, "density": 1.0, "ks": 200.0,
                      "pinned": [[0, 5], [5, 5]]},
            "simulation": {"simulation_steps": 5}, **extra}


def test_every_kind_names_a_scene_field_and_a_pass_module_with_the_protocol() -> None:
    from clothsim.sim.passes import forces as passes

    fields = {f.name for f in dataclasses.fields(Scene)}
    assert [k.key for k in FORCES] == ["wind"]
    assert len(passes.FORCES) == len(FORCES)
    for kind, module in zip(FORCES, passes.FORCES):
        assert kind.attr in fields, kind
        assert module.__name__ == f"clothsim.sim.passes.{kind.pass_module}"
        assert tuple(module.Group._fields)  # a NamedTuple
        assert module.NAME == kind.key and module.ABSENT
        assert list(inspect.signature(module.work.py_func).parameters)[1:] == ["pos", "last", "substep", "c0", "c1"]
        assert len(inspect.signature(module.gather.py_func).parameters) == 3
        assert list(inspect.signature(module.pack).parameters) == ["sim"]


def test_the_loader_reads_each_kind_and_names_it_for_an_unknown_key() -> None:
    scene = scene_from_dict(_scene(wind={"velocity": [1, 0, 0]}), "f.json")
    assert scene_forces(scene) == (WindSpec(velocity=(1.0, 0.0, 0.0)),)
    with pytest.raises(SceneError) as err:
        scene_from_dict(_scene(gale={}), "f.json")
    for kind in FORCES:
        assert kind.key in str(err.value)


def test_memory_guard_cost_and_writer_read_the_registry() -> None:
    from clothsim.serve.limits import frame_seconds
    from clothsim.sim.guard import driven_speed
    from clothsim.sweeps.params import scene_json

    still = scene_from_dict(_scene(wind={"velocity": [0, 0, 0]}), "f.json")
    gusty = scene_from_dict(_scene(wind={"velocity": [3, 0, 4], "turbulence": 2}), "f.json")
    assert [k.bytes_per_point(still.winds) for k in FORCES] == [0]
    assert [k.bytes_per_point(gusty.winds) for k in FORCES] == [432]
    assert driven_speed(gusty) == pytest.approx(7.0)
    assert frame_seconds(gusty) > frame_seconds(scene_from_dict(_scene(), "f.json"))
    again = scene_from_dict(scene_json(gusty), "f.json")
    assert again.winds == gusty.winds


def test_a_scene_without_forces_plans_an_empty_tuple_and_the_profiler_says_why() -> None:
    from clothsim.sim import Simulation
    from clothsim.sim.profile import Profiler

    sim = Simulation(scene_from_dict(_scene(), "f.json"))
    assert sim._kernel_args.forces == ()
    skipped = Profiler(sim).skipped()
    assert skipped["wind"] == "scene has no wind (or only still air)"
    blown = Simulation(scene_from_dict(_scene(wind={"velocity": [0, 0, 2]}), "f.json"))
    assert [type(g).__name__ for g in blown._kernel_args.forces] == ["Wind"]
    assert "wind" not in Profiler(blown).skipped()
    blown.step(2)
    assert np.isfinite(blown.positions).all()
