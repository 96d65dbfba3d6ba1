"""One frame = ``steps`` substeps in a single compiled call, in the spec's substep order:
forces (+ the registered forces: wind) -> integrate (+ moving pins) -> self-collision -> colliders
-> Provot.

The call is run by a team of threads (:mod:`clothsim.sim.team`) that share out each pass by
the same work items as the per-pass parallel kernels (``spring_pass``, ``verlet``, ...) and meet
at a barrier between passes, so a substep costs a few barriers instead of a fork and join per
pass. Those kernels stay for the other integrators.

The state comes as a few named tuples (see :mod:`clothsim.sim.state`): the cloth's arrays and
constants, and one group per optional pass (the spec's self-collision hash, the 27-cell grid
search, the colliders), each ``None`` when the scene does not use it. Numba prunes the branches of
an argument that is ``None`` before typing, so a scene's kernel is compiled with only its own
passes, and a new feature adds a field or a group, not a dozen positional arguments.

Colliders come as one tuple of the groups of the kinds the scene has
(:mod:`clothsim.sim.passes.colliders`): member 0 poses the moving ones, every member tests which
the cloth's bounding box reaches and collides its own work items.

The passes every plan runs (springs, gather, Verlet, Provot's two phases) and the contact mode's two
(``ClothState.calls``), and each collider kind's passes (``Colliders.calls``, a row per kind) are
kernels of their own that the member calls by address, like the spec hash's query and the mesh pass:
each is compiled once for every plan that has it, and none is linked into the member and re-
optimised there, so a plan compiles little more than its own loop (docs/history/team.md,
"Passes called by address").

A frame starts in Python: :func:`run_substeps` calls the team's parallel loop, :func:`_launch`,
with the address of the plan laid out as Numba lays it out
(:func:`~clothsim.jit.internals.packed_value`, once per plan); the loop is one compiled kernel for
every plan, and each of its threads calls :func:`_enter` (per plan, small), which reads the plan
back and calls the member. A parallel loop given the plan's groups themselves was compiled per
plan, and slowly for plans of many groups (docs/history/team.md, "The team's launcher"); a small
kernel per plan that copied it to its stack cost about 0.9 s of compiling a plan.
"""

from __future__ import annotations

from functools import lru_cache
from typing import NamedTuple

import numba
import numpy as np
from numba import njit, prange, types

from ...jit import CHUNKS, KERNEL, PARALLEL
from ...jit.internals import call_native, load_value, native_address, stack_address, type_ref

from ..passes.forces import force_gather, force_work
from ..passes.colliders import SET_COLLIDE, SET_POSE, SET_REACHABLE, kind_kernels, set_kernels
from ..passes.colliders.bounds import member_bounds, merge_bounds
from ..passes.provot import provot_bands, provot_bands_of, provot_cuts_of
from ..passes.meshsprings import mesh_gather, mesh_limit, mesh_work
from ..passes.springs import gather_one, spring_jobs
from .verlet import verlet_one
from ..clock import substep_time
from ..passes.pins import offset_at, pin_chunk
from ..passes.colliders.mesh import MeshGroup, collide_meshes_chunk, collide_types
from ..passes.contact import contact_bound, contact_joined, contact_stale
from ..passes.contactreference import count_squeezed, left_balls, rereference
from ..passes.contactgroup import CUT, FLAG, STALE
from ..passes.contactsearch import contact_search, fall_back, overflowed
from ..passes.selfcollide import cell_keys, count_slots, grid_self_collide, place_slots, repel_slots, scatter_slots, query_share
from ..state import Plan
from ..team import ABORT, FAILED, START, TIMED, atomic_cas, barrier, roll_call, share

#: Pass bits of :func:`run_substeps`: spring forces and Verlet, self-collision, colliders, Provot,
#: the contact mode's pass; and PASS_TIMED, which times every pass of the frame (team.barrier).
PASS_INTEGRATE, PASS_SELF, PASS_COLLIDERS, PASS_PROVOT, PASS_CONTACT = 1, 2, 4, 8, 16
PASS_ALL = 31
PASS_TIMED = 32

