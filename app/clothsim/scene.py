"""Scene files: the course's JSON format (plus optional extensions) -> a validated, typed :class:`Scene`.

Course files load unchanged: top-level ``cloth``, ``sphere``, ``plane``. Extensions, all optional:
a ``simulation`` object, ``sphere``/``plane`` given as lists, ``wind`` (:mod:`clothsim.wind`),
``cloth.pin_motion`` (:mod:`clothsim.motion`), and a ``render`` object that the renderer
validates itself. Every problem raises :class:`~clothsim.errors.SceneError` naming the
file, the field path (``cloth.num_width_points``, ``sphere[1].radius``) and what is wrong.
"""

from __future__ import annotations

import json
import os
from dataclasses import dataclass, field, fields, replace
from pathlib import Path
from typing import Any, Mapping

from . import validate as V
from .errors import ClothsimError, SceneError
from .colliders import (KINDS, MAX_LENGTH, MIN_LENGTH, BoxSpec, CapsuleSpec, PlaneSpec,  # noqa: F401 - re-exported
                        SphereSpec, collider_json)
from .motion import MOTION, MotionSpec
from .meshcollider import MeshSpec
from .clothmesh import CLOTH_MESH, ClothMesh
from .resources import data_dir
from .validate import SceneWarning  # noqa: F401 - warned by the rules, imported from here by users
from .forces import FORCES
from .wind import WindSpec

HORIZONTAL = 0
VERTICAL = 1

INTEGRATORS = ("verlet", "symplectic_euler", "implicit_euler", "xpbd")
DAMPING_MODES = ("spec", "rate")
SELF_COLLISION_MODES = ("spec", "grid", "off", "contact")

