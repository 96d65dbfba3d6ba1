"""The one clock of prescribed motion, and the one compiled evaluation of a motion track
(:func:`clothsim.motion.position_at`) and of a collider's turn (:func:`turn_at`): moving pins, the wind's gusts, and the poses of moving
colliders of every kind (spheres, planes, capsules, boxes, meshes) all read time from here.

The clock is a (2,) array owned by the :class:`~clothsim.sim.Simulation`: (time at the last
re-plan, substeps run since), and the substep length ``dt`` of the plan. Substep ``s`` of a call
starts at ``clock[0] + (clock[1] + s) * dt``: computed, not summed up, so a run gives the same
times however its substeps are grouped into calls (frames, single substeps in the blow-up replay,
pass by pass in the profiler).

Moving spheres, planes, capsules and boxes count a substep's times from the call's start
(:func:`call_time` plus ``step`` substep lengths, the end one substep length later), the others
from the clock's base (:func:`substep_time`): each is the arithmetic its motion had before they
shared this clock, so no scene's numbers changed when they did (the two differ in the last bits).

One dispatcher for the track on purpose: Numba's on-disk cache files a function's compiled
versions under the function and its argument types, not its options, so two dispatchers of the
same Python function with different options load each other's code (a pin then landed one ulp
off its track). Like every :data:`~clothsim.jit.EXACT` kernel it is compiled without fast-math
whoever calls it: the frame kernel's contracted arithmetic once put a pin one ulp off rest +
``Track.at(t)``, the Python evaluation the tests compare with.
"""

from __future__ import annotations

import numpy as np
from numba import njit

from ..motion import position_at
from ..jit import EXACT

track_at = njit(**EXACT)(position_at)


@njit(**EXACT)
def euler_into(angles: np.ndarray, out: np.ndarray) -> None:
    """R = Rz . Ry . Rx of ``angles`` (3,) in degrees into ``out`` (3, 3): the static ``rotation``'s
    convention (right-handed, x applied first)."""
    rx = angles[0] * (np.pi / 180.0)
    ry = angles[1] * (np.pi / 180.0)
    rz = angles[2] * (np.pi / 180.0)
    cx, sx, cy, sy, cz, sz = np.cos(rx), np.sin(rx), np.cos(ry), np.sin(ry), np.cos(rz), np.sin(rz)
    out[0, 0] = cz * cy
    out[0, 1] = cz * sy * sx - sz * cx
    out[0, 2] = cz * sy * cx + sz * sx
    out[1, 0] = sz * cy
    out[1, 1] = sz * sy * sx + cz * cx
    out[1, 2] = sz * sy * cx - cz * sx
    out[2, 0] = -sy
    out[2, 1] = cy * sx
    out[2, 2] = cy * cx


@njit(**EXACT)
def turn_at(times: np.ndarray, angles: np.ndarray, omega: np.ndarray, rest: np.ndarray, t: float,
            work: np.ndarray, out: np.ndarray) -> None:
    """A collider's turn Q(t) = Rot(omega t) . E(angles(t)) . rest^T into ``out`` (3, 3) (see
    :mod:`clothsim.motion`): ``angles(t)`` the orientation keyframes (degrees) linear in time and
    held at the ends (:func:`track_at` with no velocity), E their matrix (:func:`euler_into`), Rot
    the turn by the rotation vector ``omega t`` (radians; Rodrigues' formula). ``work`` (5, 3) is
    work space whose last row must hold zeros; ``out`` must not be part of it."""
    angle = work[0]
    e = work[1:4]
    track_at(times, angles, work[4], t, angle)  # no velocity after the last keyframe
    euler_into(angle, e)
    vx, vy, vz = omega[0] * t, omega[1] * t, omega[2] * t
    turn = np.sqrt(vx * vx + vy * vy + vz * vz)
    if turn == 0.0:
        for i in range(3):
            for j in range(3):
                out[i, j] = e[i, 0] * rest[j, 0] + e[i, 1] * rest[j, 1] + e[i, 2] * rest[j, 2]
        return
    kx, ky, kz = vx / turn, vy / turn, vz / turn
    c, s = np.cos(turn), np.sin(turn)
    u = 1.0 - c
    r00, r01, r02 = c + kx * kx * u, kx * ky * u - kz * s, kx * kz * u + ky * s
    r10, r11, r12 = ky * kx * u + kz * s, c + ky * ky * u, ky * kz * u - kx * s
    r20, r21, r22 = kz * kx * u - ky * s, kz * ky * u + kx * s, c + kz * kz * u
    for j in range(3):
        # column j of E . rest^T, then Rot times it
        m0 = e[0, 0] * rest[j, 0] + e[0, 1] * rest[j, 1] + e[0, 2] * rest[j, 2]
        m1 = e[1, 0] * rest[j, 0] + e[1, 1] * rest[j, 1] + e[1, 2] * rest[j, 2]
        m2 = e[2, 0] * rest[j, 0] + e[2, 1] * rest[j, 1] + e[2, 2] * rest[j, 2]
        out[0, j] = r00 * m0 + r01 * m1 + r02 * m2
        out[1, j] = r10 * m0 + r11 * m1 + r12 * m2
        out[2, j] = r20 * m0 + r21 * m1 + r22 * m2


@njit(**EXACT)
def substep_time(clock: np.ndarray, step: int, dt: float) -> float:
    """Time (s) at the start of substep ``step`` of a call (``step`` may be one past the last, for
    the time at a substep's end): clock = (base time, substeps since)."""
    return clock[0] + (clock[1] + step) * dt


@njit(**EXACT)
def call_time(clock: np.ndarray, dt: float) -> float:
    """Time (s) at the start of a call: the simulation's ``time``."""
    return clock[0] + clock[1] * dt
