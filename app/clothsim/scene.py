"""Scene files: the course's JSON format (plus optional extensions) -> a validated, typed :class:`Scene`.

Course files load unchanged: top-level ``cloth``, ``sphere``, ``plane``. Extensions, all optional:
a ``simulation`` object, ``sphere``/``plane`` given as lists, and a ``render`` object that the
renderer validates itself. Every problem raises :class:`~clothsim.errors.SceneError` naming the
file, the field path (``cloth.num_width_points``, ``sphere[1].radius``) and what is wrong.
"""

from __future__ import annotations

import json
import math
import os
import warnings
from dataclasses import dataclass, field, replace
from pathlib import Path
from typing import Any

from .errors import ClothsimError, SceneError
from .resources import data_dir

HORIZONTAL = 0
VERTICAL = 1

INTEGRATORS = ("verlet", "symplectic_euler", "implicit_euler", "xpbd")
DAMPING_MODES = ("spec", "rate")
SELF_COLLISION_MODES = ("spec", "grid", "off")

# Bytes a simulation needs per grid point: positions, last positions, forces, scratch and
# mesh buffers (~20 float64 x 3) plus about six springs (two int32 ends, a float64 rest
# length, an int8 kind) and the hash tables. Measured allocation is below this bound.
BYTES_PER_POINT = 640


class SceneWarning(UserWarning):
    """A scene loaded, but something in it was ignored (e.g. an unknown key)."""


@dataclass(frozen=True)
class ClothSpec:
    """The ``cloth`` object. Units: metres, kg/m^2 (density), N/m (ks), percent (damping)."""

    width: float
    height: float
    num_width_points: int
    num_height_points: int
    thickness: float
    orientation: int
    damping: float
    density: float
    ks: float
    pinned: tuple[tuple[int, int], ...] = ()
    enable_structural: bool = True
    enable_shearing: bool = True
    enable_bending: bool = True

    @property
    def num_points(self) -> int:
        return self.num_width_points * self.num_height_points


@dataclass(frozen=True)
class SphereSpec:
    """A static sphere collider."""

    origin: tuple[float, float, float]
    radius: float
    friction: float


@dataclass(frozen=True)
class PlaneSpec:
    """A static plane collider; ``normal`` is stored normalised."""

    point: tuple[float, float, float]
    normal: tuple[float, float, float]
    friction: float


@dataclass(frozen=True)
class SimulationSpec:
    """The optional ``simulation`` object (spec defaults)."""

    frames_per_sec: float = 90.0
    simulation_steps: int = 30
    gravity: tuple[float, float, float] = (0.0, -9.8, 0.0)
    self_collision: str = "spec"
    seed: int = 0
    integrator: str = "verlet"
    damping_mode: str = "spec"
    max_stretch: float | None = 0.1
    rest_tolerance: float = 1e-5
    rest_frames: int = 30


@dataclass(frozen=True)
class Scene:
    """A whole scene. ``render`` is the raw ``render`` object (validated by the renderer)."""

    cloth: ClothSpec
    spheres: tuple[SphereSpec, ...] = ()
    planes: tuple[PlaneSpec, ...] = ()
    simulation: SimulationSpec = field(default_factory=SimulationSpec)
    render: dict[str, Any] | None = None
    path: str = "<scene>"

    def with_cloth(self, **changes: Any) -> "Scene":
        """A copy with some cloth fields replaced (no re-validation)."""
        return replace(self, cloth=replace(self.cloth, **changes))

    def with_simulation(self, **changes: Any) -> "Scene":
        """A copy with some simulation fields replaced (no re-validation)."""
        return replace(self, simulation=replace(self.simulation, **changes))


# ----------------------------------------------------------------------------------------------
# Locating scene files


def bundled_scene_names() -> list[str]:
    """Names of the scenes shipped with the package (without ``.json``)."""
    return sorted(p.stem for p in data_dir("scenes").glob("*.json"))


