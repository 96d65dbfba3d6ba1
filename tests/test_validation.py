"""Every way in goes through one rule set: scene dicts, render settings, setters and flags.

The fuzz tests draw valid-ish scenes and corrupt them (wrong types, NaN/inf, huge and negative
numbers, missing keys, nested garbage) in every object; each must end in a clean short run or in a
ClothsimError, never in another exception. Grids stay small (at most 5 x 5 points, or refused by
the memory check, which is given a 4 MiB budget here) so that a run is one quick frame.
"""

from __future__ import annotations

import copy
import json
import math
import warnings

import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from clothsim import scene as scene_module
from clothsim import validate as V
from clothsim.errors import ClothsimError, FieldError, SceneError
from clothsim.render.settings import SHADERS, TERMS, RenderSettings
from clothsim.scene import (DAMPING_MODES, INTEGRATORS, SceneWarning, load_scene, parse_scene,
                            scene_from_dict)
from clothsim.sim import Simulation, guard
from conftest import run_cli

FUZZ = settings(max_examples=150, deadline=None, suppress_health_check=[HealthCheck.too_slow])

# A budget that refuses any grid beyond ~4000 points: a corrupted count can't start a long run.
FUZZ_MEMORY = 4 * 1024**2
REAL_AVAILABLE_MEMORY = scene_module.available_memory


@pytest.fixture(scope="module", autouse=True)
def small_memory():
    with pytest.MonkeyPatch.context() as mp:
        mp.setattr(scene_module, "available_memory", lambda: FUZZ_MEMORY)
        yield


# ----------------------------------------------------------------------------------------------
# Strategies

finite = st.floats(allow_nan=False, allow_infinity=False)
special_numbers = st.sampled_from([
    math.nan, math.inf, -math.inf, -1, -1.0, 0, 0.0, 1e-320, 1e308, -1e308, 2**31, 2**63, 10**30, -(10**30),
    10**400, 0.5, 2.5, True, False,
])
garbage = st.recursive(
    st.none() | st.booleans() | st.integers(-10, 10) | special_numbers | st.floats() | st.text(max_size=8),
    lambda inner: st.lists(inner, max_size=4) | st.dictionaries(st.text(max_size=6), inner, max_size=3),
    max_leaves=8,
)


def vec(lo: float, hi: float) -> st.SearchStrategy:
    return st.lists(st.floats(lo, hi), min_size=3, max_size=3)


@st.composite
def cloth(draw: st.DrawFn) -> dict:
    nw, nh = draw(st.integers(2, 5)), draw(st.integers(2, 5))
    c = {
        "width": draw(st.floats(0.05, 3.0)), "height": draw(st.floats(0.05, 3.0)),
        "num_width_points": nw, "num_height_points": nh,
        "thickness": draw(st.floats(1e-4, 0.1)),
        "orientation": draw(st.sampled_from([0, 1, "horizontal", "vertical", "Vertical", 0.0])),
        "damping": draw(st.floats(0.0, 100.0)), "density": draw(st.floats(0.1, 1000.0)),
        "ks": draw(st.floats(0.0, 2e4)),
    }
    if draw(st.booleans()):
        c["pinned"] = draw(st.lists(st.tuples(st.integers(0, nw - 1), st.integers(0, nh - 1)).map(list), max_size=4))
    for key in ("enable_structural", "enable_shearing", "enable_bending"):
        if draw(st.booleans()):
            c[key] = draw(st.booleans())
    return c


