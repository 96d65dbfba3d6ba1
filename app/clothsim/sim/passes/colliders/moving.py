"""The pose of every moving collider, for every kind: a collider with a ``motion`` is a track of
its anchor (:mod:`clothsim.motion`), evaluated at the simulation's one clock
(:mod:`clothsim.sim.clock`, shared with the moving pins and the wind).

A kind's group (see :mod:`clothsim.sim.passes.colliders`) holds its moving colliders' tracks as one
:class:`Tracks` group of flat arrays, or None when none of them moves. Each substep the kind's
``pose`` puts each of them at its pose at the end of the substep and records its displacement
over the substep (its *carry*, read by the swept tests): :func:`pose_rows` translates a row's
point columns (``base + position(t) - anchor``); a mesh, whose triangles stay put in its own frame,
keeps its translation at the substep's start and end instead (:mod:`.mesh`).

A collider whose motion turns it (:mod:`clothsim.motion`: rotation keyframes or an angular
velocity) is posed by its kind's group's :class:`Turns` as well (None when no collider of the kind
turns, so that a scene without a turn compiles and runs exactly the code it did before turns): its
pose at time t is ``x -> p(t) + Q(t) (x - anchor)``, Q(t) from :func:`~clothsim.sim.clock.turn_at`.
:func:`turn_rows` poses such rows (points turned about the anchor and moved, direction columns
turned) and writes each row's *motion* over the substep, the rigid map R x + d that takes where a
point of the collider was at the substep's start to where it is at its end: the swept tests carry a
point's last position by it (``R last + d``), as they add the carry without a turn, so that friction
acts on the motion relative to the turning surface.

The Python helpers below give the same poses to the renderer and the exporters.
"""

from __future__ import annotations

import dataclasses
import math
from typing import Any, Callable, NamedTuple

import numpy as np
from numba import njit

from ....jit import KERNEL
from ....motion import spin_of
from ...clock import call_time, track_at as position_at, turn_at


class Tracks(NamedTuple):
    """The tracks of one kind's moving colliders and where their poses go."""

    #: keyframe times and points of all tracks, concatenated; track m is span[m, 0]:span[m, 1]
    times: np.ndarray
    points: np.ndarray
    span: np.ndarray
    #: (M, 3) velocity after each track's last time
    velocity: np.ndarray
    #: (M,) the row of the kind's group that each track moves
    row: np.ndarray
    #: (M, 3) the position the scene gives (the track's value is where it is moved to)
    anchor: np.ndarray
    #: (M, 6) the unmoved point columns of its row (a capsule's a and b; others the first three)
    base: np.ndarray
    #: the simulation's clock (see :mod:`clothsim.sim.clock`) and the substep length
    clock: np.ndarray
    dt: float
    #: (2, 3) work space: the pose at the substep's start and end
    scratch: np.ndarray


def pack_tracks(specs: tuple, clock: np.ndarray, dt: float,
                base: Callable[[Any], tuple[float, ...]] | None = None) -> Tracks | None:
    """The :class:`Tracks` of those of ``specs`` (one kind's, in scene order) that move, or None.

    ``base(spec)`` gives the point columns a pose translates (up to six floats; default: the
    anchor). Without ``base`` a spec's track is its own (a mesh's: its translation, anchor and base
    zero)."""
    tracks, rows, anchors, bases = [], [], [], []
    for r, spec in enumerate(specs):
        if spec.motion is None:
            continue
        rows.append(r)
        if base is None:
            tracks.append(spec.track())
            anchors.append((0.0, 0.0, 0.0))
            bases.append((0.0,) * 6)
            continue
        tracks.append(spec.motion.track(spec.anchor))
        anchors.append(spec.anchor)
        cols = tuple(base(spec))
        bases.append(cols + (0.0,) * (6 - len(cols)))
    if not tracks:
        return None
    ends = np.cumsum([len(t.times) for t in tracks])
    span = np.stack([ends - [len(t.times) for t in tracks], ends], axis=1).astype(np.int64)
    return Tracks(np.concatenate([t.times for t in tracks]), np.concatenate([t.points for t in tracks]), span,
                  np.array([t.velocity for t in tracks], dtype=np.float64), np.array(rows, dtype=np.int64),
                  np.array(anchors, dtype=np.float64), np.array(bases, dtype=np.float64), clock, dt, np.zeros((2, 3)))


