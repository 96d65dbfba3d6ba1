"""The colliders: one registry of kinds (sphere, plane, capsule, box, mesh), and the collider pass
every integrator runs over whichever of them a scene has.

A collider kind is one module of this package (:mod:`.sphere` is the simplest) that defines:

* ``Group``: a ``NamedTuple`` of its flat arrays: its rows, its reach flags ``on`` (one per
  collider) and the :class:`~.moving.Tracks` of its moving colliders (None when none moves);
* ``pack(scene, clock, dt, swept)``: its group for a scene that has colliders of the kind;
  ``clock`` and ``dt`` are the simulation's one clock and substep length, ``swept``
  says that something in the scene moves (the sphere and the plane then take their swept tests).
  A kind with ``ALWAYS = True`` (the course's sphere and plane) is in every plan with colliders,
  its group empty when the scene has none of it, so that scenes with either or both share one
  compiled plan;
* ``pose(g, substep)``: compiled; puts its moving colliders at their pose for substep
  ``substep`` of the call (:func:`~.moving.pose_rows` does it for rows of points);
* ``reach(g, box, on, offset) -> int``: compiled; marks in ``on`` which colliders the cloth's
  bounding box (:mod:`.bounds`) may touch this substep, and returns how many it ruled out (a
  collider ruled out could not have moved a point, so skipping it is exact);
* ``collide(g, pos, last, free, c, on, offset)``: compiled; work item ``c`` (of
  :data:`~clothsim.jit.CHUNKS`) of the free points against its reachable colliders. A point's
  correction depends on that point alone, so the work items may run on any thread.

The kinds whose colliders are one float64 row each (sphere, plane, capsule, box) take their group
type, their ``pack`` and all three functions from :mod:`.rows` and write only their two tests.

Its line in :data:`clothsim.colliders.KINDS` (the scene's side: key, rule, JSON, and the name of
this module) is all the simulator needs. A plan holds the groups of the kinds its scene has, as one
tuple in registry order. Each kind's three functions are compiled on their own for its group's
type (:func:`pose_kind`, :func:`reach_kind`, :func:`collide_kind`: a kind's code is compiled once
whichever other kinds a plan has) and called by address (``Colliders.calls``, one row per kind:
:func:`kind_addresses`): the thread team (member 0 poses, every member tests reach itself and
collides its own work items) and every other integrator (:func:`collide_reachable`) make the same
calls. Every point meets the kinds in registry order, the colliders of a kind in scene order.
"""

from __future__ import annotations

from importlib import import_module
from types import ModuleType
from typing import Any

import numpy as np
from numba import njit, prange, typeof, types
from numba.extending import overload

from ....colliders import KINDS
from ....jit import CHUNKS, KERNEL, PARALLEL
from ....jit.internals import call_native, load_value
from .bounds import cloth_bounds

#: Every kind's pass module, in registry order (the order a point meets them).
KIND_MODULES: tuple[ModuleType, ...] = tuple(import_module(f"{__package__}.{kind.pass_module}") for kind in KINDS)

_BY_GROUP = {module.Group: module for module in KIND_MODULES}


def _module(group_type) -> ModuleType:  # noqa: ANN001
    cls = getattr(group_type, "instance_class", None)
    if cls not in _BY_GROUP:
        raise TypeError(f"{group_type} is not the group of a registered collider kind "
                        "(clothsim.sim.passes.colliders.KIND_MODULES)")
    return _BY_GROUP[cls]


def plan_colliders(scene: Any, clock: np.ndarray, dt: float) -> tuple:
    """The groups of the collider kinds ``scene`` has (and of the ``ALWAYS`` kinds, when it has
    any collider), in registry order: a plan's ``colliders``; empty without colliders."""
    if not scene.colliders:
        return ()
    swept = any(spec.motion is not None for spec in scene.colliders)
    return tuple(module.pack(scene, clock, dt, swept) for module, kind in zip(KIND_MODULES, KINDS)
                 if getattr(scene, kind.attr) or getattr(module, "ALWAYS", False))


def pose_colliders(cols: tuple, substep: int) -> None:
    """Every moving collider of ``cols`` to its pose for substep ``substep`` (compiled code only)."""
    raise NotImplementedError("compiled code only")


