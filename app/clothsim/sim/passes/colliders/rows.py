"""What the kinds of rows share: sphere, plane, capsule and box are each one float64 row per
collider, and their groups, their packing and their three passes (``pose``, ``reach``,
``collide``: see :mod:`clothsim.sim.passes.colliders`) are the same for all four. A kind of rows
defines only what is its own:

* ``Group``: a type of its own made by :func:`row_group`, with the fields of :class:`Rows`, or of
  :class:`CarriedRows` for a kind whose carries are an array of their own (sphere, plane: ``None``
  in a scene where nothing moves, so that their swept tests are pruned before typing); the others
  keep their carry in their rows' last three columns;
* ``pack``, made by :func:`packer` from how a spec becomes a row;
* ``POINTS`` and ``CARRY_AT``: how many points (xyz column triples) a pose moves at the start of a
  row, and the column of the carry (in the group's carries, or in its rows);
* ``TURNS``: the direction columns (xyz column triples) a turn turns (a plane's normal, a box's
  axes), and ``turned(spec)``: those directions at the scene pose (the points a turn moves are the
  ``POINTS`` a pose moves);
* ``reach_rows(box, rows, on, [carry,] turn, offset) -> int``: marks which colliders the cloth's box
  may touch in ``on``, returns how many it ruled out;
* ``collide_rows(pos, last, part, rows, on, [carry,] turn, offset)``: the points ``part`` against the
  reachable colliders;

and imports ``pose``, ``reach`` and ``collide`` from here (``carry`` is passed to a kind of
:class:`CarriedRows` only; ``turn`` is the rows' motions over the substep, :attr:`~.moving.Turns.motion`,
where a collider of the kind turns, and None otherwise, so that the tests of a kind none of whose
colliders turns are pruned back to what they were before turns).
"""

from __future__ import annotations

import sys
from collections.abc import Callable
from typing import Any, NamedTuple

import numpy as np
from numba import types
from numba.extending import overload

from ....jit import KERNEL
from ...team import chunk_of
from .moving import Tracks, Turns, pack_tracks, pack_turns, pose_rows, turn_rows


class Rows(NamedTuple):
    """A kind of rows' group: one row per collider, its reach flags, and the tracks of its moving
    colliders (None when none moves). Each kind subclasses it, so that its group is a type of its
    own."""

    rows: np.ndarray
    on: np.ndarray
    tracks: Tracks | None
    turns: Turns | None


class CarriedRows(NamedTuple):
    """:class:`Rows` with the colliders' carries as an array of their own, (n, 3), None where
    nothing in the scene moves."""

    rows: np.ndarray
    on: np.ndarray
    carry: np.ndarray | None
    tracks: Tracks | None
    turns: Turns | None


def row_group(name: str, module: str, doc: str, carried: bool = False) -> type:
    """A kind's group type, ``name`` in ``module``: the fields of :class:`Rows` (of
    :class:`CarriedRows` when ``carried``) in a type of the kind's own, by which the registry and
    Numba tell the kinds apart."""
    return type(name, (CarriedRows if carried else Rows,), {"__slots__": (), "__doc__": doc, "__module__": module})


def packer(group: type, attr: str, row: Callable[[Any], tuple], width: int,
           anchor: Callable[[Any], tuple], turns: tuple = (),
           turned: Callable[[Any], tuple] | None = None) -> Callable[[Any, np.ndarray, float, bool], Any]:
    """A kind's ``pack(scene, clock, dt, swept)``: the ``group`` of the specs ``scene.<attr>``,
    each spec's row given by ``row`` (``width`` columns), its reach flags, its carries (for a
    ``carried`` group in a scene where something moves) and the tracks of the moving ones
    (``anchor(spec)``: the point columns a pose translates) and their turns (``turns``: the
    direction columns a turn turns, ``turned(spec)`` those directions at the scene pose). An empty
    group for no specs."""

    def pack(scene: Any, clock: np.ndarray, dt: float, swept: bool) -> Any:
        specs = getattr(scene, attr)
        rows = np.array([row(spec) for spec in specs], dtype=np.float64).reshape(-1, width)
        on = np.zeros(len(rows), dtype=np.bool_)
        tracks = pack_tracks(specs, clock, dt, anchor)
        spins = pack_turns(specs, turns, turned)
        if issubclass(group, CarriedRows):
            return group(rows, on, np.zeros((len(rows), 3)) if swept else None, tracks, spins)
        return group(rows, on, tracks, spins)

    pack.__doc__ = f"The group of the scene's {attr} (see :func:`clothsim.sim.passes.colliders.rows.packer`)."
    return pack


