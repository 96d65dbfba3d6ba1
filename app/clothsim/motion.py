"""Prescribed motion over time: keyframes or a constant velocity, for colliders and pinned points.

A scene writes ``"motion": {"keyframes": [[t0, [x, y, z]], [t1, [x, y, z]], ...]}`` (times in seconds
since the start, strictly increasing; linear between keyframes, held before the first and after
the last) or ``"motion": {"velocity": [vx, vy, vz]}`` (moving from the object's own position at
time 0, for ever). What a keyframe's vector means belongs to the object that carries the motion: a
sphere's origin, a box's center, the offset of every pinned point.

Either form becomes one :class:`Track`, three flat arrays a kernel can evaluate without knowing
which form it came from: ``times`` (K,), ``points`` (K, 3) and ``velocity`` (3,), the velocity
continuing after the last keyframe (zero for keyframes, the given one for the velocity form).

A collider's motion may also turn it about its anchor (:class:`Spin`): ``"rotation_keyframes":
[[t, [rx, ry, rz]], ...]`` (its orientation at those times, degrees, R = Rz . Ry . Rx as the static
``rotation`` key: the orientation replaces the static one, as a position keyframe replaces the
anchor; the three angles linear in time between keyframes, held before the first and after the
last) or ``"angular_velocity": [wx, wy, wz]`` (degrees a second: at time t the static orientation
followed by a turn of |w| t about the world axis w / |w| through the anchor). Either way the
collider's pose at time t is ``x -> p(t) + Q(t) (x - anchor)`` for a point x of its scene pose,
p(t) the translation's position and Q(t) = Rot(w t) . E(angles(t)) . R_static^T
(:func:`clothsim.sim.clock.turn_at`).
"""

from __future__ import annotations

import math
from collections.abc import Callable
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
#: Fastest a collider may turn, in degrees a second (100 turns a second): at the course's substep of
#: 1/2700 s that is 13.3 degrees a substep, within which the swept tests' straight relative path
#: stays close to the arc a point on the surface sweeps. For rotation keyframes the bound holds for
#: |d rx| + |d ry| + |d rz| between two keyframes (a bound on the turn's rate).
MAX_ANGULAR_SPEED = 36000.0
#: Bound of a rotation keyframe's angles, in degrees (the static ``rotation``'s).
MAX_ANGLE = 36000.0


@dataclass(frozen=True)
class MotionSpec:
    """A validated ``motion`` object: ``keyframes`` ((t, (x, y, z)), ...) or ``velocity``, never both."""

    keyframes: tuple[tuple[float, tuple[float, float, float]], ...] = ()
    velocity: tuple[float, float, float] | None = None
    #: a collider's turn (see the module's docstring): orientation keyframes (t, (rx, ry, rz)) in
    #: degrees, or an angular velocity in degrees a second; never both, and neither for pins
    rotation_keyframes: tuple[tuple[float, tuple[float, float, float]], ...] = ()
    angular_velocity: tuple[float, float, float] | None = None

    @property
    def turns(self) -> bool:
        """Whether the motion turns its collider (rotation keyframes or an angular velocity)."""
        return bool(self.rotation_keyframes) or self.angular_velocity is not None

    @property
    def ends(self) -> float:
        """Time (s) after which the motion no longer changes (inf for a velocity)."""
        if self.velocity is not None or self.angular_velocity is not None:
            return float("inf")
        return max([0.0] + [frames[-1][0] for frames in (self.keyframes, self.rotation_keyframes) if frames])

    def as_json(self) -> dict[str, Any]:
        """The object as a scene file writes it (what loads back to the same spec)."""
        out: dict[str, Any] = {}
        if self.velocity is not None:
            out["velocity"] = list(self.velocity)
        elif self.keyframes:
            out["keyframes"] = [[t, list(p)] for t, p in self.keyframes]
        if self.angular_velocity is not None:
            out["angular_velocity"] = list(self.angular_velocity)
        elif self.rotation_keyframes:
            out["rotation_keyframes"] = [[t, list(a)] for t, a in self.rotation_keyframes]
        return out

    def track(self, start: tuple[float, float, float] = (0.0, 0.0, 0.0)) -> "Track":
        """The arrays to evaluate; ``start`` is the position a velocity moves from (and where a
        motion that only turns keeps its anchor)."""
        if self.velocity is not None:
            return Track(np.zeros(1), np.array([start], dtype=np.float64), np.array(self.velocity, dtype=np.float64))
        if not self.keyframes:
            return Track(np.zeros(1), np.array([start], dtype=np.float64), np.zeros(3))
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


@dataclass(frozen=True)
class Spin:
    """A turn as arrays: the orientation keyframes ``times`` (K,) and ``angles`` (K, 3) in degrees
    (one keyframe of zeros for an angular velocity or no turn), ``omega`` (3,) the angular velocity
    in radians a second, and ``rest`` (3, 3) the static rotation the keyframes replace (the identity
    for an angular velocity, which turns the collider from its static orientation)."""

    times: np.ndarray
    angles: np.ndarray
    omega: np.ndarray
    rest: np.ndarray


def spin_of(motion: "MotionSpec | None", rest: np.ndarray | None = None) -> Spin:
    """The :class:`Spin` of a collider's motion (no turn for None); ``rest`` is its static rotation
    matrix (the identity when None), which orientation keyframes replace."""
    if motion is not None and motion.rotation_keyframes:
        return Spin(np.array([t for t, _ in motion.rotation_keyframes], dtype=np.float64),
                    np.array([a for _, a in motion.rotation_keyframes], dtype=np.float64).reshape(-1, 3), np.zeros(3),
                    np.eye(3) if rest is None else np.asarray(rest, dtype=np.float64).reshape(3, 3))
    omega = np.zeros(3) if motion is None or motion.angular_velocity is None else np.radians(motion.angular_velocity)
    return Spin(np.zeros(1), np.zeros((1, 3)), np.asarray(omega, dtype=np.float64), np.eye(3))


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