def reach_colliders(cols: tuple, box: np.ndarray, ons: tuple, offset: float) -> int:
    """Every kind's reach test, its flags into the matching array of ``ons``; returns the
    colliders ruled out (compiled code only)."""
    raise NotImplementedError("compiled code only")


def collide_colliders(cols: tuple, pos: np.ndarray, last: np.ndarray, free: np.ndarray, ons: tuple, offset: float,
                      c: int) -> None:
    """Work item ``c`` of the free points against every kind's reachable colliders, kind by kind
    (compiled code only)."""
    raise NotImplementedError("compiled code only")


def member_flags(cols: tuple, own: bool) -> tuple:
    """The reach flags of every kind, as a tuple of arrays: the groups' own (``own`` False), or new
    ones (a team member other than the first, which tests reach for itself) (compiled code only)."""
    raise NotImplementedError("compiled code only")


@overload(pose_colliders, jit_options=KERNEL)
def _pose_colliders(cols, substep):  # noqa: ANN001, ANN202
    if len(cols.types) == 0:
        return lambda cols, substep: None
    pose = _module(cols.types[0]).pose

    def impl(cols, substep):  # noqa: ANN001, ANN202
        pose(cols[0], substep)
        pose_colliders(cols[1:], substep)

    return impl


@overload(reach_colliders, jit_options=KERNEL)
def _reach_colliders(cols, box, ons, offset):  # noqa: ANN001, ANN202
    if len(cols.types) == 0:
        return lambda cols, box, ons, offset: 0
    reach = _module(cols.types[0]).reach

    def impl(cols, box, ons, offset):  # noqa: ANN001, ANN202
        skipped = reach(cols[0], box, ons[0], offset)
        return skipped + reach_colliders(cols[1:], box, ons[1:], offset)

    return impl


@overload(collide_colliders, jit_options=KERNEL)
def _collide_colliders(cols, pos, last, free, ons, offset, c):  # noqa: ANN001, ANN202
    if len(cols.types) == 0:
        return lambda cols, pos, last, free, ons, offset, c: None
    collide = _module(cols.types[0]).collide

    def impl(cols, pos, last, free, ons, offset, c):  # noqa: ANN001, ANN202
        collide(cols[0], pos, last, free, c, ons[0], offset)
        collide_colliders(cols[1:], pos, last, free, ons[1:], offset, c)

    return impl


@overload(member_flags, jit_options=KERNEL)
def _member_flags(cols, own):  # noqa: ANN001, ANN202
    if len(cols.types) == 0:
        return lambda cols, own: ()

    def impl(cols, own):  # noqa: ANN001, ANN202
        on = cols[0].on
        if own:
            on = np.empty_like(on)
        return (on,) + member_flags(cols[1:], own)

    return impl


#: Columns of ``Colliders.calls``, one row per kind of the plan: the kind's pose, reach and collide
#: passes, each compiled on its own for the kind's group (:func:`pose_kind`, :func:`reach_kind`,
#: :func:`collide_kind`) and called by address from every integrator's collider pass. A kind's
#: code is then compiled once for each type of its group, whichever kinds it meets in a plan,
#: and linked into no plan's kernel.
POSE, REACH, COLLIDE = range(3)
KIND_CALLS = 3


@njit(**KERNEL)
def pose_kind(g: tuple, substep: int) -> None:
    """One kind's moving colliders to their pose for substep ``substep`` (its ``pose``), compiled on
    its own for a call by address."""
    pose_colliders((g,), substep)


@njit(**KERNEL)
def reach_kind(g: tuple, box: np.ndarray, on: np.ndarray, offset: float, skipped: np.ndarray) -> None:
    """One kind's reach test (its ``reach``), compiled on its own for a call by address; the
    colliders it ruled out go to ``skipped[0]``."""
    skipped[0] = reach_colliders((g,), box, (on,), offset)


@njit(**KERNEL)
def collide_kind(g: tuple, pos: np.ndarray, last: np.ndarray, free: np.ndarray, on: np.ndarray, offset: float,
                 lo: int, hi: int) -> None:
    """Work items ``lo`` to ``hi`` of one kind's collide pass (its ``collide``), compiled on its own
    for a call by address."""
    for c in range(lo, hi):
        collide_colliders((g,), pos, last, free, (on,), offset, c)


