"""Forces beyond the springs and gravity: the registry, and the three calls every substep makes
over whichever of them a scene uses.

A force is one module of this package (:mod:`.wind` is the worked example) that defines:

* ``Group``: a ``NamedTuple`` of its flat arrays and constants; ``NAME``, and ``ABSENT``: why a
  scene has no such pass (``clothsim simulate --profile`` says it);
* ``pack(sim)``: its group for a :class:`~clothsim.sim.Simulation`, or None when the scene
  does not need the pass (no wind, or only still air);
* ``work(group, pos, last, substep, c0, c1)``: compiled; work items ``c0..c1-1`` (of
  :data:`~clothsim.jit.CHUNKS`), reading positions and last positions only and writing the
  group's own buffers, at substep ``substep`` of the call (its time from the one clock,
  :mod:`clothsim.sim.clock`);
* ``gather(group, forces, c)``: compiled, inlined; adds to the forces of the c-th point range
  what the work items left for them.

Its kind's line in :data:`clothsim.forces.FORCES` (which names the module) is all the simulator needs: a plan holds the groups of the forces its
scene uses, as one tuple, and :func:`force_work`, :func:`force_gather` and :func:`add_forces`
are resolved at compile time, for that tuple's types, into direct calls of those forces' functions
(an empty tuple compiles to nothing). The thread team (:mod:`clothsim.sim.solvers.frame`) runs
every force's work items in the springs' phase and its gathers chunk by chunk with the springs'
gather; every other integrator (:mod:`clothsim.sim.solvers.substep`) calls :func:`add_forces`
after the springs. The scene's side of a force is its spec and rule in the scene layer (as
:mod:`clothsim.wind`), the same registry line, and its field of :class:`~clothsim.scene.Scene`.
"""

from __future__ import annotations

from importlib import import_module
from types import ModuleType

import numpy as np
from numba import njit
from numba.extending import overload

from ...forces import FORCES as KINDS
from ...jit import CHUNKS, KERNEL

#: Every force's pass module, in registry order (the order their forces are added to a point).
FORCES: tuple[ModuleType, ...] = tuple(import_module(f"{__package__}.{kind.pass_module}") for kind in KINDS)

_BY_GROUP = {module.Group: module for module in FORCES}


def _module(group_type) -> ModuleType:  # noqa: ANN001
    cls = getattr(group_type, "instance_class", None)
    if cls not in _BY_GROUP:
        raise TypeError(f"{group_type} is not the group of a registered force (clothsim.sim.passes.forces.FORCES)")
    return _BY_GROUP[cls]


def plan_forces(sim) -> tuple:  # noqa: ANN001
    """The groups of the forces ``sim``'s scene uses, in :data:`FORCES` order (a plan's ``forces``)."""
    return tuple(g for g in (module.pack(sim) for module in FORCES) if g is not None)


def force_work(forces: tuple, pos: np.ndarray, last: np.ndarray, substep: int, c0: int, c1: int) -> None:
    """Work items ``c0..c1-1`` of every force in ``forces`` (compiled code only)."""
    raise NotImplementedError("force_work runs in compiled code only")


def force_gather(forces: tuple, out: np.ndarray, c: int) -> None:
    """Every force's share of the c-th point range added to ``out`` (compiled code only)."""
    raise NotImplementedError("force_gather runs in compiled code only")


@overload(force_work, jit_options=KERNEL)
def _force_work(forces, pos, last, substep, c0, c1):  # noqa: ANN001, ANN202
    if len(forces.types) == 0:
        return lambda forces, pos, last, substep, c0, c1: None
    work = _module(forces.types[0]).work

    def impl(forces, pos, last, substep, c0, c1):  # noqa: ANN001, ANN202
        work(forces[0], pos, last, substep, c0, c1)
        force_work(forces[1:], pos, last, substep, c0, c1)

    return impl


@overload(force_gather, jit_options=KERNEL, inline="always")
def _force_gather(forces, out, c):  # noqa: ANN001, ANN202
    if len(forces.types) == 0:
        return lambda forces, out, c: None
    gather = _module(forces.types[0]).gather

    def impl(forces, out, c):  # noqa: ANN001, ANN202
        gather(forces[0], out, c)
        force_gather(forces[1:], out, c)

    return impl


@njit(**KERNEL)
def add_forces(forces: tuple, pos: np.ndarray, last: np.ndarray, out: np.ndarray, substep: int) -> None:
    """out += every force of ``forces`` at substep ``substep`` of the call, force by force (the
    substep of every integrator but the thread team's)."""
    _add_each(forces, pos, last, out, substep)


def _add_each(forces: tuple, pos: np.ndarray, last: np.ndarray, out: np.ndarray, substep: int) -> None:
    raise NotImplementedError("_add_each runs in compiled code only")


@overload(_add_each, jit_options=KERNEL)
def _add_each_impl(forces, pos, last, out, substep):  # noqa: ANN001, ANN202
    if len(forces.types) == 0:
        return lambda forces, pos, last, out, substep: None
    module = _module(forces.types[0])
    work, gather = module.work, module.gather

    def impl(forces, pos, last, out, substep):  # noqa: ANN001, ANN202
        work(forces[0], pos, last, substep, 0, CHUNKS)
        for c in range(CHUNKS):
            gather(forces[0], out, c)
        _add_each(forces[1:], pos, last, out, substep)

    return impl