class Turns(NamedTuple):
    """The turns of one kind's moving colliders (indexed like their :class:`Tracks`), and each row's
    motion over the current substep; a kind's group holds one only when one of its colliders turns."""

    #: orientation keyframe times and angles (degrees) of all turns, concatenated; turn m is span[m, 0]:span[m, 1]
    times: np.ndarray
    angles: np.ndarray
    span: np.ndarray
    #: (M, 3) angular velocity (radians a second); (M, 3, 3) the static rotation keyframes replace
    omega: np.ndarray
    rest: np.ndarray
    #: (D, 3) int64: the columns of each direction vector a turn turns (a plane's normal, a box's
    #: axes), and (M, 3 D) those directions at the scene pose
    dirs_at: np.ndarray
    dirs: np.ndarray
    #: per row of the kind (rows: (n, 12), R row-major then d: the motion R x + d over the substep,
    #: the identity for a row that does not move; meshes: (M, 18), Q at the substep's start and end)
    motion: np.ndarray
    #: (2, 3, 3) Q at the substep's start and end; (5, 3) work space of turn_at (last row zeros)
    q: np.ndarray
    work: np.ndarray


def static_rotation(spec: Any) -> np.ndarray | None:
    """The rotation matrix of a collider's static ``rotation`` (a box's, a mesh's), or None."""
    if hasattr(spec, "rotation_matrix"):
        return np.asarray(spec.rotation_matrix(), dtype=np.float64)
    if hasattr(spec, "matrix"):
        return np.array(spec.matrix(), dtype=np.float64)
    return None


def pack_turns(specs: tuple, dirs_at: tuple = (), dirs: Callable[[Any], tuple] | None = None,
               width: int = 12) -> Turns | None:
    """The :class:`Turns` of the moving ones of ``specs`` (one kind's, in scene order, as
    :func:`pack_tracks` takes them), or None when none of them turns. ``dirs_at`` names the
    direction columns of a row, ``dirs(spec)`` gives them at the scene pose; ``width`` is a motion
    row's (12 for rows, 18 for meshes)."""
    moving = [spec for spec in specs if spec.motion is not None]
    if not any(spec.motion.turns for spec in moving):
        return None
    spins = [spin_of(spec.motion, static_rotation(spec)) for spec in moving]
    ends = np.cumsum([len(s.times) for s in spins])
    span = np.stack([ends - [len(s.times) for s in spins], ends], axis=1).astype(np.int64)
    motion = np.zeros((len(specs), width))
    motion[:, [0, 4, 8]] = 1.0
    if width == 18:
        motion[:, [9, 13, 17]] = 1.0
    at = np.array(dirs_at, dtype=np.int64).reshape(-1, 3)
    scene_dirs = np.array([dirs(spec) if dirs is not None else () for spec in moving], dtype=np.float64)
    return Turns(np.concatenate([s.times for s in spins]), np.concatenate([s.angles for s in spins]), span,
                 np.array([s.omega for s in spins], dtype=np.float64), np.array([s.rest for s in spins]), at,
                 scene_dirs.reshape(len(moving), 3 * len(at)), motion, np.zeros((2, 3, 3)), np.zeros((5, 3)))


