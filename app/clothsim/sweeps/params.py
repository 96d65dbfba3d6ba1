"""A sweep's parameters: ``--set FIELD=VALUES`` parsing, grid and sampling expansion, and each
run's scene built from the base scene's JSON and validated by the scene loader's own rules.

``FIELD`` is a dotted path into the scene file's JSON (``cloth.ks``, ``render.light.intensity``,
``sphere.1.radius`` for the second sphere of a list). ``VALUES`` is a comma-separated list of JSON
scalars (a bare word that is not JSON is taken as a string: ``spec,grid``). With sampling, a
field may instead be ``uniform:A:B`` or ``loguniform:A:B``; a list is then drawn from uniformly.
Run ``i`` of a sampled sweep draws from ``numpy.random.default_rng([seed, i])`` only, so its
parameters depend on the seed and its index alone.
"""

from __future__ import annotations

import copy
import dataclasses
import itertools
import json
import math
import re
import warnings
from dataclasses import dataclass
from typing import Any

import numpy as np

from ..errors import ClothsimError, FieldError
from ..colliders import KINDS
from ..forces import FORCES
from ..scene import Scene, scene_from_dict
from ..validate import SceneWarning, shown

__all__ = ["Distribution", "Run", "build_scene", "expand", "parse_set", "parse_values", "run_id",
           "scene_json", "set_field"]

_DISTRIBUTIONS = ("uniform", "loguniform")
_INDEX = re.compile(r"[0-9]+")  # a list index in a field path


@dataclass(frozen=True)
class Distribution:
    """``uniform:A:B`` or ``loguniform:A:B`` (A < B; both > 0 for loguniform)."""

    kind: str
    low: float
    high: float

    def draw(self, rng: np.random.Generator) -> float:
        if self.kind == "uniform":
            return float(rng.uniform(self.low, self.high))
        return float(math.exp(rng.uniform(math.log(self.low), math.log(self.high))))

    def __str__(self) -> str:
        return f"{self.kind}:{self.low!r}:{self.high!r}"


@dataclass(frozen=True)
class Run:
    """One run of a sweep: its id (``run_00000``), index and parameter values by field path."""

    index: int
    params: dict[str, Any]

    @property
    def id(self) -> str:
        return run_id(self.index)


def run_id(index: int) -> str:
    return f"run_{index:05d}"


# -- parsing -------------------------------------------------------------------------------------
def _scalar(text: str, label: str) -> Any:
    text = text.strip()
    if not text:
        raise ClothsimError(f"{label}: empty value (VALUES is a comma-separated list)")
    for kind in _DISTRIBUTIONS:
        if text.startswith(kind + ":"):
            return _distribution(kind, text, label)
    try:
        value = json.loads(text)
    except ValueError:
        return text  # a bare word: a string, e.g. spec,grid
    if isinstance(value, (list, dict)) or value is None:
        raise ClothsimError(f"{label}: {text!r} is not a scalar (VALUES is a comma-separated list of "
                            "numbers, true/false or strings)")
    if isinstance(value, float) and not math.isfinite(value):
        raise ClothsimError(f"{label}: {text!r} is not a finite number")
    return value


def _distribution(kind: str, text: str, label: str) -> Distribution:
    parts = text.split(":")
    try:
        if len(parts) != 3:
            raise ValueError
        low, high = float(parts[1]), float(parts[2])
    except ValueError:
        raise ClothsimError(f"{label}: expected {kind}:A:B with numbers A < B, got {text!r}") from None
    if not (math.isfinite(low) and math.isfinite(high) and low < high):
        raise ClothsimError(f"{label}: expected {kind}:A:B with finite A < B, got {text!r}")
    if kind == "loguniform" and low <= 0:
        raise ClothsimError(f"{label}: loguniform needs 0 < A < B, got {text!r}")
    return Distribution(kind, low, high)


def parse_values(field: str, values: Any, label: str | None = None) -> list[Any]:
    """The values of one field: a text ``1,15,1000`` or a list (from the API); checked for shape."""
    label = label or f"--set {field}"
    if isinstance(values, str):
        return [_scalar(v, label) for v in values.split(",")]
    if isinstance(values, Distribution):
        return [values]
    if isinstance(values, (list, tuple)):
        if not values:
            raise ClothsimError(f"{label}: no values")
        out = []
        for v in values:
            if isinstance(v, str):
                out.append(_scalar(v, label))
            elif isinstance(v, (bool, int, float, Distribution)) or isinstance(v, np.generic):
                out.append(v.item() if isinstance(v, np.generic) else v)
            else:
                raise ClothsimError(f"{label}: {shown(v)} is not a scalar")
        return out
    if isinstance(values, (bool, int, float)):
        return [values]
    raise ClothsimError(f"{label}: expected a list of values, got {shown(values)}")


def parse_set(text: str) -> tuple[str, list[Any]]:
    """``"cloth.ks=10,5000"`` -> ``("cloth.ks", [10, 5000])``."""
    field, sep, values = text.partition("=")
    field = field.strip()
    if not sep or not field:
        raise ClothsimError(f"--set {text}: expected FIELD=VALUES, e.g. cloth.ks=10,5000,200000")
    return field, parse_values(field, values, f"--set {field}")