#: The laps of a timed frame (PASS_TIMED): the barriers of a substep, each named for the pass before
#: it; each barrier is given its lap's number (see team.barrier).
(LAP_FORCES, LAP_INTEGRATE, LAP_KEYS, LAP_PLACE, LAP_SCATTER, LAP_QUERY, LAP_GRID, LAP_STALE, LAP_SEARCH,
 LAP_RESPOND, LAP_POSE, LAP_BOUNDS, LAP_COLLIDE, LAP_BANDS, LAP_CUTS, LAP_BOUND) = range(16)
LAP_NAMES = ("springs and forces", "gather and Verlet", "hash: keys", "hash: slots placed", "hash: points placed",
             "hash: query", "grid self-collision", "contact: stale?", "contact: search", "contact: join, moves, response",
             "colliders posed", "colliders: cloth box", "colliders", "Provot: bands", "Provot: cuts", "contact: bound")

#: The passes the member calls by address, in ``ClothState.calls``: those every plan runs, then
#: the contact mode's four (0 without it: the response with the rebuild's join, the bound, whether
#: to rebuild, a member's parts of the rebuild). Each is compiled once for every plan that has it,
#: so that a plan compiles only its own loop.
(CALL_SPRINGS, CALL_GATHER, CALL_VERLET, CALL_BANDS, CALL_CUTS, CALL_RESPOND, CALL_BOUND, CALL_STALE,
 CALL_SEARCH) = range(9)
CALLS = 9


@njit(inline="always", **KERNEL)
def _collide_items(col: tuple, colliders_at: int, pos: np.ndarray, last: np.ndarray, box: np.ndarray, own: bool,
                   lo: int, hi: int, skipped: np.ndarray) -> None:
    """The collider pass's work items ``lo`` to ``hi`` (a member's), the kinds' groups at the address
    ``colliders_at``. It allocates the reach flags of a member other than the first: a failure ends
    this member as a failed allocation of its own would."""
    if call_native(col.sets[SET_COLLIDE], (colliders_at, col.calls, pos, last, col.free, box, col.offset, own,
                                           np.int64(lo), np.int64(hi), skipped, type_ref(None))) != 0:
        raise MemoryError("the collider pass could not allocate its reach flags")


@njit(inline="always", **KERNEL)
def _bounds_now(pos: np.ndarray, last: np.ndarray, col: tuple, cols: np.ndarray, box: np.ndarray, lo: int, hi: int,
                sync: np.ndarray, size: int, gen: int) -> int:
    """The colliders' box of the positions as they are now (a pass the profile runs on its own):
    each member's bounds over its work items ``lo`` to ``hi``, a barrier, then their merge into
    ``box``. Returns the barrier's generation (negative when the team gave up)."""
    member_bounds(pos, last, col.boxes, cols, lo, hi)
    gen = barrier(sync, size, gen, np.int64(LAP_BOUNDS))
    if gen >= 0:
        merge_bounds(col.boxes, 0.0, box)
    return gen


