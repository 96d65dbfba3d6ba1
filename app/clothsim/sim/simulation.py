"""The :class:`Simulation`: cloth state as flat arrays plus the plan of passes a scene needs."""

from __future__ import annotations

import ctypes

import numba
import numpy as np

from ..cloth import (BENDING, BENDING_STIFFNESS_FACTOR, STRUCTURAL, Springs, Surface, cloth_surface, enabled_mask,
                     pinned_mask, spring_blocks, spring_streams)
from ..errors import SimulationBlowUp
from ..scene import Scene, check_field
from ..validate import At, check, integer
from ..wind import WINDS
from . import team
from .passes.colliders import KIND_CALLS, SETS, kind_addresses, plan_colliders
from .passes.colliders.plane import SURFACE_OFFSET
from .solvers.frame import CALLS, PASS_ALL, Addresses, kernel_addresses, run_substeps, with_mesh_address
from .passes.forces import plan_forces
from .passes.meshsprings import mesh_streams, pack_mesh_springs
from .topology import cloth_springs, mean_mass, point_masses, rest_positions, spacing
from ..jit import CHUNKS
from ..jit.internals import packed_value
from .passes.pins import move_pins
from .passes.colliders.mesh import MeshGroup, collide_address
from .passes.colliders.moving import top_speed
from .passes.selfcollide import MODE_GRID, MODE_SPEC, slot_copies, spec_table_size, table_size
from .passes.contactgroup import DROPPED, MOVING, SQUEEZED, UNSAFE, contact_group, response_reach, \
    restore_reference, snapshot_reference, with_more_room
from .passes.contactreference import any_outside
from .state import ClothState, Colliders, GridHash, PinMotion, Plan, SpecHash

#: The contact mode: a pass of its own (passes/contact.py), not a query of the hash.
MODE_CONTACT = 3
_SELF_MODES = {"off": 0, "spec": MODE_SPEC, "grid": MODE_GRID, "contact": MODE_CONTACT}
_FRAMES = integer(ge=0)
#: Rest length given to cut springs: no cloth stretches that far, and its square stays finite.
CUT_REST = 1e30


def scene_field(section: str, name: str, doc: str) -> property:
    """A property of :class:`Simulation` for field ``name`` of the scene's ``section`` ("cloth" or
    "simulation"): read from the scene, and set through the section's setter (checked, then the
    simulation re-planned)."""
    setter = "_set_cloth" if section == "cloth" else "_set_sim"
    return property(lambda self: getattr(getattr(self.scene, section), name),
                    lambda self, value: getattr(self, setter)(name, value), doc=doc)


