"""The two GL calls a frame waits in (glFinish, glReadPixels), called without holding the GIL.

moderngl keeps the GIL through every call, and on a software driver (llvmpipe) a frame's
rasterisation happens inside the call that first needs its pixels: the resolve and the read-back.
Calling those waits through ctypes, which releases the GIL around a foreign call, lets another
Python thread (the simulation of the next frames, which holds the GIL through its Numba kernels)
run while the driver's threads draw. The calls are the same GL entry points moderngl uses, so
the pixels are the same bytes.

Where the entry points cannot be found (no libEGL for ctypes, an EGL without
``eglGetProcAddress``), :func:`gl_calls` returns None and the renderer uses moderngl's calls.
"""

from __future__ import annotations

import ctypes
import ctypes.util
from dataclasses import dataclass
from typing import Any

import numpy as np

GL_PACK_ALIGNMENT = 0x0D05
GL_RGB = 0x1907
GL_RGBA = 0x1908
GL_UNSIGNED_BYTE = 0x1401
GL_PIXEL_PACK_BUFFER = 0x88EB


@dataclass(frozen=True)
class GLCalls:
    """ctypes entry points of the current EGL context's GL (dispatched per thread, like moderngl's)."""

    finish: Any
    read_pixels: Any
    pixel_store: Any
    bind_buffer: Any

    def read_rgb(self, fbo: Any, image: np.ndarray) -> None:
        """Read ``fbo``'s colour into ``image`` ((H, W, 3) uint8, C-contiguous), as moderngl's
        ``read_into(image, components=3, alignment=1)`` does."""
        self._read(fbo, image, GL_RGB, 1)

    def read_rgba(self, fbo: Any, image: np.ndarray) -> None:
        """Read ``fbo``'s colour into ``image`` ((H, W) uint32, C-contiguous): each pixel's four
        bytes, red first in memory."""
        self._read(fbo, image, GL_RGBA, 4)

    def _read(self, fbo: Any, image: np.ndarray, layout: int, alignment: int) -> None:
        height, width = image.shape[:2]
        fbo.use()  # binds it for reading (and drawing) through moderngl, which tracks the binding
        self.bind_buffer(GL_PIXEL_PACK_BUFFER, 0)
        self.pixel_store(GL_PACK_ALIGNMENT, alignment)
        self.read_pixels(0, 0, width, height, layout, GL_UNSIGNED_BYTE, image.ctypes.data)


_CACHE: list[GLCalls | None] = []


def gl_calls() -> GLCalls | None:
    """The entry points, looked up once per process; None where ctypes cannot reach them."""
    if not _CACHE:
        _CACHE.append(_lookup())
    return _CACHE[0]


def _lookup() -> GLCalls | None:
    egl = None
    for name in ("libEGL.so.1", ctypes.util.find_library("EGL")):
        try:
            egl = ctypes.CDLL(name) if name else None
        except OSError:
            continue
        if egl is not None:
            break
    proc = getattr(egl, "eglGetProcAddress", None)
    if proc is None:
        return None
    proc.restype = ctypes.c_void_p
    proc.argtypes = [ctypes.c_char_p]
    c_int, c_uint = ctypes.c_int, ctypes.c_uint
    signatures = {
        "glFinish": ctypes.CFUNCTYPE(None),
        "glReadPixels": ctypes.CFUNCTYPE(None, c_int, c_int, c_int, c_int, c_uint, c_uint, ctypes.c_void_p),
        "glPixelStorei": ctypes.CFUNCTYPE(None, c_uint, c_int),
        "glBindBuffer": ctypes.CFUNCTYPE(None, c_uint, c_uint),
    }
    found = {}
    for fn, proto in signatures.items():
        address = proc(fn.encode())
        if not address:
            return None
        found[fn] = proto(address)
    return GLCalls(finish=found["glFinish"], read_pixels=found["glReadPixels"],
                   pixel_store=found["glPixelStorei"], bind_buffer=found["glBindBuffer"])
