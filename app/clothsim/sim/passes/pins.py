"""Moving pins (``cloth.pin_motion``): every pinned point at its rest position plus the track's
offset at the end of each substep, exactly (the pass runs only in a scene whose pins move).

The integrators leave pinned points where they were; this pass then moves them: ``last`` keeps
where a pinned point was at the start of the substep and ``pos`` is set to rest + offset(t + dt),
so the Verlet velocity (x - x_last) / dt of a moving pin is its true velocity (the wind and the
next substep's springs see it) and a pin is never more than round-off off its track: each
position is computed from the rest position and the offset, not accumulated.
"""

from __future__ import annotations

import numpy as np
from numba import njit

from ...jit import CHUNKS, KERNEL
from ..team import share
from ..clock import track_at as offset_at


@njit(inline="always", **KERNEL)
def pin_chunk(pos: np.ndarray, last: np.ndarray, pm: tuple, offset: np.ndarray, c: int) -> None:
    """Work item ``c``: the pinned points of the c-th point range to rest + ``offset``; ``last``
    <- where they were. ``pm`` is a :class:`~clothsim.sim.state.PinMotion`."""
    lo, hi = share(pos.shape[1], c, CHUNKS)
    for k in range(pm.pins.shape[0]):
        q = pm.pins[k]
        if lo <= q < hi:
            for ax in range(3):
                last[ax, q] = pos[ax, q]
                pos[ax, q] = pm.rest[ax, k] + offset[ax]


@njit(**KERNEL)
def move_pins(pos: np.ndarray, last: np.ndarray, pm: tuple, t: float, offset: np.ndarray) -> None:
    """Every pinned point to rest + offset(t) (the other integrators' pass; ``offset`` is (3,) work
    space)."""
    offset_at(pm.times, pm.points, pm.velocity, t, offset)
    for c in range(CHUNKS):
        pin_chunk(pos, last, pm, offset, c)


@njit(**KERNEL)
def pin_velocities(pos: np.ndarray, last: np.ndarray, vel: np.ndarray, pm: tuple, dt: float) -> None:
    """vel = (x - x_last) / dt for the pinned points (a velocity-based integrator's stiffness term
    sees the moving pins' true velocity)."""
    inv = 1.0 / dt
    for k in range(pm.pins.shape[0]):
        q = pm.pins[k]
        for ax in range(3):
            vel[ax, q] = (pos[ax, q] - last[ax, q]) * inv

