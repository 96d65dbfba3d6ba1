"""The renderer: draws a simulation's current state with one look and reads the image back.

Per frame it computes the cloth's normals (and tangents for the looks that need them) with a
Numba kernel, over the grid or over a mesh cloth's surface (drawn.py), writes them into ONE
dynamic vertex buffer, draws cloth, spheres and planes into a multisampled framebuffer, resolves
it and reads back RGB bytes. Everything else (programs, index buffers, sphere/plane meshes,
textures) is built once and cached, so a Renderer is meant to be reused across frames and scenes.
"""

from __future__ import annotations

import time
from dataclasses import dataclass
from typing import TYPE_CHECKING, Any, Callable, Protocol

import numpy as np

from ..cloth import Springs
from ..errors import ClothsimError
from ..colliders import KINDS
from ..scene import Scene, available_memory
from ..sim.passes.colliders.moving import placement
from . import mesh, textures
from .camera import FLIP_Y, Camera, cloth_size, default_position, default_target
from .drawn import ClothGeometry, drawn_surface, grid_geometry, surface_geometry, surface_name
from .context import create_context
from .overlap import covers_once, register_warm
from .programs import IDS, Programs, set_matrix, set_uniform
from .seen import Seen, worth_it
from .seen import register_warm as register_seen_warm
from .settings import (SHADERS, USES_COLOR_TEXTURE, USES_CUBEMAP, USES_HEIGHT_MAP, USES_TANGENTS,
                       RenderSettings, srgb_to_linear)
from .waits import gl_calls

if TYPE_CHECKING:
    from .channels import Channels
    from .views import ViewCamera

GL_SRGB8_ALPHA8 = 0x8C43
# Texture units, fixed per sampler so that binding order never matters.
UNIT_COLOR, UNIT_HEIGHT, UNIT_CUBE = 0, 1, 2
# How far (scene units) every corner of the cloth must be on the camera's side of a plane for
# a frame to be drawn without the depth test: far above float32's rounding of the plane's quad.
PLANE_MARGIN = 1e-5
# The course draws its sphere a little smaller than the collider so that the cloth, which
# rests exactly on the collider's surface, is not pierced by the sphere's flat facets.
SPHERE_DRAW_SCALE = 0.92
FAMILY_COLORS = ((0.95, 0.35, 0.30), (0.35, 0.85, 0.45), (0.40, 0.60, 1.00))  # sRGB
STAGES = ("mesh", "upload", "draw", "readback")
# A collider shape's vertex buffer: position, normal, tangent, uv (mesh.py, facets.py).
SHAPE_LAYOUT = "3f 3f 3f 2f"
SHAPE_ATTRIBUTES = ("in_position", "in_normal", "in_tangent", "in_uv")


# Mesa's llvmpipe addresses a buffer with 32-bit signed offsets (lp_limits.h), whatever
# GL_MAX_RENDERBUFFER_SIZE says; measured with Mesa 22.3 / LLVM 15.
LLVMPIPE_LIMIT = ("it holds at most 2 GiB in one buffer: with 4x multisampling up to 16384x8192 pixels, "
                  "without 16384x16384")
# Drivers that rasterise on the CPU keep their framebuffers in the process's own memory.
_SOFTWARE = ("llvmpipe", "softpipe", "swrast", "lavapipe")


class RenderSizeError(ClothsimError):
    """The requested image is larger than the driver or the memory allows; the message says
    which limit, and the command line prefixes it with the flag or scene field that set the size."""


def framebuffer_bytes(width: int, height: int, samples: int, software: bool = True) -> int:
    """Memory a Renderer of this size takes: 4-byte colour and 4-byte depth per sample, the
    4-byte resolved colour, and the 3-byte image read back into NumPy. A hardware driver keeps
    the framebuffers in its own memory, so only the read-back counts then."""
    pixels = int(width) * int(height)
    gl = pixels * (max(int(samples), 1) * (4 + 4) + 4) if software else 0
    return gl + pixels * 3


def _is_software(gl_renderer: str) -> bool:
    return any(name in gl_renderer.lower() for name in _SOFTWARE)


def _gib(n: int) -> str:
    # (in MiB below a tenth of a GiB: a GPU's read-back alone would read "0.0 GiB")
    return f"{n / 2**30:.1f} GiB" if n >= 2**30 / 10 else f"{n / 2**20:.0f} MiB"


class ClothState(Protocol):
    """What the renderer reads from a simulation (``clothsim.Simulation`` has all of it)."""

    scene: Scene
    nw: int  # the grid's points across and down; 0 for a mesh cloth, drawn from ``surface``
    nh: int
    positions: np.ndarray  # (N, 3) float64; a grid's row-major
    springs: Springs
    live_springs: Springs  # the springs that act (enabled, not cut): what the wireframe draws
    # (a mesh cloth's state also has ``surface``, a clothsim.cloth.Surface: see drawn.py)