def _path_parts(field: str) -> list[str | int]:
    parts: list[str | int] = []
    for part in field.split("."):
        if not part:
            raise ClothsimError(f"--set {field}: empty component in the field path")
        # ASCII digits only: str.isdigit() also accepts '²' and '①', which int() refuses.
        if not _INDEX.fullmatch(part) and any(c.isdigit() or c.isnumeric() for c in part):
            if not any(c.isalpha() or c == "_" for c in part):
                raise ClothsimError(f"--set {field}: {part!r} is not a list index (an index is written "
                                    "with the digits 0-9, e.g. sphere.1.radius)")
        parts.append(int(part) if _INDEX.fullmatch(part) else part)
    if isinstance(parts[0], int):
        raise ClothsimError(f"--set {field}: a field path starts with an object name (cloth, sphere, ...)")
    return parts


def loader_path(field: str) -> str:
    """The field as the scene loader names it: ``sphere.1.radius`` -> ``sphere[1].radius``."""
    out = ""
    for part in _path_parts(field):
        out += f"[{part}]" if isinstance(part, int) else (f".{part}" if out else part)
    return out


# -- expansion -----------------------------------------------------------------------------------
def expand(space: dict[str, list[Any]], samples: int | None = None, seed: int | None = None) -> list[Run]:
    """The runs of a sweep: the full grid in order (last field fastest), or ``samples`` draws."""
    if not space:
        raise ClothsimError("--set: give at least one FIELD=VALUES")
    if samples is None:
        for field, values in space.items():
            for v in values:
                if isinstance(v, Distribution):
                    raise ClothsimError(f"--set {field}: {v} needs --samples N (a grid takes listed values)")
        combos = itertools.product(*space.values())
        return [Run(i, dict(zip(space, combo))) for i, combo in enumerate(combos)]
    if seed is None:
        raise ClothsimError("--samples: needs --seed S (run i's parameters depend on S and i only)")
    runs = []
    for i in range(samples):
        rng = np.random.default_rng([seed, i])
        params = {}
        for field, values in space.items():
            if len(values) == 1 and isinstance(values[0], Distribution):
                params[field] = values[0].draw(rng)
            else:
                pick = values[int(rng.integers(len(values)))]
                params[field] = pick.draw(rng) if isinstance(pick, Distribution) else pick
        runs.append(Run(i, params))
    return runs


# -- scenes --------------------------------------------------------------------------------------
def set_field(data: dict[str, Any], field: str, value: Any) -> None:
    """Set a dotted path in a scene's JSON (in place); intermediate objects are created."""
    parts = _path_parts(field)
    node: Any = data
    for k, part in enumerate(parts):
        last = k == len(parts) - 1
        where = ".".join(str(p) for p in parts[:k + 1])
        if isinstance(part, int):
            if isinstance(node, dict):
                if part != 0:  # a single object is item 0 of a one-item list
                    raise ClothsimError(f"--set {field}: {where[:where.rfind('.')]} is one object, "
                                        f"not a list (only index 0 exists)")
                if last:
                    raise ClothsimError(f"--set {field}: cannot replace a whole object")
                continue
            if not isinstance(node, list) or not 0 <= part < len(node):
                n = len(node) if isinstance(node, list) else 0
                raise ClothsimError(f"--set {field}: no item {part} (the list has {n})")
            if last:
                node[part] = value
            else:
                node = node[part]
            continue
        if isinstance(node, list):
            raise ClothsimError(f"--set {field}: {where[:where.rfind('.')]} is a list; "
                                f"name an item, e.g. {where[:where.rfind('.')]}.0.{part}")
        if not isinstance(node, dict):
            raise ClothsimError(f"--set {field}: {where[:where.rfind('.')]} is not an object")
        if last:
            node[part] = value
        else:
            if part not in node:
                node[part] = {}
            node = node[part]


def build_scene(base: dict[str, Any], params: dict[str, Any], path: str, label: str = "") -> Scene:
    """The scene of one run: ``base`` with ``params`` set, validated as a scene file would be.

    Raises one line naming the field path; a field the loader does not know (it would only warn
    and ignore it in a file) is an error here, since a sweep over it would change nothing.
    """
    data = copy.deepcopy(base)
    for field, value in params.items():
        set_field(data, field, value)
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always", SceneWarning)
        try:
            scene = scene_from_dict(data, path)
            if scene.render is not None:
                from ..render.settings import RenderSettings

                RenderSettings.from_scene(scene)
        except FieldError as exc:
            raise ClothsimError(f"{exc}{label}") from None
    swept = [loader_path(f) for f in params]
    for w in caught:
        text = str(w.message)
        for field, lp in zip(params, swept):
            if f": {lp}: " in text or text.startswith(f"{lp}: ") or f": {lp.replace('[0]', '')}: " in text:
                raise ClothsimError(f"--set {field}: unknown field {lp} (not part of the scene format)")
        warnings.warn_explicit(w.message, w.category, w.filename, w.lineno)
    return scene


def scene_json(scene: Scene) -> dict[str, Any]:
    """A run's full resolved scene (every default filled in) as scene-file JSON."""
    return {
        "cloth": scene.cloth.as_json(),
        # every kind the scene has; the course's two always (its files name both)
        **{kind.key: [kind.to_json(c) for c in getattr(scene, kind.attr)] for kind in KINDS
           if getattr(scene, kind.attr) or kind.key in ("sphere", "plane")},
        **{kind.key: [kind.to_json(f) for f in getattr(scene, kind.attr)] for kind in FORCES
           if getattr(scene, kind.attr)},
        "simulation": dataclasses.asdict(scene.simulation),
        **({"render": scene.render} if scene.render is not None else {}),
    }


def params_text(params: dict[str, Any]) -> str:
    return ", ".join(f"{k}={shown(v)}" for k, v in params.items())
