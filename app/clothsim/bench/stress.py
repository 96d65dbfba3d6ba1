"""The self-collision stress set: scenes where a cloth folds onto and around itself.

Each run is on an ``n`` x ``n`` grid (50 x 50 in ``clothsim bench selfcollision``). Five where the
cloth folds by itself, or by its pins:

- ``selfCollision``: the course's vertical cloth falling in folds onto a plane;
- ``flag``: a flag in gusty wind, folding over itself at its free end;
- ``heap``: a cloth whose top edge is lowered and carried sideways onto a floor, laid down in a
  heap of folds (the bundled ``heap`` scene);
- ``push``: a cloth lying on a floor, pushed into folds by a moving box (the bundled ``push``
  scene);
- ``twist``: a cloth held at its top and bottom edges, the two edges turned in opposite
  directions a full turn each (two turns against each other) while they approach, so the cloth
  wrings into a rope. A scene's motion tracks are translations, so this run is driven through the
  public API: one substep per :meth:`Simulation.step` call, the pinned points set to the edges'
  turned poses (and their last positions to the poses one substep earlier) before each substep.

And five where moving colliders or pins drive a cloth lying on a floor into folds and press them
against the floor (``DRIVEN_SCENES``). In the first four a box slides along the floor and pushes
the cloth into a heap of folds (by 0.8 s), then another collider comes down on the heap and
presses it until 1.2 s:

- ``lid``: a plane, to 3 cm over the floor;
- ``press``: a ball 25 cm in radius, to 3 cm;
- ``roller``: a capsule lying across the cloth, to 3 cm;
- ``stamp``: the bundled torus lying flat, to 3.3 cm;
- ``drag``: no collider but the floor: two corners of the cloth are dragged over it to the far
  side and lifted, folding it onto itself.

And one where two colliders close on the cloth further than its layers allow (``SQUEEZE_SCENES``):

- ``squeeze``: as ``lid``, but the plane comes down to 5 mm over the floor, on a heap of layers
  each of which keeps the contact distance (9.5 mm at 50 x 50) from the next. Something has to
  give: in the contact mode the colliders keep the cloth between them and the cloth crosses
  itself there, in substeps that are counted (``Simulation.squeezed_substeps``).

A bundled scene on another grid keeps its pins where they were (each new point is pinned when the
nearest point of the scene's own grid is) and its thickness in proportion to the point spacing,
so every size has the same neighbours per point in the self-collision hash.
"""

from __future__ import annotations

import math
from collections.abc import Callable

import numpy as np

from ..scene import SIMULATION, SELF_COLLISION_MODES, Scene, load_scene

#: The runs where the cloth folds by itself or by its pins (``clothsim bench selfcollision``'s default).
FOLDING_SCENES = ("selfCollision", "flag", "heap", "push", "twist")
#: The runs where moving colliders and pins drive the folds (see the module's docstring).
DRIVEN_SCENES = ("lid", "press", "roller", "stamp", "drag")
#: The runs where colliders squeeze the cloth thinner than it can be (see the module's docstring).
SQUEEZE_SCENES = ("squeeze",)
#: Every run of the stress set, in the order the benchmark prints them.
STRESS_SCENES = FOLDING_SCENES + DRIVEN_SCENES + SQUEEZE_SCENES
#: The squeeze's gap between the plane and the floor at the end (m).
SQUEEZE_GAP = 0.005
#: The driven runs' floor: the cloth starts 5 cm over it, at the course's height of 1 m.
FLOOR = 0.95
#: The twist: seconds before the edges start turning, seconds to turn, turns of each edge, and the
#: distance each edge moves towards the middle meanwhile (m).
TWIST_START = 0.1
TWIST_SECONDS = 3.0
TWIST_TURNS = 1.0
TWIST_APPROACH = 0.3


def self_collision_modes() -> tuple[str, ...]:
    """Every ``simulation.self_collision`` mode the scene validator accepts, in its order."""
    rule = SIMULATION.fields["self_collision"].rule
    return tuple(getattr(rule, "options", SELF_COLLISION_MODES))


def resized(scene: Scene, n: int) -> Scene:
    """``scene`` on an ``n`` x ``n`` grid: pins kept in place, thickness scaled with the spacing."""
    cloth = scene.cloth
    nw, nh = cloth.num_width_points, cloth.num_height_points
    old = set(cloth.pinned)
    pins = tuple((x, y) for y in range(n) for x in range(n)
                 if (round(x * (nw - 1) / (n - 1)), round(y * (nh - 1) / (n - 1))) in old)
    thickness = cloth.thickness * (nw - 1) / (n - 1)
    return scene.with_cloth(num_width_points=n, num_height_points=n, pinned=pins, thickness=thickness)


