"""clothsim: a mass-spring cloth simulator (NumPy + Numba) with a headless ModernGL renderer."""

from __future__ import annotations

from typing import Any

from .errors import ClothsimError, SceneError
from .scene import Scene, load_scene
from .sim import Simulation

__version__ = "0.1.0"
__all__ = ["ClothsimError", "Renderer", "Scene", "SceneError", "Simulation", "export", "load_scene", "sweep", "__version__"]


def __getattr__(name: str) -> Any:
    # The renderer pulls in moderngl/EGL; load it only when asked for.
    if name == "Renderer":
        from .render.renderer import Renderer

        return Renderer
    if name == "export":  # the function; its package is clothsim.exporters
        from .exporters.api import export

        return export
    if name == "sweep":  # the function; its package is clothsim.sweeps
        from .sweeps.api import sweep

        return sweep
    raise AttributeError(name)