# Bytes a run needs per grid point. Measured with tracemalloc (NumPy reports its buffers to it)
# over Simulation(scene) plus one frame, 64x64 to 512x512 points, every self-collision mode: the
# Simulation keeps 751.6 B a point; the peak of a frame is 800-816 B with the spec's Verlet and
# 1336-1380 B with symplectic_euler, implicit_euler and xpbd (their per-run state). Peak RSS of a
# 724x724 run agreed (787-790 and 726-1299 B). The constants add 25 % for what tracemalloc does
# not see (Numba's allocations inside kernels) and for the output's copies (.npz, vertex buffers).
BYTES_PER_POINT = 1024
BYTES_PER_POINT_OTHER_INTEGRATORS = 1728
# What the contact self-collision mode adds a point, counted from its arrays' sizes (not
# measured by tracemalloc: the search's tables are Numba's), plus 25 % as above: its group, 2,814-
# 2,828 B from 20x20 to 256x256 (pair arrays for 16 pairs of each kind a point, 1,920 B; the
# reference, the balls, the points' and elements' cells), and for each member of the thread team
# searching a rebuild, that search's tables (the elements' boxes, their grids' runs and entries,
# the boxes copied in table order): 618 B on the folded 20x20 cloth, counted as 1,024 B since a
# grid may have up to 8 cells an element.
CONTACT_BYTES_PER_POINT = 3584
CONTACT_SEARCH_BYTES_PER_POINT = 1280
# What a mesh cloth adds beyond its points (which count as a grid's: BYTES_PER_POINT covers the
# per-point state and the grid's six springs a point), counted from the arrays' sizes, not measured:
# a spring's ends, family and rest length in the cloth's springs (17 B) and in the simulator's lists
# (ends, stiffness, rest, its force buffer, two entries of the points' tables, Provot's copy: about
# 100 B), 144 B with the 25 %, taken as 192; a triangle's points, render vertices and line in
# the ClothMesh (56 B) and what the renderer and exporters build from it, taken as 128.
MESH_BYTES_PER_SPRING = 192
MESH_BYTES_PER_TRIANGLE = 128
#: The thread team's most members (clothsim.jit.CHUNKS, not imported here: that loads Numba).
MOST_MEMBERS = 8


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
    #: offset of every pinned point over time (``cloth.pin_motion``), None: pins stay put
    pin_motion: MotionSpec | None = None
    #: the cloth read from an OBJ (``cloth.mesh``); None for the spec's grid. A mesh cloth has no
    #: grid: width, height and the point counts are 0, orientation HORIZONTAL, ``pinned`` empty.
    mesh: ClothMesh | None = None
    #: a mesh cloth's pins: 0-based indices of the OBJ's ``v`` lines (through the weld to points)
    pinned_vertices: tuple[int, ...] = ()

    @property
    def is_mesh(self) -> bool:
        """True for a cloth read from an OBJ (``cloth.mesh``), False for the spec's grid."""
        return self.mesh is not None

    @property
    def num_points(self) -> int:
        if self.mesh is not None:
            return int(self.mesh.points.shape[0])
        return self.num_width_points * self.num_height_points

    def as_json(self) -> dict[str, Any]:
        """The object as a scene file writes it (what loads back to the same cloth); a grid's keys
        in the order of the fields."""
        if self.mesh is not None:
            out: dict[str, Any] = {"mesh": self.mesh.as_json(), "thickness": self.thickness,
                                   "damping": self.damping, "density": self.density, "ks": self.ks,
                                   "pinned_vertices": list(self.pinned_vertices)}
        else:
            out = {f.name: getattr(self, f.name) for f in fields(self) if f.name not in ("mesh", "pinned_vertices")}
            out["pinned"] = [list(p) for p in self.pinned]
        for key in ("enable_structural", "enable_shearing", "enable_bending"):
            out[key] = getattr(self, key)
        motion = self.pin_motion
        out.pop("pin_motion", None)
        if motion is not None:
            out["pin_motion"] = ({"velocity": list(motion.velocity)} if motion.velocity is not None else
                                 {"keyframes": [[t, list(p)] for t, p in motion.keyframes]})
        return out


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
    capsules: tuple[CapsuleSpec, ...] = ()
    boxes: tuple[BoxSpec, ...] = ()
    winds: tuple[WindSpec, ...] = ()
    simulation: SimulationSpec = field(default_factory=SimulationSpec)
    render: dict[str, Any] | None = None
    path: str = "<scene>"
    meshes: tuple[MeshSpec, ...] = ()

    @property
    def colliders(self) -> tuple[SphereSpec | PlaneSpec | CapsuleSpec | BoxSpec | MeshSpec, ...]:
        """Every collider, kind by kind in the order of :data:`clothsim.colliders.KINDS`."""
        return tuple(spec for kind in KINDS for spec in getattr(self, kind.attr))

    @property
    def moving(self) -> bool:
        """True when any collider carries a ``motion``."""
        return any(c.motion is not None for c in self.colliders)

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


def parse_scene(text: str, path: str = "<scene>", files: Any = None) -> Scene:
    """Parse scene JSON text; ``path`` is used in error messages.

    The files the scene names (meshes) are read beside ``path``, or, with ``files`` (an
    uploaded scene's :class:`~clothsim.assets.UploadedFiles`), only through it.
    """
    if not text.strip():
        raise SceneError(path, "", "file is empty (expected a JSON object)")
    try:
        data = json.loads(text)
    except json.JSONDecodeError as exc:
        raise SceneError(path, "", f"not valid JSON: {exc.msg} at line {exc.lineno} column {exc.colno}") from None
    except RecursionError:
        raise SceneError(path, "", "not valid JSON: nested too deeply") from None
    except ValueError as exc:  # e.g. an integer of more than 4300 digits
        raise SceneError(path, "", f"not valid JSON: {exc}") from None
    return scene_from_dict(data, path, files)


