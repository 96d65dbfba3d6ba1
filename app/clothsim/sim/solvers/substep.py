"""The substep of every integrator but the spec's fast path, as one ordered list of passes:

    forces (springs + gravity) -> the registered forces (wind) -> the integrator's advance -> moving pins
    -> (XPBD: its constraint solve) -> corrections (self-collision, colliders, Provot)
    -> velocities re-derived from the corrected positions

An integrator is only its advance rule, a group of its own (:class:`~.verlet.VerletRate`,
:class:`~.symplectic.Symplectic`, :class:`~.implicit.Implicit`, :class:`~.xpbd.Xpbd`): exactly one
is given, the others are ``None``, and Numba prunes the branches of the absent ones before typing,
so each integrator compiles only its own code, as each optional pass (pins, colliders) does; the
forces of :mod:`..passes.forces` come as one tuple of the groups the scene uses.
The spec's fast path runs the same passes' work items in the thread team (:mod:`.frame`).
"""

from __future__ import annotations

from typing import NamedTuple

import numpy as np
from numba import njit

from ...jit import EXACT, KERNEL
from ..passes.forces import add_forces
from ..passes.springs import accumulate_forces
from ..passes.meshsprings import add_spring_forces
from ...jit.internals import call_native, stack_address
from ..clock import substep_time
from ..passes.pins import move_pins, pin_velocities
from ..state import Corrections
from .implicit import Implicit, update_address
from .symplectic import Symplectic, symplectic_step
from .verlet import VerletRate, verlet_rate_step
from .xpbd import Xpbd, kick, predict, solve_constraints

__all__ = ["Step", "implicit_address", "integrate_substeps", "velocities_from_positions"]


class Step(NamedTuple):
    """What every integrator's substep reads: the (3, N) state and its velocity, the force buffer,
    the free points, Provot's spring blocks and rest lengths, the grid width, the point mass,
    gravity, dt, the damping factors (velocity factor ``f``, force-term scale ``phi``) and whether
    symplectic and implicit Euler re-derive velocities from the corrected positions (XPBD always
    does, Verlet keeps none)."""

    pos: np.ndarray
    last: np.ndarray
    vel: np.ndarray
    forces: np.ndarray
    free: np.ndarray
    blocks: np.ndarray
    rest: np.ndarray
    nw: int
    mass: float
    gravity: np.ndarray
    dt: float
    f: float
    phi: float
    fix_velocity: bool
    #: a mesh cloth's springs (``ClothState.mesh``), None for a grid cloth
    mesh: tuple | None = None


@njit(**KERNEL)
def velocities_from_positions(pos: np.ndarray, last: np.ndarray, vel: np.ndarray, free: np.ndarray,
                              dt: float) -> None:
    """v = (x - x_last)/dt, so that collision and Provot corrections also change the velocity."""
    inv = 1.0 / dt
    for ax in range(3):
        for k in range(free.shape[0]):
            p = free[k]
            vel[ax, p] = (pos[ax, p] - last[ax, p]) * inv


@njit(inline="always", **KERNEL)
def implicit_arguments(s: Step, g: Implicit) -> tuple:
    """The arguments of :func:`~.implicit.implicit_update` for a substep, in its order (also called
    from Python, for the types its address is compiled for: :func:`implicit_address`)."""
    return (s.pos, s.last, s.vel, s.forces, s.free, g.mask, g.si, g.sj, s.rest, g.kspr, g.jac, g.scratch, s.mass,
            s.dt, g.c, g.keep_after, g.tol, g.max_iter, g.its, g.point_mass)


def implicit_address(s: Step, g: Implicit) -> int:
    """``Implicit.at`` for the substep's state ``s`` and the rule's group ``g``."""
    return update_address(implicit_arguments.py_func(s, g))