def _keyframe_rule(vector: Callable[[Any, V.At], tuple[float, float, float]], what: str) -> Callable:
    # a keyframe [time, vector]: a position ([x, y, z]) or an orientation ([rx, ry, rz])
    def rule(value: Any, at: V.At) -> tuple[float, tuple[float, float, float]]:
        items = V.items_of(value)
        if items is None or len(items) != 2:
            raise at.fail(f"expected a keyframe [time, {what}], got {V.shown(value)}")
        return V.number(ge=0.0)(items[0], at.index(0)), vector(items[1], at.index(1))

    return rule


def _increasing_rule(change: Callable[[tuple, tuple], float], limit: float, moves: str) -> Callable:
    # keyframes in increasing time, none changing faster than ``limit`` a second: ``change`` is
    # how much it does between two, and ``moves`` the message (its {amount} and {dt} filled in)
    def rule(frames: tuple, at: V.At) -> tuple:
        if len(frames) > MAX_KEYFRAMES:
            raise at.fail(f"has {len(frames)} keyframes, at most {MAX_KEYFRAMES} are allowed")
        for i in range(1, len(frames)):
            (t0, a), (t1, b) = frames[i - 1], frames[i]
            if not t1 > t0:
                raise at.index(i).index(0).fail(f"keyframe times must increase: {V.shown(t1)} follows {V.shown(t0)}")
            amount = change(a, b)
            if amount > limit * (t1 - t0):  # a product: the quotient overflows for times 1e-300 apart
                raise at.index(i).fail(moves.format(amount=f"{amount:.6g}", dt=f"{t1 - t0:.6g}"))
        return frames

    return rule


_OFFSET = V.vec3(V.number(ge=-MAX_OFFSET, le=MAX_OFFSET))
_keyframe = _keyframe_rule(_OFFSET, "[x, y, z]")
_increasing = _increasing_rule(math.dist, MAX_SPEED, "moves {amount} m in {dt} s after the keyframe before it, faster than "
                               f"{MAX_SPEED:g} m/s")


_FIELDS = V.record({
    "keyframes": V.optional(V.then(V.list_of(_keyframe, nonempty=True, what="keyframes [time, [x, y, z]]"),
                                   _increasing)),
    "velocity": V.optional(V.vec3(V.number(ge=-MAX_SPEED, le=MAX_SPEED))),
})


def MOTION(value: Any, at: V.At) -> MotionSpec:  # noqa: N802 - a rule, named like the scene's records
    """The rule for a ``motion`` object that only translates (the pins'): exactly one of
    ``keyframes`` and ``velocity``."""
    fields = _FIELDS(value, at)
    if ("keyframes" in fields) == ("velocity" in fields):
        raise at.fail('expected exactly one of "keyframes" and "velocity"')
    return MotionSpec(**fields)


def _angular_speed(w: tuple[float, float, float], at: V.At) -> tuple[float, float, float]:
    speed = math.hypot(*w)
    if speed > MAX_ANGULAR_SPEED:
        raise at.fail(f"turns at {speed:.6g} degrees/s, faster than {MAX_ANGULAR_SPEED:g} degrees/s")
    return w


_ANGLES = V.vec3(V.number(ge=-MAX_ANGLE, le=MAX_ANGLE))
_rotation_keyframe = _keyframe_rule(_ANGLES, "[rx, ry, rz]")
_turning_increasing = _increasing_rule(
    lambda a, b: sum(abs(q - p) for p, q in zip(a, b)), MAX_ANGULAR_SPEED,
    "turns {amount} degrees (|d rx| + |d ry| + |d rz|) in {dt} s after the keyframe before it, faster than "
    f"{MAX_ANGULAR_SPEED:g} degrees/s")

_COLLIDER_FIELDS = V.record({
    "keyframes": V.optional(V.then(V.list_of(_keyframe, nonempty=True, what="keyframes [time, [x, y, z]]"),
                                   _increasing)),
    "velocity": V.optional(V.vec3(V.number(ge=-MAX_SPEED, le=MAX_SPEED))),
    "rotation_keyframes": V.optional(V.then(V.list_of(_rotation_keyframe, nonempty=True,
                                                      what="keyframes [time, [rx, ry, rz]]"), _turning_increasing)),
    "angular_velocity": V.optional(V.then(V.vec3(V.number(ge=-MAX_ANGULAR_SPEED, le=MAX_ANGULAR_SPEED)),
                                          _angular_speed)),
})


def COLLIDER_MOTION(value: Any, at: V.At) -> MotionSpec:  # noqa: N802 - a rule, named like the scene's records
    """The rule for a collider's ``motion``: at most one of ``keyframes`` and ``velocity`` (the
    translation), at most one of ``rotation_keyframes`` and ``angular_velocity`` (the turn), and at
    least one of the four."""
    fields = _COLLIDER_FIELDS(value, at)
    if "keyframes" in fields and "velocity" in fields:
        raise at.fail('expected one of "keyframes" and "velocity", not both')
    if "rotation_keyframes" in fields and "angular_velocity" in fields:
        raise at.fail('expected one of "rotation_keyframes" and "angular_velocity", not both')
    if not fields:
        raise at.fail('expected "keyframes" or "velocity" (a translation), "rotation_keyframes" or '
                      '"angular_velocity" (a turn), or one of each')
    return MotionSpec(**fields)