sphere = st.fixed_dictionaries({"origin": vec(-2, 2), "radius": st.floats(0.01, 1.0), "friction": st.floats(0, 1)})
plane = st.fixed_dictionaries({"point": vec(-2, 2), "normal": vec(-1, 1), "friction": st.floats(0, 1)})
simulation = st.fixed_dictionaries({}, optional={
    "frames_per_sec": st.floats(10, 240), "simulation_steps": st.integers(1, 4), "gravity": vec(-20, 20),
    "self_collision": st.sampled_from([True, False, "spec", "grid", "off"]), "seed": st.integers(0, 2**32),
    "integrator": st.sampled_from(INTEGRATORS), "damping_mode": st.sampled_from(DAMPING_MODES),
    "max_stretch": st.none() | st.floats(0, 1), "rest_tolerance": st.floats(1e-9, 1e-2),
    "rest_frames": st.integers(1, 100),
})
colour = st.lists(st.floats(0, 1), min_size=3, max_size=3) | st.sampled_from(["#8060c0", "#FFFFFF", "000000"])
render = st.fixed_dictionaries({}, optional={
    "shader": st.sampled_from(SHADERS), "size": st.sampled_from(["64x48", [32, 32], "8*8"]),
    "samples": st.sampled_from([0, 1, 2, 4, 8, 16]),
    "camera": st.fixed_dictionaries({}, optional={"position": vec(-5, 5), "target": vec(-5, 5),
                                                  "fov": st.floats(1, 179), "near": st.floats(0.001, 1),
                                                  "far": st.floats(1, 1000)}),
    "color": colour, "background": colour,
    "light": st.fixed_dictionaries({}, optional={"position": vec(-5, 5), "intensity": vec(0, 10)}),
    "phong": st.fixed_dictionaries({}, optional={"k_a": st.floats(0, 1), "k_d": st.floats(0, 1),
                                                 "k_s": st.floats(0, 1), "p": st.floats(1, 500),
                                                 "I_a": vec(0, 2),
                                                 "terms": st.lists(st.sampled_from(TERMS), min_size=1)}),
    "normal_scaling": st.floats(0, 10), "height_scaling": st.floats(0, 1), "reflectivity": st.floats(0, 1),
    "sphere_resolution": st.integers(2, 64) | st.tuples(st.integers(2, 64), st.integers(3, 64)).map(list),
    "wireframe": st.fixed_dictionaries({}, optional={"color_by_family": st.booleans()}),
})


@st.composite
def scene_dict(draw: st.DrawFn) -> dict:
    d: dict = {"cloth": draw(cloth())}
    for key, strategy in (("sphere", sphere), ("plane", plane)):
        if draw(st.booleans()):
            d[key] = draw(strategy if draw(st.booleans()) else st.lists(strategy, max_size=2))
    if draw(st.booleans()):
        d["simulation"] = draw(simulation)
    if draw(st.booleans()):
        d["render"] = draw(render)
    return d


def _containers(value: object, path: tuple = ()) -> list[tuple]:
    """Paths of every object and list inside ``value`` (the places a corruption can go)."""
    out = [path] if isinstance(value, (dict, list)) else []
    items = value.items() if isinstance(value, dict) else enumerate(value) if isinstance(value, list) else ()
    for k, v in items:
        out += _containers(v, path + (k,))
    return out


@st.composite
def corrupted_scene(draw: st.DrawFn, base: st.SearchStrategy | None = None) -> dict:
    """A valid-ish scene (``base``, default :func:`scene_dict`) with one to three things broken anywhere in it."""
    # A copy: sampled_from hands out the same list object every time (size [32, 32]), and
    # corrupting it in place would change what later examples draw from the same choices.
    d = copy.deepcopy(draw(scene_dict() if base is None else base))
    for _ in range(draw(st.integers(1, 3))):
        path = draw(st.sampled_from(_containers(d)))
        target = d
        for k in path:
            target = target[k]
        keys = list(target) if isinstance(target, dict) else list(range(len(target)))
        action = draw(st.sampled_from(["replace", "delete", "add", "replace"] if keys else ["add"]))
        if action == "add":
            if isinstance(target, dict):
                target[draw(st.text(max_size=6))] = draw(garbage)
            else:
                target.append(draw(garbage))
        elif action == "delete":
            del target[draw(st.sampled_from(keys))]
        else:
            target[draw(st.sampled_from(keys))] = draw(garbage)
    return d


@st.composite
def motion(draw: st.DrawFn) -> dict:
    """A ``motion`` object within the limits: a velocity, or keyframes 0.01-0.5 s apart."""
    if draw(st.booleans()):
        return {"velocity": draw(vec(-5, 5))}
    times = np.cumsum(draw(st.lists(st.floats(0.01, 0.5), min_size=1, max_size=3))) - 0.01
    return {"keyframes": [[float(t), draw(vec(-1, 1))] for t in times]}