def resolve_scene_path(name_or_path: str | os.PathLike[str]) -> Path:
    """Return the file of a scene given as a path or as a bundled scene's name.

    Only a bare name (no path separator, no ``.json`` suffix) names a bundled scene:
    ``sphere`` is the bundled sphere scene, while ``sphere.json``, ``scenes/sphere.json`` and
    ``/any/dir/sphere.json`` are paths and must exist; a mistyped path never falls back to a
    bundled scene. A bare name that is not bundled is a path too (``./sphere`` reaches a local
    file of that name). A scene file must be a regular file.
    """
    text = os.fspath(name_or_path)
    p = Path(text)
    bare = bool(text) and text not in (".", "..") and not text.endswith(".json") and not any(
        sep in text for sep in (os.sep, os.altsep) if sep)
    if bare:
        candidate = data_dir("scenes") / f"{text}.json"
        if candidate.is_file():
            return candidate
    try:
        exists, is_dir, is_file = p.exists(), p.is_dir(), p.is_file()
    except OSError as exc:
        raise ClothsimError(f"{p}: cannot read scene file: {exc.strerror or exc}") from None
    if not exists:
        names = ", ".join(bundled_scene_names())
        hint = ""
        if p.name.endswith(".json") and p.name[:-5] in bundled_scene_names():
            hint = f"; the bundled scene is named without a path or .json: {p.name[:-5]}"
        raise ClothsimError(f"{p}: no such scene file (bundled scenes: {names}){hint}")
    if is_dir:
        raise ClothsimError(f"{p}: not a scene file (it is a directory)")
    if not is_file:
        raise ClothsimError(f"{p}: not a regular file")
    return p


def load_scene(path: str | os.PathLike[str]) -> Scene:
    """Load and validate a scene file (a path, or the bare name of a bundled scene)."""
    p = resolve_scene_path(path)
    try:
        text = p.read_text(encoding="utf-8")
    except OSError as exc:
        raise ClothsimError(f"{p}: cannot read scene file: {exc.strerror or exc}") from None
    except UnicodeDecodeError as exc:
        raise ClothsimError(f"{p}: cannot read scene file: not UTF-8 text ({exc.reason} at byte {exc.start})") from None
    return parse_scene(text, str(p))


def parse_scene(text: str, path: str = "<scene>") -> Scene:
    """Parse scene JSON text; ``path`` is used in error messages."""
    if not text.strip():
        raise SceneError(path, "", "file is empty (expected a JSON object)")
    try:
        data = json.loads(text)
    except json.JSONDecodeError as exc:
        raise SceneError(path, "", f"not valid JSON: {exc.msg} at line {exc.lineno} column {exc.colno}") from None
    except RecursionError:
        raise SceneError(path, "", "not valid JSON: nested too deeply") from None
    return scene_from_dict(data, path)


def scene_from_dict(data: Any, path: str = "<scene>") -> Scene:
    """Validate an already-parsed JSON value into a :class:`Scene`."""
    v = _Validator(path)
    if not isinstance(data, dict):
        raise SceneError(path, "", f"top level must be a JSON object, got {_type_name(data)}")
    allowed = ("cloth", "sphere", "plane", "simulation", "render")
    for key in data:
        if key not in allowed:
            raise SceneError(path, key, f"unknown top-level object (expected one of: {', '.join(allowed)})")
    if "cloth" not in data:
        raise SceneError(path, "cloth", "missing required object")
    cloth = v.cloth(data["cloth"], "cloth")
    spheres = tuple(v.each(data.get("sphere"), "sphere", v.sphere))
    planes = tuple(v.each(data.get("plane"), "plane", v.plane))
    sim = v.simulation(data["simulation"], "simulation") if "simulation" in data else SimulationSpec()
    render = None
    if "render" in data:
        render = v.obj(data["render"], "render")
    _check_memory(cloth, path)
    return Scene(cloth=cloth, spheres=spheres, planes=planes, simulation=sim, render=render, path=path)