def scene_from_dict(data: Any, path: str = "<scene>", files: Any = None) -> Scene:
    """Validate an already-parsed JSON value into a :class:`Scene` (``files`` as in :func:`parse_scene`)."""
    if not isinstance(data, dict):
        raise SceneError(path, "", f"top level must be a JSON object, got {V.shown(data)}")
    values = SCENE(data, V.At(path, files=files))
    cloth = ClothSpec(**values["cloth"])
    forces = {kind.attr: values[kind.attr] for kind in FORCES}
    _check_memory(cloth, values["simulation"], path, forces, {kind.attr: values[kind.attr] for kind in KINDS})
    return Scene(cloth=cloth, simulation=values["simulation"], render=values["render"], path=path,
                 **{kind.attr: values[kind.attr] for kind in KINDS}, **forces)


def check_field(section: str, name: str, value: Any) -> Any:
    """Check one value of the ``cloth`` or ``simulation`` object as the loader does and return it
    converted (e.g. ``"vertical"`` -> 1); raises :class:`~clothsim.errors.FieldError` naming
    ``section.name``. The API setters of :class:`~clothsim.sim.Simulation` go through here."""
    rules = {"cloth": CLOTH, "simulation": SIMULATION}[section]
    return rules.check_one(name, value, V.At(None, f"{section}.{name}"))


# ----------------------------------------------------------------------------------------------
# The rules of each object (see validate.py)

# Counts that reach the kernels (substeps) or the .npz (seed, as int64) must fit 64 bits; a frame
# of a million substeps already takes seconds on the smallest grid. Springs hold their ends as
# int32 point indices, which bounds a side (the memory check bounds the whole grid far sooner).
MAX_SUBSTEPS = 1_000_000
MAX_SEED = 2**63 - 1
MAX_SIDE = 2**31 - 1
# Physical quantities are bounded far beyond any cloth (the course uses 1 m, 150 kg/m^2, ks 5000,
# 90 frames/s) so that what the step derives from them stays a finite, non-zero float64 for any
# combination: the mass per point (1e-28 kg at least), the substep (1e-12 s at least, and its
# square) and the stable-step estimate (ks / mass). Without the bounds, e.g. ks = 1e308 or
# frames_per_sec = 1e200 ended the stability check in a ZeroDivisionError.
MIN_DENSITY, MAX_DENSITY = 1e-6, 1e6
MAX_KS = 1e12
MIN_FPS, MAX_FPS = 1e-3, 1e6


def _pinned(done: dict[str, Any]) -> V.Rule:
    nw, nh = done["num_width_points"], done["num_height_points"]
    index = V.integer()

    def pair(value: Any, at: V.At) -> tuple[int, int]:
        items = V.items_of(value)
        if items is None or len(items) != 2:
            raise at.fail(f"expected an [x, y] index pair, got {V.shown(value)}")
        x, y = index(items[0], at.index(0)), index(items[1], at.index(1))
        if not 0 <= x < nw:
            raise at.index(0).fail(f"x index {x} out of range 0..{nw - 1} (num_width_points is {nw})")
        if not 0 <= y < nh:
            raise at.index(1).fail(f"y index {y} out of range 0..{nh - 1} (num_height_points is {nh})")
        return (x, y)
    return V.list_of(pair, what="[x, y] index pairs")


def _pinned_vertices(done: dict[str, Any]) -> V.Rule:
    mesh: ClothMesh = done["mesh"]
    count = int(mesh.vertex_point.shape[0])
    index = V.integer()

    def one(value: Any, at: V.At) -> int:
        i = index(value, at)
        if not 0 <= i < count:
            raise at.fail(f"vertex index {i} out of range 0..{count - 1} (the OBJ has {count} vertices)")
        if mesh.vertex_point[i] < 0:
            raise at.fail(f"vertex {i} is not part of the cloth: no face uses it")
        return i
    return V.list_of(one, what="0-based OBJ vertex indices")


def _pin_motion(pins: str) -> Any:
    def depends(done: dict[str, Any]) -> V.Rule:
        def check(value: Any, at: V.At) -> MotionSpec | None:
            if value is None:
                return None
            motion = MOTION(value, at)
            if not done.get(pins):
                raise at.fail(f"the cloth has no pinned points to move (cloth.{pins} is empty)")
            return motion
        return check
    return depends


