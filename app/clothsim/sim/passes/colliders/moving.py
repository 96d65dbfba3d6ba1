"""The pose of every moving collider: each substep, every collider with a ``motion`` (a sphere,
plane, capsule, box or triangle mesh) is put at its pose at the end of the substep, and its
displacement over the substep (its *carry*) is recorded for the collision tests (see
:mod:`clothsim.sim.passes.colliders.shapes`).

All tracks are packed into one :class:`Motion` group of flat arrays, evaluated at the one clock's
times (:mod:`clothsim.sim.clock`, shared with the moving pins and the wind). A moving collider is
a (kind, row) pair: the pose update translates that row's point columns (``base + position(t) -
anchor``) and writes its carry; a mesh, whose triangles stay put in its own frame, gets its
translation at the substep's start and end instead (``mesh_pose``, read by
:mod:`clothsim.sim.passes.colliders.mesh`). Another kind joins by adding its kind number, the
columns it translates and where its carry goes. Only a scene with a moving collider builds the
group; without it the group is ``None`` and the moving code is pruned from the kernels before
typing.

Spheres and planes keep the course's row layout, so their carries live here
(``sphere_carry``, ``plane_carry``); a moving scene tests them with the carry-aware variants below
(the plane test is then a sign change of the distance measured in the plane's moving frame: a swept
test, exact at any speed; spheres are sub-sampled like capsules and boxes).
"""

from __future__ import annotations

import dataclasses
from typing import Any, NamedTuple

import numpy as np
from numba import njit

from ....jit import KERNEL
from .shapes import CAPSULE_CARRY, CUBOID_CARRY, samples
from ....colliders import kind_number, scene_colliders
from ...clock import call_time, substep_time, track_at as position_at

#: Kind numbers of a moving collider: places in the registry of kinds (:data:`clothsim.colliders.KINDS`).
KIND_SPHERE, KIND_PLANE, KIND_CAPSULE, KIND_CUBOID, KIND_MESH = (kind_number(k) for k in ("sphere", "plane", "capsule",
                                                                                        "box", "mesh"))


class Motion(NamedTuple):
    """Every moving collider's track and where its pose goes."""

    #: keyframe times and points of all tracks, concatenated; track m is span[m, 0]:span[m, 1]
    times: np.ndarray
    points: np.ndarray
    span: np.ndarray
    #: (M, 3) velocity after each track's last time
    velocity: np.ndarray
    #: (M,) kind and row of each moving collider
    kind: np.ndarray
    row: np.ndarray
    #: (M, 3) the position the scene gives (the track's value is where it is moved to)
    anchor: np.ndarray
    #: (M, 6) the unmoved point columns of its row (a capsule's a and b; others the first three)
    base: np.ndarray
    #: the simulation's clock (see :mod:`clothsim.sim.clock`) and the substep length
    clock: np.ndarray
    dt: float
    #: (2, 3) work space for the pose update
    scratch: np.ndarray
    sphere_carry: np.ndarray
    plane_carry: np.ndarray
    #: (meshes, 6) each mesh's translation at the start and at the end of the substep (the
    #: mesh group's ``pose``: static meshes' rows are set once, at packing)
    mesh_pose: np.ndarray


def pack_motion(scene: Any, clock: np.ndarray, dt: float, mesh_pose: np.ndarray) -> Motion | None:
    """The :class:`Motion` group of ``scene``'s moving colliders, or None when nothing moves.
    ``clock`` is the simulation's clock and ``mesh_pose`` the mesh group's pose rows (every mesh
    of the scene, moving or not; (0, 6) without meshes)."""
    tracks, kinds, rows, anchors, bases = [], [], [], [], []
    for entry, r, spec in scene_colliders(scene):
        if spec.motion is None:
            continue
        kind = entry.number
        kinds.append(kind)
        rows.append(r)
        if kind == KIND_MESH:  # a mesh's track is its translation (its vertices stay put)
            tracks.append(spec.track())
            anchors.append((0.0, 0.0, 0.0))
            bases.append((0.0,) * 6)
            continue
        tracks.append(spec.motion.track(spec.anchor))
        anchors.append(spec.anchor)
        bases.append((*spec.a, *spec.b) if kind == KIND_CAPSULE else (*spec.anchor, 0.0, 0.0, 0.0))
    if not tracks:
        return None
    ends = np.cumsum([len(t.times) for t in tracks])
    span = np.stack([ends - [len(t.times) for t in tracks], ends], axis=1).astype(np.int64)
    return Motion(np.concatenate([t.times for t in tracks]), np.concatenate([t.points for t in tracks]), span,
                  np.array([t.velocity for t in tracks], dtype=np.float64), np.array(kinds, dtype=np.int64),
                  np.array(rows, dtype=np.int64), np.array(anchors, dtype=np.float64),
                  np.array(bases, dtype=np.float64), clock, dt, np.zeros((2, 3)),
                  np.zeros((len(scene.spheres), 3)), np.zeros((len(scene.planes), 3)), mesh_pose)


