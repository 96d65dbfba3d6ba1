"""The one set of rules every input passes through: scene files, render settings, CLI flags, setters.

A rule is a callable ``rule(value, at) -> converted value`` that raises the error ``at.fail``
builds. :class:`At` carries where the value came from: the file (``None`` for a flag or an API
call), the field path (``cloth.ks``, ``sphere[1].radius``) and, for flags, how a field path is
shown (``camera.fov`` -> ``--fov``). Every message is one line: ``file: field: problem``.

The rules are plain Python on purpose: this module imports only the standard library, and the
messages and the leniencies of the course format (``50.0`` is an integer, ``true`` is not a
number, unknown keys warn) are written here once instead of being mapped from a library's.
"""

from __future__ import annotations

import json
import math
import numbers
import warnings
from typing import Any, Callable, Iterable, Mapping

from .errors import FieldError, SceneError

Rule = Callable[[Any, "At"], Any]

# Longest piece of a user's string quoted back in a message: a message stays one readable line.
_QUOTE_CHARS = 40


class SceneWarning(UserWarning):
    """A scene loaded, but something in it was ignored (e.g. an unknown key)."""


class At:
    """Where a value came from: ``source`` (a file name, or None), its field ``path`` and a ``label``
    that turns a field path into what the user typed (e.g. a flag); errors and warnings name both.

    ``files`` says where the files a value names (an OBJ mesh, an image) may come from: ``None``
    for the file system beside ``source``, else an object with ``locate(name, at, kind) -> Path``
    (:class:`clothsim.assets.UploadedFiles`) that is the only way to a file.
    """

    # A plain class, not a dataclass: generating a dataclass costs about a millisecond of import,
    # which every CLI call pays.
    __slots__ = ("source", "path", "label", "files")

    def __init__(self, source: str | None = None, path: str = "", label: Callable[[str], str] | None = None,
                 files: Any = None) -> None:
        self.source = source
        self.path = path
        self.label = label
        self.files = files

    def __repr__(self) -> str:
        return f"At({self.source!r}, {self.path!r})"

    def key(self, name: Any) -> "At":
        """The location of ``name`` inside this object."""
        text = _key_text(name)
        return At(self.source, f"{self.path}.{text}" if self.path else text, self.label, self.files)

    def index(self, i: int) -> "At":
        """The location of item ``i`` of this list."""
        return At(self.source, f"{self.path}[{i}]", self.label, self.files)

    @property
    def shown(self) -> str:
        """The field as the user knows it: the path, or its label (a flag name)."""
        return self.label(self.path) if self.label is not None else self.path

    def fail(self, problem: str) -> FieldError:
        """The error to raise for this field: a :class:`SceneError` when it came from a file."""
        if self.source is None:
            return FieldError(None, self.shown, problem)
        return SceneError(self.source, self.shown, problem)

    def warn(self, problem: str) -> None:
        """Warn (one line, naming the file and field) that something here was ignored."""
        where = ": ".join(p for p in (self.source, self.shown) if p)
        warnings.warn(f"{where}: {problem}" if where else problem, SceneWarning, stacklevel=4)


def _key_text(key: Any) -> str:
    # A key goes into a field path as typed, unless it could break the line or be misread.
    if isinstance(key, str) and key.isprintable() and 0 < len(key) <= _QUOTE_CHARS and not any(c in key for c in ".[]\"'"):
        return key
    return shown(key)


def shown(value: Any) -> str:
    """``value`` as a message shows it: JSON-like, short, never more than one line."""
    if value is None:
        return "null"
    if isinstance(value, bool):
        return "true" if value else "false"
    if isinstance(value, numbers.Integral):
        n = int(value)
        # Python refuses to print integers of more than 4300 digits; huge ones are shown by size.
        if n.bit_length() > 64:
            return f"an integer of about {'-' if n < 0 else ''}10^{int(n.bit_length() * math.log10(2))}"
        return str(n)
    if isinstance(value, numbers.Real):
        return repr(float(value))
    if isinstance(value, str):
        if len(value) > _QUOTE_CHARS:
            return json.dumps(value[:_QUOTE_CHARS])[:-1] + '..."'
        return json.dumps(value)
    if isinstance(value, (list, tuple)):
        return f"a list of {len(value)} item{'s' if len(value) != 1 else ''}"
    if isinstance(value, Mapping):
        return "an object"
    return f"a {type(value).__name__}"


def _is_number(value: Any) -> bool:
    return isinstance(value, numbers.Real) and not isinstance(value, bool)


def items_of(value: Any) -> list[Any] | None:
    """The items of a list-like value (a list, tuple or 1-D array), else None."""
    if isinstance(value, (list, tuple)):
        return list(value)
    if getattr(value, "ndim", None) == 1 and hasattr(value, "tolist"):
        return list(value.tolist())
    return None


# ----------------------------------------------------------------------------------------------
# Scalars


def _bound(x: float) -> str:
    return str(x) if isinstance(x, int) else f"{x:g}"


