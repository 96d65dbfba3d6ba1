"""The messages the page sends over its WebSocket, checked with the project's rule set.

Every message is a JSON object with a ``type``; :func:`parse_message` returns it checked and
converted, or raises one :class:`~clothsim.errors.FieldError` line naming the field
(``message: value: expected a number, got "x"``). Values of simulation parameters and of the
look are checked later by the same setters and render rules the API and the CLI use, so a
message only says *which* parameter, and those rules say whether its value is good.
"""

from __future__ import annotations

import json
from typing import Any

from .. import validate as V
from ..errors import FieldError

SOURCE = "message"

#: Parameters of :class:`~clothsim.sim.Simulation` the page may set (its course-GUI setters).
SIM_FIELDS: tuple[str, ...] = ("ks", "density", "damping", "enable_structural", "enable_shearing",
                               "enable_bending", "gravity", "frames_per_sec", "simulation_steps")
#: Fields of the scene's ``render`` object the page may set (dotted, as in a scene file).
LOOK_FIELDS: tuple[str, ...] = ("shader", "color", "phong.k_a", "phong.k_d", "phong.k_s", "phong.p",
                                "phong.terms", "normal_scaling", "height_scaling")
CLIP_FORMATS: tuple[str, ...] = ("mp4", "gif")
# A drag or wheel event never moves more than this many pixels; anything beyond is not a pointer.
MAX_PIXELS = 1e5

_ANY = lambda value, at: value  # noqa: E731 - checked by the setter or render rule it goes to
_pixels = V.number(ge=-MAX_PIXELS, le=MAX_PIXELS)


def _kind(name: str) -> V.Field:
    return V.required(V.choice((name,)))


_RULES: dict[str, V.record] = {
    "set": V.record({"type": _kind("set"), "field": V.required(V.choice(SIM_FIELDS)),
                     "value": V.required(_ANY)}, unknown="unknown key"),
    "look": V.record({"type": _kind("look"), "field": V.required(V.choice(LOOK_FIELDS)),
                      "value": V.required(_ANY)}, unknown="unknown key"),
    "toggle_pause": V.record({"type": _kind("toggle_pause")}, unknown="unknown key"),
    "step": V.record({"type": _kind("step")}, unknown="unknown key"),
    "restart": V.record({"type": _kind("restart")}, unknown="unknown key"),
    "reset_camera": V.record({"type": _kind("reset_camera")}, unknown="unknown key"),
    "rotate": V.record({"type": _kind("rotate"), "dx": V.required(_pixels), "dy": V.required(_pixels)},
                       unknown="unknown key"),
    "pan": V.record({"type": _kind("pan"), "dx": V.required(_pixels), "dy": V.required(_pixels)},
                    unknown="unknown key"),
    "zoom": V.record({"type": _kind("zoom"), "factor": V.required(V.number(ge=0.01, le=100.0))},
                     unknown="unknown key"),
    "scene": V.record({"type": _kind("scene"), "name": V.required(V.choice(()))}, unknown="unknown key"),
    "record": V.record({"type": _kind("record"), "action": V.required(V.choice(("start", "stop"))),
                        "format": V.default(V.choice(CLIP_FORMATS), "mp4")}, unknown="unknown key"),
}
TYPES: tuple[str, ...] = tuple(_RULES)


def parse_message(text: str | bytes, scenes: tuple[str, ...] = ()) -> dict[str, Any]:
    """Check one message; ``scenes`` are the names a ``scene`` message may ask for."""
    at = V.At(SOURCE)
    if isinstance(text, bytes):
        try:
            text = text.decode("utf-8")
        except UnicodeDecodeError:
            raise FieldError(SOURCE, "", "not UTF-8 text") from None
    try:
        data = json.loads(text)
    except (json.JSONDecodeError, RecursionError, ValueError) as exc:
        why = exc.msg if isinstance(exc, json.JSONDecodeError) else "nested too deeply or too large"
        raise FieldError(SOURCE, "", f"not valid JSON: {why}") from None
    if not isinstance(data, dict):
        raise at.fail(f"expected a JSON object, got {V.shown(data)}")
    kind = V.choice(TYPES)(data.get("type"), at.key("type")) if "type" in data else None
    if kind is None:
        raise at.key("type").fail("missing required field")
    rules = _RULES[kind]
    if kind == "scene":
        rules = V.record({**rules.fields, "name": V.required(V.choice(scenes))}, unknown="unknown key")
    return rules(data, at)


def look_overrides(field: str, value: Any) -> dict[str, Any]:
    """A ``render``-shaped object setting one dotted look field (``phong.k_s`` -> {"phong": {"k_s": v}})."""
    head, _, rest = field.partition(".")
    return {head: {rest: value}} if rest else {head: value}


def error_reply(message: str) -> str:
    """The JSON text of an error reply: one line the page shows as it is."""
    return json.dumps({"type": "error", "message": message})
