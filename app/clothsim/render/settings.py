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
     "wireframe": {"color_by_family": false}}

Colours are sRGB in [0, 1] (or ``#rrggbb``), as a colour picker shows them; the renderer
linearises them before lighting. Texture paths are relative to the scene file.
"""

from __future__ import annotations

import math
import warnings
from dataclasses import dataclass, fields, replace
from pathlib import Path
from typing import Any, Callable

from ..errors import SceneError
from ..scene import Scene, SceneWarning

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

    @classmethod
    def from_scene(cls, scene: Scene) -> "RenderSettings":
        """Defaults updated by the scene's ``render`` object (raises SceneError on bad values)."""
        if scene.render is None:
            return cls()
        base = Path(scene.path).parent if scene.path and not scene.path.startswith("<") else Path(".")
        values = _RenderValidator(scene.path, base, lambda f: f"render.{f}" if f else "render").parse(scene.render)
        return replace(cls(), **values)

    def with_overrides(self, overrides: dict[str, Any], source: str = "command line",
                       label: Callable[[str], str] | None = None) -> "RenderSettings":
        """A copy updated from a ``render``-shaped dict (e.g. built from CLI flags).

        Paths are relative to the working directory; errors name ``source`` and ``label(field)``.
        """
        values = _RenderValidator(source, Path("."), label or (lambda f: f)).parse(overrides)
        return replace(self, **values)


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


class _RenderValidator:
    def __init__(self, path: str, base: Path, label: Callable[[str], str]) -> None:
        self.path = path
        self.base = base
        self.label = label

    def fail(self, field: str, problem: str) -> SceneError:
        return SceneError(self.path, self.label(field), problem)

    # -- primitives ------------------------------------------------------------------------
    def number(self, v: Any, f: str, lo: float | None = None, hi: float | None = None,
               lo_open: bool = False) -> float:
        if isinstance(v, bool) or not isinstance(v, (int, float)):
            raise self.fail(f, f"expected a number, got {v!r}")
        x = float(v)
        if not math.isfinite(x):
            raise self.fail(f, f"must be finite, got {v!r}")
        if lo is not None and (x <= lo if lo_open else x < lo):
            raise self.fail(f, f"must be {'>' if lo_open else '>='} {lo:g}, got {v!r}")
        if hi is not None and x > hi:
            raise self.fail(f, f"must be <= {hi:g}, got {v!r}")
        return x

    def integer(self, v: Any, f: str, lo: int, hi: int) -> int:
        if isinstance(v, bool) or not isinstance(v, (int, float)) or (isinstance(v, float) and not v.is_integer()):
            raise self.fail(f, f"expected an integer, got {v!r}")
        n = int(v)
        if not lo <= n <= hi:
            raise self.fail(f, f"must be between {lo} and {hi}, got {n}")
        return n

    def vec3(self, v: Any, f: str, lo: float | None = None) -> Vec3:
        if not isinstance(v, (list, tuple)) or len(v) != 3:
            raise self.fail(f, f"expected a list of 3 numbers, got {v!r}")
        x, y, z = (self.number(c, f"{f}[{i}]", lo) for i, c in enumerate(v))
        return (x, y, z)

    def color(self, v: Any, f: str) -> Vec3:
        if isinstance(v, str):
            s = v.strip().lstrip("#")
            if len(s) != 6 or any(ch not in "0123456789abcdefABCDEF" for ch in s):
                raise self.fail(f, f"expected #rrggbb or [r, g, b] in 0..1, got {v!r}")
            r, g, b = (int(s[k:k + 2], 16) / 255.0 for k in (0, 2, 4))
            return (r, g, b)
        if not isinstance(v, (list, tuple)) or len(v) != 3:
            raise self.fail(f, f"expected #rrggbb or [r, g, b] in 0..1, got {v!r}")
        r, g, b = (self.number(c, f"{f}[{i}]", 0.0, 1.0) for i, c in enumerate(v))
        return (r, g, b)

    def obj(self, v: Any, f: str, known: tuple[str, ...]) -> dict[str, Any]:
        if not isinstance(v, dict):
            raise self.fail(f, f"expected an object, got {v!r}")
        for key in v:
            if key not in known:
                sub = f"{f}.{key}" if f else key
                warnings.warn(f"{self.path}: {self.label(sub)}: unknown key, ignored",
                              SceneWarning, stacklevel=5)
        return v

    def file(self, v: Any, f: str) -> str:
        if not isinstance(v, str) or not v:
            raise self.fail(f, f"expected an image file path, got {v!r}")
        p = Path(v).expanduser()
        if not p.is_absolute():
            p = self.base / p
        if not p.is_file():
            raise self.fail(f, f"no such image file: {p}")
        return str(p)

    # -- the object ------------------------------------------------------------------------
    def parse(self, raw: Any) -> dict[str, Any]:
        known = ("shader", "size", "samples", "camera", "color", "background", "light", "phong",
                 "normal_scaling", "height_scaling", "reflectivity", "sphere_resolution", "textures",
                 "wireframe")
        o = self.obj(raw, "", known)
        out: dict[str, Any] = {}
        if "shader" in o:
            s = o["shader"]
            if not isinstance(s, str) or s not in SHADERS:
                raise self.fail("shader", f"unknown shader {s!r} (expected one of: {', '.join(SHADERS)})")
            out["shader"] = s
        if "size" in o:
            out["size"] = self.size(o["size"], "size")
        if "samples" in o:
            n = self.integer(o["samples"], "samples", 0, 16)
            if n & (n - 1):
                raise self.fail("samples", f"must be 0 (no multisampling) or a power of two (1, 2, 4, 8, 16), got {n}")
            out["samples"] = n
        if "camera" in o:
            cam = self.obj(o["camera"], "camera", ("position", "target", "fov", "near", "far"))
            if "position" in cam:
                out["camera_position"] = self.vec3(cam["position"], "camera.position")
            if "target" in cam:
                out["camera_target"] = self.vec3(cam["target"], "camera.target")
            if "fov" in cam:
                out["fov"] = self.number(cam["fov"], "camera.fov", 0.0, 179.0, lo_open=True)
            if "near" in cam:
                out["near"] = self.number(cam["near"], "camera.near", 0.0, lo_open=True)
            if "far" in cam:
                out["far"] = self.number(cam["far"], "camera.far", 0.0, lo_open=True)
        for key in ("color", "background"):
            if key in o:
                out[key] = self.color(o[key], key)
        if "light" in o:
            light = self.obj(o["light"], "light", ("position", "intensity"))
            if "position" in light:
                out["light_position"] = self.vec3(light["position"], "light.position")
            if "intensity" in light:
                out["light_intensity"] = self.vec3(light["intensity"], "light.intensity", 0.0)
        if "phong" in o:
            ph = self.obj(o["phong"], "phong", ("k_a", "k_d", "k_s", "p", "I_a", "terms"))
            for k in ("k_a", "k_d", "k_s"):
                if k in ph:
                    out[k] = self.number(ph[k], f"phong.{k}", 0.0)
            if "p" in ph:
                out["p"] = self.number(ph["p"], "phong.p", 0.0, lo_open=True)
            if "I_a" in ph:
                out["I_a"] = self.vec3(ph["I_a"], "phong.I_a", 0.0)
            if "terms" in ph:
                out["terms"] = self.terms(ph["terms"], "phong.terms")
        for key, hi in (("normal_scaling", None), ("height_scaling", None), ("reflectivity", 1.0)):
            if key in o:
                out[key] = self.number(o[key], key, 0.0, hi)
        if "sphere_resolution" in o:
            r = o["sphere_resolution"]
            if isinstance(r, (int, float)) and not isinstance(r, bool):
                r = [r, r]
            if not isinstance(r, (list, tuple)) or len(r) != 2:
                raise self.fail("sphere_resolution", f"expected [lat, long] or one integer, got {r!r}")
            out["sphere_resolution"] = (
                self.integer(r[0], "sphere_resolution[0]", 2, MAX_SPHERE_RESOLUTION),
                self.integer(r[1], "sphere_resolution[1]", 3, MAX_SPHERE_RESOLUTION),
            )
        if "textures" in o:
            tex = self.obj(o["textures"], "textures", ("color", "height", "cubemap"))
            if "color" in tex:
                out["color_texture"] = self.file(tex["color"], "textures.color")
            if "height" in tex:
                out["height_texture"] = self.file(tex["height"], "textures.height")
            if "cubemap" in tex:
                faces = tex["cubemap"]
                if not isinstance(faces, (list, tuple)) or len(faces) != 6:
                    raise self.fail("textures.cubemap", "expected a list of 6 image paths (+x, -x, +y, -y, +z, -z)")
                out["cubemap"] = tuple(self.file(p, f"textures.cubemap[{i}]") for i, p in enumerate(faces))
        if "wireframe" in o:
            wf = self.obj(o["wireframe"], "wireframe", ("color_by_family",))
            if "color_by_family" in wf:
                v = wf["color_by_family"]
                if not isinstance(v, bool):
                    raise self.fail("wireframe.color_by_family", f"expected true or false, got {v!r}")
                out["color_by_family"] = v
        return out

    def size(self, v: Any, f: str) -> tuple[int, int]:
        if isinstance(v, str):
            try:
                v = list(parse_size(v))
            except ValueError:
                raise self.fail(f, f"expected WIDTHxHEIGHT or [width, height], got {v!r}") from None
        if not isinstance(v, (list, tuple)) or len(v) != 2:
            raise self.fail(f, f"expected WIDTHxHEIGHT or [width, height], got {v!r}")
        return (self.integer(v[0], f"{f}[0]", 1, MAX_SIZE), self.integer(v[1], f"{f}[1]", 1, MAX_SIZE))

    def terms(self, v: Any, f: str) -> tuple[str, ...]:
        if isinstance(v, str):
            v = [t.strip() for t in v.split(",") if t.strip()]
        if not isinstance(v, (list, tuple)) or not v:
            raise self.fail(f, f"expected a non-empty list drawn from {', '.join(TERMS)}")
        for t in v:
            if t not in TERMS:
                raise self.fail(f, f"unknown term {t!r} (expected some of: {', '.join(TERMS)})")
        return tuple(t for t in TERMS if t in v)