@st.composite
def extension_scene(draw: st.DrawFn) -> dict:
    """A small cloth with every extension at once: moving pins, a moving sphere, capsule and box,
    a plane and a gusty wind. Self-collision off and Verlet, so every example runs the same
    compiled frame kernel (a mesh collider, which needs an OBJ file, is left to its own tests)."""
    c = draw(cloth())
    c["pinned"] = [[0, 0], [c["num_width_points"] - 1, 0]]
    c["pin_motion"] = draw(motion())
    friction = st.floats(0, 1)
    return {
        "cloth": c,
        "sphere": {"origin": draw(vec(-2, 2)), "radius": draw(st.floats(0.01, 1.0)), "friction": draw(friction),
                   "motion": draw(motion())},
        "plane": draw(plane),
        "capsule": {"a": draw(vec(-2, 2)), "b": draw(vec(-2, 2)), "radius": draw(st.floats(0.01, 0.5)),
                    "friction": draw(friction), "motion": draw(motion())},
        "box": {"center": draw(vec(-2, 2)), "half_extents": draw(vec(0.01, 1)), "rotation": draw(vec(-360, 360)),
                "friction": draw(friction), "motion": draw(motion())},
        "wind": {"velocity": draw(vec(-20, 20)), "turbulence": draw(st.floats(0.1, 5)), "drag": draw(st.floats(0, 2)),
                 "lift": draw(st.floats(-1, 1)), "air_density": draw(st.floats(0, 2)),
                 "seed": draw(st.integers(0, 2**63 - 1)), "turbulence_scale": draw(st.floats(0.01, 10))},
        "simulation": {"self_collision": "off", "integrator": "verlet",
                       "simulation_steps": draw(st.integers(1, 4))},
    }


# ----------------------------------------------------------------------------------------------
# What every input must end in


def _clean_run_or_clothsim_error(d: object) -> None:
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", SceneWarning)
        try:
            scene = scene_from_dict(d, "fuzz.json")
            RenderSettings.from_scene(scene)
            guard.stability_warning(scene)  # every simulate and render call runs it
            sim = Simulation(scene)
            sim.step(1)
        except ClothsimError as exc:
            assert "\n" not in str(exc)


@FUZZ
@given(scene_dict())
def test_valid_ish_scenes_run_or_fail_cleanly(d):
    _clean_run_or_clothsim_error(d)


@FUZZ
@given(corrupted_scene())
def test_corrupted_scenes_run_or_fail_cleanly(d):
    _clean_run_or_clothsim_error(d)


EXTENSIONS = settings(FUZZ, max_examples=40)
#: Both run one plan (every extension at once): on one worker, one after the other (on two, the
#: second waited for the first's compile on a cold cache).
EXTENSIONS_PLAN = pytest.mark.xdist_group("every extension's plan")


@EXTENSIONS_PLAN
@EXTENSIONS
@given(extension_scene())
def test_scenes_with_every_extension_run_or_fail_cleanly(d):
    _clean_run_or_clothsim_error(d)


@EXTENSIONS_PLAN
@EXTENSIONS
@given(corrupted_scene(extension_scene()))
def test_corrupted_extensions_run_or_fail_cleanly(d):
    _clean_run_or_clothsim_error(d)


@FUZZ
@given(garbage)
def test_garbage_at_the_top_level_is_a_scene_error(d):
    with pytest.raises(SceneError):
        scene_from_dict(d, "fuzz.json")


@settings(max_examples=60, deadline=None)
@given(st.text(max_size=40) | st.binary(max_size=40).map(lambda b: b.decode("latin-1")))
def test_any_text_parses_or_is_a_scene_error(text):
    try:
        parse_scene(text, "fuzz.json")
    except SceneError as exc:
        assert "\n" not in str(exc)