def kind_kernels(group: types.Type, pos: types.Type, last: types.Type, free: types.Type, box: types.Type,
                 offset: types.Type) -> tuple[tuple[Any, tuple], ...]:
    """(kernel, argument types) of a kind's three passes (``POSE``, ``REACH``, ``COLLIDE`` order) for
    its group's type and the state's types."""
    i64 = types.int64
    on = group.types[group.fields.index("on")]
    return ((pose_kind, (group, i64)),
            (reach_kind, (group, box, on, offset, types.Array(i64, 1, "C"))),
            (collide_kind, (group, pos, last, free, on, offset, i64, i64)))


def pose_by_address(cols: tuple, calls: np.ndarray, substep: int) -> None:
    """:func:`pose_kind` of every kind of ``cols``, by the addresses in ``calls`` (compiled code only)."""
    raise NotImplementedError("compiled code only")


def reach_by_address(cols: tuple, calls: np.ndarray, box: np.ndarray, ons: tuple, offset: float,
                     skipped: np.ndarray) -> int:
    """:func:`reach_kind` of every kind of ``cols`` by address, their flags into the matching array
    of ``ons``; returns the colliders ruled out (``skipped`` is scratch) (compiled code only)."""
    raise NotImplementedError("compiled code only")


def collide_by_address(cols: tuple, calls: np.ndarray, pos: np.ndarray, last: np.ndarray, free: np.ndarray,
                       ons: tuple, offset: float, lo: int, hi: int) -> None:
    """:func:`collide_kind` of every kind of ``cols`` by address, over work items ``lo`` to ``hi``
    (a point meets the kinds in registry order; its correction depends on that point alone)
    (compiled code only)."""
    raise NotImplementedError("compiled code only")


@overload(pose_by_address, jit_options=KERNEL)
def _pose_by_address(cols, calls, substep):  # noqa: ANN001, ANN202
    if len(cols.types) == 0:
        return lambda cols, calls, substep: None

    def impl(cols, calls, substep):  # noqa: ANN001, ANN202
        call_native(calls[0, POSE], (cols[0], substep))
        pose_by_address(cols[1:], calls[1:], substep)

    return impl


@overload(reach_by_address, jit_options=KERNEL)
def _reach_by_address(cols, calls, box, ons, offset, skipped):  # noqa: ANN001, ANN202
    if len(cols.types) == 0:
        return lambda cols, calls, box, ons, offset, skipped: 0

    def impl(cols, calls, box, ons, offset, skipped):  # noqa: ANN001, ANN202
        call_native(calls[0, REACH], (cols[0], box, ons[0], offset, skipped))
        here = skipped[0]
        return here + reach_by_address(cols[1:], calls[1:], box, ons[1:], offset, skipped)

    return impl


@overload(collide_by_address, jit_options=KERNEL)
def _collide_by_address(cols, calls, pos, last, free, ons, offset, lo, hi):  # noqa: ANN001, ANN202
    if len(cols.types) == 0:
        return lambda cols, calls, pos, last, free, ons, offset, lo, hi: None

    def impl(cols, calls, pos, last, free, ons, offset, lo, hi):  # noqa: ANN001, ANN202
        call_native(calls[0, COLLIDE], (cols[0], pos, last, free, ons[0], offset, lo, hi))
        collide_by_address(cols[1:], calls[1:], pos, last, free, ons[1:], offset, lo, hi)

    return impl


@njit(**KERNEL)
def pose_set(at: int, calls: np.ndarray, substep: int, cols_type: Any) -> None:
    """Every kind of a plan posed for substep ``substep``: the plan's groups read from the address
    ``at`` (:func:`~clothsim.jit.internals.stack_address`, of type ``cols_type``), each kind's pose
    called by its address in ``calls``. Compiled per set of kinds, and small: the thread team's
    member calls it by address, so that the member is one kernel for every set of kinds."""
    pose_by_address(load_value(at, cols_type), calls, substep)


