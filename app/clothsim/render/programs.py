"""GLSL sources (glsl/*.vert, *.frag) -> compiled programs, one per look, compiled on first use."""

from __future__ import annotations

import re
from pathlib import Path
from typing import Any

from ..errors import ClothsimError
from ..resources import data_dir

# look -> (vertex shader, fragment shader). Displacement and custom move vertices, so they
# need their own vertex stage; the rest share one.
LOOKS: dict[str, tuple[str, str]] = {
    "wireframe": ("wireframe.vert", "wireframe.frag"),
    "normal": ("mesh.vert", "normal.frag"),
    "diffuse": ("mesh.vert", "diffuse.frag"),
    "phong": ("mesh.vert", "phong.frag"),
    "texture": ("mesh.vert", "texture.frag"),
    "bump": ("mesh.vert", "bump.frag"),
    "displacement": ("displacement.vert", "bump.frag"),
    "mirror": ("mesh.vert", "mirror.frag"),
    "custom": ("displacement.vert", "custom.frag"),
    # Not a look: a dataset's depth, flow, mask and normals, drawn into float targets (channels.py).
    "channels": ("channels.vert", "channels.frag"),
}

#: Suffix of a look's id-pass program in the cache (:meth:`Programs.ids`).
IDS = "/ids"

_INCLUDE = re.compile(r'^\s*#include\s+"([^"]+)"\s*$', re.MULTILINE)


def read_source(name: str, glsl_dir: Path | None = None) -> str:
    """A shader's text with ``#include "file"`` lines replaced by that file (one level)."""
    root = glsl_dir or data_dir("glsl")
    text = (root / name).read_text(encoding="utf-8")
    return _INCLUDE.sub(lambda m: (root / m.group(1)).read_text(encoding="utf-8"), text)


class Programs:
    """Compiles and caches one program per look on a context.

    ``sources`` can replace a look's (vertex, fragment) texts, which the tests use to check that
    a broken shader is caught.
    """

    def __init__(self, ctx: Any, sources: dict[str, tuple[str, str]] | None = None) -> None:
        self.ctx = ctx
        self._sources = dict(sources or {})
        self._cache: dict[str, Any] = {}
        self._as_given: dict[str, bool] = {}

    def get(self, look: str) -> Any:
        """The compiled program of ``look``."""
        prog = self._cache.get(look)
        if prog is None:
            prog = self._cache[look] = self._compile(look, *self._texts(look))
        return prog

    def ids(self, look: str) -> Any:
        """``look``'s vertex stage with the id pass's fragment stage (``ids.frag``, see seen.py)."""
        name = look + IDS
        prog = self._cache.get(name)
        if prog is None:
            prog = self._cache[name] = self._compile(name, self._texts(look)[0], read_source("ids.frag"))
        return prog

    def _texts(self, look: str) -> tuple[str, str]:
        """``look``'s (vertex, fragment) texts: the replaced ones if given, else the files'."""
        given = self._sources.get(look)
        return given if given else (read_source(LOOKS[look][0]), read_source(LOOKS[look][1]))

    def _compile(self, name: str, vert: str, frag: str) -> Any:
        try:
            return self.ctx.program(vertex_shader=vert, fragment_shader=frag)
        except Exception as exc:  # moderngl.Error carries the driver's compile log
            first = " ".join(str(exc).split())[:300]
            raise ClothsimError(f"shader '{name}' failed to compile: {first}") from None

    def places_as_given(self, look: str) -> bool:
        """True if ``look``'s vertex stage puts each vertex where the model and view-projection
        matrices say (the shared ``mesh.vert``, not replaced), so the CPU knows where it lands."""
        known = self._as_given.get(look)
        if known is None:
            vertex = LOOKS[look][0]
            replaced = self._sources.get(look)
            known = vertex == "mesh.vert" and (replaced is None or replaced[0] == read_source(vertex))
            self._as_given[look] = known
        return known

    def release(self) -> None:
        for prog in self._cache.values():
            prog.release()
        self._cache.clear()


def set_uniform(prog: Any, name: str, value: Any) -> None:
    """Set a uniform if the linked program kept it (unused uniforms are optimised away)."""
    if name in prog:
        u = prog[name]
        if isinstance(value, (bytes, bytearray, memoryview)):
            u.write(value)
        else:
            u.value = value


def set_matrix(prog: Any, name: str, m: Any) -> None:
    """Set a mat4 uniform from a row-major NumPy matrix (GL reads uniforms column by column)."""
    import numpy as np

    set_uniform(prog, name, np.ascontiguousarray(np.asarray(m).T, dtype=np.float32).tobytes())