SETTER_VALUES = {
    "ks": st.floats(0, 2e4), "density": st.floats(0.1, 1000), "damping": st.floats(0, 100),
    "enable_structural": st.booleans(), "enable_shearing": st.booleans(), "enable_bending": st.booleans(),
    "gravity": vec(-20, 20) | vec(-20, 20).map(tuple) | vec(-20, 20).map(np.array),
    "frames_per_sec": st.floats(10, 240), "simulation_steps": st.integers(1, 4),
}
setter_value = garbage | st.sampled_from([np.float32(np.nan), np.int64(-3), np.array([1.0, 2.0]), "5", object()])


RULES = [V.number(), V.number(ge=0.0, le=1.0), V.number(gt=0.0), V.integer(ge=2, le=100), V.boolean,
         V.vec3(), V.vec3(nonzero=True), V.choice(("a", "b"), aliases={True: "a", 0: "b"}),
         V.list_of(V.integer(), length=2), V.list_of(V.choice(("x",)), nonempty=True), V.one_or_many(V.number()),
         V.nullable(V.number()), V.record({"k": V.required(V.number()), "o": V.default(V.boolean, False)})]


@FUZZ
@given(st.sampled_from(range(len(RULES))), garbage | setter_value)
def test_every_rule_returns_or_raises_one_field_error(i, value):
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", SceneWarning)
        try:
            RULES[i](value, V.At(None, "f"))
        except FieldError as exc:
            assert str(exc).startswith("f") and "\n" not in str(exc)


@pytest.fixture(scope="module")
def small_scene():
    return scene_from_dict({"cloth": {"width": 1, "height": 1, "num_width_points": 4, "num_height_points": 4,
                                      "thickness": 0.01, "orientation": 0, "damping": 0.2, "density": 150,
                                      "ks": 5000, "pinned": [[0, 0], [3, 0]]},
                            "simulation": {"simulation_steps": 2}})


@FUZZ
@given(st.lists(st.sampled_from(sorted(SETTER_VALUES)).flatmap(
    lambda name: st.tuples(st.just(name), SETTER_VALUES[name] | setter_value)), min_size=1, max_size=4))
def test_setters_accept_or_raise_a_clothsim_error(small_scene, changes):
    sim = Simulation(small_scene)
    for name, value in changes:
        before = getattr(sim, name)
        try:
            setattr(sim, name, value)
        except ClothsimError as exc:
            assert str(exc).startswith(f"{'cloth' if name in _CLOTH else 'simulation'}.{name}")
            assert getattr(sim, name) == before  # a refused value changes nothing
    try:
        sim.step(1)
    except ClothsimError:
        pass


_CLOTH = {"ks", "density", "damping", "enable_structural", "enable_shearing", "enable_bending"}


# ----------------------------------------------------------------------------------------------
# The cases found by hand


@pytest.fixture
def sim(small_scene):
    return Simulation(small_scene)


@pytest.mark.parametrize("name, value, message", [
    ("simulation_steps", 0, "simulation.simulation_steps: must be >= 1, got 0"),
    ("simulation_steps", 2.5, "simulation.simulation_steps: expected an integer, got 2.5"),
    ("ks", math.nan, "cloth.ks: must be >= 0, got nan"),
    ("ks", math.inf, "cloth.ks: must be <= 1e+12, got inf"),
    ("ks", "5000", 'cloth.ks: expected a number, got "5000"'),
    ("density", 0, "cloth.density: must be >= 1e-06, got 0"),
    ("ks", 1e308, "cloth.ks: must be <= 1e+12, got 1e+308"),
    ("damping", 101, "cloth.damping: must be <= 100, got 101"),
    ("enable_bending", 1, "cloth.enable_bending: expected true or false, got 1"),
    ("enable_shearing", None, "cloth.enable_shearing: expected true or false, got null"),
    ("gravity", (0, -9.8), "simulation.gravity: expected 3 numbers, got 2"),
    ("gravity", [0, math.nan, 0], "simulation.gravity[1]: must be finite, got nan"),
    ("frames_per_sec", -90, "simulation.frames_per_sec: must be >= 0.001, got -90"),
    ("frames_per_sec", 1e200, "simulation.frames_per_sec: must be <= 1e+06, got 1e+200"),
    ("frames_per_sec", math.inf, "simulation.frames_per_sec: must be <= 1e+06, got inf"),
])
def test_each_setter_validates_like_the_loader(sim, name, value, message):
    before = getattr(sim, name)
    with pytest.raises(FieldError) as info:
        setattr(sim, name, value)
    assert str(info.value) == message
    assert getattr(sim, name) == before
    sim.step(1)  # the simulation is still usable


