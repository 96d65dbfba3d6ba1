"""The forces a scene may name beyond the springs and gravity, in one registry (:data:`FORCES`):
the scene language's side of each (the simulator's is :mod:`clothsim.sim.passes.forces`).

Each :class:`ForceKind` names its scene-file key, the :class:`~clothsim.scene.Scene` field that
holds its specs, the rule that validates the scene's value, how a spec is written back as scene
JSON, the memory its pass adds per point, the fastest air (or other driver) it may bring to the
cloth, and its pass module in :mod:`clothsim.sim.passes`. The scene loader, the memory check,
the blow-up guard, serve's frame-cost model, the sweeps' scene writer and ``clothsim bench
speed`` iterate :data:`FORCES` rather than naming a force.
"""

from __future__ import annotations

from typing import Any, Callable, NamedTuple

from .wind import WINDS, WIND_BYTES_PER_POINT, wind_speed


class ForceKind(NamedTuple):
    """One force a scene may name (see the module's notes)."""

    key: str
    attr: str
    rule: Callable[[Any, Any], tuple]
    to_json: Callable[[Any], Any]
    #: bytes per cloth point its pass adds, given the scene's specs (0 when it makes no pass)
    bytes_per_point: Callable[[tuple], int]
    #: bound (m/s) on the speed of what it brings to the cloth, given the scene's specs
    top_speed: Callable[[tuple], float]
    #: its pass module in clothsim.sim.passes
    pass_module: str


#: Every force kind, in the order the scene lists them and their passes add to a point.
FORCES: tuple[ForceKind, ...] = (
    ForceKind("wind", "winds", WINDS, lambda w: w.as_json(),
              lambda ws: WIND_BYTES_PER_POINT if any(not w.still for w in ws) else 0, wind_speed, "wind"),
)


def scene_forces(scene: Any) -> tuple:
    """Every force spec of ``scene``, kind by kind in :data:`FORCES` order."""
    return tuple(spec for kind in FORCES for spec in getattr(scene, kind.attr))
