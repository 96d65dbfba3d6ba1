"""Headless rendering: EGL context, cloth/sphere/plane meshes, camera, GLSL looks, renderer.

Importing this package does not load libEGL; the first :class:`Renderer` does.
"""

from __future__ import annotations

from typing import TYPE_CHECKING, Any

from .settings import SHADERS, RenderSettings

if TYPE_CHECKING:
    from .renderer import Renderer

__all__ = ["Renderer", "RenderSettings", "SHADERS"]


def __getattr__(name: str) -> Any:
    # The renderer pulls in moderngl; keep that out of `import clothsim.render`.
    if name == "Renderer":
        from .renderer import Renderer

        return Renderer
    raise AttributeError(name)
