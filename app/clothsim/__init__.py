"""clothsim: a mass-spring cloth simulator (NumPy + Numba) with a headless ModernGL renderer."""

from __future__ import annotations

from typing import Any

from .errors import ClothsimError, SceneError
from .scene import Scene, load_scene

from .version import __version__

__all__ = ["ClothsimError", "Renderer", "Scene", "SceneError", "Simulation", "count_crossings", "export", "load_scene",
           "sweep", "__version__"]


def __getattr__(name: str) -> Any:
    # The simulator pulls in Numba (a third of a second), the renderer moderngl/EGL: load each
    # only when asked for, so commands that do neither (a sweep's parent, --help) start at once.
    if name == "Simulation":
        from .sim import Simulation

        return Simulation
    if name == "Renderer":
        from .render.renderer import Renderer

        return Renderer
    if name == "count_crossings":  # edge-triangle crossings of a cloth's positions (Numba)
        from .sim.crossings import count_crossings

        return count_crossings
    if name == "export":  # the function; its package is clothsim.exporters
        from .exporters.api import export

        return export
    if name == "sweep":  # the function; its package is clothsim.sweeps
        from .sweeps.api import sweep

        return sweep
    raise AttributeError(name)
