"""Prescribed motion over time: keyframes or a constant velocity, for colliders and pinned points.

A scene writes ``"motion": {"keyframes": [[t0, [x, y, z]], [t1, [x, y, z]], ...]}`` (times in seconds
since the start, strictly increasing; linear between keyframes, held before the first and after
the last) or ``"motion": {"velocity": [vx, vy, vz]}`` (moving from the object's own position at
time 0, for ever). What a keyframe's vector means belongs to the object that carries the motion: a
sphere's origin, a box's center, the offset of every pinned point.

Either form becomes one :class:`Track`, three flat arrays a kernel can evaluate without knowing
which form it came from: ``times`` (K,), ``points`` (K, 3) and ``velocity`` (3,), the velocity
continuing after the last keyframe (zero for keyframes, the given one for the velocity form).
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any

import numpy as np

from . import validate as V

#: Most keyframes one track may hold: a scene file, not a motion-capture stream.
MAX_KEYFRAMES = 100_000
#: Fastest a prescribed motion may move, in m/s (a collider or the pins; the wind has the same bound):
#: beyond it a substep of the course's 1/2700 s moves further than a cloth is wide, and a speed near the
#: float range overflows the blow-up guard's energy bound into a misleading "blew up" message.
MAX_SPEED = 1e3
#: Largest keyframe offset, in m: the scene's length bound.
MAX_OFFSET = 1e6


@dataclass(frozen=True)
class MotionSpec:
    """A validated ``motion`` object: ``keyframes`` ((t, (x, y, z)), ...) or ``velocity``, never both."""

    keyframes: tuple[tuple[float, tuple[float, float, float]], ...] = ()
    velocity: tuple[float, float, float] | None = None

    def track(self, start: tuple[float, float, float] = (0.0, 0.0, 0.0)) -> "Track":
        """The arrays to evaluate; ``start`` is the position a velocity moves from."""
        if self.velocity is not None:
            return Track(np.zeros(1), np.array([start], dtype=np.float64), np.array(self.velocity, dtype=np.float64))
        times = np.array([t for t, _ in self.keyframes], dtype=np.float64)
        points = np.array([p for _, p in self.keyframes], dtype=np.float64).reshape(-1, 3)
        return Track(times, points, np.zeros(3))


@dataclass(frozen=True)
class Track:
    """Motion as arrays: ``times`` (K,) increasing, ``points`` (K, 3), ``velocity`` (3,) after the last time."""

    times: np.ndarray
    points: np.ndarray
    velocity: np.ndarray

    def at(self, t: float) -> np.ndarray:
        """The position at time ``t`` (seconds), as a new (3,) array."""
        out = np.empty(3)
        position_at(self.times, self.points, self.velocity, float(t), out)
        return out


def position_at(times: np.ndarray, points: np.ndarray, velocity: np.ndarray, t: float, out: np.ndarray) -> None:
    """Write the position at time ``t`` into ``out`` (3,).

    Plain NumPy-compatible Python that Numba also compiles (``njit(position_at)`` inside a kernel):
    a binary search over the times, then one linear blend, so each evaluation is O(log K).
    """
    k = times.shape[0]
    if t <= times[0]:
        for c in range(3):
            out[c] = points[0, c]
        return
    if t >= times[k - 1]:
        dt = t - times[k - 1]
        for c in range(3):
            out[c] = points[k - 1, c] + velocity[c] * dt
        return
    lo, hi = 0, k - 1  # times[lo] < t < times[hi]
    while hi - lo > 1:
        mid = (lo + hi) // 2
        if times[mid] <= t:
            lo = mid
        else:
            hi = mid
    w = (t - times[lo]) / (times[hi] - times[lo])
    for c in range(3):
        out[c] = points[lo, c] + w * (points[hi, c] - points[lo, c])


# ----------------------------------------------------------------------------------------------
# Validation


def _keyframe(value: Any, at: V.At) -> tuple[float, tuple[float, float, float]]:
    items = V.items_of(value)
    if items is None or len(items) != 2:
        raise at.fail(f"expected a keyframe [time, [x, y, z]], got {V.shown(value)}")
    return V.number(ge=0.0)(items[0], at.index(0)), _OFFSET(items[1], at.index(1))


def _increasing(frames: tuple, at: V.At) -> tuple:
    if len(frames) > MAX_KEYFRAMES:
        raise at.fail(f"has {len(frames)} keyframes, at most {MAX_KEYFRAMES} are allowed")
    for i in range(1, len(frames)):
        (t0, p0), (t1, p1) = frames[i - 1], frames[i]
        if not t1 > t0:
            raise at.index(i).index(0).fail(f"keyframe times must increase: {V.shown(t1)} follows {V.shown(t0)}")
        distance = math.dist(p0, p1)
        if distance > MAX_SPEED * (t1 - t0):  # a product: the quotient overflows for times 1e-300 apart
            raise at.index(i).fail(
                f"moves {distance:.6g} m in {t1 - t0:.6g} s after the keyframe before it, faster than "
                f"{MAX_SPEED:g} m/s")
    return frames


_OFFSET = V.vec3(V.number(ge=-MAX_OFFSET, le=MAX_OFFSET))


_FIELDS = V.record({
    "keyframes": V.optional(V.then(V.list_of(_keyframe, nonempty=True, what="keyframes [time, [x, y, z]]"),
                                   _increasing)),
    "velocity": V.optional(V.vec3(V.number(ge=-MAX_SPEED, le=MAX_SPEED))),
})


def MOTION(value: Any, at: V.At) -> MotionSpec:  # noqa: N802 - a rule, named like the scene's records
    """The rule for a ``motion`` object: exactly one of ``keyframes`` and ``velocity``."""
    fields = _FIELDS(value, at)
    if ("keyframes" in fields) == ("velocity" in fields):
        raise at.fail('expected exactly one of "keyframes" and "velocity"')
    return MotionSpec(**fields)
