"""The integrators: every run other than the spec fast path, integrator and damping mode chosen
per scene. Each is an advance rule in a module of its own, run by the one substep of
:mod:`.substep`.

``advance(sim, steps)`` runs ``steps`` substeps in the spec's order (forces -> integrate ->
self-collision -> colliders -> Provot) with the integrator of ``sim.scene.simulation``:

* ``verlet``: position Verlet; reached here only with ``damping_mode == "rate"``, where it gets
  the second-order start and the consistent damping discretisation (see :mod:`.verlet`).
* ``symplectic_euler``: kick-drift with an explicit velocity (first order).
* ``implicit_euler``: linearised backward Euler, CG solve (see :mod:`.implicit`).
* ``xpbd``: compliant distance constraints (see :mod:`.xpbd`).

Extra per-run state lives in ``sim.integrator_state`` (an :class:`IntegratorState`), created on
first use from the current positions: the starting velocity is (x - x_last)/dt, zero at reset.
``sim.last_positions`` keeps meaning "position before the last substep" for every integrator, because
the collision kernels move points relative to it.
"""

from __future__ import annotations

import copy
import math
from typing import Any

import numba
import numpy as np

from ..passes.springs import accumulate_forces
from ..passes.meshsprings import add_spring_forces
from ..passes.corrections import corrections_into, has_corrections
from ..state import Corrections
from .implicit import CG_MAX_ITERATIONS, CG_TOLERANCE, Implicit
from .substep import Step, implicit_address, integrate_substeps
from .symplectic import Symplectic
from .verlet import VerletRate, verlet_start
from .xpbd import XPBD_ITERATIONS, Xpbd

#: Points from which these integrators split their passes over Numba's threads. Each pass is a
#: parallel loop of its own, a fork and join per pass and substep; on the 2-core development
#: machine (TBB threading layer) two threads ran 4-15x slower than one up to 25 x 25 points and
#: 1.0-4x slower at 50 x 50 (verlet rate, symplectic, implicit, xpbd; ms per frame, alternated),
#: and 1.05-1.2x faster only at 100 x 100.
PARALLEL_MIN_POINTS = 8192

# The spec's substep length (90 frames/s x 30 substeps): "rate" damping is calibrated so that at
# this dt exp(-c dt) equals the spec's per-substep factor 1 - damping/100.
SPEC_DT = 1.0 / 2700.0


def damping_rate(damping_percent: float) -> float:
    """Per-second damping rate c with exp(-c * SPEC_DT) == 1 - damping/100 (finite even at 100 %)."""
    keep = max(1.0 - damping_percent / 100.0, 1e-300)
    return -math.log(keep) / SPEC_DT


def damping_factors(sim: Any) -> tuple[float, float, float]:
    """(f, phi, c) for one substep: velocity factor, force-term scale, rate (c = 0 in spec mode).

    Spec mode: f = 1 - damping/100, phi = 1. Rate mode: f = exp(-c dt),
    phi = (1 - f)/(c dt) (-> 1 as c dt -> 0).
    """
    if sim.scene.simulation.damping_mode == "spec":
        return float(sim.plan.st.keep), 1.0, 0.0
    c = damping_rate(sim.scene.cloth.damping)
    cdt = c * sim.dt
    f = math.exp(-cdt)
    phi = 1.0 if cdt < 1e-12 else -math.expm1(-cdt) / cdt
    return f, phi, c


class IntegratorState:
    """Velocities, spring arrays and scratch buffers of one run (copyable for replays)."""

    def __init__(self, sim: Any) -> None:
        st = sim.plan.st
        n = st.pos.shape[1]
        self.vel = (st.pos - st.last) / sim.dt
        self.started = False
        self.iterations = int(getattr(sim, "xpbd_iterations", XPBD_ITERATIONS))
        self.mask = (~sim.pinned).astype(np.float64)
        self.inv_mass = self.mask / sim.point_mass
        #: a mesh cloth's point masses for implicit Euler's mass matrix (None: a grid's one mass)
        self.point_mass = None if sim.scene.cloth.mesh is None else np.ascontiguousarray(sim.point_mass)
        self.scratch = np.zeros((7, 3, n))
        self.cg_iterations = 0
        #: implicit Euler: its last substep's CG iterations, and ``Implicit.at`` (see _advance)
        self.cg_last = np.zeros(1, np.int64)
        self.implicit_at = 0
        #: the plan whose first call took the compile lock (see _advance)
        self.compiled_for: Any = None
        #: ``Corrections.at`` for the plan it was compiled for
        self.post_at = 0
        self.bind_springs(sim)

    def bind_springs(self, sim: Any) -> None:
        """(Re)derive per-spring arrays when the enabled springs or ks changed."""
        sp = sim.springs
        self._spring_k = sim.spring_stiffness  # re-made by every re-plan (ks, enable_*, cuts)
        self.si = np.ascontiguousarray(sp.i)
        self.sj = np.ascontiguousarray(sp.j)
        self.kspr = np.ascontiguousarray(sim.spring_stiffness, dtype=np.float64)  # 0 for cut springs
        self.jac = np.zeros((6, len(sp)))
        self.lam = np.zeros(len(sp))

    def current(self, sim: Any) -> "IntegratorState":
        """This state, re-bound if the simulation re-planned its springs or stiffness."""
        if self._spring_k is not sim.spring_stiffness or self.mask.shape[0] != sim.pinned.shape[0]:
            self.bind_springs(sim)
            self.inv_mass = self.mask / sim.point_mass
            if self.point_mass is not None:
                self.point_mass = np.ascontiguousarray(sim.point_mass)
        return self

    def copy(self) -> "IntegratorState":
        """A copy for the blow-up replay: the evolving arrays are copied, scratch buffers shared."""
        new = copy.copy(self)
        new.vel = self.vel.copy()
        return new