@njit(**EXACT)
def integrate_substeps(steps: int, s: Step, stream: tuple, post: tuple, forces: tuple, pins: tuple | None,
                       verlet: VerletRate | None, symplectic: Symplectic | None, implicit: Implicit | None,
                       xpbd: Xpbd | None) -> tuple[int, int]:
    """``steps`` substeps with the one integrator whose group is given; returns (colliders
    skipped, CG iterations). ``post`` is the :class:`~clothsim.sim.state.Corrections` group
    (with its ``at`` filled in: :func:`~clothsim.sim.solvers.corrections_address`),
    ``forces`` the groups of :mod:`clothsim.sim.passes.forces` the scene uses, ``pins`` the
    :class:`~clothsim.sim.state.PinMotion` group or None."""
    pos = s.pos
    last = s.last
    skipped = 0
    iterations = 0
    offset = np.empty(3)
    out = np.zeros(1, np.int64)
    # the corrections take the collider kinds' groups by address (valid through this call): one
    # compiled corrections kernel for every set of kinds
    post = Corrections(post.pinned, post.self_mode, post.hash, post.stretch_limit, post.col,
                       stack_address(post.colliders), post.contact, post.at, post.mesh)
    for substep in range(steps):
        # forces: XPBD takes the springs as constraints, and only the other forces as forces. (Each test
        # names a group that is None for XPBD: Numba prunes a branch on an argument that is None,
        # not one on an argument that is not, so XPBD then compiles no spring-force code.)
        if verlet is not None:
            accumulate_forces(pos, s.forces, stream, s.mass, s.gravity)
        if symplectic is not None:
            accumulate_forces(pos, s.forces, stream, s.mass, s.gravity)
        if implicit is not None:
            accumulate_forces(pos, s.forces, stream, s.mass, s.gravity)
        if len(forces) > 0:
            if xpbd is not None:
                s.forces[:, :] = 0.0
            add_forces(forces, pos, last, s.forces, substep)
        if xpbd is None:
            # last: a mesh cloth's springs, and every force scaled to its point's mass (XPBD
            # takes the springs as constraints and the masses as its weights)
            add_spring_forces(s.mesh, pos, s.forces)
        # the integrator's advance
        if verlet is not None:
            verlet_rate_step(pos, last, s.forces, s.free, 1.0 / s.mass, s.dt, s.f, s.phi)
        if symplectic is not None:
            symplectic_step(pos, last, s.vel, s.forces, s.free, 1.0 / s.mass, s.dt, s.f, s.phi)
        if implicit is not None:
            # by address: the rule's code is the one compiled for it, not a copy linked in here
            # (see .implicit), so a cold and a warm start run the same instructions
            call_native(implicit.at, implicit_arguments(s, implicit))
            iterations += implicit.its[0]
        if xpbd is not None:
            if len(forces) > 0:
                kick(s.vel, s.forces, s.free, xpbd.w, s.dt * s.phi)
            predict(pos, last, s.vel, s.free, s.gravity, s.dt, s.f, s.phi)
        # moving pins
        if pins is not None:
            move_pins(pos, last, pins, substep_time(pins.clock, substep + 1, pins.dt), offset)
            if implicit is not None:
                pin_velocities(pos, last, s.vel, pins, s.dt)
        if xpbd is not None:
            solve_constraints(pos, xpbd.w, xpbd.si, xpbd.sj, s.rest, xpbd.kspr, xpbd.lam, s.dt, xpbd.iterations)
        # constraints and contacts
        call_native(post.at, (pos, last, s.free, s.blocks, s.rest, s.nw, post, np.int64(substep), out))
        skipped += out[0]
        # velocities follow the corrected positions (Verlet's velocity is its positions already)
        if symplectic is not None:
            if s.fix_velocity:
                velocities_from_positions(pos, last, s.vel, s.free, s.dt)
        if implicit is not None:
            if s.fix_velocity:
                velocities_from_positions(pos, last, s.vel, s.free, s.dt)
        if xpbd is not None:
            velocities_from_positions(pos, last, s.vel, s.free, s.dt)
    return skipped, iterations