_ORIENTATION = V.choice((), aliases={0: HORIZONTAL, 1: VERTICAL, "horizontal": HORIZONTAL, "vertical": VERTICAL},
                        expected='0/"horizontal" or 1/"vertical"', fold_case=True)

_THICKNESS = V.required(V.number(gt=0.0))
_MATERIAL = {
    "damping": V.required(V.number(ge=0.0, le=100.0)),
    "density": V.required(V.number(ge=MIN_DENSITY, le=MAX_DENSITY)),
    "ks": V.required(V.number(ge=0.0, le=MAX_KS)),
    "enable_structural": V.default(V.boolean, True),
    "enable_shearing": V.default(V.boolean, True),
    "enable_bending": V.default(V.boolean, True),
}
_GRID = {
    "width": V.required(V.number(ge=MIN_LENGTH, le=MAX_LENGTH)),
    "height": V.required(V.number(ge=MIN_LENGTH, le=MAX_LENGTH)),
    "num_width_points": V.required(V.integer(ge=2, le=MAX_SIDE)),
    "num_height_points": V.required(V.integer(ge=2, le=MAX_SIDE)),
    "thickness": _THICKNESS,
    "orientation": V.required(_ORIENTATION),
    "pinned": V.Field(depends=_pinned, default=()),
    **_MATERIAL,
    "pin_motion": V.Field(depends=_pin_motion("pinned"), default=None),
}
#: The grid's keys, which a mesh cloth takes from its mesh (or, for pins, from ``pinned_vertices``).
GRID_ONLY = ("width", "height", "num_width_points", "num_height_points", "orientation", "pinned")
_MESH_CLOTH = V.record({
    "mesh": V.required(CLOTH_MESH),
    "thickness": _THICKNESS,
    "pinned_vertices": V.Field(depends=_pinned_vertices, default=()),
    **_MATERIAL,
    "pin_motion": V.Field(depends=_pin_motion("pinned_vertices"), default=None),
})
_NO_GRID = {"width": 0.0, "height": 0.0, "num_width_points": 0, "num_height_points": 0, "orientation": HORIZONTAL,
            "pinned": ()}


class _Cloth(V.record):
    """The ``cloth`` object: the spec's grid, or with ``mesh`` a cloth read from an OBJ. Its own
    fields (and :meth:`check_one`, the setters') are the grid's."""

    def __call__(self, value: Any, at: V.At) -> dict[str, Any]:
        if isinstance(value, Mapping) and value.get("mesh") is not None:
            for key in GRID_ONLY:
                if key in value:
                    why = ("pin OBJ vertices with cloth.pinned_vertices" if key == "pinned"
                           else "the mesh gives the shape")
                    raise at.key(key).fail(f"not allowed with cloth.mesh ({why})")
            return {**_NO_GRID, **_MESH_CLOTH(value, at)}
        if isinstance(value, Mapping) and ("mesh" in value or "pinned_vertices" in value):
            # a grid written out with every field (``"mesh": null``, no pinned vertices) loads as one
            pins = value.get("pinned_vertices")
            if pins is not None and V.items_of(pins) != []:
                raise at.key("pinned_vertices").fail("only with cloth.mesh (a grid cloth pins [x, y] index "
                                                     "pairs with cloth.pinned)")
            value = {k: v for k, v in value.items() if k not in ("mesh", "pinned_vertices")}
        return super().__call__(value, at)


CLOTH = _Cloth(_GRID)