def post_args(sim: Any) -> Corrections:
    """The correction passes' group (:class:`~clothsim.sim.state.Corrections`)."""
    plan = sim.bound_plan()
    # the contact mode is a pass of its own (plan.contact), not one of the hash's modes
    mode = 0 if plan.contact is not None else sim.self_mode
    return Corrections(sim.pinned, mode, sim.self_hash(), plan.st.stretch_limit, plan.col, plan.colliders,
                       plan.contact, 0, plan.st.mesh)


def corrections_address(step: Step, post: Corrections) -> int:
    """``Corrections.at``: the address of :func:`~clothsim.sim.passes.corrections.corrections_into`
    compiled (or loaded) for ``step``'s arrays and ``post``'s type, by one process at a time (see
    :func:`clothsim.jit.compile.compiling_alone`)."""
    from ...jit.compile import compiling_alone
    from ...jit.internals import native_address

    i64 = numba.types.int64
    # the kernel gets the collider kinds' groups by address (see substep.integrate_substeps)
    argtypes = (*(numba.typeof(x) for x in (step.pos, step.last, step.free, step.blocks, step.rest)), i64,
                numba.typeof(post._replace(colliders=0)), i64, numba.types.Array(i64, 1, "C"))
    with compiling_alone(corrections_into, argtypes):
        return native_address(corrections_into, argtypes)


def state_of(sim: Any) -> IntegratorState:
    """``sim.integrator_state``, created on first use."""
    if sim.integrator_state is None:
        sim.integrator_state = IntegratorState(sim)
    return sim.integrator_state.current(sim)


def advance(sim: Any, steps: int) -> None:
    """Advance ``steps`` substeps with the scene's integrator and damping mode (in place).

    A cloth of fewer than :data:`PARALLEL_MIN_POINTS` points runs on one thread (results do not
    depend on the thread count, only the speed does).
    """
    if steps <= 0:
        return
    threads = numba.get_num_threads()
    if threads == 1 or sim.num_points >= PARALLEL_MIN_POINTS:
        _advance(sim, steps)
        return
    numba.set_num_threads(1)  # this thread's setting only
    try:
        _advance(sim, steps)
    finally:
        numba.set_num_threads(threads)


def _advance(sim: Any, steps: int) -> None:
    name = sim.scene.simulation.integrator
    st = state_of(sim)
    post = post_args(sim)
    fix = has_corrections(post)
    f, phi, c = damping_factors(sim)
    dt = sim.dt
    plan = sim.plan
    cloth = plan.st
    stream = (cloth.offsets, cloth.k, cloth.spring_rest, cloth.buf)
    verlet = symplectic = implicit = xpbd = None
    if name == "verlet":
        if not st.started:
            accumulate_forces(cloth.pos, cloth.forces, stream, sim.mass, cloth.gravity)
            add_spring_forces(cloth.mesh, cloth.pos, cloth.forces)
            verlet_start(cloth.pos, cloth.last, st.vel, cloth.forces, sim.free, 1.0 / sim.mass, dt, c)
            st.started = True
        verlet = VerletRate(1.0 / sim.mass)
    elif name == "symplectic_euler":
        symplectic = Symplectic(1.0 / sim.mass)
    elif name == "implicit_euler":
        # Rate damping goes into the implicit system; spec damping scales the solved velocity.
        keep_after = 1.0 if c > 0.0 else f
        implicit = Implicit(st.mask, st.si, st.sj, st.kspr, st.jac, st.scratch, c, keep_after, CG_TOLERANCE,
                            CG_MAX_ITERATIONS, st.cg_last, st.point_mass)
    elif name == "xpbd":
        xpbd = Xpbd(st.inv_mass, st.si, st.sj, st.kspr, st.lam, st.iterations)
    else:  # the scene validator only admits the four names above
        raise ValueError(f"unknown integrator {name!r}")
    step = Step(cloth.pos, cloth.last, st.vel, cloth.forces, sim.free, cloth.blocks, cloth.rest, cloth.nw, sim.mass,
                cloth.gravity, dt, f, phi, fix, cloth.mesh)
    if st.compiled_for is not plan:
        st.post_at = corrections_address(step, post)
        if implicit is not None:
            st.implicit_at = implicit_address(step, implicit)
    if implicit is not None:
        implicit = implicit._replace(at=st.implicit_at)
    args = (steps, step, stream, post._replace(at=st.post_at), plan.forces, plan.pins, verlet, symplectic, implicit,
            xpbd)
    if st.compiled_for is not plan:
        # the plan's first call: compiled by one process at a time (see jit.compile.compiling_alone)
        from ...jit.compile import compiling_alone

        with compiling_alone(integrate_substeps, tuple(numba.typeof(a) for a in args)):
            skipped, iterations = integrate_substeps(*args)
        st.compiled_for = plan
    else:
        skipped, iterations = integrate_substeps(*args)
    sim.colliders_skipped += skipped
    st.cg_iterations += iterations
