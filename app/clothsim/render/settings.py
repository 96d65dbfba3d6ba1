"""Render settings: defaults, validation of a scene's ``render`` object, and CLI overrides.

The ``render`` object (all keys optional)::

    {"shader": "phong", "size": [800, 800], "samples": 4,
     "camera": {"position": [x, y, z], "target": [x, y, z], "fov": 35, "near": 0.01, "far": 100},
     "color": "#8060c0" or [r, g, b], "background": [r, g, b],
     "light": {"position": [0.5, 2, 2], "intensity": [3, 3, 3]},
     "phong": {"k_a": 0.1, "k_d": 1.0, "k_s": 0.5, "p": 100, "I_a": [1, 1, 1],
               "terms": ["ambient", "diffuse", "specular"]},
     "normal_scaling": 2.0, "height_scaling": 0.1, "reflectivity": 0.35,
     "sphere_resolution": [40, 40],
     "textures": {"color": "cloth.png", "height": "bumps.png",
                  "cubemap": ["px.png", "nx.png", "py.png", "ny.png", "pz.png", "nz.png"]},
     "wireframe": {"color_by_family": false},
     "views": [{"position": [x, y, z], "target": [x, y, z], "fov": 35}, ...]}

``views`` are the fixed cameras of a sweep dataset's ``--views`` (each ``fov`` defaults to the
camera's); without them the dataset's cameras are drawn around the cloth from the run's seed.

Colours are sRGB in [0, 1] (or ``#rrggbb``), as a colour picker shows them; the renderer
linearises them before lighting. Texture paths are relative to the scene file.
"""

from __future__ import annotations

from dataclasses import dataclass, fields, replace
from pathlib import Path
from typing import Any, Callable

from .. import validate as V
from ..scene import Scene

SHADERS: tuple[str, ...] = (
    "wireframe", "normal", "diffuse", "phong", "texture", "bump", "displacement", "mirror", "custom",
)
TERMS: tuple[str, ...] = ("ambient", "diffuse", "specular")
# Looks that sample each resource; everything else never loads it.
USES_COLOR_TEXTURE = frozenset({"texture", "custom"})
USES_HEIGHT_MAP = frozenset({"bump", "displacement", "custom"})
USES_CUBEMAP = frozenset({"mirror", "custom"})
USES_TANGENTS = USES_HEIGHT_MAP
MAX_SIZE = 16384
MAX_SPHERE_RESOLUTION = 1024

Vec3 = tuple[float, float, float]


@dataclass(frozen=True)
class RenderSettings:
    """Everything that decides how a frame looks. Colours are sRGB in [0, 1]."""

    shader: str = "phong"
    size: tuple[int, int] = (800, 800)
    samples: int = 4
    camera_position: Vec3 | None = None  # None: the course's default view (see camera.py)
    camera_target: Vec3 | None = None
    fov: float = 35.0
    near: float = 0.01
    far: float = 100.0
    color: Vec3 = (1.0, 1.0, 1.0)
    background: Vec3 = (0.12, 0.13, 0.16)
    light_position: Vec3 = (0.5, 2.0, 2.0)
    light_intensity: Vec3 = (3.0, 3.0, 3.0)
    k_a: float = 0.1
    k_d: float = 1.0
    k_s: float = 0.5
    p: float = 100.0
    I_a: Vec3 = (1.0, 1.0, 1.0)
    terms: tuple[str, ...] = TERMS
    normal_scaling: float = 2.0
    height_scaling: float = 0.1
    reflectivity: float = 0.35
    sphere_resolution: tuple[int, int] = (40, 40)
    color_texture: str | None = None  # None: the built-in procedural texture
    height_texture: str | None = None
    cubemap: tuple[str, ...] | None = None  # six faces: +x, -x, +y, -y, +z, -z
    color_by_family: bool = False
    views: tuple[tuple[Vec3, Vec3, float | None], ...] | None = None  # (position, target, fov)

    @classmethod
    def from_scene(cls, scene: Scene, files: Any = None) -> "RenderSettings":
        """Defaults updated by the scene's ``render`` object (raises SceneError on bad values).

        Image paths are relative to the scene's folder; with ``files`` (an uploaded scene's
        :class:`~clothsim.assets.UploadedFiles`) they resolve through it alone.
        """
        if scene.render is None:
            return cls()
        base = Path(scene.path).parent if scene.path and not scene.path.startswith("<") else Path(".")
        return replace(cls(), **_render_values(scene.render, V.At(scene.path, "render", files=files), base))

    def with_overrides(self, overrides: dict[str, Any], source: str | None = None,
                       label: Callable[[str], str] | None = None) -> "RenderSettings":
        """A copy updated from a ``render``-shaped dict (e.g. built from CLI flags).

        Paths are relative to the working directory; errors name ``source`` (a file; none for
        flags) and ``label(field)`` (e.g. ``camera.fov`` -> ``--fov``).
        """
        return replace(self, **_render_values(overrides, V.At(source, "", label), Path(".")))


