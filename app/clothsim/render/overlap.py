"""Whether the cloth's image covers any sample twice; where it cannot, the depth test decides nothing.

A frame that draws the cloth alone (no collider) needs its depth test only where the cloth lies
over itself on screen. If every triangle of the grid keeps one winding on screen and the grid's
border projects to a simple closed curve, it does not anywhere: each point of the screen is
covered as many times as the border winds around it (the degree of the map, every triangle
counting +1), and a simple curve winds at most once around any point. Triangles that share an
edge or a corner then meet only there, where the rasteriser's fill rule gives each sample to one
of them, so every sample is drawn by at most one triangle and the depth test would pass every
fragment it is given: the image is the same bytes without it. On llvmpipe with multisampling the
test runs per sample and its buffer is cleared every frame (what that costs: docs/performance-rendering.md,
"Frames drawn without the depth test").

The test is made on the positions the renderer uploads (float32), projected in float64, with a
margin of :data:`SLACK` pixels per coordinate for the driver's float32 transform and its snapping
of vertices to 1/256 of a pixel: a triangle must keep its winding, and two border segments their
distance, whichever way each corner moves within the margin. Anything closer, or a corner near
or behind the camera's near plane or far outside the image, answers no and the frame is drawn
with the depth test as before.
"""

from __future__ import annotations

import math

import numpy as np
from numba import njit, types

from ..jit import EXACT
from ..jit.compile import on_warm

#: How far (pixels, each screen coordinate) the driver may put a corner from where it is
#: computed here: its snapping is 1/512 and float32's transform about 1e-4 at these sizes.
SLACK = 1.0 / 64.0
#: A corner further than this many image sizes outside the image answers no: far outside it the
#: driver clips triangles, making corners of its own.
REACH = 4.0


@njit(**EXACT)
def _apart(ax, ay, bx, by, cx, cy, dx, dy):  # pragma: no cover - compiled
    """Distance between the segments ab and cd (0 where they cross); a segment may be a point."""
    o1 = (bx - ax) * (cy - ay) - (by - ay) * (cx - ax)
    o2 = (bx - ax) * (dy - ay) - (by - ay) * (dx - ax)
    o3 = (dx - cx) * (ay - cy) - (dy - cy) * (ax - cx)
    o4 = (dx - cx) * (by - cy) - (dy - cy) * (bx - cx)
    if o1 * o2 < 0.0 and o3 * o4 < 0.0:
        return 0.0
    nearest = math.inf
    for k in range(4):  # each end against the other segment
        if k == 0:
            px, py, sx, sy, ex, ey = cx, cy, ax, ay, bx, by
        elif k == 1:
            px, py, sx, sy, ex, ey = dx, dy, ax, ay, bx, by
        elif k == 2:
            px, py, sx, sy, ex, ey = ax, ay, cx, cy, dx, dy
        else:
            px, py, sx, sy, ex, ey = bx, by, cx, cy, dx, dy
        ux, uy = ex - sx, ey - sy
        length2 = ux * ux + uy * uy
        t = 0.0
        if length2 > 0.0:
            t = min(max(((px - sx) * ux + (py - sy) * uy) / length2, 0.0), 1.0)
        qx, qy = px - (sx + t * ux), py - (sy + t * uy)
        nearest = min(nearest, math.sqrt(qx * qx + qy * qy))
    return nearest


