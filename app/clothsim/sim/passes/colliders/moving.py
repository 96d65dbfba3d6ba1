"""The pose of every moving collider, for every kind: a collider with a ``motion`` is a track of
its anchor (:mod:`clothsim.motion`), evaluated at the simulation's one clock
(:mod:`clothsim.sim.clock`, shared with the moving pins and the wind).

A kind's group (see :mod:`clothsim.sim.passes.colliders`) holds its moving colliders' tracks as one
:class:`Tracks` group of flat arrays, or None when none of them moves. Each substep the kind's
``pose`` puts each of them at its pose at the end of the substep and records its displacement
over the substep (its *carry*, read by the swept tests): :func:`pose_rows` translates a row's
point columns (``base + position(t) - anchor``); a mesh, whose triangles stay put in its own frame,
keeps its translation at the substep's start and end instead (:mod:`.mesh`).

The Python helpers below give the same poses to the renderer and the exporters.
"""

from __future__ import annotations

import dataclasses
from typing import Any, Callable, NamedTuple

import numpy as np
from numba import njit

from ....jit import KERNEL
from ...clock import call_time, track_at as position_at


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