def _bounds_text(ge: float | None, gt: float | None, le: float | None) -> str:
    if ge is not None:
        return f">= {_bound(ge)}"
    return f"> {_bound(gt)}" if gt is not None else f"<= {_bound(le)}"


class number:  # noqa: N801 - rules read like types in a schema
    """A finite real number (not a boolean), optionally bounded: ``ge``/``gt`` below, ``le`` above."""

    def __init__(self, *, ge: float | None = None, gt: float | None = None, le: float | None = None) -> None:
        self.ge, self.gt, self.le = ge, gt, le

    def in_bounds(self, x: float) -> bool:
        """True when ``x`` meets every bound (False for NaN whenever there is a bound)."""
        return ((self.ge is None or x >= self.ge) and (self.gt is None or x > self.gt)
                and (self.le is None or x <= self.le))

    def bounds_problem(self, value: Any) -> str:
        """The message for a value outside the bounds: the bound it breaks (NaN breaks the lower)."""
        x = value if isinstance(value, numbers.Integral) else float(value)
        if self.le is not None and (x > self.le or (self.ge is None and self.gt is None)):
            text = _bounds_text(None, None, self.le)
        else:
            text = _bounds_text(self.ge, self.gt, None)
        return f"must be {text}, got {shown(value)}"

    def __call__(self, value: Any, at: At) -> float:
        if not _is_number(value):
            raise at.fail(f"expected a number, got {shown(value)}")
        try:
            x = float(value)
        except OverflowError:  # an integer beyond the float range
            x = math.inf if value > 0 else -math.inf
        if not self.in_bounds(x):
            raise at.fail(self.bounds_problem(value))
        if not math.isfinite(x):
            raise at.fail(f"must be finite, got {shown(value)}")
        return x


class integer(number):  # noqa: N801
    """A whole number: an int, or a float with no fraction (JSON writers emit ``50.0``), bounded."""

    def __init__(self, *, ge: int | None = None, le: int | None = None) -> None:
        super().__init__(ge=ge, le=le)

    def __call__(self, value: Any, at: At) -> int:
        if not _is_number(value):
            raise at.fail(f"expected an integer, got {shown(value)}")
        if isinstance(value, numbers.Integral):
            n = int(value)
            if not self.in_bounds(n):  # compared as integers: exact at any size
                raise at.fail(self.bounds_problem(value))
            return n
        x = float(value)
        if math.isfinite(x) and not x.is_integer():
            raise at.fail(f"expected an integer, got {shown(value)}")
        if not self.in_bounds(x):
            raise at.fail(self.bounds_problem(value))
        if not math.isfinite(x):
            raise at.fail(f"must be finite, got {shown(value)}")
        return int(x)


def boolean(value: Any, at: At) -> bool:
    """``true`` or ``false`` (a NumPy boolean too); numbers and strings are refused."""
    if isinstance(value, bool):
        return value
    dtype = getattr(value, "dtype", None)
    if dtype is not None and getattr(dtype, "kind", "") == "b" and getattr(value, "ndim", 1) == 0:
        return bool(value)
    raise at.fail(f"expected true or false, got {shown(value)}")


class choice:  # noqa: N801
    """One of a fixed set of names. ``aliases`` maps other accepted values (``true``, ``1``) to a
    result, ``expected`` replaces the list of options in the message, and ``fold_case`` accepts
    names in any case."""

    def __init__(self, options: Iterable[Any], *, aliases: Mapping[Any, Any] | None = None,
                 expected: str | None = None, fold_case: bool = False) -> None:
        self.options = tuple(options)
        self.aliases = dict(aliases or {})
        self.expected = expected or "one of: " + ", ".join(str(o) for o in self.options)
        self.fold_case = fold_case

    def __call__(self, value: Any, at: At) -> Any:
        key = value.lower() if self.fold_case and isinstance(value, str) else value
        for alias, result in self.aliases.items():
            # `1 == True` in Python: a boolean alias must match a boolean, a number a number.
            if isinstance(alias, bool) == isinstance(key, bool) and _hashable(key) and key == alias:
                return result
        if isinstance(key, str) and key in self.options:
            return key
        raise at.fail(f"expected {self.expected}; got {shown(value)}")


def _hashable(value: Any) -> bool:
    return isinstance(value, (str, int, float, bool)) or value is None


def nullable(rule: Rule) -> Rule:
    """``null`` (None) or whatever ``rule`` accepts."""
    def check(value: Any, at: At) -> Any:
        return None if value is None else rule(value, at)
    return check


def then(rule: Rule, *checks: Callable[[Any, At], Any]) -> Rule:
    """``rule``, followed by further checks that each take the converted value and return it."""
    def check(value: Any, at: At) -> Any:
        out = rule(value, at)
        for extra in checks:
            out = extra(out, at)
        return out
    return check


# ----------------------------------------------------------------------------------------------
# Lists and objects


