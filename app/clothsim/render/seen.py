"""The triangles a frame can show, found by an id pass, for the looks that move their vertices.

llvmpipe's multisampled path runs the fragment stage for every fragment it rasterises, hidden or
not (its early depth test masks the shader's lanes, it does not skip them), and the displaced
looks (``displacement``, ``custom``) puff a draped cloth's folds out into one another: about three
quarters of their triangles are hidden, and all of them were shaded. So on such a driver a frame
of those looks is first drawn cheaply: without multisampling, with the look's own vertex stage and
a fragment stage that writes each triangle's number (``glsl/ids.frag``), into a framebuffer of
the image's size. The numbers left there are the triangles that win the depth test at some pixel
centre, and the frame is drawn from those alone (docs/performance-rendering.md, "Displaced looks").

The image changes a little, on purpose: the multisampled image looks at four points of a pixel and
the id pass at its centre, so a triangle that wins only at some of those points and at no centre
is not drawn, and what lies behind it shows there instead: single pixels where folds and the
sphere's spikes meet, 0.02-0.03 % of an 800 x 800 frame of the bundled scenes with colliders and
0.05-0.1 % at 512 x 512. The smaller the triangles are on screen, the more of them fall between
pixel centres (5 % of a 96 x 96 frame), so an image with fewer than ``PIXELS_PER_TRIANGLE`` pixels
for each triangle drawn is drawn whole. The same state, look and size give the same image. A
driver that skips hidden fragments itself (a GPU) draws every triangle, as every look does
without multisampling.
"""

from __future__ import annotations

from typing import Any

import numpy as np
from numba import njit, types

from ..jit import BORROWED
from ..jit.compile import on_warm

#: Triangle numbers fit in the id pass's three bytes (0 is no triangle); a frame with more
#: triangles is drawn whole.
MOST_IDS = (1 << 24) - 1
#: Pixels an image needs for each triangle drawn for the id pass to be used: at 32 (an 800 x 800
#: frame of the sphere scene has 80, a 512 x 512 one 33) 0.2 % of the pixels change at most.
PIXELS_PER_TRIANGLE = 32


def worth_it(pixels: int, triangles: int) -> bool:
    """Whether an image of ``pixels`` drawing ``triangles`` is drawn from the id pass's triangles."""
    return 0 < triangles <= MOST_IDS and pixels >= PIXELS_PER_TRIANGLE * triangles


@njit(**BORROWED)
def mark_found(ids: np.ndarray, found: np.ndarray) -> None:
    """``found[i]`` set for every number ``i`` in ``ids`` (the id pass's pixels; a scatter that
    NumPy's ``bincount`` does six times slower)."""
    for k in range(ids.shape[0]):
        found[ids[k]] = True


def _warm() -> None:
    mark_found(np.zeros(4, dtype=np.uint32), np.zeros(1, dtype=np.bool_))


_SIGNATURE = (types.Array(types.uint32, 1, "C"), types.Array(types.bool_, 1, "C"))


def register_warm() -> None:
    """Have :func:`~clothsim.jit.compile.warm_side_kernels` compile (or load) the id pass's
    kernel; done for the looks that use it only (:meth:`Renderer.prepare
    <clothsim.render.renderer.Renderer.prepare>`)."""
    on_warm("3 render seen", _warm, beside=((mark_found, _SIGNATURE),))


class Seen:
    """One renderer's id pass: its framebuffer, each draw call's first number and triangle count
    in the order drawn, which triangles the pass found, and the index buffers of the kept ones."""

    def __init__(self, ctx: Any, width: int, height: int) -> None:
        self.ctx = ctx
        self.pixels = width * height
        self._color = ctx.renderbuffer((width, height), 4)
        self._depth = ctx.depth_renderbuffer((width, height))
        self.fbo = ctx.framebuffer(self._color, self._depth)
        self._ids = np.empty((height, width), dtype=np.uint32)
        self._calls: list[tuple[int, int]] = []  # (first number, triangles) per draw call
        self._numbered = 0  # triangles numbered so far this frame
        self._next = 0  # the next draw call of the kept pass
        self._found = np.zeros(1, dtype=bool)
        self._kept: dict[Any, tuple[Any, int]] = {}  # (geometry, key) -> (index buffer, its triangles)
        #: The last frame's triangles, and how many of them were drawn.
        self.triangles = 0
        self.drawn = 0

    def begin(self) -> None:
        """Start a frame's id pass: its framebuffer bound and cleared (no triangle anywhere)."""
        self.fbo.use()
        self.ctx.clear(0.0, 0.0, 0.0, 0.0, depth=1.0)
        self._calls.clear()
        self._numbered = 0
        self.triangles = self.drawn = 0

    def number(self, prog: Any, triangles: int) -> None:
        """Number the next draw call's ``triangles`` (set ``u_first`` of the id program ``prog``)."""
        first = 1 + self._numbered
        self._calls.append((first, triangles))
        self._numbered += triangles
        if "u_first" in prog:
            prog["u_first"].value = first

    def read(self, gl: Any) -> bool:
        """Read the pass back and note which triangles it found; False when the frame is to be
        drawn whole after all (too many triangles for its size: :func:`worth_it`)."""
        total = self.triangles = self._numbered
        if not worth_it(self.pixels, total):
            self.drawn = total  # every one, drawn whole
            return False
        if gl is not None:
            gl.read_rgba(self.fbo, self._ids)
        else:
            self.fbo.read_into(self._ids, components=4, alignment=4)
        # the alpha byte is always 0: a pixel's uint32 is its number
        self._found = np.zeros(total + 1, dtype=np.bool_)
        mark_found(self._ids.reshape(-1), self._found)
        self._next = 0
        self.drawn = 0  # counted by kept()
        return True

    def kept(self, place: Any, indices: np.ndarray) -> tuple[Any, int, bool]:
        """The next draw call's triangles that the pass found: an index buffer holding them first,
        their count, and whether the buffer is new (``place`` names the geometry, whose full
        ``indices`` (3T,) uint32 the call draws)."""
        first, triangles = self._calls[self._next]
        self._next += 1
        found = self._found[first:first + triangles]
        chosen = np.ascontiguousarray(indices.reshape(-1, 3)[found])
        buffer, room = self._kept.get(place, (None, 0))
        fresh = buffer is None or room < triangles
        if fresh:
            if buffer is not None:
                buffer.release()
            buffer = self.ctx.buffer(reserve=max(indices.nbytes, 12), dynamic=True)
            self._kept[place] = (buffer, triangles)
        if chosen.size:
            buffer.write(chosen)
        self.drawn += int(chosen.shape[0])
        return buffer, int(chosen.shape[0]), fresh

    def release(self) -> None:
        for buffer, _ in self._kept.values():
            buffer.release()
        self._kept.clear()
        for obj in (self.fbo, self._color, self._depth):
            obj.release()