@njit(**KERNEL)
def _member(member: int, size: int, steps: int, st: tuple, spec: tuple | None, grid: tuple | None,
            col: tuple | None, colliders_at: int, forces: tuple, pins: tuple | None, contact: tuple | None,
            sync: np.ndarray, passes: int) -> None:
    """One member's part of ``steps`` substeps; members meet at a barrier between passes.

    Returns early, with the state half-way through a substep, when a barrier reports that the
    frame was given up (see :func:`clothsim.sim.team.barrier`); the caller then restores it.
    """
    pos = st.pos
    last = st.last
    jobs = st.offsets.shape[0] * CHUNKS
    bands = provot_bands(pos, st.nw)
    n = pos.shape[1]
    integrate = passes & PASS_INTEGRATE != 0
    self_on = passes & PASS_SELF != 0
    colliding = passes & PASS_COLLIDERS != 0
    provot_on = st.stretch_limit > 0.0 and passes & PASS_PROVOT != 0
    # the member's own points (its chunks)
    c0, c1 = share(CHUNKS, member, size)
    own0, own1 = share(n, c0, CHUNKS)[0], share(n, c1, CHUNKS)[0]
    if spec is not None:
        table = spec.start.shape[0] - 1
        # a member alone (see team.roll_call) sorts with one row of counts, not the team's
        hist = spec.counted[0, :size]
        cursor = spec.counted[1, :size]
        # the member's part of the hash table
        t0, t1 = share(table, member, size)
    if col is not None:
        # Each member tests the colliders itself (no barrier between the test and its use); member
        # 0 in the caller's arrays, the others in their own.
        box = col.box
        if member != 0:
            box = np.empty(6)
        own = member != 0
        # Moving colliders: member 0 poses them at the start of the collider pass, behind one
        # more barrier (the pass reads the poses right after).
        posing = col.moving
        # The members' boxes are taken right after Verlet, before self-collision, which moves no
        # point by dist / sim_steps or more (an average of pushes each shorter than dist, over
        # sim_steps): widened by that, the box still bounds the cloth the colliders see, so
        # skipping stays exact.
        margin = 0.0 if not self_on else col.self_margin
        cols = np.empty((2, 64))
        skipped = np.zeros(1, np.int64)
    if pins is not None:
        offset = np.empty(3)
    if contact is not None:
        # whether this substep rebuilds the contact reference, and the member's parts of it
        stale = np.zeros(FLAG, np.int64)
    gen = np.int64(0)
    if sync[TIMED] != 0:
        # a timed frame's first lap starts once the team is together
        gen = barrier(sync, size, gen, np.int64(START))
        if gen < 0:
            return
    for substep in range(steps):
        if integrate:
            lo, hi = share(jobs, member, size)
            call_native(st.calls[CALL_SPRINGS], (pos, st.offsets, st.k, st.spring_rest, st.buf, np.int64(lo),
                                                 np.int64(hi)))
            # the other forces read only positions: same phase as the springs
            w0, w1 = share(CHUNKS, member, size)
            force_work(forces, pos, last, substep, w0, w1)
            mesh_work(st.mesh, pos, w0, w1)
            if pins is not None:
                offset_at(pins.times, pins.points, pins.velocity, substep_time(pins.clock, substep + 1, pins.dt), offset)
            gen = barrier(sync, size, gen, np.int64(LAP_FORCES))
            if gen < 0:
                return
            # a point's force is final once gathered, so its Verlet step follows at once
            lo, hi = share(CHUNKS, member, size)
            if spec is not None:
                if self_on:
                    hist[member] = 0
            for c in range(lo, hi):
                call_native(st.calls[CALL_GATHER], (st.offsets, st.buf, st.mass, st.gravity, st.forces, np.int64(c)))
                force_gather(forces, st.forces, c)
                # last: a mesh cloth's gather scales the whole force to the point's mass
                mesh_gather(st.mesh, st.forces, c)
                call_native(st.calls[CALL_VERLET], (pos, last, st.forces, st.pins, st.h2, st.keep, np.int64(c)))
                if pins is not None:
                    pin_chunk(pos, last, pins, offset, c)
                if spec is not None:
                    if self_on:
                        # the spec's map is of the positions just integrated: bin them while in cache
                        p0, p1 = share(n, c, CHUNKS)
                        cell_keys(pos, spec.cell[0], spec.cell[1], spec.cell[2], spec.keys, spec.slots, table,
                                  p0, p1)
                        count_slots(spec.slots, hist[member], p0, p1)
            if col is not None:
                member_bounds(pos, last, col.boxes, cols, lo, hi)
            gen = barrier(sync, size, gen, np.int64(LAP_INTEGRATE))
            if gen < 0:
                return
        elif spec is not None:
            if self_on:
                cell_keys(pos, spec.cell[0], spec.cell[1], spec.cell[2], spec.keys, spec.slots, table, own0, own1)
                hist[member] = 0
                count_slots(spec.slots, hist[member], own0, own1)
                gen = barrier(sync, size, gen, np.int64(LAP_KEYS))
                if gen < 0:
                    return
        if spec is not None:
            if self_on:
                # A counting sort split over the team: each member places the slots of its part of
                # the table, then puts its own points in place. A point's owner copies it into its
                # slot (its position is in the owner's cache): on selfCollision 2.47-2.49 ms a frame
                # (medians of 15 x 30 frames from frame 60), against 2.68-2.70 when the member
                # repelling a slot copied it, and 2.50-2.56 with one member sorting alone. Then the
                # busy slots of all parts are shared out by estimated cost.
                spec.tally[member, 0], spec.tally[member, 1] = place_slots(hist, cursor, spec.start, spec.busy,
                                                                           spec.cum, t0, t1)
                gen = barrier(sync, size, gen, np.int64(LAP_PLACE))
                if gen < 0:
                    return
                scatter_slots(pos, spec.keys, spec.slots, cursor[member], spec.order, spec.xs, spec.ys, spec.zs,
                              spec.ks, own0, own1)
                gen = barrier(sync, size, gen, np.int64(LAP_SCATTER))
                if gen < 0:
                    return
                for r in range(size):
                    i0, i1 = query_share(spec.cum, spec.tally, table, r, member, size)
                    if i0 < i1:
                        r0 = share(table, r, size)[0]
                        call_native(spec.repel, (pos, spec.movable, spec.dist, spec.sim_steps, spec.start, spec.order,
                                                 spec.busy, spec.xs, spec.ys, spec.zs, spec.ks, np.int64(r0 + i0),
                                                 np.int64(r0 + i1)))
                gen = barrier(sync, size, gen, np.int64(LAP_QUERY))
                if gen < 0:
                    return
        if grid is not None:
            if self_on:
                if member == 0:
                    grid_self_collide(pos, grid.free, grid.thickness, grid.sim_steps, grid.cell[0], grid.cell[1],
                                      grid.cell[2], grid.keys, grid.slots, grid.start, grid.order)
                gen = barrier(sync, size, gen, np.int64(LAP_GRID))
                if gen < 0:
                    return
        if contact is not None:
            if self_on:
                # the contact response, where the hash's self-collision would be; a rebuild of its
                # reference is searched by the whole team, each member its parts. Every member
                # decides for itself, from the same arrays, before any moves a point.
                call_native(st.calls[CALL_STALE], (pos, last, contact, stale, np.int64(member), np.int64(size)))
                gen = barrier(sync, size, gen, np.int64(LAP_STALE))
                if gen < 0:
                    return
                if stale[STALE] != 0:
                    call_native(st.calls[CALL_SEARCH], (last, contact, stale, np.int64(member)))
                    gen = barrier(sync, size, gen, np.int64(LAP_SEARCH))
                    if gen < 0:
                        return
                if member == 0:
                    if stale[STALE] != 0 and overflowed(contact, stale[CUT]):
                        fall_back(stale)
                        call_native(st.calls[CALL_SEARCH], (last, contact, stale, np.int64(0)))
                    call_native(st.calls[CALL_RESPOND], (pos, last, contact, stale))
                gen = barrier(sync, size, gen, np.int64(LAP_RESPOND))
                if gen < 0:
                    return
        if col is not None:
            if colliding:
                if posing:
                    if member == 0:
                        call_native(col.sets[SET_POSE], (colliders_at, col.calls, np.int64(substep), type_ref(None)))
                    gen = barrier(sync, size, gen, np.int64(LAP_POSE))
                    if gen < 0:
                        return
                lo, hi = share(CHUNKS, member, size)
                if integrate:
                    merge_bounds(col.boxes, margin, box)
                else:
                    # run on its own (profile): bound the positions as they are now
                    gen = _bounds_now(pos, last, col, cols, box, lo, hi, sync, size, gen)
                    if gen < 0:
                        return
                _collide_items(col, colliders_at, pos, last, box, own, lo, hi, skipped)
                if member == 0:
                    st.skips[0] += skipped[0]
                gen = barrier(sync, size, gen, np.int64(LAP_COLLIDE))
                if gen < 0:
                    return
        if provot_on and mesh_limit(pos, st.pinned, st.mesh, st.stretch_limit, c0, c1, False):
            # a mesh cloth's springs within the members' point ranges side by side, then those
            # between ranges on one member
            gen = barrier(sync, size, gen, np.int64(LAP_BANDS))
            if gen < 0:
                return
            if member == 0:
                mesh_limit(pos, st.pinned, st.mesh, st.stretch_limit, 0, 0, True)
            gen = barrier(sync, size, gen, np.int64(LAP_CUTS))
            if gen < 0:
                return
        elif provot_on:
            lo, hi = share(bands, member, size)
            call_native(st.calls[CALL_BANDS], (pos, st.pinned, st.blocks, st.rest, st.nw, st.stretch_limit,
                                               np.int64(lo), np.int64(hi), np.int64(bands)))
            gen = barrier(sync, size, gen, np.int64(LAP_BANDS))
            if gen < 0:
                return
            lo, hi = share(bands - 1, member, size)
            call_native(st.calls[CALL_CUTS], (pos, st.pinned, st.blocks, st.rest, st.nw, st.stretch_limit,
                                              np.int64(lo), np.int64(hi), np.int64(bands)))
            gen = barrier(sync, size, gen, np.int64(LAP_CUTS))
            if gen < 0:
                return
        if contact is not None:
            # last in the substep: no later pass may move a point past the bound
            if passes & PASS_CONTACT != 0:
                if member == 0:
                    call_native(st.calls[CALL_BOUND], (pos, contact))
                gen = barrier(sync, size, gen, np.int64(LAP_BOUND))
                if gen < 0:
                    return
                if col is not None and col.moving:
                    # a moving collider has the last word (contactreference.left_balls); its time
                    # goes to the colliders' lap
                    lo, hi = share(CHUNKS, member, size)
                    if not colliding:
                        # run on its own (profile): the colliders' box of the positions as they are now
                        gen = _bounds_now(pos, last, col, cols, box, lo, hi, sync, size, gen)
                        if gen < 0:
                            return
                    _collide_items(col, colliders_at, pos, last, box, own, lo, hi, skipped)
                    left_balls(pos, contact, col.free, lo, hi)
                    gen = barrier(sync, size, gen, np.int64(LAP_COLLIDE))
                    if gen < 0:
                        return
                    if member == 0:
                        count_squeezed(contact)