FIELD_NAMES = frozenset(f.name for f in fields(RenderSettings))


def srgb_to_linear(c: Vec3) -> Vec3:
    """Decode an sRGB colour to linear light (the exact piecewise curve)."""
    def one(x: float) -> float:
        return x / 12.92 if x <= 0.04045 else ((x + 0.055) / 1.055) ** 2.4
    return (one(c[0]), one(c[1]), one(c[2]))


def parse_size(text: str) -> tuple[int, int]:
    """``"800x600"`` -> (800, 600); raises ValueError."""
    parts = text.lower().replace("*", "x").split("x")
    if len(parts) != 2:
        raise ValueError(f"expected WIDTHxHEIGHT, got {text!r}")
    return int(parts[0]), int(parts[1])


def _size(value: Any, at: V.At) -> tuple[int, int]:
    if isinstance(value, str):
        try:
            value = list(parse_size(value))
        except ValueError:
            raise at.fail(f"expected WIDTHxHEIGHT or [width, height], got {V.shown(value)}") from None
    items = V.items_of(value)
    if items is None or len(items) != 2:
        raise at.fail(f"expected WIDTHxHEIGHT or [width, height], got {V.shown(value)}")
    side = V.integer(ge=1, le=MAX_SIZE)
    return (side(items[0], at.index(0)), side(items[1], at.index(1)))


def _power_of_two(n: int, at: V.At) -> int:
    if n & (n - 1):
        raise at.fail(f"must be 0 (no multisampling) or a power of two (1, 2, 4, 8, 16), got {n}")
    return n


def _colour(value: Any, at: V.At) -> Vec3:
    if isinstance(value, str):
        s = value.strip().lstrip("#")
        if len(s) != 6 or any(ch not in "0123456789abcdefABCDEF" for ch in s):
            raise at.fail(f"expected #rrggbb or [r, g, b] in 0..1, got {V.shown(value)}")
        r, g, b = (int(s[k:k + 2], 16) / 255.0 for k in (0, 2, 4))
        return (r, g, b)
    items = V.items_of(value)
    if items is None or len(items) != 3:
        raise at.fail(f"expected #rrggbb or [r, g, b] in 0..1, got {V.shown(value)}")
    return V.vec3(V.number(ge=0.0, le=1.0))(items, at)


def _terms(value: Any, at: V.At) -> tuple[str, ...]:
    if isinstance(value, str):
        value = [t.strip() for t in value.split(",") if t.strip()]
    chosen = V.list_of(V.choice(TERMS), nonempty=True, what=f"terms from {', '.join(TERMS)}")(value, at)
    return tuple(t for t in TERMS if t in chosen)


def _sphere_resolution(value: Any, at: V.At) -> tuple[int, int]:
    if isinstance(value, (int, float)) and not isinstance(value, bool):
        value = [value, value]
    items = V.items_of(value)
    if items is None or len(items) != 2:
        raise at.fail(f"expected [lat, long] or one integer, got {V.shown(value)}")
    return (V.integer(ge=2, le=MAX_SPHERE_RESOLUTION)(items[0], at.index(0)),
            V.integer(ge=3, le=MAX_SPHERE_RESOLUTION)(items[1], at.index(1)))


