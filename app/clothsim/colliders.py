"""The collider kinds a scene may hold, in one registry (:data:`KINDS`): sphere, plane, capsule,
box and triangle mesh.

Each :class:`ColliderKind` names its scene-file key, the :class:`~clothsim.scene.Scene` field
that holds its specs, the rule that validates one object into a spec, how a spec is written back
as scene JSON, and its pass module in :mod:`clothsim.sim.passes.colliders` (the simulator's side:
its group, packing, pose, reach test and collision). The order of :data:`KINDS` is the order in
which colliders are packed, collided, drawn and exported; the scene loader, the simulator, the
sweeps' scene writer, the renderer, the exporters and the serve limits iterate :data:`KINDS`
rather than naming the kinds. Every kind may carry a ``motion`` (:mod:`clothsim.motion`): a
translation track of its ``anchor`` and a turn about it, evaluated at the simulation's one clock
(:mod:`clothsim.sim.clock`).
"""

from __future__ import annotations

import math
from dataclasses import dataclass, fields
from typing import Any, Callable, ClassVar

from . import validate as V
from .meshcollider import MESH, MESH_BYTES_PER_POINT
from .motion import COLLIDER_MOTION, MotionSpec

#: Bounds of every length a scene gives (the cloth's sides, a collider's sizes): far beyond any
#: cloth, so that what the step derives from them stays a finite, non-zero float64.
MIN_LENGTH, MAX_LENGTH = 1e-6, 1e6
_FRICTION = V.number(ge=0.0, le=1.0)


class Anchored:
    """A collider spec whose ``motion`` keyframes give the position of one of its fields (named by
    ``ANCHOR``): its ``anchor``."""

    ANCHOR: ClassVar[str]

    @property
    def anchor(self) -> tuple[float, float, float]:
        """The position a ``motion`` keyframe gives (the field ``ANCHOR`` names)."""
        return getattr(self, self.ANCHOR)


@dataclass(frozen=True)
class SphereSpec(Anchored):
    """A sphere collider; ``motion`` (optional) moves its origin."""

    ANCHOR: ClassVar[str] = "origin"
    origin: tuple[float, float, float]
    radius: float
    friction: float
    motion: MotionSpec | None = None


@dataclass(frozen=True)
class PlaneSpec(Anchored):
    """A plane collider; ``normal`` is stored normalised; ``motion`` (optional) moves its point."""

    ANCHOR: ClassVar[str] = "point"
    point: tuple[float, float, float]
    normal: tuple[float, float, float]
    friction: float
    motion: MotionSpec | None = None


@dataclass(frozen=True)
class CapsuleSpec:
    """A capsule collider: the points within ``radius`` of the segment a-b. ``motion`` (optional)
    moves the segment rigidly: a keyframe gives the position of its midpoint."""

    a: tuple[float, float, float]
    b: tuple[float, float, float]
    radius: float
    friction: float
    motion: MotionSpec | None = None

    @property
    def anchor(self) -> tuple[float, float, float]:
        """The segment's midpoint (what a ``motion`` keyframe places)."""
        return tuple(0.5 * (p + q) for p, q in zip(self.a, self.b))  # type: ignore[return-value]


@dataclass(frozen=True)
class BoxSpec(Anchored):
    """An oriented box collider: ``center``, ``half_extents`` along its own axes and ``rotation``
    in degrees about x, y, z, applied as R = Rz . Ry . Rx (x first, right-handed). ``motion``
    (optional) moves and turns it about its center."""

    ANCHOR: ClassVar[str] = "center"
    center: tuple[float, float, float]
    half_extents: tuple[float, float, float]
    rotation: tuple[float, float, float]
    friction: float
    motion: MotionSpec | None = None

    def matrix(self) -> tuple[tuple[float, float, float], ...]:
        """R = Rz . Ry . Rx as three rows: box axes to world (column k is the box's k-th axis)."""
        rx, ry, rz = (math.radians(a) for a in self.rotation)
        cx, sx, cy, sy, cz, sz = math.cos(rx), math.sin(rx), math.cos(ry), math.sin(ry), math.cos(rz), math.sin(rz)
        return ((cz * cy, cz * sy * sx - sz * cx, cz * sy * cx + sz * sx),
                (sz * cy, sz * sy * sx + cz * cx, sz * sy * cx - cz * sx),
                (-sy, cy * sx, cy * cx))


# ----------------------------------------------------------------------------------------------
# Rules

