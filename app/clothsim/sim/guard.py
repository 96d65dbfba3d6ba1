"""Stability guard: the explicit step bound before a run, blow-up detection during it.

Before stepping, the highest angular frequency of the spring network is bounded by Gershgorin's
theorem: each row of M^-1 K sums to at most 2 * (sum of the stiffnesses of the springs at that
point) / m, so omega_max^2 <= 2 max_p(sum_k) / m. Verlet and symplectic Euler are stable for
dt < 2 / omega_max (undamped leapfrog bound; damping only widens it). Since Gershgorin
over-estimates omega_max the bound is on the safe side.

During a run a frame has blown up when a position is non-finite or when the kinetic energy of the
free points exceeds ENERGY_FACTOR times the work gravity has done on them plus a small slack
(see :func:`blow_up_reason`): an unstable explicit run passes that within a few frames, even
when Provot's limit keeps its positions bounded.
"""

from __future__ import annotations

import math
from typing import Any

import numpy as np
from numba import njit

from ..cloth import BENDING, BENDING_STIFFNESS_FACTOR, enabled_mask, pinned_mask
from ..forces import FORCES
from ..scene import Scene
from ..jit import EXACT
from ..jit.compile import on_warm
from .topology import cloth_springs, point_masses, rest_positions

EXPLICIT_INTEGRATORS = ("verlet", "symplectic_euler")

# A frame has blown up when the free points' kinetic energy per kg exceeds
# ENERGY_FACTOR x (work done by gravity per kg) + ENERGY_SLACK (J/kg; 2 J/kg = 2 m/s RMS).
ENERGY_FACTOR = 4.0
ENERGY_SLACK = 2.0


def omega_max(scene: Scene) -> float:
    """Gershgorin bound on the highest angular frequency (rad/s) of the free points' springs."""
    cloth = scene.cloth
    pos = rest_positions(cloth, scene.simulation.seed)
    springs = cloth_springs(cloth, pos)
    springs = springs.select(enabled_mask(springs.kind, cloth.enable_structural, cloth.enable_shearing,
                                          cloth.enable_bending))
    k = np.where(springs.kind == BENDING, cloth.ks * BENDING_STIFFNESS_FACTOR, cloth.ks)
    total = np.bincount(springs.i, weights=k, minlength=cloth.num_points)
    total += np.bincount(springs.j, weights=k, minlength=cloth.num_points)
    free = ~pinned_mask(cloth)
    if not free.any():
        return 0.0
    # each point's own mass (a grid's are all one: dividing by it keeps which point is largest, and
    # the quotient is the same correctly rounded number)
    return math.sqrt(2.0 * float((total[free] / point_masses(cloth)[free]).max()))


def stable_dt(scene: Scene) -> float:
    """Largest substep (s) the explicit integrators are predicted to be stable at (inf if no springs)."""
    w = omega_max(scene)
    return math.inf if w == 0.0 else 2.0 / w


def substeps_for_dt(scene: Scene, dt: float) -> int:
    """Smallest substep count per frame with a substep no longer than ``dt``."""
    if math.isinf(dt):
        return 1
    # tiny slack so that an exact multiple does not round up through floating-point noise
    return max(1, math.ceil(1.0 / (scene.simulation.frames_per_sec * dt) * (1.0 - 1e-12)))


def estimate_stable_substeps(scene: Scene) -> int | None:
    """Smallest stable ``simulation_steps`` for the scene's explicit integrator; None for implicit/xpbd."""
    if scene.simulation.integrator not in EXPLICIT_INTEGRATORS:
        return None
    return substeps_for_dt(scene, stable_dt(scene))


def stability_warning(scene: Scene) -> str | None:
    """A one-line warning when the scene's explicit step is beyond the stable bound, else None."""
    need = estimate_stable_substeps(scene)
    steps = scene.simulation.simulation_steps
    if need is None or steps >= need:
        return None
    dt = 1.0 / (scene.simulation.frames_per_sec * steps)
    return (f"{scene.path}: {scene.simulation.integrator} is likely unstable at {steps} substeps per frame "
            f"(dt={dt:.3g} s > 2/omega_max={stable_dt(scene):.3g} s for ks={scene.cloth.ks:g}, "
            f"density={scene.cloth.density:g}); use simulation_steps >= {need} (or --auto-substeps), "
            "or integrator implicit_euler or xpbd")