_SIM_DEFAULTS = SimulationSpec()
SIMULATION = V.record({
    "frames_per_sec": V.default(V.number(ge=MIN_FPS, le=MAX_FPS), _SIM_DEFAULTS.frames_per_sec),
    "simulation_steps": V.default(V.integer(ge=1, le=MAX_SUBSTEPS), _SIM_DEFAULTS.simulation_steps),
    "gravity": V.default(V.vec3(), _SIM_DEFAULTS.gravity),
    "self_collision": V.default(
        V.choice(SELF_COLLISION_MODES, aliases={True: "spec", False: "off"},
                 expected='true, false, "spec", "grid", "off" or "contact"'),
        _SIM_DEFAULTS.self_collision),
    "seed": V.default(V.integer(ge=0, le=MAX_SEED), _SIM_DEFAULTS.seed),
    "integrator": V.default(V.choice(INTEGRATORS), _SIM_DEFAULTS.integrator),
    "damping_mode": V.default(V.choice(DAMPING_MODES), _SIM_DEFAULTS.damping_mode),
    "max_stretch": V.default(V.nullable(V.number(ge=0.0)), _SIM_DEFAULTS.max_stretch),
    "rest_tolerance": V.default(V.number(gt=0.0), _SIM_DEFAULTS.rest_tolerance),
    "rest_frames": V.default(V.integer(ge=1), _SIM_DEFAULTS.rest_frames),
})


def _simulation(value: Any, at: V.At) -> SimulationSpec:
    return SimulationSpec(**SIMULATION(value, at))


def _render(value: Any, at: V.At) -> dict[str, Any]:
    # Only its shape here: the renderer checks the contents (render/settings.py), with the same rules.
    if not isinstance(value, dict):
        raise at.fail(f"expected an object, got {V.shown(value)}")
    return value


SCENE = V.record({
    "cloth": V.required(CLOTH),
    **{kind.key: V.default(V.one_or_many(kind.rule), (), dest=kind.attr) for kind in KINDS},
    **{kind.key: V.default(kind.rule, (), dest=kind.attr) for kind in FORCES},
    "simulation": V.default(_simulation, _SIM_DEFAULTS, dest="simulation"),
    "render": V.default(_render, None),
}, unknown=("unknown top-level object (expected one of: cloth, " + ", ".join(k.key for k in KINDS)
            + "".join(f", {k.key}" for k in FORCES) + ", simulation, render)"))


# ----------------------------------------------------------------------------------------------
# Memory


def _human_bytes(n: float) -> str:
    n = float(n)
    for unit in ("B", "KiB", "MiB", "GiB", "TiB", "PiB"):
        if n < 1024 or unit == "PiB":
            return f"{n:.1f} {unit}" if unit != "B" else f"{int(n)} B"
        n /= 1024
    return f"{n:.1f} PiB"


CGROUP_ROOT = Path("/sys/fs/cgroup")
# cgroup v1 writes "no limit" as a page-rounded 2^63; anything this large is no limit.
_NO_LIMIT = 2**60


def _read_number(path: Path) -> int | None:
    try:
        text = path.read_text(encoding="ascii").strip()
        return None if text == "max" else int(text)
    except (OSError, ValueError):
        return None


def _stat_value(path: Path, key: str) -> int:
    try:
        with open(path, encoding="ascii") as fh:
            for line in fh:
                name, _, value = line.partition(" ")
                if name == key:
                    return int(value)
    except (OSError, ValueError):
        pass
    return 0


def cgroup_memory_available(root: Path = CGROUP_ROOT, self_cgroup: Path = Path("/proc/self/cgroup")) -> int | None:
    """Bytes this process's memory cgroup still allows (its limit less its usage, page cache that
    can be dropped not counted as used), the tightest over the cgroup and its parents; None when
    no limit is set or none can be read. Reads cgroup v2 (``memory.max``) and v1
    (``memory/memory.limit_in_bytes``)."""
    try:
        lines = self_cgroup.read_text(encoding="ascii").splitlines()
    except (OSError, UnicodeDecodeError):
        lines = []
    own: dict[str, str] = {}
    for line in lines:
        _, controllers, rel = line.split(":", 2) if line.count(":") >= 2 else ("", "", "")
        if controllers == "":
            own["v2"] = rel
        elif "memory" in controllers.split(","):
            own["v1"] = rel
    layouts = (("v2", root, "memory.max", "memory.current", "inactive_file"),
               ("v1", root / "memory", "memory.limit_in_bytes", "memory.usage_in_bytes", "total_inactive_file"))
    best: int | None = None
    for version, base, limit_file, usage_file, cache_key in layouts:
        # The process's own cgroup and its parents up to the mount point; inside a container with
        # its own cgroup namespace the mount point itself is the container's cgroup.
        rel = Path(own.get(version, "/").lstrip("/"))
        dirs = [base / rel, *[base / p for p in rel.parents]]
        for d in dict.fromkeys(dirs):
            limit = _read_number(d / limit_file)
            if limit is None or limit >= _NO_LIMIT:
                continue
            usage = _read_number(d / usage_file)
            used = 0 if usage is None else max(0, usage - _stat_value(d / "memory.stat", cache_key))
            left = max(0, limit - used)
            best = left if best is None else min(best, left)
    return best