@dataclass
class _ClothBuffers:
    geometry: ClothGeometry
    vertices: np.ndarray  # (R, 9) float32, refilled every frame
    vbo: Any
    uv_vbo: Any
    tri_ibo: Any
    triangles: np.ndarray  # (3T,) uint32, what tri_ibo holds
    next_vbo: Any = None  # the data channels' next positions (made on first use)


class Renderer:
    """Headless renderer of cloth scenes; ``render`` returns an (H, W, 3) uint8 sRGB image.

    ``samples`` is the multisampling count (clamped to what the driver offers; 0 turns
    anti-aliasing off, which on llvmpipe halves the draw time). ``sources``
    replaces looks' GLSL texts ({look: (vertex, fragment)}), for experiments and tests.
    Set ``profile`` to wait for the GPU after drawing, so that :attr:`timings` separates draw
    from read-back (costs a little throughput).
    """

    def __init__(self, width: int = 800, height: int = 800, samples: int = 4, *,
                 sources: dict[str, tuple[str, str]] | None = None, profile: bool = False) -> None:
        if width < 1 or height < 1:
            raise RenderSizeError(f"image size must be positive, got {width}x{height}")
        self.width, self.height = int(width), int(height)
        self.profile = profile
        self._framebuffer_objects: list[Any] = []
        self.ctx = create_context()
        try:
            self.samples = max(0, min(int(samples), int(self.ctx.max_samples)))
            self._check_size()
            (self._ms_color, self._ms_depth, self._ms_fbo, self._ms_color_fbo, self._color,
             self._fbo) = self._framebuffers()
            self.programs = Programs(self.ctx, sources)
        except BaseException:
            # Nobody holds this Renderer yet, so nobody else can release what it made: a caller
            # that catches the error (a size fallback, a test) would otherwise leak a context
            # and up to gigabytes of framebuffer with it.
            with self.ctx:
                self._release_framebuffers()
            self.ctx.release()
            raise
        self._cloth: _ClothBuffers | None = None
        self._springs: tuple[Springs, Any] | None = None  # the springs drawn and their point -> vertex map
        self._spring_ibo: Any = None
        self._spring_ranges: list[tuple[int, int, int]] = []  # (family, first index, count)
        # (vertex buffer, index buffer, the indices (3T,) uint32) of each collider shape drawn
        self._spheres: dict[tuple[int, int], tuple[Any, Any, np.ndarray]] = {}
        self._planes: dict[tuple[Any, ...], tuple[Any, Any, np.ndarray]] = {}
        self._shapes: dict[tuple[Any, ...], tuple[Any, Any, np.ndarray]] = {}
        self._meshes: dict[int, tuple[Any, Any, Any, np.ndarray]] = {}  # id(MeshSpec) -> (spec, vbo, ibo, idx)
        self._vaos: dict[tuple[Any, ...], Any] = {}
        self._textures: dict[tuple[Any, ...], Any] = {}
        self._settings_for: tuple[Scene | None, RenderSettings | None] = (None, None)
        self._channels: Any = None  # the data pass's float targets (channels.py), made on first use
        # The id pass of the looks that move their vertices, on a driver that shades hidden
        # fragments under multisampling (seen.py); made on first use. ``_seen_phase`` is "ids"
        # or "kept" while a frame's id pass or its drawing from the kept triangles runs.
        self._picks = self.samples > 0 and _is_software(str(self.ctx.info.get("GL_RENDERER", "")))
        self._seen: Seen | None = None
        self._seen_phase: str | None = None
        self._seen_whole: Any = None  # the scene whose last id pass found it had too many triangles
        # glFinish and glReadPixels without the GIL, so that a simulation thread runs while the
        # driver draws (see waits.py); None: moderngl's own calls.
        self._gl = gl_calls()
        self._warned_uvs: set[str] = set()  # the mesh cloths without UVs warned about
        self.timings: dict[str, float] = dict.fromkeys(STAGES, 0.0)

    # -- public --------------------------------------------------------------------------------
    def render(self, simulation: ClothState, shader: str | None = None,
               settings: RenderSettings | None = None, camera: Camera | None = None) -> np.ndarray:
        """Draw ``simulation``'s current state; returns a new (height, width, 3) uint8 array.

        ``settings`` defaults to the scene's ``render`` object; ``shader`` overrides its look;
        ``camera`` overrides the settings' camera (a dataset's fixed views).
        The image size is the renderer's, whatever ``settings.size`` says.
        """
        settings = settings or self.settings_for(simulation.scene)
        look = shader or settings.shader
        if look not in SHADERS:
            raise ClothsimError(f"unknown shader {look!r} (expected one of: {', '.join(SHADERS)})")
        t0 = time.perf_counter()
        # GL calls go to the thread's current context: make ours current, so that several
        # renderers (each with its own context) can be used side by side.
        with self.ctx:
            buffers = self._cloth_buffers(simulation)
            buffers.geometry.fill(np.ascontiguousarray(simulation.positions, dtype=np.float64),
                                  look in USES_TANGENTS, buffers.vertices)
            t1 = time.perf_counter()
            buffers.vbo.write(buffers.vertices)
            t2 = time.perf_counter()
            self._draw(simulation, look, settings, buffers, camera)
            if self.profile:
                self._finish()
            t3 = time.perf_counter()
            image = self._read()
            t4 = time.perf_counter()
        self.timings = {"mesh": t1 - t0, "upload": t2 - t1, "draw": t3 - t2, "readback": t4 - t3}
        return image

    def render_channels(self, simulation: ClothState, view: ViewCamera,
                        next_positions: np.ndarray | None = None) -> Channels:
        """Depth, optical flow to ``next_positions``, mask and normals of ``simulation``'s
        current state seen from ``view`` (of this renderer's size); see :mod:`.channels`."""
        from .channels import draw_channels

        return draw_channels(self, simulation, view, next_positions)

    def prepare(self, scene: Scene, look: str) -> None:
        """Get ready to draw ``scene`` with ``look`` in a clip: a mesh cloth is drawn by the surface
        kernel (drawn.py), a grid scene that draws the cloth alone or over one plane has its frames
        tested for overlap (overlap.py), and a look that moves its vertices is drawn from an id
        pass's triangles on llvmpipe (seen.py); the kernel each needs is then compiled (or loaded)
        with the other side kernels, before a clip's simulation thread starts and, on a cold
        start, beside the simulation's first plan. (Without this, the first frame compiles it.)"""
        if getattr(scene.cloth, "is_mesh", False):
            mesh.register_surface_warm()  # (and no overlap test: a mesh cloth draws with the depth test)
        elif self._in_order(scene, look):
            register_warm()
        if self._picks and look != "wireframe" and not self.programs.places_as_given(look):
            register_seen_warm()

    def settings_for(self, scene: Scene) -> RenderSettings:
        """The scene's render settings (validated once per scene object)."""
        if self._settings_for[0] is not scene:
            self._settings_for = (scene, RenderSettings.from_scene(scene))
        settings = self._settings_for[1]
        assert settings is not None
        return settings

    def camera(self, simulation: ClothState, settings: RenderSettings) -> Camera:
        """The camera ``settings`` ask for; unset parts follow the course's defaults.

        The default target is the cloth's current centroid, so a default camera tracks the
        cloth; give ``camera_target`` for a fixed one. The default distance follows the cloth's
        size (:func:`~.camera.cloth_size`).
        """
        scene = simulation.scene
        if settings.camera_target is not None:
            target = np.asarray(settings.camera_target, dtype=np.float64)
        else:
            target = default_target(simulation.positions)
        if settings.camera_position is not None:
            position = np.asarray(settings.camera_position, dtype=np.float64)
        else:
            size = cloth_size(scene.cloth)
            position = default_position(target, size, size)
        if np.allclose(position, target):
            raise ClothsimError("camera position and target coincide")
        return Camera(position, target, settings.fov, settings.near, settings.far)

    def info(self) -> dict[str, str]:
        """GL vendor, renderer, version and GLSL version of the context."""
        from .context import describe

        with self.ctx:
            return describe(self.ctx)

    def release(self) -> None:
        """Free every GL object and the context."""
        with self.ctx:
            self.programs.release()
            if self._seen is not None:
                self._seen.release()
                self._seen = None
            if self._channels is not None:
                self._channels.release()
                self._channels = None
            self._release_framebuffers()
        self.ctx.release()

    def __enter__(self) -> "Renderer":
        return self

    def __exit__(self, *exc: object) -> None:
        self.release()

    # -- framebuffers ----------------------------------------------------------------------
    def _check_size(self) -> None:
        """Refuse, with the limit, an image the driver or the memory cannot hold, before
        allocating anything (a driver may take seconds to fail, or succeed and swap)."""
        info = self.ctx.info
        limit_w = limit_h = int(info.get("GL_MAX_RENDERBUFFER_SIZE", 0)) or None
        viewport = info.get("GL_MAX_VIEWPORT_DIMS")
        if limit_w is not None and viewport:
            limit_w, limit_h = min(limit_w, int(viewport[0])), min(limit_h, int(viewport[1]))
        gl = str(info.get("GL_RENDERER", "this OpenGL driver"))
        if limit_w is not None and (self.width > limit_w or self.height > limit_h):
            raise RenderSizeError(f"image size {self.width}x{self.height} is larger than {gl} can draw "
                                  f"({limit_w}x{limit_h} at most)")
        need = framebuffer_bytes(self.width, self.height, self.samples, software=_is_software(gl))
        avail = available_memory()
        if need > avail:
            raise RenderSizeError(f"image size {self.width}x{self.height} with {self._aa()} needs about "
                                  f"{_gib(need)} of memory for its framebuffers and image, more than the "
                                  f"{_gib(avail)} available; use a smaller size or fewer samples")

    def _framebuffers(self) -> tuple[Any, Any, Any, Any, Any, Any]:
        import moderngl

        size = (self.width, self.height)
        made = self._framebuffer_objects
        try:
            made.append(self.ctx.renderbuffer(size, 4, samples=self.samples))
            made.append(self.ctx.depth_renderbuffer(size, samples=self.samples))
            made.append(self.ctx.framebuffer(made[0], made[1]))
            made.append(self.ctx.framebuffer(made[0]))  # the same colour, no depth (overlap.py)
            made.append(self.ctx.renderbuffer(size, 4))
            made.append(self.ctx.framebuffer(made[4]))
        except moderngl.Error as exc:
            # Drivers have limits of their own beyond the ones GL reports.
            gl = str(self.ctx.info.get("GL_RENDERER", "this OpenGL driver"))
            if "llvmpipe" in gl.lower():
                why = LLVMPIPE_LIMIT
            else:
                why = "it refused: " + " ".join(str(exc).split())
            raise RenderSizeError(f"image size {self.width}x{self.height} with {self._aa()} is more than "
                                  f"{gl} can allocate ({why}); use a smaller size or fewer samples") from None
        return made[0], made[1], made[2], made[3], made[4], made[5]

    def _release_framebuffers(self) -> None:
        while self._framebuffer_objects:
            self._framebuffer_objects.pop().release()

    def _aa(self) -> str:
        return f"{self.samples}x multisampling" if self.samples else "no multisampling"

    # -- per-scene resources ---------------------------------------------------------------
    def _cloth_buffers(self, state: ClothState) -> _ClothBuffers:
        """The buffers of ``state``'s cloth: its grid's, or its surface's for a mesh cloth (made
        once per grid size or surface object)."""
        nw, nh = state.nw, state.nh
        surface = drawn_surface(state)
        b = self._cloth
        if b is not None and b.geometry.fits(nw, nh, surface):
            return b
        if surface is None:
            geometry = grid_geometry(nw, nh)
        else:
            geometry = surface_geometry(surface, int(np.shape(state.positions)[0]))
            self._warn_without_uvs(state.scene, surface)
        if b is not None:
            for obj in (b.vbo, b.uv_vbo, b.tri_ibo, b.next_vbo):
                if obj is not None:
                    obj.release()
            self._drop_vaos("cloth")
        vertices = np.zeros((geometry.vertex_count, mesh.CLOTH_FLOATS), dtype=np.float32)
        self._cloth = _ClothBuffers(
            geometry=geometry, vertices=vertices,
            vbo=self.ctx.buffer(reserve=vertices.nbytes, dynamic=True),
            uv_vbo=self.ctx.buffer(geometry.uvs),
            tri_ibo=self.ctx.buffer(geometry.triangles),
            triangles=geometry.triangles,
        )
        return self._cloth

    def _warn_without_uvs(self, scene: Scene, surface: Any) -> None:
        """One warning line per mesh cloth without UVs and renderer (a render run): its textures
        are laid on by the planar projection ``cloth_surface`` made instead."""
        if surface.has_uvs:
            return
        name = surface_name(scene.cloth)
        if name in self._warned_uvs:
            return
        self._warned_uvs.add(name)
        import warnings

        warnings.warn(f"{name}: the cloth mesh has no UVs (texture coordinates); its textures use a planar "
                      "projection", UserWarning, stacklevel=4)

    def _next_buffer(self, buffers: _ClothBuffers) -> Any:
        if buffers.next_vbo is None:
            buffers.next_vbo = self.ctx.buffer(reserve=buffers.geometry.vertex_count * 12, dynamic=True)
        return buffers.next_vbo

    def _channel_targets(self) -> Any:
        if self._channels is None:
            from .channels import _Targets

            self._channels = _Targets(self.ctx, self.width, self.height)
        return self._channels

    def _spring_buffer(self, springs: Springs, point_vertex: np.ndarray | None = None) -> None:
        """The wireframe's index buffer: the springs family by family, as pairs of render vertices
        (``point_vertex`` maps a mesh cloth's points to them; None: the same numbers, a grid)."""
        if self._springs is not None and self._springs[0] is springs and self._springs[1] is point_vertex:
            return
        springs_in = springs
        if self._spring_ibo is not None:
            self._spring_ibo.release()
            self._drop_vaos("springs")
        if point_vertex is not None:
            i, j = point_vertex[springs.i], point_vertex[springs.j]
            springs = Springs(i, j, springs.rest, springs.kind).select((i >= 0) & (j >= 0))
        order = np.argsort(springs.kind, kind="stable")
        pairs = np.stack([springs.i[order], springs.j[order]], axis=1).astype(np.uint32)
        # A GL buffer cannot be empty: a cloth with every family disabled gets a dummy index.
        self._spring_ibo = self.ctx.buffer(pairs.tobytes() if len(springs) else b"\0\0\0\0")
        counts = np.bincount(springs.kind.astype(np.int64), minlength=3)
        first = 0
        self._spring_ranges = []
        for family in range(3):
            n = int(counts[family]) * 2
            if n:
                self._spring_ranges.append((family, first, n))
            first += n
        self._springs = (springs_in, point_vertex)

    def _sphere(self, resolution: tuple[int, int]) -> tuple[Any, Any, np.ndarray]:
        if resolution not in self._spheres:
            verts, idx = mesh.sphere_mesh(*resolution)
            self._spheres[resolution] = (self.ctx.buffer(verts), self.ctx.buffer(idx), _indices(idx))
        return self._spheres[resolution]

    def _plane(self, point: tuple[float, ...], normal: tuple[float, ...]) -> tuple[Any, Any, np.ndarray]:
        key = (tuple(point), tuple(normal))
        if key not in self._planes:
            verts, idx = mesh.plane_mesh(point, normal)  # type: ignore[arg-type]
            self._planes[key] = (self.ctx.buffer(verts), self.ctx.buffer(idx), _indices(idx))
        return self._planes[key]

    def _draw_shape(self, prog: Any, look: str, key: tuple[Any, ...], build: Any, model: np.ndarray) -> None:
        """Draw a collider mesh made once by ``build()`` (world space at its scene pose), placed by
        ``model`` (its motion's map from the scene pose, :func:`~clothsim.sim.passes.colliders.moving.placement`)."""
        if key not in self._shapes:
            verts, idx = build()
            self._shapes[key] = (self.ctx.buffer(verts), self.ctx.buffer(idx), _indices(idx))
        vbo, ibo, idx = self._shapes[key]
        set_matrix(prog, "u_model", model)
        self._draw_indexed(prog, look, "shape", key, [(vbo, SHAPE_LAYOUT, *SHAPE_ATTRIBUTES)], ibo, idx)

    def _drop_vaos(self, geometry: str) -> None:
        for key in [k for k in self._vaos if k[1] == geometry]:
            self._vaos.pop(key).release()

    def _vao(self, look: str, geometry: str, key: Any, build: Any, prog: Any = None) -> Any:
        """The vertex array of ``geometry`` (``key``) for ``look``'s program, or for ``prog``
        (cached under the name ``look``), made by ``build(program)`` once."""
        full = (look, geometry, key)
        vao = self._vaos.get(full)
        if vao is None:
            vao = build(prog if prog is not None else self.programs.get(look))
            self._vaos[full] = vao
        return vao

    def _draw_indexed(self, prog: Any, look: str, geometry: str, key: Any, content: list[tuple[Any, ...]],
                      ibo: Any, indices: np.ndarray) -> None:
        """Draw the triangles ``indices`` (held by ``ibo``) of vertex buffers ``content`` with
        ``prog``, ``look``'s program; in a frame's id pass numbered, with the id program, and in
        its drawing from the kept triangles only those the pass found (seen.py)."""
        import moderngl

        def build(index_buffer: Any) -> Any:
            return lambda p: self.ctx.vertex_array(p, content, index_buffer, index_element_size=4, skip_errors=True)

        seen, phase = self._seen, self._seen_phase
        if phase is None or seen is None:
            self._vao(look, geometry, key, build(ibo)).render(moderngl.TRIANGLES)
        elif phase == "ids":
            seen.number(prog, indices.size // 3)
            self._vao(look + IDS, geometry, key, build(ibo), prog).render(moderngl.TRIANGLES)
        else:
            kept, count, fresh = seen.kept((geometry, key), indices)
            place = ("seen", key)
            if fresh:  # a new buffer: the vertex arrays made on the old one go
                for k in [k for k in self._vaos if k[1] == geometry and k[2] == place]:
                    self._vaos.pop(k).release()
            if count:
                self._vao(look, geometry, place, build(kept)).render(moderngl.TRIANGLES, vertices=3 * count)

    # -- textures ----------------------------------------------------------------------------
    def _color_texture(self, path: str | None) -> Any:
        key = ("color", path)
        if key not in self._textures:
            img = textures.load_image(path) if path else textures.default_color_texture()
            tex = self.ctx.texture((img.shape[1], img.shape[0]), 4, img.tobytes(),
                                   internal_format=GL_SRGB8_ALPHA8)
            tex.build_mipmaps()
            self._textures[key] = tex
        return self._textures[key]

    def _height_texture(self, path: str | None) -> Any:
        key = ("height", path)
        if key not in self._textures:
            img = textures.load_image(path, gray=True) if path else textures.default_height_map()
            tex = self.ctx.texture((img.shape[1], img.shape[0]), 1, np.ascontiguousarray(img).tobytes())
            # Bump mapping differences neighbouring texels of the full-size image (the course's
            # formula), so no mipmaps: they would flatten the bumps at a distance.
            self._textures[key] = tex
        return self._textures[key]

    def _cubemap(self, paths: tuple[str, ...] | None) -> Any:
        key = ("cube", paths)
        if key not in self._textures:
            faces = textures.load_cubemap(paths) if paths else textures.default_cubemap()
            size = faces[0].shape[0]
            data = b"".join(f.tobytes() for f in faces)
            tex = self.ctx.texture_cube((size, size), 4, data, internal_format=GL_SRGB8_ALPHA8)
            tex.build_mipmaps()
            self._textures[key] = tex
        return self._textures[key]

    # -- drawing -----------------------------------------------------------------------------
    def _draw(self, sim: ClothState, look: str, settings: RenderSettings, buffers: _ClothBuffers,
              camera: Camera | None = None) -> None:
        import moderngl

        ctx = self.ctx
        cam = camera if camera is not None else self.camera(sim, settings)
        view_projection = self._view_projection(cam)
        # A frame whose image covers no sample twice, and whose cloth is in front of its plane if
        # it has one, draws the same bytes without the depth test and its buffer.
        once = self._without_depth(sim, look, buffers, cam, view_projection)
        # a look that moves its vertices, on llvmpipe with multisampling: only the triangles an
        # id pass finds are drawn (seen.py)
        picked = not once and self._pick_seen(sim, look, settings, buffers, cam, view_projection)
        target = self._ms_color_fbo if once else self._ms_fbo
        target.use()
        ctx.viewport = (0, 0, self.width, self.height)
        ctx.enable_only(moderngl.NOTHING if once else moderngl.DEPTH_TEST)
        ctx.front_face = "cw"  # the y flip turns counter-clockwise triangles clockwise
        ctx.wireframe = False
        bg = settings.background
        ctx.clear(bg[0], bg[1], bg[2], 1.0, depth=1.0)  # the framebuffer holds sRGB values

        prog = self.programs.get(look)
        self._set_common_uniforms(prog, look, cam, settings, view_projection)
        ident = np.eye(4)

        if once:  # a plane, if any, first: the cloth is in front of it (see _without_depth)
            self._draw_colliders(prog, look, sim, settings)
        self._seen_phase = "kept" if picked else None
        try:
            if look == "wireframe":
                self._draw_wireframe(prog, sim, settings, buffers)
            else:
                set_matrix(prog, "u_model", ident)
                self._draw_cloth(prog, look, buffers)

            if look == "wireframe":
                # Colliders as line meshes, dimmer than the cloth.
                ctx.wireframe = True
                dim = tuple(0.45 * c for c in srgb_to_linear(settings.color))
                set_uniform(prog, "u_color", (*dim, 1.0))
            if not once:
                self._draw_colliders(prog, look, sim, settings)
        finally:
            self._seen_phase = None
        ctx.wireframe = False
        # The driver draws in the call that first needs the pixels; wait here, without the GIL,
        # rather than inside moderngl's resolve.
        self._finish()
        ctx.copy_framebuffer(self._fbo, target)  # resolves the multisampled image

    def _draw_cloth(self, prog: Any, look: str, buffers: _ClothBuffers) -> None:
        self._draw_indexed(prog, look, "cloth", None,
                           [(buffers.vbo, "3f 3f 3f", "in_position", "in_normal", "in_tangent"),
                            (buffers.uv_vbo, "2f", "in_uv")], buffers.tri_ibo, buffers.triangles)

    def _pick_seen(self, sim: ClothState, look: str, settings: RenderSettings, buffers: _ClothBuffers,
                   cam: Camera, view_projection: np.ndarray) -> bool:
        """A frame's id pass (seen.py), for a look that moves its vertices on a driver that shades
        hidden fragments under multisampling: the cloth and the colliders drawn as the look draws
        them, numbered; True when the frame is then to be drawn from the triangles found."""
        import moderngl

        if (not self._picks or look == "wireframe" or self.programs.places_as_given(look)
                or not worth_it(self.width * self.height, buffers.triangles.size // 3) or sim.scene is self._seen_whole):
            return False
        if self._seen is None:
            self._seen = Seen(self.ctx, self.width, self.height)
        seen = self._seen
        ctx = self.ctx
        seen.begin()
        ctx.viewport = (0, 0, self.width, self.height)
        ctx.enable_only(moderngl.DEPTH_TEST)
        ctx.front_face = "cw"
        ctx.wireframe = False
        prog = self.programs.ids(look)
        self._set_common_uniforms(prog, look, cam, settings, view_projection)
        self._seen_phase = "ids"
        try:
            set_matrix(prog, "u_model", np.eye(4))
            self._draw_cloth(prog, look, buffers)
            self._draw_colliders(prog, look, sim, settings)
        finally:
            self._seen_phase = None
        if seen.read(self._gl):
            return True
        self._seen_whole = sim.scene  # its colliders' triangles too: drawn whole from now on
        return False

    def _in_order(self, scene: Scene, look: str) -> bool:
        """Whether ``look`` may draw ``scene`` without the depth test, frame by frame
        (:meth:`_without_depth`): its vertex stage leaves the positions where they are (the CPU
        knows where they land) and the scene draws the cloth alone or over one plane."""
        if not self.programs.places_as_given(look):
            return False
        drawn = [kind.key for kind in KINDS for _ in getattr(scene, kind.attr)]
        return drawn in ([], ["plane"])

    def _without_depth(self, sim: ClothState, look: str, buffers: _ClothBuffers, cam: Camera,
                       view_projection: np.ndarray) -> bool:
        """Whether this frame's image is the same without the depth test: no sample covered twice
        by the cloth (overlap.py) and, with a plane, the camera and every drawn corner of the
        cloth on the same side of it, so that the cloth drawn after the plane hides what it
        would hide with the test (the plane is pushed back in depth besides)."""
        scene = sim.scene
        # (the test below knows a grid's triangles and border; a mesh cloth draws with the depth test)
        if buffers.geometry.surface is not None or not self._in_order(scene, look):
            return False
        now = float(getattr(sim, "time", 0.0))
        for plane in scene.planes:
            place = placement(plane, now)
            normal = place[:3, :3] @ np.asarray(plane.normal, dtype=np.float64)
            base = float(normal @ (place[:3, :3] @ np.asarray(plane.point, dtype=np.float64) + place[:3, 3]))
            side = float(normal @ cam.position) - base
            heights = (buffers.vertices[:, :3].astype(np.float64) @ normal - base) * np.sign(side)
            if not heights.min() > PLANE_MARGIN * float(np.linalg.norm(normal)):
                return False
        return bool(covers_once(buffers.vertices, buffers.geometry.nw, buffers.geometry.nh, view_projection,
                                self.width, self.height))

    def _draw_colliders(self, prog: Any, look: str, sim: ClothState, settings: RenderSettings,
                        mark: Callable[[int], None] | None = None) -> None:
        """Every collider, kind by kind in the registry's order (:data:`clothsim.colliders.KINDS`).
        ``mark(k)`` is called before the k-th (from 0) is drawn (the data pass's mask ids)."""
        import moderngl

        scene = sim.scene
        # Moving colliders are drawn where they are at the simulation's time: the shape built at
        # its scene pose, moved by the model matrix. Kind by kind, in the registry's order.
        now = float(getattr(sim, "time", 0.0))
        drawn = 0
        for kind in KINDS:
            draw = getattr(self, f"_draw_{kind.key}")
            for spec in getattr(scene, kind.attr):
                if mark is not None:
                    mark(drawn)
                drawn += 1
                draw(prog, look, settings, spec, now)
        self.ctx.disable(moderngl.CULL_FACE)
        self.ctx.polygon_offset = (0.0, 0.0)

    def _mesh_collider(self, spec: Any) -> tuple[Any, Any, np.ndarray]:
        entry = self._meshes.get(id(spec))
        if entry is None or entry[0] is not spec:
            from .facets import mesh_collider_vertices

            if entry is not None:  # another scene's mesh had this id: drop what was built for it
                for key in [k for k in self._vaos if k[1] == "mesh" and k[2] in (id(spec), ("seen", id(spec)))]:
                    self._vaos.pop(key).release()
                entry[1].release()
                entry[2].release()

            verts, idx = mesh_collider_vertices(spec)
            entry = (spec, self.ctx.buffer(verts), self.ctx.buffer(idx), _indices(idx))
            self._meshes[id(spec)] = entry
        return entry[1], entry[2], entry[3]

    # -- colliders, one method per kind (see clothsim.colliders.KINDS) --------------------------
    def _solid(self, look: str, culled: bool, offset: bool) -> None:
        """Draw state of a collider: back faces culled (a closed shape seen from outside: its far
        side is hidden by its near side, and culling halves the triangles rasterised, small
        triangles dominating llvmpipe's MSAA cost), and pushed back in depth (a cloth resting on
        a plane or a box face sits 0.0001 above it; the two must never fight for the same
        pixels)."""
        import moderngl

        if culled and look != "wireframe":
            self.ctx.enable(moderngl.CULL_FACE)
        else:
            self.ctx.disable(moderngl.CULL_FACE)
        self.ctx.polygon_offset = (1.0, 4.0) if offset else (0.0, 0.0)

    def _draw_sphere(self, prog: Any, look: str, settings: RenderSettings, sphere: Any, now: float) -> None:
        self._solid(look, True, False)
        vbo, ibo, idx = self._sphere(settings.sphere_resolution)
        model = np.diag([*(3 * [sphere.radius * SPHERE_DRAW_SCALE]), 1.0])
        model[:3, 3] = sphere.origin
        model = placement(sphere, now) @ model
        set_matrix(prog, "u_model", model)
        self._draw_indexed(prog, look, "sphere", settings.sphere_resolution,
                           [(vbo, SHAPE_LAYOUT, *SHAPE_ATTRIBUTES)], ibo, idx)

    def _draw_capsule(self, prog: Any, look: str, settings: RenderSettings, capsule: Any, now: float) -> None:
        self._solid(look, True, False)
        # drawn thinner for the reason spheres are (see SPHERE_DRAW_SCALE)
        key = ("capsule", capsule.a, capsule.b, capsule.radius, settings.sphere_resolution)
        self._draw_shape(prog, look, key, lambda c=capsule: mesh.capsule_mesh(
            c.a, c.b, c.radius * SPHERE_DRAW_SCALE, *settings.sphere_resolution), placement(capsule, now))

    def _draw_plane(self, prog: Any, look: str, settings: RenderSettings, plane: Any, now: float) -> None:
        self._solid(look, False, True)
        vbo, ibo, idx = self._plane(plane.point, plane.normal)
        set_matrix(prog, "u_model", placement(plane, now))
        self._draw_indexed(prog, look, "plane", (plane.point, plane.normal),
                           [(vbo, SHAPE_LAYOUT, *SHAPE_ATTRIBUTES)], ibo, idx)

    def _draw_box(self, prog: Any, look: str, settings: RenderSettings, box: Any, now: float) -> None:
        self._solid(look, True, True)
        key = ("box", box.center, box.half_extents, box.rotation)
        self._draw_shape(prog, look, key, lambda b=box: mesh.box_mesh(b.center, b.half_extents, b.matrix()),
                         placement(box, now))

    def _draw_mesh(self, prog: Any, look: str, settings: RenderSettings, spec: Any, now: float) -> None:
        """A triangle mesh at its place at the simulation's time (culled from behind when closed,
        both sides when open)."""
        self._solid(look, spec.closed, False)
        vbo, ibo, idx = self._mesh_collider(spec)
        if spec.sequence is not None:  # a deforming mesh: its shape at this time (as many vertices)
            from .facets import mesh_collider_vertices

            vbo.write(mesh_collider_vertices(spec, now)[0])
        model = np.eye(4)
        model[:3, 3] = spec.translate
        set_matrix(prog, "u_model", placement(spec, now) @ model)
        self._draw_indexed(prog, look, "mesh", id(spec), [(vbo, SHAPE_LAYOUT, *SHAPE_ATTRIBUTES)], ibo, idx)

    def _draw_wireframe(self, prog: Any, sim: ClothState, settings: RenderSettings,
                        buffers: _ClothBuffers) -> None:
        import moderngl

        self._spring_buffer(sim.live_springs, buffers.geometry.point_vertex)
        vao = self._vao("wireframe", "springs", None, lambda p: self.ctx.vertex_array(
            p, [(buffers.vbo, "3f 24x", "in_position")], self._spring_ibo, index_element_size=4))
        set_matrix(prog, "u_model", np.eye(4))
        if settings.color_by_family:
            for family, first, count in self._spring_ranges:
                set_uniform(prog, "u_color", (*srgb_to_linear(FAMILY_COLORS[family]), 1.0))
                vao.render(moderngl.LINES, vertices=count, first=first)
        elif self._spring_ranges:
            total = sum(c for _, _, c in self._spring_ranges)
            vao.render(moderngl.LINES, vertices=total, first=0)

    def _view_projection(self, cam: Camera) -> np.ndarray:
        # Rendered upside down (clip-space y negated, winding flipped to match in _draw), so
        # the framebuffer's bottom-up rows read back as a top-down image with no copy.
        return FLIP_Y @ cam.view_projection(self.width / self.height)

    def _set_common_uniforms(self, prog: Any, look: str, cam: Camera, settings: RenderSettings,
                             view_projection: np.ndarray) -> None:
        set_matrix(prog, "u_view_projection", view_projection)
        set_uniform(prog, "u_cam_pos", tuple(float(c) for c in cam.position))
        set_uniform(prog, "u_light_pos", settings.light_position)
        set_uniform(prog, "u_light_intensity", settings.light_intensity)
        set_uniform(prog, "u_color", (*srgb_to_linear(settings.color), 1.0))
        set_uniform(prog, "u_k_a", settings.k_a)
        set_uniform(prog, "u_k_d", settings.k_d)
        set_uniform(prog, "u_k_s", settings.k_s)
        set_uniform(prog, "u_p", settings.p)
        set_uniform(prog, "u_I_a", settings.I_a)
        set_uniform(prog, "u_terms", tuple(1.0 if t in settings.terms else 0.0
                                           for t in ("ambient", "diffuse", "specular")))
        set_uniform(prog, "u_normal_scaling", settings.normal_scaling)
        set_uniform(prog, "u_height_scaling", settings.height_scaling)
        set_uniform(prog, "u_reflectivity", settings.reflectivity)
        if look in USES_COLOR_TEXTURE:
            self._color_texture(settings.color_texture).use(UNIT_COLOR)
            set_uniform(prog, "u_texture_1", UNIT_COLOR)
        if look in USES_HEIGHT_MAP:
            tex = self._height_texture(settings.height_texture)
            tex.use(UNIT_HEIGHT)
            set_uniform(prog, "u_texture_2", UNIT_HEIGHT)
            set_uniform(prog, "u_texture_2_size", (float(tex.width), float(tex.height)))
        if look in USES_CUBEMAP:
            self._cubemap(settings.cubemap).use(UNIT_CUBE)
            set_uniform(prog, "u_texture_cubemap", UNIT_CUBE)

    def _finish(self) -> None:
        if self._gl is not None:
            self._gl.finish()
        else:
            self.ctx.finish()

    def _read(self) -> np.ndarray:
        image = np.empty((self.height, self.width, 3), dtype=np.uint8)
        if self._gl is not None:
            self._gl.finish()  # the resolve, without the GIL
            self._gl.read_rgb(self._fbo, image)
        else:
            self._fbo.read_into(image, components=3, alignment=1)
        return image


def _indices(idx: Any) -> np.ndarray:
    """A shape's triangle indices as the flat uint32 array its index buffer holds."""
    return np.ascontiguousarray(np.asarray(idx, dtype=np.uint32).ravel())