def pose(g: Rows, substep: int) -> None:
    """Put the kind's moving colliders at their pose at the end of substep ``substep`` (compiled
    code only)."""
    raise NotImplementedError("compiled code only")


def reach(g: Rows, box: np.ndarray, on: np.ndarray, offset: float) -> int:
    """Mark the kind's colliders the cloth's box reaches in ``on``; returns how many were ruled
    out (compiled code only)."""
    raise NotImplementedError("compiled code only")


def collide(g: Rows, pos: np.ndarray, last: np.ndarray, free: np.ndarray, c: int, on: np.ndarray,
            offset: float) -> None:
    """Work item ``c`` (of CHUNKS) of the free points against the kind's reachable colliders
    (compiled code only)."""
    raise NotImplementedError("compiled code only")


def _kind(group: Any) -> tuple[Any, bool]:
    """The pass module of a group's type, and whether its carries are an array of their own."""
    cls = group.instance_class
    return sys.modules[cls.__module__], issubclass(cls, CarriedRows)


def _turns(group: Any) -> bool:
    """Whether a group's type holds turns (a collider of the kind turns)."""
    return not isinstance(group.types[group.fields.index("turns")], types.NoneType)


@overload(pose, jit_options=KERNEL)
def _pose(g, substep):  # noqa: ANN001, ANN202
    kind, carried = _kind(g)
    points, at = kind.POINTS, kind.CARRY_AT
    if _turns(g):
        if carried:
            return lambda g, substep: turn_rows(g.tracks, g.turns, g.rows, points, g.carry, at, substep)
        return lambda g, substep: turn_rows(g.tracks, g.turns, g.rows, points, g.rows, at, substep)
    if carried:
        return lambda g, substep: pose_rows(g.tracks, g.rows, points, g.carry, at, substep)
    return lambda g, substep: pose_rows(g.tracks, g.rows, points, g.rows, at, substep)


def _motion(g):  # noqa: ANN001, ANN202
    """The rows' motions of a group with turns, None for one without (compiled code only)."""
    raise NotImplementedError("compiled code only")


@overload(_motion, jit_options=KERNEL)
def _motion_impl(g):  # noqa: ANN001, ANN202
    if _turns(g):
        return lambda g: g.turns.motion
    return lambda g: None


# (the carry goes to the kind's functions as an argument of its own: Numba prunes a branch on an
# argument that is None, not on a group's field)

@overload(reach, jit_options=KERNEL)
def _reach(g, box, on, offset):  # noqa: ANN001, ANN202
    kind, carried = _kind(g)
    test = kind.reach_rows
    if carried:
        return lambda g, box, on, offset: test(box, g.rows, on, g.carry, _motion(g), offset)
    return lambda g, box, on, offset: test(box, g.rows, on, _motion(g), offset)


@overload(collide, jit_options=KERNEL)
def _collide(g, pos, last, free, c, on, offset):  # noqa: ANN001, ANN202
    kind, carried = _kind(g)
    push = kind.collide_rows
    if carried:
        return lambda g, pos, last, free, c, on, offset: push(pos, last, chunk_of(free, c), g.rows, on, g.carry,
                                                               _motion(g), offset)
    return lambda g, pos, last, free, c, on, offset: push(pos, last, chunk_of(free, c), g.rows, on, _motion(g),
                                                           offset)