@njit(**EXACT)
def covers_once(vertices, nw, nh, view_projection, width, height):  # pragma: no cover - compiled
    """True if the nw x nh grid whose positions are ``vertices[:, :3]`` (float32, the renderer's
    vertex stream), seen through ``view_projection`` (4 x 4, row-major, the one the vertex stage
    gets) in a ``width`` x ``height`` image, covers no sample twice (see the module docstring)."""
    if nw < 2 or nh < 2:
        return False
    m = view_projection
    sx = np.empty(vertices.shape[0])
    sy = np.empty(vertices.shape[0])
    for i in range(vertices.shape[0]):  # window coordinates; near, far and reach checked
        x, y, z = float(vertices[i, 0]), float(vertices[i, 1]), float(vertices[i, 2])
        cx = m[0, 0] * x + m[0, 1] * y + m[0, 2] * z + m[0, 3]
        cy = m[1, 0] * x + m[1, 1] * y + m[1, 2] * z + m[1, 3]
        cz = m[2, 0] * x + m[2, 1] * y + m[2, 2] * z + m[2, 3]
        cw = m[3, 0] * x + m[3, 1] * y + m[3, 2] * z + m[3, 3]
        inner = cw * (1.0 - 1e-5)
        if not (cw > 0.0 and -inner < cz < inner):
            return False
        sx[i] = (cx / cw + 1.0) * 0.5 * width
        sy[i] = (cy / cw + 1.0) * 0.5 * height
        if not (-REACH * width < sx[i] < (1.0 + REACH) * width and -REACH * height < sy[i] < (1.0 + REACH) * height):
            return False
    d = SLACK
    sign = 0.0
    for y in range(nh - 1):  # every triangle (the renderer's two a quad) keeps one winding
        for x in range(nw - 1):
            a = y * nw + x
            for half in range(2):
                p, q, r = (a, a + nw, a + 1) if half == 0 else (a + 1, a + nw, a + nw + 1)
                ux, uy = sx[q] - sx[p], sy[q] - sy[p]
                vx, vy = sx[r] - sx[p], sy[r] - sy[p]
                area2 = ux * vy - uy * vx
                # each of u's and v's coordinates can move by 2d
                room = 2.0 * d * (abs(ux) + abs(uy) + abs(vx) + abs(vy)) + 8.0 * d * d
                if not abs(area2) > room:
                    return False
                if sign == 0.0:
                    sign = area2
                elif (area2 > 0.0) != (sign > 0.0):
                    return False
    # The border, a closed polygon, must be simple with room to spare: segments that share no
    # corner more than 2 x SLACK x sqrt 2 apart, neighbours' far corners as far from each other.
    n = 2 * (nw - 1) + 2 * (nh - 1)
    ring = np.empty(n + 2, dtype=np.int64)
    for k in range(n + 2):
        j = k % n
        if j < nw - 1:
            ring[k] = j
        elif j < nw - 1 + nh - 1:
            ring[k] = (j - (nw - 1)) * nw + nw - 1
        elif j < 2 * (nw - 1) + nh - 1:
            ring[k] = (nh - 1) * nw + (nw - 1) - (j - (nw - 1 + nh - 1))
        else:
            ring[k] = (nh - 1 - (j - (2 * (nw - 1) + nh - 1))) * nw
    gap = 2.0 * math.sqrt(2.0) * SLACK
    for s in range(n):
        a, b, c = ring[s], ring[s + 1], ring[s + 2]
        if not (_apart(sx[a], sy[a], sx[a], sy[a], sx[b], sy[b], sx[c], sy[c]) > gap
                and _apart(sx[c], sy[c], sx[c], sy[c], sx[a], sy[a], sx[b], sy[b]) > gap):
            return False
        for t in range(s + 2, n - 1 if s == 0 else n):
            c, e = ring[t], ring[t + 1]
            if (min(sx[c], sx[e]) > max(sx[a], sx[b]) + gap or min(sx[a], sx[b]) > max(sx[c], sx[e]) + gap
                    or min(sy[c], sy[e]) > max(sy[a], sy[b]) + gap or min(sy[a], sy[b]) > max(sy[c], sy[e]) + gap):
                continue
            if not _apart(sx[a], sy[a], sx[b], sy[b], sx[c], sy[c], sx[e], sy[e]) > gap:
                return False
    return True


def _warm() -> None:
    covers_once(np.zeros((4, 9), dtype=np.float32), 2, 2, np.eye(4), 8, 8)


# The renderer's call: its vertex stream, the grid's size, the matrix, the image's size.
_SIGNATURE = (types.Array(types.float32, 2, "C"), types.int64, types.int64, types.Array(types.float64, 2, "C"),
              types.int64, types.int64)


def register_warm() -> None:
    """Have :func:`~clothsim.jit.compile.warm_side_kernels` compile (or load) the test, which a
    cold start compiles beside the simulation's first plan; done for the scenes that use it only
    (:meth:`Renderer.prepare <clothsim.render.renderer.Renderer.prepare>`)."""
    on_warm("3 render overlap", _warm, beside=((covers_once, _SIGNATURE),))