@njit(**KERNEL)
def collide_set(at: int, calls: np.ndarray, pos: np.ndarray, last: np.ndarray, free: np.ndarray, box: np.ndarray,
                offset: float, own: bool, lo: int, hi: int, skipped: np.ndarray, cols_type: Any) -> None:
    """A team member's collider pass over work items ``lo`` to ``hi``: every kind's reach test
    (into the groups' own flags, or new ones when ``own``; the colliders ruled out go to
    ``skipped[0]``), then every kind's collide, each by its address in ``calls`` (see
    :func:`pose_set`)."""
    cols = load_value(at, cols_type)
    ons = member_flags(cols, own)
    skipped[0] = reach_by_address(cols, calls, box, ons, offset, skipped)
    collide_by_address(cols, calls, pos, last, free, ons, offset, lo, hi)


@njit(inline="always", **KERNEL)
def _collide_chunk(pos: np.ndarray, last: np.ndarray, col: tuple, at: int, cols_type: Any, c: int) -> None:
    cols = load_value(at, cols_type)
    collide_by_address(cols, col.calls, pos, last, col.free, member_flags(cols, False), col.offset, np.int64(c),
                       np.int64(c + 1))


@njit(**PARALLEL)
def collide_reachable(pos: np.ndarray, last: np.ndarray, col: tuple, at: int, substep: int, skipped: np.ndarray,
                      cols_type: Any) -> None:
    """The collider pass of every integrator but the thread team's, at substep ``substep`` of the
    call: moving colliders posed, the cloth bounded, reach tested, then the work items over the
    cores; the colliders ruled out go to ``skipped[0]``. ``col`` is the
    :class:`~clothsim.sim.state.Colliders` group, the kinds' groups are read from the address
    ``at`` (see :func:`pose_set`). Compiled per set of kinds and called by address
    (``Colliders.sets``), so that the corrections that call it are one kernel for every set."""
    cols = load_value(at, cols_type)
    calls = col.calls
    pose_by_address(cols, calls, substep)
    cloth_bounds(pos, last, col.box)
    skipped[0] = reach_by_address(cols, calls, col.box, member_flags(cols, False), col.offset, skipped)
    # the loop's threads read the groups from the address too: a parallel loop takes no tuple of
    # groups (see jit.internals.stack_address)
    for c in prange(CHUNKS):
        _collide_chunk(pos, last, col, at, cols_type, c)


#: Columns of ``Colliders.sets``: the kernels of a plan's set of kinds (:func:`set_kernels`).
SET_POSE, SET_COLLIDE, SET_REACHABLE = range(3)
SETS = 3


def set_kernels(cols: types.Type, col: types.Type, pos: types.Type, last: types.Type) -> tuple[tuple[Any, tuple], ...]:
    """(kernel, argument types) of :func:`pose_set`, :func:`collide_set` and
    :func:`collide_reachable` (``SET_*`` order) for a plan's tuple of groups ``cols``, its
    :class:`~clothsim.sim.state.Colliders` group ``col`` and the state's types."""
    i64 = types.int64
    calls = col.types[col.fields.index("calls")]
    free, box, offset = (col.types[col.fields.index(name)] for name in ("free", "box", "offset"))
    scratch = types.Array(i64, 1, "C")
    ref = types.TypeRef(cols)
    return ((pose_set, (i64, calls, i64, ref)),
            (collide_set, (i64, calls, pos, last, free, box, offset, types.boolean, i64, i64, scratch, ref)),
            (collide_reachable, (pos, last, col, i64, i64, scratch, ref)))


def kind_addresses(cols: tuple, pos: np.ndarray, last: np.ndarray, col: Any) -> tuple[np.ndarray, np.ndarray]:
    """``Colliders.calls`` and ``Colliders.sets`` for the groups ``cols`` and the state's arrays:
    each kind's passes and the set's kernels compiled (or loaded from the cache) by one process at
    a time."""
    from ....jit.compile import compiling_alone
    from ....jit.internals import native_address

    state = tuple(typeof(x) for x in (pos, last, col.free, col.box, col.offset))
    calls = np.zeros((len(cols), KIND_CALLS), np.int64)
    for k, g in enumerate(cols):
        kernels = kind_kernels(typeof(g), *state)
        with compiling_alone(*kernels[COLLIDE]):
            calls[k] = [native_address(*kernel) for kernel in kernels]
    kernels = set_kernels(typeof(cols), typeof(col), state[0], state[1])
    with compiling_alone(*kernels[SET_REACHABLE]):
        sets = np.array([native_address(*kernel) for kernel in kernels], np.int64)
    return calls, sets