def test_the_loader_gives_the_same_message_with_the_file_in_front(small_scene):
    cloth = {f.name: getattr(small_scene.cloth, f.name) for f in small_scene.cloth.__dataclass_fields__.values()}
    cloth.update(ks=math.nan, pinned=[list(p) for p in cloth["pinned"]])
    with pytest.raises(SceneError) as info:
        scene_from_dict({"cloth": cloth}, "my.json")
    assert str(info.value) == "my.json: cloth.ks: must be >= 0, got nan"


def test_setters_still_take_numpy_values(sim):
    sim.ks = np.float32(100.0)
    sim.simulation_steps = np.int64(3)
    sim.gravity = np.array([0.0, -1.0, 0.0])
    sim.enable_bending = np.bool_(False)
    assert (sim.ks, sim.simulation_steps, sim.gravity, sim.enable_bending) == (100.0, 3, (0.0, -1.0, 0.0), False)
    sim.step(1)


def test_step_refuses_a_bad_frame_count(sim):
    for bad in (-1, 1.5, "2", None):
        with pytest.raises(FieldError, match="^frames: "):
            sim.step(bad)
    sim.step(0)
    assert sim.frame == 0


def test_huge_integer_in_a_file_is_one_line():
    text = json.dumps({"cloth": {"width": 1}})[:-2] + ", \"ks\": " + "9" * 5000 + "}}"
    with pytest.raises(SceneError, match="not valid JSON"):
        parse_scene(text, "big.json")


def test_course_scenes_load_unchanged():
    for name in ("pinned2", "pinned4", "sphere", "plane", "selfCollision"):
        with warnings.catch_warnings():
            warnings.simplefilter("error")
            load_scene(name)


# ----------------------------------------------------------------------------------------------
# Flags through the real command line: one line, exit 2, the flag named


@pytest.mark.parametrize("args, flag", [
    (["simulate", "pinned4", "--steps", "0"], "--steps"),
    (["simulate", "pinned4", "--steps", "2000000"], "--steps"),
    (["simulate", "pinned4", "--steps", "abc"], "argument --steps"),
    (["simulate", "pinned4", "--fps", "nan"], "--fps"),
    (["simulate", "pinned4", "--fps", "-90"], "--fps"),
    (["simulate", "pinned4", "--seed", "-1"], "--seed"),
    (["simulate", "pinned4", "--frames", "-1"], "--frames"),
    (["render", "pinned4", "-o", "x.png", "--fov", "0"], "--fov"),
    (["render", "pinned4", "-o", "x.png", "--size", "0x10"], "--size"),
    (["render", "pinned4", "-o", "x.png", "--samples", "3"], "--samples"),
    (["render", "pinned4", "-o", "x.gif", "--every", "0"], "--every"),
    (["render", "pinned4", "-o", "x.gif", "--video-fps", "inf"], "--video-fps"),
    (["render", "pinned4", "-o", "x.png", "--terms", "glow"], "--terms"),
    (["bench", "speed", "--frames", "0"], "--frames"),
    (["bench", "scaling", "--sizes", "1"], "--sizes"),
])
def test_bad_flag_is_one_line_naming_it(tmp_path, args, flag):
    out = ["--out", str(tmp_path / "s.npz")] if args[0] == "simulate" else []
    r = run_cli(*args, *out, cwd=tmp_path)
    assert r.returncode == 2, r.stderr
    lines = r.stderr.strip().splitlines()
    assert len(lines) == 1 and "Traceback" not in r.stderr, r.stderr
    assert lines[0].startswith(f"clothsim: error: {flag}: "), lines[0]
    assert list(tmp_path.iterdir()) == []


# ----------------------------------------------------------------------------------------------
# A user's texture