def top_speed(scene: Any) -> float:
    """The highest speed (m/s) any of ``scene``'s colliders ever moves at (0 when none moves)."""
    top = 0.0
    for spec in scene.colliders:
        if spec.motion is None:
            continue
        track = spec.motion.track()  # a speed: the same from any start
        top = max(top, float(np.linalg.norm(track.velocity)))
        if len(track.times) > 1:
            steps = np.linalg.norm(np.diff(track.points, axis=0), axis=1) / np.diff(track.times)
            top = max(top, float(steps.max()))
    return top


def shift(spec: Any, t: float) -> np.ndarray:
    """How far a collider's ``motion`` has moved it from its scene pose at time ``t``, (3,) (zero
    for a static one): the translation to draw or export it with."""
    if spec.motion is None:
        return np.zeros(3)
    return spec.motion.track(spec.anchor).at(t) - np.asarray(spec.anchor, dtype=np.float64)


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


# ----------------------------------------------------------------------------------------------
# Kernels


@njit(**KERNEL)
def _translate(rows: np.ndarray | None, r: int, base: np.ndarray, count: int, x: float, y: float, z: float,
               carry_at: int, cx: float, cy: float, cz: float) -> None:
    if rows is None:
        return
    for j in range(count):
        rows[r, 3 * j] = base[3 * j] + x
        rows[r, 3 * j + 1] = base[3 * j + 1] + y
        rows[r, 3 * j + 2] = base[3 * j + 2] + z
    rows[r, carry_at] = cx
    rows[r, carry_at + 1] = cy
    rows[r, carry_at + 2] = cz


@njit(**KERNEL)
def update_poses(motion: Motion | None, spheres: np.ndarray, planes: np.ndarray, capsules: np.ndarray | None,
                 cuboids: np.ndarray | None, substep: int) -> None:
    """Put every moving collider at its pose at the end of substep ``substep`` of the call, and
    record its displacement over that substep (its carry)."""
    if motion is None:
        return
    # (two readings of the one clock: see clothsim.sim.clock)
    dt = motion.dt
    t0 = call_time(motion.clock, dt) + substep * dt
    t1 = t0 + dt
    s0 = substep_time(motion.clock, substep, dt)
    s1 = substep_time(motion.clock, substep + 1, dt)
    p0 = motion.scratch[0]
    p1 = motion.scratch[1]
    for m in range(motion.kind.shape[0]):
        a = motion.span[m, 0]
        b = motion.span[m, 1]
        kind = motion.kind[m]
        r = motion.row[m]
        position_at(motion.times[a:b], motion.points[a:b], motion.velocity[m], s0 if kind == KIND_MESH else t0, p0)
        position_at(motion.times[a:b], motion.points[a:b], motion.velocity[m], s1 if kind == KIND_MESH else t1, p1)
        if kind == KIND_MESH:
            for c in range(3):
                motion.mesh_pose[r, c] = p0[c]
                motion.mesh_pose[r, 3 + c] = p1[c]
            continue
        x = p1[0] - motion.anchor[m, 0]
        y = p1[1] - motion.anchor[m, 1]
        z = p1[2] - motion.anchor[m, 2]
        cx = p1[0] - p0[0]
        cy = p1[1] - p0[1]
        cz = p1[2] - p0[2]
        base = motion.base[m]
        if kind == KIND_SPHERE:
            spheres[r, 0] = base[0] + x
            spheres[r, 1] = base[1] + y
            spheres[r, 2] = base[2] + z
            motion.sphere_carry[r, 0] = cx
            motion.sphere_carry[r, 1] = cy
            motion.sphere_carry[r, 2] = cz
        elif kind == KIND_PLANE:
            planes[r, 0] = base[0] + x
            planes[r, 1] = base[1] + y
            planes[r, 2] = base[2] + z
            motion.plane_carry[r, 0] = cx
            motion.plane_carry[r, 1] = cy
            motion.plane_carry[r, 2] = cz
        elif kind == KIND_CAPSULE:
            _translate(capsules, r, base, 2, x, y, z, CAPSULE_CARRY, cx, cy, cz)
        else:
            _translate(cuboids, r, base, 1, x, y, z, CUBOID_CARRY, cx, cy, cz)


@njit(**KERNEL)
def moving(motion: Motion | None) -> bool:
    """True when the scene has moving colliders (a constant of the compiled kernel)."""
    return motion is not None