def _unit(v: tuple[float, float, float], at: V.At) -> tuple[float, float, float]:
    length = math.hypot(*v)
    return (v[0] / length, v[1] / length, v[2] / length)


# Collider sizes: positive and bounded like the cloth's lengths (MIN_LENGTH..MAX_LENGTH), so that a collider's bounding box
# and the sub-sampling step derived from its smallest size stay finite and non-zero.
_SIZE = V.number(ge=MIN_LENGTH, le=MAX_LENGTH)
_ANGLE = V.number(ge=-36000.0, le=36000.0)

SPHERE = V.record({
    "origin": V.required(V.vec3()),
    "radius": V.required(V.number(gt=0.0)),
    "friction": V.required(_FRICTION),
    "motion": V.optional(COLLIDER_MOTION),
})

PLANE = V.record({
    "point": V.required(V.vec3()),
    "normal": V.required(V.then(V.vec3(nonzero=True), _unit)),
    "friction": V.required(_FRICTION),
    "motion": V.optional(COLLIDER_MOTION),
})

CAPSULE = V.record({
    "a": V.required(V.vec3()),
    "b": V.required(V.vec3()),
    "radius": V.required(_SIZE),
    "friction": V.required(_FRICTION),
    "motion": V.optional(COLLIDER_MOTION),
})

BOX = V.record({
    "center": V.required(V.vec3()),
    "half_extents": V.required(V.vec3(_SIZE)),
    "rotation": V.default(V.vec3(_ANGLE), (0.0, 0.0, 0.0)),
    "friction": V.required(_FRICTION),
    "motion": V.optional(COLLIDER_MOTION),
})


def collider_json(spec: SphereSpec | PlaneSpec | CapsuleSpec | BoxSpec) -> dict[str, Any]:
    """A collider as scene-file JSON (what loads back to the same spec)."""
    out: dict[str, Any] = {k: list(v) if isinstance(v, tuple) else v
                           for k, v in ((f.name, getattr(spec, f.name)) for f in fields(spec)) if k != "motion"}
    if spec.motion is not None:
        out["motion"] = motion_json(spec.motion)
    return out


def motion_json(motion: MotionSpec) -> dict[str, Any]:
    """A ``motion`` object as scene-file JSON."""
    return motion.as_json()


@dataclass(frozen=True)
class ColliderKind:
    """One kind of collider (see the module's docstring)."""

    #: the scene file's top-level key ("sphere")
    key: str
    #: the :class:`~clothsim.scene.Scene` field holding this kind's specs ("spheres")
    attr: str
    #: validates one scene object into a spec
    rule: V.Rule
    #: a spec back as scene-file JSON (what loads back to the same spec)
    to_json: Callable[[Any], dict[str, Any]]
    #: its pass module in clothsim.sim.passes.colliders
    pass_module: str
    #: bytes per cloth point its pass adds, given the scene's specs of the kind (for the memory check)
    bytes_per_point: Callable[[tuple], int] = lambda specs: 0


def _spec_rule(record: V.Rule, spec: type) -> V.Rule:
    return V.then(record, lambda v, at: spec(**v))


#: Every collider kind, in scene order (the order colliders are packed, collided, drawn, exported).
KINDS: tuple[ColliderKind, ...] = (
    ColliderKind("sphere", "spheres", _spec_rule(SPHERE, SphereSpec), collider_json, "sphere"),
    ColliderKind("plane", "planes", _spec_rule(PLANE, PlaneSpec), collider_json, "plane"),
    ColliderKind("capsule", "capsules", _spec_rule(CAPSULE, CapsuleSpec), collider_json, "capsule"),
    ColliderKind("box", "boxes", _spec_rule(BOX, BoxSpec), collider_json, "box"),
    ColliderKind("mesh", "meshes", MESH, lambda spec: spec.as_json(), "mesh",
                 lambda specs: len(specs) * MESH_BYTES_PER_POINT),
)
#: The kinds by scene-file key.
BY_KEY: dict[str, ColliderKind] = {k.key: k for k in KINDS}


def scene_colliders(scene: Any) -> list[tuple[ColliderKind, int, Any]]:
    """Every collider of ``scene`` as (kind, index within its kind, spec), kind by kind."""
    return [(kind, i, spec) for kind in KINDS for i, spec in enumerate(getattr(scene, kind.attr))]


def kinds_text(final: str = "or") -> str:
    """The kinds' keys as prose: "sphere, plane, capsule, box or mesh"."""
    keys = [k.key for k in KINDS]
    return f"{', '.join(keys[:-1])} {final} {keys[-1]}"