@lru_cache(maxsize=None)
def _addresses(argtypes: tuple, plan_type: types.Type) -> Addresses:
    from ...jit.compile import compile_elsewhere, compiling_alone, side_kernels_beside, warm_side_kernels
    from .. import guard, rest  # noqa: F401 - they register their kernels' warm-up on import

    # argtypes = (member, size, steps, *the Plan's groups, sync, passes)
    groups = Plan(*argtypes[3 : 3 + len(Plan._fields)])
    sync = argtypes[3 + len(Plan._fields)]
    st, spec = groups.st, groups.spec
    i64 = types.int64
    repel = None
    if spec != types.none:
        # repel_slots is called by address too, so that it is compiled here while the member
        # compiles in the second process, and linked into neither
        def field(name: str) -> types.Type:
            return spec.types[spec.fields.index(name)]

        repel = (st.types[st.fields.index("pos")], field("movable"), field("dist"), field("sim_steps"),
                 *(field(n) for n in ("start", "order", "busy", "xs", "ys", "zs", "ks")), i64, i64)

    collide = None
    col = groups.col
    meshes = [t for t in groups.colliders.types if getattr(t, "instance_class", None) is MeshGroup]
    if meshes:
        # the mesh pass too: compiled on its own, and kept out of the member's module
        collide = collide_types(st.types[st.fields.index("pos")], st.types[st.fields.index("last")],
                                col.types[col.fields.index("free")], meshes[0])
    kinds: list[tuple[tuple, ...]] = []
    sets: tuple[tuple, ...] = ()
    if col != types.none:
        # each kind's passes, shared by every plan with that kind's group, and the plan's set of
        # kinds (small), which the member calls
        state = (st.types[st.fields.index("pos")], st.types[st.fields.index("last")],
                 *(col.types[col.fields.index(name)] for name in ("free", "box", "offset")))
        kinds = [kind_kernels(g, *state) for g in groups.colliders.types]
        # (the team does not use the other integrators' collider pass: compiled when one runs)
        sets = set_kernels(groups.colliders, col, *state[:2])[:SET_REACHABLE]
    # the member takes the kinds' groups by address (see _enter): one member for every set of kinds
    member = tuple(i64 if k == 3 + Plan._fields.index("colliders") else t for k, t in enumerate(argtypes))
    enter = (i64, i64, i64, i64, i64, sync, i64, types.TypeRef(plan_type))
    launch = (i64, i64, i64, i64, sync, i64, i64)

    contact = None
    moves = ()
    if groups.contact != types.none:
        pos, last = st.types[st.fields.index("pos")], st.types[st.fields.index("last")]
        flag = types.Array(types.int64, 1, "C")
        contact = ((contact_joined, (pos, last, groups.contact, flag)), (contact_bound, (pos, groups.contact)),
                   (contact_stale, (pos, last, groups.contact, flag, i64, i64)),
                   (contact_search, (last, groups.contact, flag, i64)))
        # the moves of a few references (about 15 s cold, a third of the mode's kernels) are a
        # callee of the first: compiled in the second process first, and loaded from the cache
        # when this one compiles the first, last
        moves = ((rereference, (pos, last, groups.contact)),)

    # A cold start's two processes: the second compiles the member (5-9 s cold) and the mesh
    # pass (8-9 s) or else the set's two kernels (3 s), and the side kernels registered to go
    # beside (the renderer's overlap test); this one the rest (the kinds' passes 3-6 s, the
    # shared passes, the launchers, the other side kernels).
    # (in the contact mode the second process starts with the moves, so the set's kernels stay here)
    sets_beside = collide is None and not contact
    beside = (*(((collide_meshes_chunk, collide),) if collide is not None else sets if sets_beside else ()),
              *side_kernels_beside())
    here = (*(contact[1:] if contact else ()), *(kernel for row in kinds for kernel in row),
            *(() if sets_beside else sets))

    def meanwhile() -> None:
        _shared_addresses(st)
        for kernel, signature in here:
            kernel.compile(signature)
        if repel is not None:
            repel_slots.compile(repel)
        _enter.compile(enter)
        _launch.compile(launch)
        warm_side_kernels(beside=False)
        if contact:
            contact[0][0].compile(contact[0][1])

    with compiling_alone(_member, member):
        compile_elsewhere(_member, member, meanwhile, beside, moves)
        warm_side_kernels(beside=True)  # loaded from what the second process compiled (if any)
        # (compiled here, on one core or when the second process failed)
        calls = (*_shared_addresses(st), *((native_address(*c) for c in contact) if contact else (0,) * 4))
        return Addresses(native_address(_member, member),
                         0 if repel is None else native_address(repel_slots, repel),
                         0 if collide is None else native_address(collide_meshes_chunk, collide),
                         native_address(_enter, enter), calls,
                         tuple(tuple(native_address(*kernel) for kernel in row) for row in kinds),
                         (*(native_address(*kernel) for kernel in sets), 0) if sets else ())