def vec3(component: Rule | None = None, *, nonzero: bool = False) -> Rule:
    """Three numbers as a tuple; ``component`` checks each (default: any finite number).
    ``nonzero`` refuses a vector of zero length (e.g. a plane's normal)."""
    each = component or number()

    def check(value: Any, at: At) -> tuple[float, float, float]:
        items = items_of(value)
        if items is None:
            raise at.fail(f"expected a list of 3 numbers, got {shown(value)}")
        if len(items) != 3:
            raise at.fail(f"expected 3 numbers, got {len(items)}")
        x, y, z = (each(c, at.index(i)) for i, c in enumerate(items))
        if nonzero and not math.hypot(x, y, z) > 1e-12:
            raise at.fail("has zero length")
        return (x, y, z)
    return check


def list_of(item: Rule, *, length: int | None = None, nonempty: bool = False, what: str = "values") -> Rule:
    """A list (tuple, 1-D array) whose items each pass ``item``; returned as a tuple."""
    expected = (f"a list of {length} {what}" if length is not None
                else f"a non-empty list of {what}" if nonempty else f"a list of {what}")

    def check(value: Any, at: At) -> tuple[Any, ...]:
        items = items_of(value)
        if items is None or (length is not None and len(items) != length) or (nonempty and not items):
            got = shown(value) if items is None else f"{len(items)} item{'s' if len(items) != 1 else ''}"
            raise at.fail(f"expected {expected}, got {got}")
        return tuple(item(v, at.index(i)) for i, v in enumerate(items))
    return check


def one_or_many(item: Rule) -> Rule:
    """``null`` (none), one object, or a list of them; returned as a tuple."""
    def check(value: Any, at: At) -> tuple[Any, ...]:
        if value is None:
            return ()
        items = items_of(value)
        if items is not None:
            return tuple(item(v, at.index(i)) for i, v in enumerate(items))
        return (item(value, at),)
    return check


_REQUIRED = object()


class Field:
    """One key of an object: its rule, whether it may be left out (then ``default`` is used, when
    given), and ``dest``, the name the result goes under (default: the key). ``rule`` may instead
    be ``depends``: a function of the fields already checked that returns the rule (e.g. pinned
    indices bounded by the grid size)."""

    __slots__ = ("rule", "default", "dest", "depends", "optional")

    def __init__(self, rule: Rule | None = None, default: Any = _REQUIRED, dest: str | None = None,
                 depends: Callable[[dict[str, Any]], Rule] | None = None, optional: bool = False) -> None:
        self.rule = rule
        self.default = default
        self.dest = dest
        self.depends = depends
        self.optional = optional

    @property
    def required(self) -> bool:
        """True when the key must be present."""
        return self.default is _REQUIRED and not self.optional

    def rule_for(self, done: dict[str, Any]) -> Rule:
        """The rule to apply, given the results of the fields checked before this one."""
        if self.depends is not None:
            return self.depends(done)
        assert self.rule is not None
        return self.rule


def required(rule: Rule, *, dest: str | None = None) -> Field:
    """A key that must be present."""
    return Field(rule, dest=dest)


def default(rule: Rule, value: Any, *, dest: str | None = None) -> Field:
    """A key that may be left out, then ``value`` (already converted) is used."""
    return Field(rule, default=value, dest=dest)


def optional(rule: Rule, *, dest: str | None = None) -> Field:
    """A key that may be left out, then nothing goes into the result."""
    return Field(rule, dest=dest, optional=True)


class record:  # noqa: N801
    """A JSON object with known keys, checked in the order given; returns a dict of the results.

    Unknown keys are warned about (course files in the wild carry extra keys), or refused with
    the problem ``unknown`` (e.g. at a file's top level, where a misspelt object would be lost).
    """

    def __init__(self, fields: Mapping[str, Field], *, unknown: str | None = None) -> None:
        self.fields = dict(fields)
        self.unknown = unknown

    def check_one(self, key: str, value: Any, at: At) -> Any:
        """Check the value of one key alone (a setter changing one field); ``at`` names it.
        Only for keys whose rule does not depend on other fields."""
        return self.fields[key].rule_for({})(value, at)

    def __call__(self, value: Any, at: At) -> dict[str, Any]:
        if not isinstance(value, Mapping):
            raise at.fail(f"expected an object, got {shown(value)}")
        for key in value:
            if key not in self.fields:
                if self.unknown is not None:
                    raise at.key(key).fail(self.unknown)
                at.key(key).warn("unknown key, ignored")
        out: dict[str, Any] = {}
        for key, f in self.fields.items():
            dest = f.dest or key
            if key in value:
                out[dest] = f.rule_for(out)(value[key], at.key(key))
            elif f.required:
                kind = "object" if isinstance(f.rule, record) else "field"
                raise at.key(key).fail(f"missing required {kind}")
            elif not f.optional:
                out[dest] = f.default
        return out


def check(rule: Rule, value: Any, field: str, *, source: str | None = None) -> Any:
    """Run ``rule`` on one value named ``field`` (e.g. a flag ``--steps``) and return the result."""
    return rule(value, At(source, field))