@njit(inline="always", **KERNEL)
def turn_ends(tu: Turns, m: int, t0: float, t1: float) -> None:
    """Turn ``m``'s Q at times ``t0`` and ``t1`` into ``tu.q[0]`` and ``[1]``."""
    a = tu.span[m, 0]
    b = tu.span[m, 1]
    turn_at(tu.times[a:b], tu.angles[a:b], tu.omega[m], tu.rest[m], t0, tu.work, tu.q[0])
    turn_at(tu.times[a:b], tu.angles[a:b], tu.omega[m], tu.rest[m], t1, tu.work, tu.q[1])


@njit(**KERNEL)
def turn_rows(tr: Tracks, tu: Turns, rows: np.ndarray, count: int, carry: np.ndarray, carry_at: int,
              substep: int) -> None:
    """:func:`pose_rows` for a kind with turning colliders: the first ``count`` points of a moving
    row r become ``p + Q (base - anchor)`` and its direction columns ``Q dir``, at the end of
    substep ``substep`` of the call; its translation over the substep goes to ``carry`` as there,
    and its motion over the substep (R = Q1 Q0^T, d = p1 - R p0) to ``tu.motion[r]``."""
    dt = tr.dt
    t0 = call_time(tr.clock, dt) + substep * dt
    t1 = t0 + dt
    p0 = tr.scratch[0]
    p1 = tr.scratch[1]
    q0 = tu.q[0]
    q1 = tu.q[1]
    mo = tu.motion
    for m in range(tr.row.shape[0]):
        track_ends(tr, m, t0, t1)
        turn_ends(tu, m, t0, t1)
        r = tr.row[m]
        base = tr.base[m]
        for j in range(count):
            x = base[3 * j] - tr.anchor[m, 0]
            y = base[3 * j + 1] - tr.anchor[m, 1]
            z = base[3 * j + 2] - tr.anchor[m, 2]
            for c in range(3):
                rows[r, 3 * j + c] = p1[c] + q1[c, 0] * x + q1[c, 1] * y + q1[c, 2] * z
        for k in range(tu.dirs_at.shape[0]):
            x = tu.dirs[m, 3 * k]
            y = tu.dirs[m, 3 * k + 1]
            z = tu.dirs[m, 3 * k + 2]
            for c in range(3):
                rows[r, tu.dirs_at[k, c]] = q1[c, 0] * x + q1[c, 1] * y + q1[c, 2] * z
        for c in range(3):
            carry[r, carry_at + c] = p1[c] - p0[c]
        for i in range(3):
            for j in range(3):
                mo[r, 3 * i + j] = q1[i, 0] * q0[j, 0] + q1[i, 1] * q0[j, 1] + q1[i, 2] * q0[j, 2]
        for i in range(3):
            mo[r, 9 + i] = p1[i] - (mo[r, 3 * i] * p0[0] + mo[r, 3 * i + 1] * p0[1] + mo[r, 3 * i + 2] * p0[2])


@njit(inline="always", **KERNEL)
def carried(mo: np.ndarray, x: float, y: float, z: float) -> tuple[float, float, float]:
    """A point (x, y, z) where it was at the substep's start carried by a turning collider's motion
    ``mo`` (a row of :attr:`Turns.motion`) to where it is at the substep's end."""
    return (mo[0] * x + mo[1] * y + mo[2] * z + mo[9], mo[3] * x + mo[4] * y + mo[5] * z + mo[10],
            mo[6] * x + mo[7] * y + mo[8] * z + mo[11])


