"""What the frame kernel (:func:`clothsim.sim.solvers.frame.run_substeps`) is given: named tuples of flat
arrays and constants, one for the cloth and one per optional pass.

A pass the scene does not use is passed as ``None``; Numba compiles the kernel separately for
each combination of groups present and prunes the code of the absent ones before typing, so a
scene pays compile time only for its own passes (and the on-disk cache holds one kernel per
combination used). A new feature adds a field to a group, or a new group, instead of growing
every signature by its arrays.
"""

from __future__ import annotations

from typing import NamedTuple

import numpy as np


class ClothState(NamedTuple):
    """The cloth: (3, N) state, the springs (streams for the forces, blocks for Provot) and the
    per-substep constants."""

    pos: np.ndarray
    last: np.ndarray
    forces: np.ndarray
    pinned: np.ndarray
    pins: np.ndarray
    blocks: np.ndarray
    rest: np.ndarray
    nw: int
    offsets: np.ndarray
    k: np.ndarray
    spring_rest: np.ndarray
    buf: np.ndarray
    mass: float
    gravity: np.ndarray
    h2: float
    keep: float
    stretch_limit: float
    skips: np.ndarray
    #: addresses of the passes the thread team's member calls by address (``CALL_*`` of
    #: :mod:`clothsim.sim.solvers.frame`, filled in by its ``kernel_addresses``); zeros until known
    calls: np.ndarray
    #: a mesh cloth's listed springs, point masses and Provot springs
    #: (:class:`clothsim.sim.passes.meshsprings.MeshSprings`; its springs of common offsets are the
    #: streams above, and the blocks are empty); None for a grid cloth
    mesh: tuple | None = None


class SpecHash(NamedTuple):
    """The spec's same-cell self-collision, its counting sort split over the team."""

    cell: np.ndarray
    keys: np.ndarray
    slots: np.ndarray
    start: np.ndarray
    order: np.ndarray
    movable: np.ndarray
    busy: np.ndarray
    xs: np.ndarray
    ys: np.ndarray
    zs: np.ndarray
    ks: np.ndarray
    cum: np.ndarray
    counted: np.ndarray
    tally: np.ndarray
    dist: float
    sim_steps: int
    #: address of the query kernel (see :func:`clothsim.sim.solvers.frame.kernel_addresses`); 0 until known
    repel: int


class GridHash(NamedTuple):
    """The 27-cell grid self-collision (run by one member)."""

    free: np.ndarray
    thickness: float
    sim_steps: int
    cell: np.ndarray
    keys: np.ndarray
    slots: np.ndarray
    start: np.ndarray
    order: np.ndarray


class Colliders(NamedTuple):
    """What the collider pass shares over the kinds (their own groups are a plan's
    ``colliders``, see :mod:`clothsim.sim.passes.colliders`): the free points, the offset a
    corrected point is put at off a plane or a box face, the cloth's bounding box, the members'
    boxes, and how far past the members' boxes (taken before self-collision) a point may be when
    the colliders run."""

    free: np.ndarray
    offset: float
    box: np.ndarray
    boxes: np.ndarray
    self_margin: float
    #: whether any collider moves (the thread team then poses them, behind one more barrier)
    moving: bool
    #: (kinds, :data:`~clothsim.sim.passes.colliders.KIND_CALLS`) addresses of each kind's pose,
    #: reach and collide passes, which every integrator's collider pass calls (filled by
    #: :func:`clothsim.sim.solvers.frame.kernel_addresses` or
    #: :func:`clothsim.sim.passes.colliders.kind_addresses`); zeros until known
    calls: np.ndarray
    #: (:data:`~clothsim.sim.passes.colliders.SETS`,) addresses of the kernels of the plan's set of
    #: kinds (:func:`clothsim.sim.passes.colliders.set_kernels`), filled as ``calls``
    sets: np.ndarray


class PinMotion(NamedTuple):
    """Moving pins (:mod:`clothsim.sim.passes.pins`): the pinned points, their rest positions (3, P),
    the offset's track (:class:`clothsim.motion.Track` arrays), the substep length and the
    simulation's one clock (:mod:`clothsim.sim.clock`)."""

    pins: np.ndarray
    rest: np.ndarray
    times: np.ndarray
    points: np.ndarray
    velocity: np.ndarray
    dt: float
    clock: np.ndarray


class Corrections(NamedTuple):
    """The position corrections every integrator but the fast path runs after its advance
    (:func:`clothsim.sim.passes.corrections.corrections`): the pinned mask, the self-collision mode
    (0 = off) with its hash (a :class:`GridHash`, whichever the mode), Provot's limit (<= 0 = off),
    the :class:`Colliders` group (None when the scene has none) with the collider kinds' groups
    (the tuple; in the kernels, its address: see :func:`clothsim.sim.solvers.substep.integrate_substeps`),
    and the contact mode's group (None in every other mode)."""

    pinned: np.ndarray
    self_mode: int
    hash: GridHash
    stretch_limit: float
    col: Colliders | None
    colliders: tuple
    #: the contact mode's group (:class:`clothsim.sim.passes.contactgroup.Contact`), run after Provot; None otherwise
    contact: tuple | None = None
    #: address of :func:`~clothsim.sim.passes.corrections.corrections_into` for this group's
    #: type, which the integrators' substep calls; 0 until known
    at: int = 0
    #: a mesh cloth's springs (``ClothState.mesh``), whose Provot limit runs here; None for a grid
    mesh: tuple | None = None


class Plan(NamedTuple):
    """Every group of a scene's compiled plan, in the frame kernel's argument order; a pass the
    scene does not use is None (see the module's notes)."""

    st: ClothState
    spec: SpecHash | None
    grid: GridHash | None
    col: Colliders | None
    #: the groups of the collider kinds the scene has (:mod:`clothsim.sim.passes.colliders`), in registry order
    colliders: tuple
    #: the groups of the forces the scene uses (:mod:`clothsim.sim.passes.forces`), in registry order
    forces: tuple
    pins: PinMotion | None
    #: the contact mode's group (:class:`clothsim.sim.passes.contactgroup.Contact`)
    contact: tuple | None = None