@njit(**KERNEL)
def reach_moving(box: np.ndarray, spheres: np.ndarray, planes: np.ndarray, sphere_on: np.ndarray,
                 plane_on: np.ndarray, motion: Motion) -> int:
    """The spheres' and planes' skip test with the cloth's box stretched by each one's carry."""
    skipped = 0
    for o in range(spheres.shape[0]):
        d2 = 0.0
        for c in range(3):
            x = spheres[o, c]
            lo = box[c] + min(motion.sphere_carry[o, c], 0.0)
            hi = box[3 + c] + max(motion.sphere_carry[o, c], 0.0)
            if x < lo:
                d2 += (lo - x) ** 2
            elif x > hi:
                d2 += (x - hi) ** 2
        sphere_on[o] = d2 <= spheres[o, 3] ** 2
        skipped += 0 if sphere_on[o] else 1
    for o in range(planes.shape[0]):
        lo = 0.0
        hi = 0.0
        for c in range(3):
            n = planes[o, 3 + c]
            a = (box[c] + min(motion.plane_carry[o, c], 0.0) - planes[o, c]) * n
            b = (box[3 + c] + max(motion.plane_carry[o, c], 0.0) - planes[o, c]) * n
            lo += a if a < b else b
            hi += a if a > b else b
        plane_on[o] = not (lo > 0.0 or hi < 0.0)
        skipped += 0 if plane_on[o] else 1
    return skipped


@njit(**KERNEL)
def collide_moving_spheres(pos: np.ndarray, last: np.ndarray, free: np.ndarray, spheres: np.ndarray,
                           on: np.ndarray, carry: np.ndarray) -> None:
    """Spheres tested along each point's path relative to the sphere, sub-sampled at most half a
    radius apart; the first sample inside is pushed to the surface, with friction relative to the
    sphere's motion."""
    for o in range(spheres.shape[0]):
        if not on[o]:
            continue
        ox = spheres[o, 0]
        oy = spheres[o, 1]
        oz = spheres[o, 2]
        r = spheres[o, 3]
        keep = 1.0 - spheres[o, 4]
        r2 = r * r
        step = 0.5 * r
        for k in range(free.shape[0]):
            p = free[k]
            lx = last[0, p] + carry[o, 0]
            ly = last[1, p] + carry[o, 1]
            lz = last[2, p] + carry[o, 2]
            x = pos[0, p]
            y = pos[1, p]
            z = pos[2, p]
            n = samples(x - lx, y - ly, z - lz, step)
            for j in range(1, n + 1):
                sx = x
                sy = y
                sz = z
                if j < n:
                    w = j / n
                    sx = lx + (x - lx) * w
                    sy = ly + (y - ly) * w
                    sz = lz + (z - lz) * w
                dx = sx - ox
                dy = sy - oy
                dz = sz - oz
                d2 = dx * dx + dy * dy + dz * dz
                if d2 <= r2 and d2 > 0.0:
                    s = r / np.sqrt(d2)
                    pos[0, p] = lx + (ox + dx * s - lx) * keep
                    pos[1, p] = ly + (oy + dy * s - ly) * keep
                    pos[2, p] = lz + (oz + dz * s - lz) * keep
                    break


@njit(**KERNEL)
def collide_moving_planes(pos: np.ndarray, last: np.ndarray, free: np.ndarray, planes: np.ndarray,
                          on: np.ndarray, carry: np.ndarray, offset: float) -> None:
    """Planes tested in their moving frame: a point crossed a plane when its distance from it
    changed sign between its carried last position and now (exact for any speed of the plane)."""
    for o in range(planes.shape[0]):
        if not on[o]:
            continue
        px = planes[o, 0]
        py = planes[o, 1]
        pz = planes[o, 2]
        nx = planes[o, 3]
        ny = planes[o, 4]
        nz = planes[o, 5]
        keep = 1.0 - planes[o, 6]
        for k in range(free.shape[0]):
            p = free[k]
            lx = last[0, p] + carry[o, 0]
            ly = last[1, p] + carry[o, 1]
            lz = last[2, p] + carry[o, 2]
            now = (pos[0, p] - px) * nx + (pos[1, p] - py) * ny + (pos[2, p] - pz) * nz
            before = (lx - px) * nx + (ly - py) * ny + (lz - pz) * nz
            if (before >= 0.0) != (now >= 0.0):
                side = offset if before >= 0.0 else -offset
                shift = side - now
                pos[0, p] = lx + (pos[0, p] + nx * shift - lx) * keep
                pos[1, p] = ly + (pos[1, p] + ny * shift - ly) * keep
                pos[2, p] = lz + (pos[2, p] + nz * shift - lz) * keep