@njit(inline="always", **KERNEL)
def carried_box(box: np.ndarray, mo: np.ndarray) -> tuple[float, float, float, float, float, float]:
    """The box (lo xyz, hi xyz) around the cloth's box ``box`` and its image under a turning
    collider's motion ``mo``: every sample of a point's relative path (between its carried last
    position and its position) lies in it."""
    lo0, lo1, lo2 = box[0], box[1], box[2]
    hi0, hi1, hi2 = box[3], box[4], box[5]
    cx, cy, cz = 0.5 * (box[0] + box[3]), 0.5 * (box[1] + box[4]), 0.5 * (box[2] + box[5])
    hx, hy, hz = 0.5 * (box[3] - box[0]), 0.5 * (box[4] - box[1]), 0.5 * (box[5] - box[2])
    x, y, z = carried(mo, cx, cy, cz)
    ex = abs(mo[0]) * hx + abs(mo[1]) * hy + abs(mo[2]) * hz
    ey = abs(mo[3]) * hx + abs(mo[4]) * hy + abs(mo[5]) * hz
    ez = abs(mo[6]) * hx + abs(mo[7]) * hy + abs(mo[8]) * hz
    return (min(lo0, x - ex), min(lo1, y - ey), min(lo2, z - ez), max(hi0, x + ex), max(hi1, y + ey),
            max(hi2, z + ez))


@njit(inline="always", **KERNEL)
def track_ends(tr: Tracks, m: int, t0: float, t1: float) -> None:
    """Track ``m``'s positions at times ``t0`` and ``t1`` into ``tr.scratch[0]`` and ``[1]``."""
    a = tr.span[m, 0]
    b = tr.span[m, 1]
    position_at(tr.times[a:b], tr.points[a:b], tr.velocity[m], t0, tr.scratch[0])
    position_at(tr.times[a:b], tr.points[a:b], tr.velocity[m], t1, tr.scratch[1])


@njit(**KERNEL)
def pose_rows(tr: Tracks | None, rows: np.ndarray, count: int, carry: np.ndarray | None, carry_at: int,
              substep: int) -> None:
    """Put the moving rows of ``rows`` at their pose at the end of substep ``substep`` of the call:
    the first ``count`` points (xyz column triples) of row r become ``base + position - anchor``;
    the displacement over the substep goes to ``carry[r, carry_at:carry_at + 3]``. Nothing when
    none moves (``tr`` is None: the code is pruned before typing).

    Times count from the call's start (see :mod:`clothsim.sim.clock`)."""
    if tr is None:
        return
    dt = tr.dt
    t0 = call_time(tr.clock, dt) + substep * dt
    t1 = t0 + dt
    p0 = tr.scratch[0]
    p1 = tr.scratch[1]
    for m in range(tr.row.shape[0]):
        track_ends(tr, m, t0, t1)
        r = tr.row[m]
        x = p1[0] - tr.anchor[m, 0]
        y = p1[1] - tr.anchor[m, 1]
        z = p1[2] - tr.anchor[m, 2]
        base = tr.base[m]
        for j in range(count):
            rows[r, 3 * j] = base[3 * j] + x
            rows[r, 3 * j + 1] = base[3 * j + 1] + y
            rows[r, 3 * j + 2] = base[3 * j + 2] + z
        carry[r, carry_at] = p1[0] - p0[0]
        carry[r, carry_at + 1] = p1[1] - p0[1]
        carry[r, carry_at + 2] = p1[2] - p0[2]


def top_speed(scene: Any) -> float:
    """The highest speed (m/s) any of ``scene``'s colliders ever moves at (0 when none moves); for
    a turning one, its anchor's speed plus its angular speed times how far from its anchor it can
    touch the cloth (:func:`turn_reach`)."""
    top = 0.0
    for spec in scene.colliders:
        # a deforming mesh's vertices move by themselves too (0 for every other collider)
        own = spec.surface_speed() if hasattr(spec, "surface_speed") else 0.0
        if spec.motion is None:
            top = max(top, own)
            continue
        track = spec.motion.track()  # a speed: the same from any start
        speed = float(np.linalg.norm(track.velocity))
        if len(track.times) > 1:
            steps = np.linalg.norm(np.diff(track.points, axis=0), axis=1) / np.diff(track.times)
            speed = max(speed, float(steps.max()))
        top = max(top, speed + angular_speed(spec.motion) * turn_reach(scene, spec) + own)
    return top