def twist_scene(n: int = 50) -> Scene:
    """The twist's scene: a 1 m x 1 m vertical cloth, its top and bottom rows pinned, no floor and
    no gravity (the cloth wrings into a rope about the axis instead of sagging onto one side)."""
    base = load_scene("selfCollision")
    cloth = base.cloth
    pins = tuple((x, y) for y in (0, n - 1) for x in range(n))
    scene = base.with_cloth(num_width_points=n, num_height_points=n, pinned=pins,
                            thickness=cloth.thickness * (cloth.num_width_points - 1) / (n - 1))
    from dataclasses import replace

    return replace(scene, planes=(), path="<twist>").with_simulation(gravity=(0.0, 0.0, 0.0))


def _keyframes(start: list[float], end: list[float], t0: float = 0.15, t1: float = 1.1) -> dict:
    # a motion held at ``start`` until t0, then in a straight line to ``end`` at t1
    return {"keyframes": [[0.0, start], [t0, start], [t1, end]]}


def driven_scene(name: str, n: int = 50) -> Scene:
    """The driven run ``name`` as a scene (see :func:`driven_scene_data`)."""
    from ..scene import scene_from_dict

    return scene_from_dict(driven_scene_data(name, n), f"<{name}>")


def driven_scene_data(name: str, n: int = 50) -> dict:
    """The driven run ``name`` (one of ``DRIVEN_SCENES`` or ``SQUEEZE_SCENES``) on an ``n`` x ``n``
    grid: the course's 1 m cloth, 5 cm over a floor, its thickness in proportion to the point
    spacing (0.0095 at 50 x 50), as a scene file's JSON object."""
    from ..resources import data_dir

    runs = DRIVEN_SCENES + SQUEEZE_SCENES
    if name not in runs:
        raise ValueError(f"unknown driven run {name!r} (expected one of: {', '.join(runs)})")
    cloth = {"width": 1.0, "height": 1.0, "num_width_points": n, "num_height_points": n,
             "thickness": 0.0095 * 49 / (n - 1), "orientation": "horizontal", "damping": 0.2, "density": 150.0,
             "ks": 5000.0}
    floor = {"point": [0.5, FLOOR, 0.5], "normal": [0.0, 1.0, 0.0], "friction": 0.5}
    y = FLOOR
    data: dict = {"cloth": cloth, "plane": floor}
    # the box reaches into the floor: a point it meets is pushed out of its front, never under it
    heap = {"center": [-0.08, y + 0.02, 0.5], "half_extents": [0.05, 0.1, 0.7], "friction": 0.3,
            "motion": _keyframes([-0.08, y + 0.02, 0.5], [0.55, y + 0.02, 0.5], t1=0.8)}
    if name in ("lid", "squeeze"):
        gap = 0.03 if name == "lid" else SQUEEZE_GAP
        data["box"] = heap
        data["plane"] = [floor, {"point": [0.5, y + 0.4, 0.5], "normal": [0.0, -1.0, 0.0], "friction": 0.5,
                                 "motion": _keyframes([0.5, y + 0.4, 0.5], [0.5, y + gap, 0.5], 0.8, 1.2)}]
    elif name == "press":
        data["box"] = heap
        data["sphere"] = {"origin": [0.72, y + 0.6, 0.5], "radius": 0.25, "friction": 0.5,
                          "motion": _keyframes([0.72, y + 0.6, 0.5], [0.72, y + 0.28, 0.5], 0.8, 1.2)}
    elif name == "roller":
        data["box"] = heap
        data["capsule"] = {"a": [0.7, y + 0.5, -0.2], "b": [0.7, y + 0.5, 1.2], "radius": 0.08, "friction": 0.3,
                           "motion": _keyframes([0.7, y + 0.5, 0.5], [0.7, y + 0.11, 0.5], 0.8, 1.2)}
    elif name == "stamp":
        data["box"] = heap
        data["mesh"] = {"path": str(data_dir("scenes") / "torus.obj"), "scale": 0.8,
                        "translate": [0.95, y + 0.5, 0.5], "friction": 0.3,
                        "motion": _keyframes([0.95, y + 0.5, 0.5], [0.95, y + 0.105, 0.5], 0.8, 1.2)}
    else:  # drag
        cloth["pinned"] = [[0, 0], [n - 1, 0]]
        cloth["pin_motion"] = {"keyframes": [[0.0, [0.0, 0.0, 0.0]], [0.15, [0.0, 0.0, 0.0]],
                                             [0.9, [0.0, 0.0, 0.85]], [1.2, [0.0, 0.25, 0.85]]]}
    return data