class Simulation:
    """A cloth scene being simulated.

    ``positions`` and ``last_positions`` are (N, 3) float64 arrays updated in place (row-major:
    index = row * num_width_points + col). Parameters the course GUI lets a user change between
    frames are properties here (``ks``, ``density``, ``damping``, the ``enable_*`` flags,
    ``gravity``, ``frames_per_sec``, ``simulation_steps``) and ``wind``; setting one re-plans the
    passes.
    """

    def __init__(self, scene: Scene) -> None:
        self.scene = scene
        if scene.simulation.self_collision == "contact" or scene.meshes or scene.cloth.is_mesh:
            # said before the first kernel compiles (the collider plan below may compile one)
            from ..jit.watch import CONTACT_FIRST_RUN_SECONDS, CONTACT_MESH_FIRST_RUN_SECONDS, MESH_FIRST_RUN_SECONDS, \
                expect

            mesh = bool(scene.meshes) or scene.cloth.is_mesh
            if scene.simulation.self_collision == "contact":
                expect(CONTACT_MESH_FIRST_RUN_SECONDS if mesh else CONTACT_FIRST_RUN_SECONDS)
            else:
                expect(MESH_FIRST_RUN_SECONDS)
        cloth = scene.cloth
        # the grid's size (0 x 0 for a mesh cloth, whose surface is :attr:`surface`)
        self.nw = cloth.num_width_points
        self.nh = cloth.num_height_points
        n = cloth.num_points
        self.initial_positions = rest_positions(cloth, scene.simulation.seed)
        # Stored as (3, N) so the kernels stream each coordinate; users see (N, 3) views.
        self._pos = np.ascontiguousarray(self.initial_positions.T)
        self._last = self._pos.copy()
        self.pinned = pinned_mask(cloth)
        self.free = np.flatnonzero(~self.pinned).astype(np.int32)
        self._all_springs = cloth_springs(cloth, self.initial_positions)
        self._cut = np.zeros(len(self._all_springs), dtype=np.bool_)
        self._forces = np.zeros((3, n))
        self._box = np.zeros(6)
        #: Top speed of the moving colliders (m/s): the blow-up guard allows the energy they give.
        self.collider_top_speed = top_speed(scene)
        # Time as (time at the last re-plan, substeps since): a substep's time is computed from it,
        # not summed up, so the same run gives the same times however its substeps are grouped.
        # The one clock of everything that moves on its own (sim/clock.py).
        self._clock = np.zeros(2)
        self._clock_dt = self.dt
        # every collider kind's group, packed once (a mesh's grid is built here); moving ones are
        # posed in place, from their scene rows kept for reset()
        self._colliders = plan_colliders(scene, self._clock, self._clock_dt)
        self._collider_rows = [g.rows.copy() if hasattr(g, "rows") else None for g in self._colliders]
        m = table_size(n)
        self._keys = np.zeros(n, dtype=np.int64)
        self._slots = np.zeros(n, dtype=np.int64)
        self._start = np.zeros(m + 1, dtype=np.int64)
        self._order = np.zeros(n, dtype=np.int64)
        # the team's counting sort: busy slots, running cost, points copied in table order, and
        # counts and cursors per member and slot (at most CHUNKS members, see team.team_size)
        self._sort = (np.zeros(m, dtype=np.int64), np.zeros(m, dtype=np.int64), *slot_copies(n),
                      np.zeros((2, CHUNKS, spec_table_size(n)), dtype=np.int32), np.zeros((CHUNKS, 2), dtype=np.int64))
        self._boxes = np.zeros((CHUNKS, 6))
        self._skips = np.zeros(1, dtype=np.int64)
        self._pins = np.flatnonzero(self.pinned)
        #: Arrays a pass makes once per simulation (the wind's mesh, say), by pass name.
        self.pass_arrays: dict[str, tuple] = {}
        self._sync = team.new_sync()
        #: Members of the next frames' thread team (recovers after a failed roll call).
        self.team = team.TeamPlan()
        self.frame = 0
        self.colliders_skipped = 0
        # Extra per-run state of the non-spec integrators (e.g. velocities); None = start afresh.
        self.integrator_state: object = None
        self._crossings_checked = False
        self._surface: Surface | None = None
        self._replan()
        self._place_pins()
        self._pins_seen = self._pos[:, self._pins].copy()

    # ------------------------------------------------------------------------------------------
    # Parameters (re-plan on change)

    # Every setter checks its value with the scene loader's rule for the same field, so a bad
    # value raises one FieldError naming it (``cloth.ks: must be >= 0, got nan``) and changes nothing.

    def _set_cloth(self, name: str, value: object) -> None:
        self.scene = self.scene.with_cloth(**{name: check_field("cloth", name, value)})
        self._replan()

    def _set_sim(self, name: str, value: object) -> None:
        self.scene = self.scene.with_simulation(**{name: check_field("simulation", name, value)})
        self._replan()

    ks = scene_field("cloth", "ks", "Spring constant (N/m, >= 0); bending springs use 0.2 * ks.")
    density = scene_field("cloth", "density", "Area density (kg/m^2, > 0); mass per point = width*height*density/N.")
    damping = scene_field("cloth", "damping", "Damping in percent (0..100) of velocity removed per substep.")
    enable_structural = scene_field("cloth", "enable_structural", "Structural springs on (True) or off.")
    enable_shearing = scene_field("cloth", "enable_shearing", "Shearing springs on (True) or off.")
    enable_bending = scene_field("cloth", "enable_bending", "Bending springs on (True) or off.")
    gravity = scene_field("simulation", "gravity", "External acceleration (m/s^2), three finite numbers.")
    frames_per_sec = scene_field("simulation", "frames_per_sec", "Frames per simulated second (> 0).")
    simulation_steps = scene_field("simulation", "simulation_steps", "Substeps per frame (an integer >= 1).")

    @property
    def wind(self) -> tuple:
        """The winds (a tuple of :class:`~clothsim.wind.WindSpec`, empty for none). Set it between
        frames to a ``wind`` object as a scene file writes it (a dict, or a list of them), a
        ``WindSpec``, or None for no wind; it is checked with the scene loader's rule."""
        return self.scene.winds

    @wind.setter
    def wind(self, value: object) -> None:
        from dataclasses import replace

        self.scene = replace(self.scene, winds=WINDS(value, At(None, "wind")))
        self._replan()

    @property
    def time(self) -> float:
        """Simulated seconds since the start (or the last :meth:`reset`)."""
        return float(self._clock[0] + self._clock[1] * self._clock_dt)

    @property
    def all_springs(self) -> Springs:
        """Every spring of the grid, all three families, in the order :meth:`cut_springs` uses."""
        return self._all_springs

    def cut_springs(self, mask: np.ndarray) -> None:
        """Cut the springs where ``mask`` (one bool per :attr:`all_springs` entry) is true.

        A cut spring makes no force and Provot's limit ignores it, with every integrator: cutting
        every spring between two rows tears the cloth in two. Cuts add up and survive
        :meth:`reset` and changes of the ``enable_*`` flags; :meth:`restore_springs` undoes them.
        """
        mask = np.asarray(mask, dtype=np.bool_)
        if mask.shape != self._cut.shape:
            raise ValueError(f"cut_springs: mask needs {self._cut.shape[0]} entries, got shape {mask.shape}")
        self._cut |= mask
        self._replan()

    def restore_springs(self) -> None:
        """Undo every :meth:`cut_springs`."""
        self._cut[:] = False
        self._replan()

    @property
    def positions(self) -> np.ndarray:
        """Current positions, (N, 3) float64: a view of the state, not a copy."""
        return self._pos.T

    @property
    def last_positions(self) -> np.ndarray:
        """Positions one substep earlier, (N, 3) float64 view."""
        return self._last.T

    def crossings(self) -> int:
        """Edge-triangle crossings of the cloth as it is now: how many (edge, triangle) pairs of its
        render mesh that share no point have the edge passing through the triangle (exact; see
        :mod:`clothsim.sim.crossings`). Zero for a cloth that does not pass through itself."""
        from .crossings import count_crossings, mesh_crossings

        if self.scene.cloth.mesh is None:
            return count_crossings(self.positions, self.nw, self.nh)
        return mesh_crossings(self.positions, self.surface.triangles)

    @property
    def unsafe_substeps(self) -> int:
        """Substeps so far in which the contact self-collision mode could not bound the cloth's
        motion: a pinned point moved farther than its bound allows in one substep, by its
        ``pin_motion`` or put there through the API. The cloth may have crossed itself there
        (:meth:`crossings` says whether it did). Always 0 in the other modes."""
        contact = self._kernel_args.contact
        return 0 if contact is None else int(contact.meta[UNSAFE])

    @property
    def squeezed_substeps(self) -> int:
        """Substeps so far in which the contact self-collision mode let a moving collider put a
        point of the cloth further than its bound allows (a collider squeezing the cloth thinner than
        it can be, against another collider or against more of the cloth): the collider keeps the
        point out of itself, and the cloth may have crossed itself there (:meth:`crossings` says
        whether it did). Always 0 in the other modes and in scenes whose colliders do not move."""
        contact = self._kernel_args.contact
        return 0 if contact is None else int(contact.meta[SQUEEZED])

    @property
    def dt(self) -> float:
        """Substep length in seconds: 1 / (frames_per_sec * simulation_steps)."""
        s = self.scene.simulation
        return 1.0 / (s.frames_per_sec * s.simulation_steps)

    @property
    def plan(self) -> Plan:
        """The groups of the current plan (:mod:`clothsim.sim.state`): the arrays the passes run on,
        re-made by every re-plan. For the integrators and tools; change them at your own risk."""
        return self._kernel_args

    def bound_plan(self) -> Plan:
        """:attr:`plan` with the mesh pass's address filled in (compiled or loaded on first use),
        for the integrators that run the collider pass outside the thread team."""
        plan = self._kernel_args
        for g in plan.colliders:
            if isinstance(g, MeshGroup) and not g.collide:
                self._kernel_args = plan = with_mesh_address(plan, collide_address(g, plan.st.pos, plan.st.last,
                                                                                   self.free))
        if plan.col is not None and not plan.col.sets.all():
            plan.col.calls[:], plan.col.sets[:] = kind_addresses(plan.colliders, plan.st.pos, plan.st.last, plan.col)
        return plan

    @property
    def spring_stiffness(self) -> np.ndarray:
        """Stiffness (N/m) of each spring of :attr:`springs` (0 for a cut one), re-made (a new
        array) by every re-plan."""
        return self._spring_k

    @property
    def self_mode(self) -> int:
        """The self-collision mode as the kernels number it (0 = off; see
        :mod:`clothsim.sim.passes.selfcollide`)."""
        return self._self_mode

    @property
    def clock(self) -> np.ndarray:
        """The one clock of prescribed motion (:mod:`clothsim.sim.clock`): (time at the last
        re-plan, substeps since), the array the passes' groups read (not a copy)."""
        return self._clock

    @property
    def mass(self) -> float:
        """Mass of one point (kg): for a mesh cloth, the mean of :attr:`point_mass`."""
        return mean_mass(self.scene.cloth)

    @property
    def point_mass(self) -> np.ndarray:
        """Each point's mass (kg), (N,) float64 (a new array): all :attr:`mass` on a grid; on a
        mesh cloth a third of each adjacent triangle's area times the density."""
        return point_masses(self.scene.cloth)

    @property
    def num_points(self) -> int:
        """Points of the cloth (N)."""
        return self._pos.shape[1]

    @property
    def surface(self) -> Surface:
        """The cloth's triangles and texture coordinates (:class:`clothsim.cloth.Surface`), for
        rendering and export, grid or mesh."""
        if self._surface is None:
            self._surface = cloth_surface(self.scene.cloth)
        return self._surface

    def _replan(self) -> None:
        """Derive the arrays the kernels see from the current parameters."""
        cloth, sim = self.scene.cloth, self.scene.simulation
        mask = enabled_mask(self._all_springs.kind, cloth.enable_structural, cloth.enable_shearing,
                            cloth.enable_bending)
        self.springs: Springs = self._all_springs.select(mask)
        self._blocks, _ = spring_blocks(self.nw, self.nh, cloth.enable_structural, cloth.enable_shearing,
                                        cloth.enable_bending)
        if cloth.mesh is not None:
            # a mesh's springs: streams where an offset is common, lists for the rest
            # (passes/meshsprings.py); no grid blocks
            self._blocks = np.zeros((0, 6), dtype=np.int64)
        # Cut springs stay in the arrays (the kernels' block layout needs every spring of a family)
        # with zero stiffness, so they make no force, and a rest length so long that Provot's
        # limit never shortens them; XPBD and the implicit Jacobian skip zero stiffness.
        cut = self._cut[mask]
        self._spring_k = np.where(self.springs.kind == BENDING, cloth.ks * BENDING_STIFFNESS_FACTOR,
                                 cloth.ks) * ~cut
        self._rest = np.where(cut, CUT_REST, self.springs.rest)
        #: The springs that act: enabled and not cut (what a wireframe should draw).
        self.live_springs: Springs = self.springs.select(~cut) if cut.any() else self.springs
        if cloth.mesh is None:
            self._stream = spring_streams(self.nw, self.nh, self._blocks, self._spring_k, self._rest)
            self._listed = None
        else:
            self._stream, self._listed = mesh_streams(self.springs.i, self.springs.j, self._spring_k, self._rest,
                                                      self.num_points)
        self._gravity = np.asarray(sim.gravity, dtype=np.float64)
        self._keep = 1.0 - cloth.damping / 100.0
        self._self_mode = _SELF_MODES[sim.self_collision]
        if sim.self_collision == "grid":
            edge = 2.0 * cloth.thickness
            self._cell = np.array([edge, edge, edge])
            self._table = self._start
        else:
            self._table = self._start[: spec_table_size(self.num_points) + 1]
            dw, dh = spacing(cloth, self._all_springs)
            w = 3.0 * dw
            h = 3.0 * dh
            self._cell = np.array([w, h, max(w, h)])
        self._stretch_limit = -1.0 if sim.max_stretch is None else 1.0 + sim.max_stretch
        # the clock restarts from the time reached, counting substeps of the (maybe new) length
        self._clock[0] = self.time
        self._clock[1] = 0.0
        self._clock_dt = self.dt
        self._kernel_args = self._pack()
        # the addresses of the kernels that run these groups, found on the first frame (typing the groups
        # to look it up takes ~0.36 ms: a third of a frame, if done every frame)
        self._kernels: Addresses | None = None
        # the plan and its native layout for the team (see run_substeps)
        self._packed: tuple | None = None

    def _pack(self) -> Plan:
        """The frame kernel's state groups (:mod:`clothsim.sim.state`), ``None`` for a pass the
        scene does not use."""
        cloth, sim = self.scene.cloth, self.scene.simulation
        offsets, k, spring_rest, buf = self._stream
        dt = self.dt
        mesh = None
        if cloth.mesh is not None:
            mesh = pack_mesh_springs(self.springs.i, self.springs.j, self._spring_k, self._rest,
                                     self.springs.kind == STRUCTURAL, self._listed, self.point_mass, self._gravity)
        # (a mesh cloth's grid is one point wide: its Provot bands, unused, then divide by 1)
        st = ClothState(self._pos, self._last, self._forces, self.pinned, self._pins, self._blocks, self._rest,
                        max(self.nw, 1), offsets, k, spring_rest, buf, self.mass, self._gravity,
                        dt * dt * (1.0 / self.mass), self._keep, self._stretch_limit, self._skips,
                        np.zeros(CALLS, np.int64), mesh)
        steps = sim.simulation_steps
        spec = grid = col = None
        if self._self_mode == MODE_SPEC:
            busy, cum, xs, ys, zs, ks, counted, tally = self._sort
            spec = SpecHash(self._cell, self._keys, self._slots, self._table, self._order, ~self.pinned, busy, xs, ys,
                            zs, ks, cum, counted, tally, 2.0 * cloth.thickness, steps, 0)
        elif self._self_mode == MODE_GRID:
            grid = self.self_hash()
        # the tracks of moving colliders count substeps of the (maybe new) length
        self._colliders = tuple(g if g.tracks is None else g._replace(tracks=g.tracks._replace(dt=dt))
                                for g in self._colliders)
        contact = self._contact_group()
        if self._colliders:
            margin = 0.0 if self._self_mode == 0 else 1.001 * (2.0 * cloth.thickness) / steps
            if contact is not None:
                margin = 1.001 * response_reach(contact)
            col = Colliders(self.free, SURFACE_OFFSET, self._box, self._boxes, margin,
                            any(g.tracks is not None for g in self._colliders),
                            np.zeros((len(self._colliders), KIND_CALLS), np.int64), np.zeros(SETS, np.int64))
        return Plan(st, spec, grid, col, self._colliders, plan_forces(self), self._pin_group(), contact)

    def _contact_group(self) -> tuple | None:
        """The contact mode's group, kept across re-plans of the same cloth (its reference state
        stays valid: a re-plan moves no point)."""
        if self._self_mode != MODE_CONTACT:
            return None
        thickness = self.scene.cloth.thickness
        old = getattr(self, "_contact", None)
        if old is None or old[0] != thickness:
            tris = np.ascontiguousarray(self.surface.triangles.T, dtype=np.int64)
            self._contact = (thickness, contact_group(np.ascontiguousarray(self.initial_positions.T), tris,
                                                      ~self.pinned, thickness))
        return self._contact[1]

    def self_hash(self) -> GridHash:
        """The self-collision hash's arrays and constants (the grid's group; the integrators'
        corrections use it for either mode)."""
        cloth = self.scene.cloth
        return GridHash(self.free, cloth.thickness, self.scene.simulation.simulation_steps, self._cell, self._keys,
                        self._slots, self._table, self._order)

    def _pin_group(self) -> PinMotion | None:
        motion = self.scene.cloth.pin_motion
        if motion is None or self._pins.shape[0] == 0:
            return None
        track = motion.track()
        return PinMotion(self._pins.astype(np.int64), np.ascontiguousarray(self.initial_positions[self._pins].T),
                         track.times, track.points, track.velocity, self.dt, self._clock)

    def _place_pins(self) -> None:
        """At the start, the whole cloth moved by the pins' offset at time 0, at rest: the pins are
        then at rest + offset(0) with no jump in the first substep."""
        pm = self._kernel_args.pins
        if pm is not None:
            offset = np.empty(3)
            move_pins(self._pos, self._last, pm, self.time, offset)
            self._pos[...] = self.initial_positions.T + offset[:, None]
            self._last[...] = self._pos

    @property
    def n_colliders(self) -> int:
        """Colliders of every kind in the scene (triangle meshes count one each)."""
        return len(self.scene.colliders)

    @property
    def colliders_still_after(self) -> float:
        """Time (s) after which nothing that drives the cloth moves any more: colliders and pins
        (inf for a constant velocity). A cloth is not taken to be at rest before then, since a
        collider or a pin may still come and move it."""
        end = 0.0
        motions = [spec.motion for spec in self.scene.colliders]
        for motion in [*motions, self.scene.cloth.pin_motion]:
            if motion is not None:
                end = max(end, motion.ends)
        return end

    # ------------------------------------------------------------------------------------------
    # Stepping

    def reset(self) -> None:
        """Back to the initial state (same seed, so the same jitter)."""
        self._pos[...] = self.initial_positions.T
        self._last[...] = self.initial_positions.T
        for g, start in zip(self._colliders, self._collider_rows):
            if start is not None:
                g.rows[...] = start
        self.frame = 0
        self.colliders_skipped = 0
        self.integrator_state = None
        self._crossings_checked = False
        self._clock[:] = 0.0
        self._forget_contacts()
        self._place_pins()
        self._pins_seen = self._pos[:, self._pins].copy()

    def step(self, frames: int = 1) -> None:
        """Advance ``frames`` frames of ``simulation_steps`` substeps each.

        Raises :class:`SimulationBlowUp` (state restored to the start of the failing frame) when
        a position becomes non-finite, naming the frame and the first bad substep, and
        :class:`~clothsim.errors.FieldError` when ``frames`` is not an integer >= 0.
        """
        for _ in range(check(_FRAMES, frames, "frames")):
            self._advance_frame()

    @property
    def uses_spec_path(self) -> bool:
        """True when the scene runs the spec's Verlet with per-substep damping (the fast path)."""
        sim = self.scene.simulation
        return sim.integrator == "verlet" and sim.damping_mode == "spec"

    def run_kernel(self, steps: int, passes: int = PASS_ALL, size: int = 1) -> bool:
        """Run the next ``steps`` substeps of the frame kernel (only the ``passes`` bits) with a
        team of ``size``; False when the team gave the frame up half-way (the state must be
        restored)."""
        if self._kernels is None:
            self._kernels = kernel_addresses(self._kernel_args, self._sync)
            plan = self._kernel_args
            plan.st.calls[:] = self._kernels.calls
            if plan.spec is not None:
                plan = plan._replace(spec=plan.spec._replace(repel=self._kernels.repel))
            if plan.col is not None:
                plan.col.calls[:] = self._kernels.colliders
                plan.col.sets[:] = self._kernels.sets
            self._kernel_args = with_mesh_address(plan, self._kernels.collide)
        k = self._kernels
        plan = self._kernel_args
        if self._packed is None or self._packed[0] is not plan:
            # (a plan is a tuple, replaced whole when a group changes: laid out again only then)
            self._packed = (plan, packed_value(plan, numba.typeof(plan)))
        self.colliders_skipped += run_substeps(steps, plan, self._sync, size, passes, k.member, k.enter,
                                               ctypes.addressof(self._packed[1]))
        if passes & PASS_ALL == PASS_ALL:  # pass by pass (the profiler), the caller counts each substep once its passes ran
            self._clock[1] += steps
        if self._sync[team.FAILED]:
            raise MemoryError("the frame kernel could not allocate its work space")
        self.team.after(self._sync, size)
        return self._sync[team.ABORT] == 0

    def _run(self, steps: int, saved: tuple | None = None, passes: int = PASS_ALL) -> int:
        """Advance the next ``steps`` substeps; returns how many threads ran them. With ``saved``
        (the state before them), the fast path may use the thread team and, if the team gives up
        half-way, restores ``saved`` and runs alone. ``passes`` may add PASS_TIMED to PASS_ALL
        (:class:`~clothsim.sim.profile.FrameLaps`)."""
        if not self.uses_spec_path:
            from .solvers import advance

            advance(self, steps)
            self._clock[1] += steps
            return 1
        size = self.team.size() if saved is not None else 1
        if not self.run_kernel(steps, passes, size):
            self._restore(saved)
            size = 1
            self.run_kernel(steps, passes, 1)
        return 1 if self._sync[team.MODE] == team.ALONE else size

    def _restore(self, saved: tuple) -> None:
        self._pos[...] = saved[0]
        self._last[...] = saved[1]
        self.integrator_state = None if saved[2] is None else saved[2].copy()
        self._clock[:] = saved[3]
        if saved[4] is not None:
            restore_reference(self._kernel_args.contact, saved[4])

    def _contact_snapshot(self) -> tuple | None:
        # The contact pass keeps its reference from one frame to the next (a rebuild costs as much
        # as many substeps), so a frame depends on the state it starts from and on that reference:
        # a replay (blow-up guard, team given up) starts from a copy of both and gives the same bits.
        contact = self._kernel_args.contact
        return None if contact is None else snapshot_reference(contact)

    def _forget_contacts(self) -> None:
        # (the next substep builds the reference afresh)
        contact = self._kernel_args.contact
        if contact is not None:
            contact.meta[0] = 0

    def _contact_sweeps(self) -> None:
        # The contact response's strength for the frame: stronger while pins move (a pin track, or
        # pins put elsewhere through the API since the last frame), so the cloth makes way for them
        # (see clothsim.sim.passes.contactresponse.respond). Such a frame also starts from a fresh
        # reference, as every frame did before the reference was kept (the stress set's twist, its
        # pins put elsewhere each frame, crossed itself without: 4 crossings at most on 16 x 16).
        # (A point the bound held back gets a new reference in the next substep.)
        contact = self._kernel_args.contact
        if contact is not None:
            put = not np.array_equal(self._pos[:, self._pins], self._pins_seen)
            moving = self._kernel_args.pins is not None or put
            contact.meta[MOVING] = moving
            # (a pin put outside its ball through the API since the last frame went there in one
            # jump that no pass could bound, maybe through the cloth: an unsafe substep, as the
            # pass counts a pin that its track moves out of its ball in one substep)
            if put and any_outside(self._pos, contact, self._pins):
                contact.meta[UNSAFE] += 1
            if moving:
                self._forget_contacts()

    def _check_crossings(self) -> None:
        # once per start: the contact mode keeps a cloth from crossing itself, but cannot undo
        # crossings it is given (positions set through the API). A grid where the scene puts it
        # has none (a flat grid, or one within its 1 mm jitter of flat: its triangles' shadows on
        # its plane do not overlap), so its first run does not compile the count for nothing.
        self._crossings_checked = True
        if self.scene.cloth.mesh is None and np.array_equal(self._pos, self.initial_positions.T):
            return
        found = self.crossings()
        if found:
            import warnings

            warnings.warn(f"self_collision \"contact\": the cloth starts with {found} self-crossing"
                          f"{'s' if found != 1 else ''} (mesh edges through triangles); they are kept from "
                          "growing, not undone", RuntimeWarning, stacklevel=4)

    def _advance_frame(self, run=None) -> None:  # noqa: ANN001
        """One frame through ``run(steps, saved)`` (default :meth:`_run`), under the blow-up guard."""
        # Once per frame: a non-finite position or an exploding kinetic energy stops the run
        # (cheap: one pass over the free points). The state is restored before raising.
        from .guard import sim_blow_up_reason

        run = run or self._run
        if self._kernel_args.contact is not None and not self._crossings_checked:
            self._check_crossings()
        state = self.integrator_state
        self._contact_sweeps()
        saved = (self._pos.copy(), self._last.copy(), None if state is None else state.copy(), self._clock.copy(),
                 self._contact_snapshot())
        steps = self.scene.simulation.simulation_steps
        dropped = self._pairs_dropped()
        run(steps, saved)
        while self._pairs_dropped() > dropped and self._more_pair_room():
            self._restore(saved)
            run(steps, saved)
        if self._kernel_args.contact is not None:
            self._pins_seen[...] = self._pos[:, self._pins]
        if sim_blow_up_reason(self) is not None:
            self._report_blow_up(saved, steps)
        self.frame += 1

    def _pairs_dropped(self) -> int:
        # the contact pairs found beyond the pair arrays' room so far
        contact = self._kernel_args.contact
        return 0 if contact is None else int(contact.meta[DROPPED])

    def _more_pair_room(self) -> bool:
        # the contact group with pair arrays twice as long, for the frame to be run again (the
        # same bits as arrays that long from the start: only the dropping depends on their length)
        grown = with_more_room(self._kernel_args.contact)
        if grown is None:
            return False
        self._kernel_args = self._kernel_args._replace(contact=grown)
        self._contact = (self._contact[0], grown)
        return True

    def _report_blow_up(self, saved: tuple, steps: int) -> None:
        # Replay the frame one substep at a time (the run is deterministic) to name the substep.
        from .guard import blow_up_advice, sim_blow_up_reason

        self._restore(saved)
        bad, what = steps, "positions became non-finite"
        for sub in range(1, steps + 1):
            self._run(1, None)
            reason = sim_blow_up_reason(self)
            if reason is not None:
                bad, what = sub, reason
                break
        self._restore(saved)
        sim = self.scene.simulation
        raise SimulationBlowUp(
            f"simulation blew up at frame {self.frame + 1}, substep {bad}: {what} "
            f"(integrator={sim.integrator}, ks={self.ks:g}, density={self.density:g}, {steps} substeps per frame); "
            f"{blow_up_advice(self.scene)}"
        )