def test_decompression_bomb_texture_is_one_clothsim_error(tmp_path, monkeypatch):
    from PIL import Image

    from clothsim.render import textures

    path = tmp_path / "big.png"
    Image.new("RGB", (64, 64)).save(path)
    monkeypatch.setattr(Image, "MAX_IMAGE_PIXELS", 100)  # 4096 pixels: over twice the limit
    with pytest.raises(ClothsimError) as info:
        textures.load_image(path)
    message = str(info.value)
    assert message.startswith(f"{path}: cannot read image:") and "\n" not in message
    assert "decompression bomb" in message


@pytest.mark.parametrize("content", [b"", b"\x89PNG\r\n\x1a\n" + b"\0" * 40, b"GIF89a\x10\x00"])
def test_broken_texture_file_is_one_clothsim_error(tmp_path, content):
    from clothsim.render import textures

    path = tmp_path / "broken.png"
    path.write_bytes(content)
    with pytest.raises(ClothsimError, match="cannot read image"):
        textures.load_image(path)


# ----------------------------------------------------------------------------------------------
# Memory: what a run allocates, and what a container allows


@pytest.mark.parametrize("integrator, bound", [("verlet", scene_module.BYTES_PER_POINT),
                                               ("symplectic_euler", scene_module.BYTES_PER_POINT_OTHER_INTEGRATORS)])
def test_a_run_allocates_less_than_the_estimate(integrator, bound):
    import tracemalloc

    n = 64
    base = load_scene("pinned4")
    scene = base.with_cloth(num_width_points=n, num_height_points=n, width=n / 50, height=n / 50,
                            pinned=((0, 0), (n - 1, 0))).with_simulation(integrator=integrator, simulation_steps=2)
    Simulation(scene.with_cloth(num_width_points=4, num_height_points=4, pinned=())).step(1)  # compile first
    tracemalloc.start()
    try:
        sim = Simulation(scene)
        try:
            sim.step(1)
        except ClothsimError:
            pass  # a blow-up has allocated all a frame needs, and more (the replay)
        peak = tracemalloc.get_traced_memory()[1]
    finally:
        tracemalloc.stop()
    assert peak / (n * n) < bound


def _cgroup_tree(tmp_path, files: dict[str, str], self_cgroup: str):
    for rel, text in files.items():
        path = tmp_path / "cg" / rel
        path.parent.mkdir(parents=True, exist_ok=True)
        path.write_text(text)
    (tmp_path / "self").write_text(self_cgroup)
    return tmp_path / "cg", tmp_path / "self"


def test_cgroup_v2_limit_less_usage_without_dropable_cache(tmp_path):
    root, me = _cgroup_tree(tmp_path, {"memory.max": str(1024 * 2**20), "memory.current": str(600 * 2**20),
                                       "memory.stat": f"anon 1\ninactive_file {100 * 2**20}\n"}, "0::/\n")
    assert scene_module.cgroup_memory_available(root, me) == 524 * 2**20


def test_cgroup_v1_nested_limit_is_found_and_unlimited_is_none(tmp_path):
    root, me = _cgroup_tree(tmp_path, {
        "memory/memory.limit_in_bytes": "9223372036854771712",
        "memory/a/b/memory.limit_in_bytes": str(2 * 2**30), "memory/a/b/memory.usage_in_bytes": str(2**30),
        "memory/a/b/memory.stat": "cache 5\ntotal_inactive_file 0\n",
    }, "5:cpu:/\n4:memory:/a/b\n0::/\n")
    assert scene_module.cgroup_memory_available(root, me) == 2**30
    root, me = _cgroup_tree(tmp_path / "x", {"memory.max": "max\n"}, "0::/\n")
    assert scene_module.cgroup_memory_available(root, me) is None
    assert scene_module.cgroup_memory_available(tmp_path / "none", tmp_path / "none") is None


def test_a_container_limit_refuses_a_grid_that_would_not_fit(monkeypatch):
    monkeypatch.setattr(scene_module, "available_memory", REAL_AVAILABLE_MEMORY)
    monkeypatch.setattr(scene_module, "cgroup_memory_available", lambda: 2 * 2**20)
    assert scene_module.available_memory() == 2 * 2**20
    with pytest.raises(SceneError, match=r"cloth.num_width_points: a 50x50 grid would need about 2.4 MiB"):
        load_scene("pinned2")
