"""How much work one client may ask of the server: a frame must stay under about a second.

The server has one simulation, advanced by one thread between the commands of every page, so a
frame that takes a minute stalls everyone and keeps Ctrl-C waiting. A scene (uploaded or
bundled) and every change of ``simulation_steps`` are therefore checked against an estimate of
the frame's cost before anything is allocated, and refused with the bound in the message.

The estimate is points x substeps x a cost per point and substep for the scene's integrator,
self-collision mode and colliders. The costs are the slowest measured on the 2-core development
machine with other work running beside it (docs/serve.md), rounded up; a frame that still runs
long (a heap of folds costs more than a flat sheet) is caught by the engine's own clock, which
pauses the simulation after one slow frame.
"""

from __future__ import annotations

import math

from ..errors import ClothsimError
from ..forces import scene_forces
from ..scene import Scene

__all__ = ["FRAME_BUDGET_S", "MAX_POINTS", "check_scene", "check_substeps", "frame_seconds"]

#: What one frame's simulation may cost (seconds, estimated).
FRAME_BUDGET_S = 1.0
#: Largest cloth the server simulates (points): a 256 x 256 grid.
MAX_POINTS = 256 * 256

# Seconds per point and substep (measured medians, rounded up, contended machine).
_INTEGRATOR_S = {"verlet": 30e-9, "symplectic_euler": 30e-9, "implicit_euler": 700e-9, "xpbd": 700e-9}
_SELF_COLLISION_S = {"off": 0.0, "spec": 120e-9, "grid": 500e-9, "contact": 2000e-9}
_PER_MESH_S = 120e-9
_PER_OTHER_S = 10e-9  # each sphere, plane, capsule, box or force (wind)


def _point_substep_s(scene: Scene) -> float:
    sim = scene.simulation
    others = len(scene.colliders) - len(scene.meshes) + len(scene_forces(scene))
    return (_INTEGRATOR_S.get(sim.integrator, max(_INTEGRATOR_S.values()))
            + _SELF_COLLISION_S.get(sim.self_collision, max(_SELF_COLLISION_S.values()))
            + _PER_MESH_S * len(scene.meshes) + _PER_OTHER_S * others)


def frame_seconds(scene: Scene, substeps: int | None = None) -> float:
    """Estimated seconds of simulation per frame of ``scene`` (at ``substeps``, else its own)."""
    steps = scene.simulation.simulation_steps if substeps is None else substeps
    return scene.cloth.num_points * steps * _point_substep_s(scene)


def _max_substeps(scene: Scene) -> int:
    return max(0, math.floor(FRAME_BUDGET_S / (scene.cloth.num_points * _point_substep_s(scene))))


def check_scene(scene: Scene, label: str) -> None:
    """Refuse a scene too big or too slow to serve: one line naming ``label``, the field and the bound."""
    cloth = scene.cloth
    if cloth.num_points > MAX_POINTS:
        shape = ("the mesh" if cloth.is_mesh else f"a {cloth.num_width_points}x{cloth.num_height_points} grid")
        raise ClothsimError(f"{label}: cloth: {shape} has {cloth.num_points} points; clothsim serve simulates "
                            f"at most {MAX_POINTS} (e.g. 256x256)")
    check_substeps(scene, scene.simulation.simulation_steps, f"{label}: simulation.simulation_steps")


def check_substeps(scene: Scene, substeps: int, field: str = "simulation_steps") -> None:
    """Refuse ``substeps`` per frame when a frame of ``scene`` would take over the budget."""
    seconds = frame_seconds(scene, substeps)
    if seconds > FRAME_BUDGET_S:
        raise ClothsimError(
            f"{field}: {substeps} substeps a frame would take about {seconds:.3g} s a frame for this scene "
            f"({scene.cloth.num_points} points, {scene.simulation.integrator}, self-collision "
            f"{scene.simulation.self_collision}); clothsim serve keeps a frame under {FRAME_BUDGET_S:g} s: "
            f"at most {_max_substeps(scene)} substeps here")