@lru_cache(maxsize=None)
def _shared_addresses(st: types.Type) -> tuple[int, ...]:
    """The passes every plan runs (``CALL_SPRINGS`` to ``CALL_CUTS``) compiled (or loaded) for the
    cloth group's type ``st``."""
    def field(name: str) -> types.Type:
        return st.types[st.fields.index(name)]

    i64 = types.int64
    pos = field("pos")
    rows = (pos, field("pinned"), field("blocks"), field("rest"), field("nw"), field("stretch_limit"), i64, i64, i64)
    # in CALL_* order
    kernels = ((spring_jobs, (pos, field("offsets"), field("k"), field("spring_rest"), field("buf"), i64, i64)),
               (gather_one, (field("offsets"), field("buf"), field("mass"), field("gravity"), field("forces"), i64)),
               (verlet_one, (pos, field("last"), field("forces"), field("pins"), field("h2"), field("keep"), i64)),
               (provot_bands_of, rows),
               (provot_cuts_of, rows))
    return tuple(native_address(*k) for k in kernels)


class Addresses(NamedTuple):
    """Where a plan's compiled kernels are (see :func:`kernel_addresses`)."""

    #: :func:`_member` compiled for the plan's groups
    member: int
    #: :func:`~clothsim.sim.passes.selfcollide.repel_slots`, which the member calls (0 without the spec's hash)
    repel: int
    #: :func:`~clothsim.sim.passes.colliders.mesh.collide_meshes_chunk`, which the member calls (0 without meshes)
    collide: int
    #: :func:`_enter` compiled for the plan's type
    enter: int
    #: the passes called by address (``ClothState.calls``, ``CALL_*``)
    calls: tuple[int, ...]
    #: each kind's collider passes (``Colliders.calls``, a row per kind: :data:`~clothsim.sim.passes.colliders.KIND_CALLS`; empty without colliders)
    colliders: tuple[tuple[int, ...], ...]
    #: the kernels of the plan's set of kinds (``Colliders.sets``, :data:`~clothsim.sim.passes.colliders.SETS`; empty without colliders)
    sets: tuple[int, ...]