def twist_pose(rest: np.ndarray, top: np.ndarray, t: float, seconds: float = TWIST_SECONDS) -> np.ndarray:
    """The pinned points at time ``t``: ``rest`` (P, 3) turned about the vertical line x = 0.5,
    z = 0, the top ones (``top``, a mask) one way and the others the other way, TWIST_TURNS turns
    each in ``seconds`` from TWIST_START, each edge moved towards the middle by up to
    TWIST_APPROACH."""
    s = _smoothstep((t - TWIST_START) / seconds)
    # the edges come together over the first half of the turn: the cloth has slack to wring into
    a = _smoothstep(2.0 * (t - TWIST_START) / seconds)
    angle = np.where(top, 1.0, -1.0) * 2.0 * math.pi * TWIST_TURNS * s
    x, z = rest[:, 0] - 0.5, rest[:, 2]
    out = np.empty_like(rest)
    out[:, 0] = 0.5 + x * np.cos(angle) - z * np.sin(angle)
    out[:, 2] = x * np.sin(angle) + z * np.cos(angle)
    out[:, 1] = rest[:, 1] + np.where(top, -1.0, 1.0) * TWIST_APPROACH * a
    return out


def _smoothstep(x: float) -> float:
    """0 before 0, 1 after 1, and between them a cubic that starts and stops with zero slope."""
    x = min(max(x, 0.0), 1.0)
    return x * x * (3.0 - 2.0 * x)


class StressRun:
    """One run of the stress set in one self-collision mode: :meth:`frame` advances one frame,
    :attr:`sim` is the :class:`~clothsim.Simulation` (its positions, its ``crossings()``).
    ``twist_seconds`` is how long the twist's edges take to turn (shorter runs for tests)."""

    def __init__(self, name: str, mode: str, n: int = 50, *, twist_seconds: float = TWIST_SECONDS) -> None:
        from ..sim import Simulation

        if name not in STRESS_SCENES:
            raise ValueError(f"unknown stress scene {name!r} (expected one of: {', '.join(STRESS_SCENES)})")
        self.name = name
        self.mode = mode
        if name == "twist":
            scene = twist_scene(n)
        elif name in DRIVEN_SCENES + SQUEEZE_SCENES:
            scene = driven_scene(name, n)
        else:
            scene = resized(load_scene(name), n)
        self.steps = scene.simulation.simulation_steps
        self._substep: Callable[[], None] | None = None
        if name == "twist":
            # one substep per call, of the same length as the scene's own
            fps = scene.simulation.frames_per_sec * self.steps
            scene = scene.with_simulation(simulation_steps=1, frames_per_sec=fps)
        self.sim = Simulation(scene.with_simulation(self_collision=mode))
        if name == "twist":
            pins = np.flatnonzero(self.sim.pinned)
            rest = self.sim.positions[pins].copy()
            top = rest[:, 1] > 0.5
            dt = self.sim.dt
            # the blow-up guard allows the kinetic energy of what drives the cloth: here the edges,
            # at most 1.5x their mean speed (the smoothstep's steepest)
            radius = float(np.max(np.hypot(rest[:, 0] - 0.5, rest[:, 2])))
            self.sim.collider_top_speed += 1.5 * (2.0 * math.pi * TWIST_TURNS * radius
                                                  + 2.0 * TWIST_APPROACH) / twist_seconds

            def substep() -> None:
                t = self.sim.time
                self.sim.last_positions[pins] = twist_pose(rest, top, t - dt, twist_seconds)
                self.sim.positions[pins] = twist_pose(rest, top, t, twist_seconds)
                self.sim.step(1)

            self._substep = substep

    @property
    def through_the_api(self) -> bool:
        """Whether the run is driven one substep at a time through the API (the twist), not by
        whole frames of its scene."""
        return self._substep is not None

    @property
    def frames(self) -> int:
        """Frames advanced so far."""
        return self.sim.frame // self.steps if self._substep is not None else self.sim.frame

    def frame(self) -> None:
        """Advance one frame (``simulation_steps`` substeps of the scene)."""
        if self._substep is None:
            self.sim.step(1)
            return
        for _ in range(self.steps):
            self._substep()

    def crossings(self) -> int:
        """The cloth's edge-triangle crossings now."""
        return self.sim.crossings()