def _image_file(base: Path) -> V.Rule:
    def check(value: Any, at: V.At) -> str:
        if not isinstance(value, str) or not value:
            raise at.fail(f"expected an image file path, got {V.shown(value)}")
        if at.files is not None:
            return str(at.files.locate(value, at, "image"))
        try:
            p = Path(value).expanduser()
            if not p.is_absolute():
                p = base / p
            found = p.is_file()
        except (OSError, ValueError, RuntimeError):  # a NUL byte, a name too long, an unknown ~user
            found = False
            p = Path(value)
        if not found:
            text = str(p)
            # a path is quoted in full unless it could break the line or flood it
            raise at.fail(f"no such image file: {text if text.isprintable() and len(text) <= 300 else V.shown(text)}")
        return str(p)
    return check


def _render_rules(base: Path) -> V.record:
    """The ``render`` object's rules; image paths are relative to ``base``. Keys of the nested
    objects go under the :class:`RenderSettings` field they set (``camera.fov`` -> ``fov``)."""
    image = _image_file(base)
    vec, at_least_0 = V.vec3(), V.number(ge=0.0)
    opt = V.optional
    return V.record({
        "shader": opt(V.choice(SHADERS)),
        "size": opt(_size),
        "samples": opt(V.then(V.integer(ge=0, le=16), _power_of_two)),
        "camera": opt(V.record({
            "position": opt(vec, dest="camera_position"),
            "target": opt(vec, dest="camera_target"),
            "fov": opt(V.number(gt=0.0, le=179.0)),
            "near": opt(V.number(gt=0.0)),
            "far": opt(V.number(gt=0.0)),
        })),
        "color": opt(_colour),
        "background": opt(_colour),
        "light": opt(V.record({
            "position": opt(vec, dest="light_position"),
            "intensity": opt(V.vec3(at_least_0), dest="light_intensity"),
        })),
        "phong": opt(V.record({
            "k_a": opt(at_least_0),
            "k_d": opt(at_least_0),
            "k_s": opt(at_least_0),
            "p": opt(V.number(gt=0.0)),
            "I_a": opt(V.vec3(at_least_0)),
            "terms": opt(_terms),
        })),
        "normal_scaling": opt(at_least_0),
        "height_scaling": opt(at_least_0),
        "reflectivity": opt(V.number(ge=0.0, le=1.0)),
        "sphere_resolution": opt(_sphere_resolution),
        "textures": opt(V.record({
            "color": opt(image, dest="color_texture"),
            "height": opt(image, dest="height_texture"),
            "cubemap": opt(V.list_of(image, length=6, what="image paths (+x, -x, +y, -y, +z, -z)")),
        })),
        "wireframe": opt(V.record({"color_by_family": opt(V.boolean)})),
        "views": opt(V.then(V.list_of(V.record({
            "position": V.required(vec),
            "target": V.required(vec),
            "fov": opt(V.number(gt=0.0, le=179.0)),
        }), nonempty=True, what="cameras {position, target, fov}"), _views)),
    })


def _views(value: tuple[dict[str, Any], ...], at: V.At) -> tuple[tuple[Vec3, Vec3, float | None], ...]:
    out = []
    for k, v in enumerate(value):
        if tuple(v["position"]) == tuple(v["target"]):
            raise at.index(k).fail("position and target coincide")
        out.append((v["position"], v["target"], v.get("fov")))
    return tuple(out)


_NESTED = ("camera", "light", "phong", "textures", "wireframe")


def _render_values(raw: Any, at: V.At, base: Path) -> dict[str, Any]:
    """The :class:`RenderSettings` fields that a ``render``-shaped object sets, checked."""
    values = _render_rules(base)(raw, at)
    for key in _NESTED:
        values.update(values.pop(key, {}))
    return values