def kernel_addresses(plan: Plan, sync: np.ndarray) -> Addresses:
    """Addresses of the kernels that run ``plan`` (:class:`Addresses`), compiled or loaded from
    the cache on first use; ``repel`` goes into ``SpecHash.repel``, ``collide`` into
    ``MeshGroup.collide`` (:func:`with_mesh_address`), the rest to :func:`run_substeps`."""
    i64 = types.int64
    return _addresses((i64, i64, i64, *(numba.typeof(x) for x in (*plan, sync)), i64), numba.typeof(plan))


@njit(**KERNEL)
def _enter(me: int, working: int, steps: int, plan_at: int, member: int, sync: np.ndarray, passes: int,
           plan_type: types.TypeRef) -> None:
    """A team thread's way into the member: the plan from :func:`run_substeps`' stack, then the
    member, both compiled for the plan; the launcher calls it by address, as one signature for
    every plan."""
    plan = load_value(plan_at, plan_type)
    # the collider kinds' groups by address: one compiled member for every set of kinds
    if call_native(member, (me, working, steps, plan.st, plan.spec, plan.grid, plan.col, stack_address(plan.colliders),
                            plan.forces, plan.pins, plan.contact, sync, passes)) != 0:
        sync[FAILED] = 1
        atomic_cas(sync, ABORT, 0, 1)


