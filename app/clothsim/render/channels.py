"""A dataset's data channels: metric depth, optical flow, segmentation mask and world normals
of one view, drawn by one GLSL program (glsl/channels.*) in one pass into two float targets.

No multisampling: every pixel holds the value of the one surface point at its centre, never a
blend of the cloth and what lies behind it. The geometry is the RGB image's (colliders drawn as
the looks draw them: spheres and capsules at :data:`~.renderer.SPHERE_DRAW_SCALE` of their
radius, planes as a large quad).
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

import numpy as np

from ..colliders import scene_colliders
from ..scene import Scene
from .camera import FLIP_Y
from .programs import set_matrix, set_uniform
from .views import ViewCamera

__all__ = ["CHANNELS", "MASK_BACKGROUND", "MASK_CLOTH_FRONT", "MASK_CLOTH_BACK", "FIRST_COLLIDER_ID",
           "Channels", "collider_ids", "draw_channels"]

CHANNELS: tuple[str, ...] = ("rgb", "depth", "normal", "mask", "flow")
MASK_BACKGROUND, MASK_CLOTH_FRONT, MASK_CLOTH_BACK = 0, 1, 2
FIRST_COLLIDER_ID = 3


def collider_ids(scene: Scene) -> list[dict[str, Any]]:
    """The mask id of every collider: 3, 4, ... kind by kind in the registry's order (sphere,
    plane, capsule, box, mesh: :data:`clothsim.colliders.KINDS`, the renderer's drawing order),
    each kind in scene order. Entries: ``{"id", "kind", "index"}``."""
    out = [{"id": FIRST_COLLIDER_ID + n, "kind": kind.key, "index": index}
           for n, (kind, index, _) in enumerate(scene_colliders(scene))]
    if FIRST_COLLIDER_ID + len(out) > 255:
        from ..errors import ClothsimError

        raise ClothsimError(f"a mask holds at most {256 - FIRST_COLLIDER_ID} colliders, the scene has {len(out)}")
    return out


@dataclass
class Channels:
    """One view's channels at one frame. ``depth`` (H, W) float32 metres along the optical axis,
    0 on the background; ``flow`` (H, W, 2) float32 pixels (x right, y down) to the next sampled
    frame, on the cloth only; ``mask`` (H, W) uint8; ``normal`` (H, W, 3) float32 unit world
    normals of the side seen, 0 on the background."""

    depth: np.ndarray
    flow: np.ndarray
    mask: np.ndarray
    normal: np.ndarray


class _Targets:
    """The data pass's framebuffer: two RGBA float32 textures and a depth buffer."""

    def __init__(self, ctx: Any, width: int, height: int) -> None:
        self.size = (width, height)
        self.made: list[Any] = []
        try:
            self.made.append(ctx.texture(self.size, 4, dtype="f4"))
            self.made.append(ctx.texture(self.size, 4, dtype="f4"))
            self.made.append(ctx.depth_renderbuffer(self.size))
            self.fbo = ctx.framebuffer(color_attachments=self.made[:2], depth_attachment=self.made[2])
        except BaseException:
            self.release()
            raise
        self.made.append(self.fbo)

    def release(self) -> None:
        while self.made:
            self.made.pop().release()


def draw_channels(renderer: Any, state: Any, view: ViewCamera,
                  next_positions: np.ndarray | None) -> Channels:
    """Draw ``state`` from ``view``; ``next_positions`` (N, 3) are the cloth's points at the next
    sampled frame (None: no next frame, the flow is 0). ``renderer`` is a :class:`~.renderer.Renderer`
    of the view's size, whose caches (cloth buffers, collider meshes) this pass shares; ``state``
    what it draws (``Renderer.render``'s ``simulation``)."""
    import moderngl

    if (view.width, view.height) != (renderer.width, renderer.height):
        raise ValueError(f"view is {view.width}x{view.height}, renderer {renderer.width}x{renderer.height}")
    ctx = renderer.ctx
    with ctx:
        targets = renderer._channel_targets()
        buffers = renderer._cloth_buffers(state)
        positions = np.ascontiguousarray(state.positions, dtype=np.float64)
        buffers.geometry.fill(positions, False, buffers.vertices)
        buffers.vbo.write(buffers.vertices)
        nxt = positions if next_positions is None else np.asarray(next_positions, dtype=np.float64)
        next_vbo = renderer._next_buffer(buffers)
        # (per render vertex: a mesh cloth's seam copies of a point move with it)
        next_vbo.write(np.ascontiguousarray(buffers.geometry.per_vertex(nxt), dtype=np.float32))

        targets.fbo.use()
        ctx.viewport = (0, 0, view.width, view.height)
        ctx.enable_only(moderngl.DEPTH_TEST)
        ctx.front_face = "cw"  # the y flip turns counter-clockwise triangles clockwise
        ctx.wireframe = False
        ctx.polygon_offset = (0.0, 0.0)
        ctx.clear(0.0, 0.0, 0.0, 0.0, depth=1.0)

        cam = view.camera()
        prog = renderer.programs.get("channels")
        set_matrix(prog, "u_view_projection", FLIP_Y @ cam.view_projection(view.width / view.height))
        set_matrix(prog, "u_view", cam.view())
        f = view.focal()
        set_uniform(prog, "u_focal", (f, f))

        vao = renderer._vao("channels", "cloth", None, lambda p: ctx.vertex_array(
            p, [(buffers.vbo, "3f 3f 12x", "in_position", "in_normal"), (next_vbo, "3f", "in_next")],
            buffers.tri_ibo, index_element_size=4))
        set_matrix(prog, "u_model", np.eye(4))
        set_uniform(prog, "u_has_next", 1)
        set_uniform(prog, "u_object", 0)
        vao.render(moderngl.TRIANGLES)

        set_uniform(prog, "u_has_next", 0)
        settings = renderer.settings_for(state.scene)

        def mark(k: int) -> None:
            set_uniform(prog, "u_object", FIRST_COLLIDER_ID + k)

        renderer._draw_colliders(prog, "channels", state, settings, mark)
        w, h = view.width, view.height
        a = np.frombuffer(targets.fbo.read(components=4, attachment=0, dtype="f4"), dtype=np.float32).reshape(h, w, 4)
        b = np.frombuffer(targets.fbo.read(components=4, attachment=1, dtype="f4"), dtype=np.float32).reshape(h, w, 4)
    return Channels(depth=a[:, :, 0].copy(), flow=a[:, :, 1:3].copy(), mask=np.rint(a[:, :, 3]).astype(np.uint8),
                    normal=b[:, :, :3].copy())