def available_memory() -> int:
    """Bytes of memory available to a new allocation: MemAvailable (else physical memory), and no
    more than the memory cgroup (a container's limit) still allows."""
    avail = None
    try:
        with open("/proc/meminfo", encoding="ascii") as fh:
            for line in fh:
                if line.startswith("MemAvailable:"):
                    avail = int(line.split()[1]) * 1024
                    break
    except (OSError, ValueError):
        pass
    if avail is None:
        try:
            avail = int(os.sysconf("SC_PAGE_SIZE") * os.sysconf("SC_PHYS_PAGES"))
        except (ValueError, OSError, AttributeError):
            avail = 8 * 1024**3
    limit = cgroup_memory_available()
    return avail if limit is None else min(avail, limit)


def bytes_per_point(simulation: SimulationSpec) -> int:
    """Memory a run needs per grid point (see BYTES_PER_POINT): the spec's Verlet keeps no state
    beyond the Simulation; every other integrator or damping mode keeps its own; the contact
    mode adds its pairs and cells, and a rebuild's tables for each member of the team that may
    search it (on the spec's Verlet, as many as the machine has cores, up to the team's most)."""
    spec_path = simulation.integrator == "verlet" and simulation.damping_mode == "spec"
    need = BYTES_PER_POINT if spec_path else BYTES_PER_POINT_OTHER_INTEGRATORS
    if simulation.self_collision == "contact":
        searching = min(MOST_MEMBERS, os.cpu_count() or 1) if spec_path else 1
        need += CONTACT_BYTES_PER_POINT + searching * CONTACT_SEARCH_BYTES_PER_POINT
    return need


def check_memory(scene: Scene) -> None:
    """Refuse (SceneError naming the grid size) a scene whose run would not fit in memory."""
    _check_memory(scene.cloth, scene.simulation, scene.path, {kind.attr: getattr(scene, kind.attr) for kind in FORCES},
                  {kind.attr: getattr(scene, kind.attr) for kind in KINDS})


def _check_memory(cloth: ClothSpec, simulation: SimulationSpec, path: str, forces: dict[str, tuple],
                  colliders: dict[str, tuple]) -> None:
    extra = (sum(kind.bytes_per_point(forces[kind.attr]) for kind in FORCES)
             + sum(kind.bytes_per_point(colliders[kind.attr]) for kind in KINDS))
    need = cloth.num_points * (bytes_per_point(simulation) + extra)
    mesh = cloth.mesh
    if mesh is not None:
        need += mesh.spring_i.shape[0] * MESH_BYTES_PER_SPRING + mesh.triangles.shape[0] * MESH_BYTES_PER_TRIANGLE
    avail = available_memory()
    if need > avail and mesh is not None:
        raise SceneError(
            path,
            "cloth.mesh.path",
            f"{mesh.path}: a cloth of {cloth.num_points} points, {mesh.spring_i.shape[0]} springs and "
            f"{mesh.triangles.shape[0]} triangles would need about {_human_bytes(need)} of memory; only "
            f"{_human_bytes(avail)} is available",
        )
    if need > avail:
        raise SceneError(
            path,
            "cloth.num_width_points",
            f"a {cloth.num_width_points}x{cloth.num_height_points} grid would need about "
            f"{_human_bytes(need)} of memory; only {_human_bytes(avail)} is available",
        )