def angular_speed(motion: Any) -> float:
    """A bound on how fast (radians a second) a motion ever turns: |w|, or for orientation keyframes
    the largest (|d rx| + |d ry| + |d rz|) / dt between two of them (0 for no turn)."""
    if motion.angular_velocity is not None:
        return math.radians(math.hypot(*motion.angular_velocity))
    frames = motion.rotation_keyframes
    rates = [sum(abs(q - p) for p, q in zip(a0, a1)) / (t1 - t0) for (t0, a0), (t1, a1) in zip(frames, frames[1:])]
    return math.radians(max(rates, default=0.0))


def turn_reach(scene: Any, spec: Any) -> float:
    """How far from its anchor a turning collider may meet the cloth (m): its own size for a
    closed shape, and for a plane (unbounded) the farthest the cloth's initial grid lies from the
    anchor plus the cloth's diagonal."""
    kind = type(spec).__name__
    if kind == "SphereSpec":
        return spec.radius
    if kind == "CapsuleSpec":
        return 0.5 * math.dist(spec.a, spec.b) + spec.radius
    if kind == "BoxSpec":
        return math.hypot(*spec.half_extents)
    if kind == "MeshSpec":
        return float(np.linalg.norm(spec.local_vertices(), axis=1).max())
    from ....cloth import grid_positions

    cloth = scene.cloth
    grid = grid_positions(cloth, scene.simulation.seed)
    far = float(np.linalg.norm(grid - np.asarray(spec.anchor, dtype=np.float64), axis=1).max())
    return far + math.hypot(cloth.width, cloth.height)


def shift(spec: Any, t: float) -> np.ndarray:
    """How far a collider's ``motion`` has moved it from its scene pose at time ``t``, (3,) (zero
    for a static one): the translation to draw or export it with."""
    if spec.motion is None:
        return np.zeros(3)
    return spec.motion.track(spec.anchor).at(t) - np.asarray(spec.anchor, dtype=np.float64)


def turn(spec: Any, t: float) -> np.ndarray:
    """A collider's turn Q(t) from its scene pose at time ``t``, (3, 3) (the identity when it does
    not turn): the same evaluation as the simulator's (:func:`~clothsim.sim.clock.turn_at`)."""
    if spec.motion is None or not spec.motion.turns:
        return np.eye(3)
    spin = spin_of(spec.motion, static_rotation(spec))
    out = np.empty((3, 3))
    work = np.zeros((5, 3))
    turn_at(spin.times, spin.angles, spin.omega, spin.rest, float(t), work, out)
    return out


def placement(spec: Any, t: float) -> np.ndarray:
    """(4, 4) the map from a collider's scene pose to its pose at time ``t``: x -> p(t) + Q(t) (x -
    anchor) (a translation by :func:`shift` when it does not turn)."""
    out = np.eye(4)
    if spec.motion is None:
        return out
    if not spec.motion.turns:
        out[:3, 3] = shift(spec, t)
        return out
    q = turn(spec, t)
    anchor = np.asarray(spec.anchor, dtype=np.float64)
    out[:3, :3] = q
    out[:3, 3] = anchor + shift(spec, t) - q @ anchor
    return out


def posed(spec: Any, t: float) -> Any:
    """``spec`` moved to its pose at time ``t`` (itself when it does not move)."""
    if spec.motion is None:
        return spec
    d = shift(spec, t)
    if hasattr(spec, "a"):
        return dataclasses.replace(spec, a=_moved(spec.a, d), b=_moved(spec.b, d))
    name = {"origin", "point", "center"}.intersection(f.name for f in dataclasses.fields(spec)).pop()
    return dataclasses.replace(spec, **{name: _moved(getattr(spec, name), d)})


def _moved(p: tuple[float, float, float], d: np.ndarray) -> tuple[float, float, float]:
    return tuple(float(c) for c in np.asarray(p, dtype=np.float64) + d)  # type: ignore[return-value]