# ----------------------------------------------------------------------------------------------
# Validation


def _type_name(value: Any) -> str:
    if value is None:
        return "null"
    if isinstance(value, bool):
        return "a boolean"
    if isinstance(value, (int, float)):
        return "a number"
    if isinstance(value, str):
        return "a string"
    if isinstance(value, list):
        return "a list"
    if isinstance(value, dict):
        return "an object"
    return type(value).__name__


def _human_bytes(n: float) -> str:
    for unit in ("B", "KiB", "MiB", "GiB", "TiB", "PiB"):
        if n < 1024 or unit == "PiB":
            return f"{n:.1f} {unit}" if unit != "B" else f"{int(n)} B"
        n /= 1024
    return f"{n:.1f} PiB"


def available_memory() -> int:
    """Bytes of memory available to a new allocation (MemAvailable, else physical memory)."""
    try:
        with open("/proc/meminfo", encoding="ascii") as fh:
            for line in fh:
                if line.startswith("MemAvailable:"):
                    return int(line.split()[1]) * 1024
    except OSError:
        pass
    try:
        return int(os.sysconf("SC_PAGE_SIZE") * os.sysconf("SC_PHYS_PAGES"))
    except (ValueError, OSError, AttributeError):
        return 8 * 1024**3


def _check_memory(cloth: ClothSpec, path: str) -> None:
    need = cloth.num_points * BYTES_PER_POINT
    avail = available_memory()
    if need > avail:
        raise SceneError(
            path,
            "cloth.num_width_points",
            f"a {cloth.num_width_points}x{cloth.num_height_points} grid would need about "
            f"{_human_bytes(need)} of memory; only {_human_bytes(avail)} is available",
        )


