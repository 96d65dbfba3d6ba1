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

Its line in :data:`clothsim.colliders.KINDS` (the scene's side: key, rule, JSON, and the name of
this module) is all the simulator needs. A plan holds the groups of the kinds its scene has, as one
tuple in registry order, and :func:`pose_colliders`, :func:`reach_colliders` and
:func:`collide_colliders` are resolved at compile time, for that tuple's types, into direct calls of
those kinds' functions: a scene compiles only its own kinds. Every point meets the kinds in
registry order, the colliders of a kind in scene order. The thread team runs these same
functions (member 0 poses, every member tests reach itself and collides its own work items); every
other integrator calls :func:`collide_reachable`.
"""

from __future__ import annotations

from importlib import import_module
from types import ModuleType
from typing import Any

import numpy as np
from numba import njit, prange
from numba.extending import overload

from ....colliders import KINDS
from ....jit import CHUNKS, KERNEL, PARALLEL, field_is_none
from ....jit.internals import load_value, stack_address, type_ref
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


def any_moving(cols: tuple) -> bool:
    """True when some collider of ``cols`` moves: a constant of the compiled kernel (compiled code only)."""
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


@overload(any_moving, jit_options=KERNEL)
def _any_moving(cols):  # noqa: ANN001, ANN202
    moving = any(not field_is_none(t, "tracks") for t in cols.types)
    return lambda cols: moving


#: The thread team's collider passes, compiled on their own for a plan's kinds and called by
#: address (``Colliders.calls``): plans of the same kinds share them, and a plan compiles only
#: its own passes.
POSE, REACH, COLLIDE = range(3)
TEAM_CALLS = 3


@njit(**KERNEL)
def pose_all(cols: tuple, substep: int) -> None:
    """:func:`pose_colliders`, compiled on its own for a call by address."""
    pose_colliders(cols, substep)


@njit(**KERNEL)
def reach_all(cols: tuple, box: np.ndarray, ons: tuple, offset: float, skipped: np.ndarray) -> None:
    """:func:`reach_colliders`, compiled on its own for a call by address; the colliders ruled out
    go to ``skipped[0]``."""
    skipped[0] = reach_colliders(cols, box, ons, offset)


@njit(**KERNEL)
def collide_range(cols: tuple, pos: np.ndarray, last: np.ndarray, free: np.ndarray, ons: tuple, offset: float,
                  lo: int, hi: int) -> None:
    """Work items ``lo`` to ``hi`` of :func:`collide_colliders`, compiled on its own for a call by address."""
    for c in range(lo, hi):
        collide_colliders(cols, pos, last, free, ons, offset, c)


@njit(inline="always", **KERNEL)
def _collide_chunk(pos: np.ndarray, last: np.ndarray, col: tuple, at: int, cols_type: Any, c: int) -> None:
    cols = load_value(at, cols_type)
    collide_colliders(cols, pos, last, col.free, member_flags(cols, False), col.offset, c)


@njit(**PARALLEL)
def collide_reachable(pos: np.ndarray, last: np.ndarray, col: tuple, cols: tuple, substep: int) -> int:
    """The collider pass of every integrator but the thread team's, at substep ``substep`` of the
    call: moving colliders posed, the cloth bounded, reach tested, then the work items over the
    cores; returns the colliders ruled out. ``col`` is the
    :class:`~clothsim.sim.state.Colliders` group, ``cols`` the kinds' groups."""
    pose_colliders(cols, substep)
    cloth_bounds(pos, last, col.box)
    skipped = reach_colliders(cols, col.box, member_flags(cols, False), col.offset)
    # the loop's threads take the groups by address: a parallel loop takes no tuple of groups
    # (see jit.internals.stack_address)
    at = stack_address(cols)
    cols_type = type_ref(cols)
    for c in prange(CHUNKS):
        _collide_chunk(pos, last, col, at, cols_type, c)
    return skipped