@njit(**PARALLEL)
def _launch(steps: int, plan_at: int, member: int, enter: int, sync: np.ndarray, size: int, passes: int) -> None:
    """The team's parallel loop: each thread answers the roll call and enters the member. It sees
    the plan only as an address, so it is compiled once for every plan (given the plan's groups,
    it compiled for each plan, slowly for plans of many groups: docs/performance-team.md)."""
    for m in prange(size):
        working = roll_call(sync, size)
        if working != 0:
            # one call site, with int64 arguments: one compiled _member whoever runs it
            me = 0
            if working == size:
                me = np.int64(m)
            call_native(enter, (me, working, steps, plan_at, member, sync, passes, type_ref(None)))


def run_substeps(steps: int, plan: Plan, sync: np.ndarray, size: int, passes: int, member: int, enter: int,
                 at: int) -> int:
    """Advance ``steps`` substeps of the spec's Verlet model; returns colliders skipped.

    ``plan`` holds the named tuples of :mod:`clothsim.sim.state`: ``colliders`` the groups of the
    collider kinds (:mod:`clothsim.sim.passes.colliders`), ``forces`` those of
    :mod:`clothsim.sim.passes.forces` the scene uses, the other groups but ``st`` ``None`` for a
    pass the scene does not use (``colliders`` is empty when ``col`` is None). ``at`` is the
    address of ``plan`` laid out by :func:`~clothsim.jit.internals.packed_value` (kept alive by
    the caller, with ``plan``): the team's parallel loop, :func:`_launch`, and :func:`_enter` read
    it there, so no kernel is compiled per plan to copy it. ``sync`` is
    :func:`clothsim.sim.team.new_sync`'s array, ``size`` the team size (see
    :mod:`clothsim.sim.team`); the result does not depend on it. After the call
    ``sync[team.ABORT]`` set means the frame was given up half-way (restore and run it alone).

    ``passes`` (PASS_* bits) runs only some passes, for :mod:`clothsim.sim.profile`; ``member``
    and ``enter`` are those of :func:`kernel_addresses` for this plan.
    ``sync[team.FAILED]`` set after the call means a member failed (it could not allocate its
    work space).
    """
    plan.st.skips[0] = 0
    sync[:] = 0
    sync[TIMED] = passes & PASS_TIMED != 0
    _launch(steps, at, member, enter, sync, size, passes & PASS_ALL)
    return int(plan.st.skips[0])


def with_mesh_address(plan: Plan, address: int) -> Plan:
    """``plan`` with the mesh pass's address (the third of :func:`kernel_addresses`) in its mesh
    group; ``plan`` itself without meshes."""
    if not address:
        return plan
    return plan._replace(colliders=tuple(g._replace(collide=address) if isinstance(g, MeshGroup) else g
                                         for g in plan.colliders))