class _Validator:
    def __init__(self, path: str) -> None:
        self.path = path

    def fail(self, field_path: str, problem: str) -> SceneError:
        return SceneError(self.path, field_path, problem)

    def warn_unknown(self, obj: dict[str, Any], where: str, known: tuple[str, ...]) -> None:
        for key in obj:
            if key not in known:
                warnings.warn(f"{self.path}: {where}.{key}: unknown key, ignored", SceneWarning, stacklevel=4)

    # -- primitive checks --------------------------------------------------------------------
    def obj(self, value: Any, where: str) -> dict[str, Any]:
        if not isinstance(value, dict):
            raise self.fail(where, f"expected an object, got {_type_name(value)}")
        return value

    def required(self, obj: dict[str, Any], key: str, where: str) -> Any:
        if key not in obj:
            raise self.fail(f"{where}.{key}", "missing required field")
        return obj[key]

    def number(self, value: Any, where: str, *, positive: bool = False, minimum: float | None = None,
               maximum: float | None = None) -> float:
        if isinstance(value, bool) or not isinstance(value, (int, float)):
            raise self.fail(where, f"expected a number, got {_type_name(value)}")
        x = float(value)
        if not math.isfinite(x):
            raise self.fail(where, f"must be finite, got {value!r}")
        if positive and x <= 0:
            raise self.fail(where, f"must be positive, got {value!r}")
        if minimum is not None and x < minimum:
            raise self.fail(where, f"must be >= {minimum:g}, got {value!r}")
        if maximum is not None and x > maximum:
            raise self.fail(where, f"must be <= {maximum:g}, got {value!r}")
        return x

    def integer(self, value: Any, where: str, *, minimum: int | None = None) -> int:
        if isinstance(value, bool) or not isinstance(value, (int, float)):
            raise self.fail(where, f"expected an integer, got {_type_name(value)}")
        if isinstance(value, float):
            if not math.isfinite(value):
                raise self.fail(where, f"must be finite, got {value!r}")
            if not value.is_integer():
                raise self.fail(where, f"expected an integer, got {value!r}")
        n = int(value)
        if minimum is not None and n < minimum:
            raise self.fail(where, f"must be >= {minimum}, got {value!r}")
        return n

    def boolean(self, value: Any, where: str) -> bool:
        if not isinstance(value, bool):
            raise self.fail(where, f"expected true or false, got {_type_name(value)}")
        return value

    def vec3(self, value: Any, where: str) -> tuple[float, float, float]:
        if not isinstance(value, list):
            raise self.fail(where, f"expected a list of 3 numbers, got {_type_name(value)}")
        if len(value) != 3:
            raise self.fail(where, f"expected 3 numbers, got {len(value)}")
        x, y, z = (self.number(c, f"{where}[{i}]") for i, c in enumerate(value))
        return (x, y, z)

    def each(self, value: Any, where: str, parse: Any) -> list[Any]:
        if value is None:
            return []
        if isinstance(value, list):
            return [parse(item, f"{where}[{i}]") for i, item in enumerate(value)]
        return [parse(value, where)]

    # -- objects -----------------------------------------------------------------------------
    def cloth(self, value: Any, where: str) -> ClothSpec:
        o = self.obj(value, where)
        known = ("width", "height", "num_width_points", "num_height_points", "thickness", "orientation",
                 "pinned", "damping", "density", "ks", "enable_structural", "enable_shearing", "enable_bending")
        self.warn_unknown(o, where, known)
        width = self.number(self.required(o, "width", where), f"{where}.width", positive=True)
        height = self.number(self.required(o, "height", where), f"{where}.height", positive=True)
        nw = self.integer(self.required(o, "num_width_points", where), f"{where}.num_width_points", minimum=2)
        nh = self.integer(self.required(o, "num_height_points", where), f"{where}.num_height_points", minimum=2)
        thickness = self.number(self.required(o, "thickness", where), f"{where}.thickness", positive=True)
        orientation = self.orientation(self.required(o, "orientation", where), f"{where}.orientation")
        damping = self.number(self.required(o, "damping", where), f"{where}.damping", minimum=0.0, maximum=100.0)
        density = self.number(self.required(o, "density", where), f"{where}.density", positive=True)
        ks = self.number(self.required(o, "ks", where), f"{where}.ks", minimum=0.0)
        pinned = self.pinned(o.get("pinned", []), f"{where}.pinned", nw, nh)
        flags = {k: self.boolean(o[k], f"{where}.{k}") if k in o else True
                 for k in ("enable_structural", "enable_shearing", "enable_bending")}
        return ClothSpec(width=width, height=height, num_width_points=nw, num_height_points=nh,
                         thickness=thickness, orientation=orientation, damping=damping, density=density,
                         ks=ks, pinned=pinned, **flags)

    def orientation(self, value: Any, where: str) -> int:
        if isinstance(value, str):
            names = {"horizontal": HORIZONTAL, "vertical": VERTICAL}
            if value.lower() in names:
                return names[value.lower()]
            raise self.fail(where, f"unknown orientation {value!r} (expected 0/\"horizontal\" or 1/\"vertical\")")
        if isinstance(value, bool) or not isinstance(value, (int, float)) or value not in (0, 1):
            raise self.fail(where, f"unknown orientation {value!r} (expected 0/\"horizontal\" or 1/\"vertical\")")
        return int(value)

    def pinned(self, value: Any, where: str, nw: int, nh: int) -> tuple[tuple[int, int], ...]:
        if not isinstance(value, list):
            raise self.fail(where, f"expected a list of [x, y] index pairs, got {_type_name(value)}")
        out = []
        for i, pair in enumerate(value):
            at = f"{where}[{i}]"
            if not isinstance(pair, list) or len(pair) != 2:
                raise self.fail(at, f"expected an [x, y] index pair, got {json.dumps(pair)}")
            x = self.integer(pair[0], f"{at}[0]")
            y = self.integer(pair[1], f"{at}[1]")
            if not 0 <= x < nw:
                raise self.fail(f"{at}[0]", f"x index {x} out of range 0..{nw - 1} (num_width_points is {nw})")
            if not 0 <= y < nh:
                raise self.fail(f"{at}[1]", f"y index {y} out of range 0..{nh - 1} (num_height_points is {nh})")
            out.append((x, y))
        return tuple(out)

    def sphere(self, value: Any, where: str) -> SphereSpec:
        o = self.obj(value, where)
        self.warn_unknown(o, where, ("origin", "radius", "friction"))
        origin = self.vec3(self.required(o, "origin", where), f"{where}.origin")
        radius = self.number(self.required(o, "radius", where), f"{where}.radius", positive=True)
        friction = self.number(self.required(o, "friction", where), f"{where}.friction", minimum=0.0, maximum=1.0)
        return SphereSpec(origin=origin, radius=radius, friction=friction)

    def plane(self, value: Any, where: str) -> PlaneSpec:
        o = self.obj(value, where)
        self.warn_unknown(o, where, ("point", "normal", "friction"))
        point = self.vec3(self.required(o, "point", where), f"{where}.point")
        normal = self.vec3(self.required(o, "normal", where), f"{where}.normal")
        length = math.sqrt(sum(c * c for c in normal))
        if not length > 1e-12:
            raise self.fail(f"{where}.normal", "has zero length")
        unit = (normal[0] / length, normal[1] / length, normal[2] / length)
        friction = self.number(self.required(o, "friction", where), f"{where}.friction", minimum=0.0, maximum=1.0)
        return PlaneSpec(point=point, normal=unit, friction=friction)

    def simulation(self, value: Any, where: str) -> SimulationSpec:
        o = self.obj(value, where)
        d = SimulationSpec()
        known = ("frames_per_sec", "simulation_steps", "gravity", "self_collision", "seed", "integrator",
                 "damping_mode", "max_stretch", "rest_tolerance", "rest_frames")
        self.warn_unknown(o, where, known)
        fps = self.number(o.get("frames_per_sec", d.frames_per_sec), f"{where}.frames_per_sec", positive=True)
        steps = self.integer(o.get("simulation_steps", d.simulation_steps), f"{where}.simulation_steps", minimum=1)
        gravity = self.vec3(o["gravity"], f"{where}.gravity") if "gravity" in o else d.gravity
        self_collision = self.self_collision(o.get("self_collision", True), f"{where}.self_collision")
        seed = self.integer(o.get("seed", d.seed), f"{where}.seed", minimum=0)
        integrator = self.choice(o.get("integrator", d.integrator), f"{where}.integrator", INTEGRATORS)
        damping_mode = self.choice(o.get("damping_mode", d.damping_mode), f"{where}.damping_mode", DAMPING_MODES)
        max_stretch: float | None = d.max_stretch
        if "max_stretch" in o:
            raw = o["max_stretch"]
            max_stretch = None if raw is None else self.number(raw, f"{where}.max_stretch", minimum=0.0)
        rest_tol = self.number(o.get("rest_tolerance", d.rest_tolerance), f"{where}.rest_tolerance", positive=True)
        rest_frames = self.integer(o.get("rest_frames", d.rest_frames), f"{where}.rest_frames", minimum=1)
        return SimulationSpec(frames_per_sec=fps, simulation_steps=steps, gravity=gravity,
                              self_collision=self_collision, seed=seed, integrator=integrator,
                              damping_mode=damping_mode, max_stretch=max_stretch,
                              rest_tolerance=rest_tol, rest_frames=rest_frames)

    def self_collision(self, value: Any, where: str) -> str:
        if value is True:
            return "spec"
        if value is False:
            return "off"
        if isinstance(value, str) and value in ("spec", "grid"):
            return value
        raise self.fail(where, f"expected true, false, \"spec\" or \"grid\", got {json.dumps(value)}")

    def choice(self, value: Any, where: str, options: tuple[str, ...]) -> str:
        if not isinstance(value, str) or value not in options:
            raise self.fail(where, f"expected one of {', '.join(options)}; got {json.dumps(value)}")
        return value