def blow_up_reason(pos: np.ndarray, last: np.ndarray, free: np.ndarray, dt: float, gravity: np.ndarray,
                   start: np.ndarray, driven: float = 0.0) -> str | None:
    """What blew up, or None. ``pos``/``last``/``start`` are (3, N), ``start`` the initial positions.

    Energy test: rest lengths are measured from the initial grid, so the cloth starts with no
    elastic energy and (static colliders and damping only remove energy) its kinetic energy can
    only come from the work gravity has done, g . (drop of the free points' centre of mass), and
    from what drives it: ``driven`` (m/s) bounds the speed of the air (wind plus gusts), of the
    moving pins and of the moving colliders, and a cloth dragged, blown or carried along moves at
    about that speed, so 1/2 driven^2 J/kg is added to the work.
    """
    finite, sum_d2, drop = _frame_sums(pos, last, free, start)
    if not finite:
        return "positions became non-finite"
    n = free.shape[0]
    if n == 0:
        return None
    ke = 0.5 * sum_d2 / (n * dt * dt)
    work = float(gravity @ drop) / n
    bound = ENERGY_FACTOR * (max(work, 0.0) + 0.5 * driven * driven) + ENERGY_SLACK
    if not ke <= bound:
        return (f"kinetic energy blew up ({ke:.3g} J/kg > bound {bound:.3g} J/kg = "
                f"{ENERGY_FACTOR:g} x gravity work + {ENERGY_SLACK:g})")
    return None


@njit(**EXACT)
def _frame_sums(pos: np.ndarray, last: np.ndarray, free: np.ndarray, start: np.ndarray) -> tuple:
    """(all positions finite, sum over free points of |pos - last|^2, sum of pos - start)."""
    finite = True
    for c in range(3):
        for p in range(pos.shape[1]):
            if not np.isfinite(pos[c, p]):
                finite = False
    sum_d2 = 0.0
    drop = np.zeros(3)
    for k in range(free.shape[0]):
        p = free[k]
        for c in range(3):
            d = pos[c, p] - last[c, p]
            sum_d2 += d * d
            drop[c] += pos[c, p] - start[c, p]
    return finite, sum_d2, drop


def sim_blow_up_reason(sim: Any) -> str | None:
    """:func:`blow_up_reason` for a :class:`~clothsim.sim.simulation.Simulation`."""
    return blow_up_reason(sim._pos, sim._last, sim.free, sim.dt, sim._gravity, sim.initial_positions.T,
                          driven_speed(sim.scene) + sim.collider_top_speed)


def driven_speed(scene: Scene) -> float:
    """Bound (m/s) on the speed of what drives the cloth: the fastest force's driver (the fastest
    wind with its gusts) plus the fastest moving pin."""
    air = max((kind.top_speed(getattr(scene, kind.attr)) for kind in FORCES), default=0.0)
    motion = scene.cloth.pin_motion
    pins = 0.0
    if motion is not None:
        track = motion.track()
        pins = float(np.linalg.norm(track.velocity))
        if track.times.shape[0] > 1:
            steps = np.linalg.norm(np.diff(track.points, axis=0), axis=1) / np.diff(track.times)
            pins = max(pins, float(steps.max()))
    return air + pins


def blow_up_advice(scene: Scene) -> str:
    """What to try after a blow-up."""
    need = estimate_stable_substeps(scene)
    if need is not None and need > scene.simulation.simulation_steps:
        return f"try simulation_steps >= {need}, or integrator implicit_euler or xpbd"
    return "try more simulation_steps, or integrator implicit_euler or xpbd"


def _warm() -> None:
    state = np.zeros((3, 4))
    _frame_sums(state, state, np.zeros(1, dtype=np.int32), np.zeros((4, 3)).T)


on_warm("1 blow-up guard", _warm)
