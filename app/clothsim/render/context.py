"""The headless OpenGL context (EGL), with a one-line error when EGL cannot be loaded."""

from __future__ import annotations

from typing import Any

from ..errors import ClothsimError

EGL_HINT = (
    "cannot create a headless OpenGL context through EGL ({reason}); install the EGL and Mesa "
    "drivers, e.g. on Debian/Ubuntu: apt-get install libegl1 libegl-mesa0 libgl1-mesa-dri"
)

# GL 3.3 core is everything the shaders need; asking for more would shut out older drivers.
REQUIRED_GL = 330


def create_context() -> Any:
    """Create a standalone moderngl context on EGL, or raise :class:`ClothsimError`."""
    try:
        import moderngl
    except ImportError as exc:  # pragma: no cover - moderngl is a hard dependency
        raise ClothsimError(EGL_HINT.format(reason=f"moderngl is not importable: {exc}")) from None
    try:
        ctx = moderngl.create_standalone_context(backend="egl", require=REQUIRED_GL)
    except Exception as exc:  # glcontext raises plain Exception for a missing libEGL
        reason = " ".join(str(exc).split()) or type(exc).__name__
        raise ClothsimError(EGL_HINT.format(reason=reason)) from None
    return ctx


def describe(ctx: Any) -> dict[str, str]:
    """Vendor, renderer and version strings of a context."""
    info = ctx.info
    return {
        "vendor": str(info.get("GL_VENDOR", "?")),
        "renderer": str(info.get("GL_RENDERER", "?")),
        "version": str(info.get("GL_VERSION", "?")),
        "version_code": str(ctx.version_code),
    }
