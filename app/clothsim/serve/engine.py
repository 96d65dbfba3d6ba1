"""The server's one simulation and one renderer, driven from one worker thread.

An OpenGL context belongs to the thread that made it current, so the :class:`Renderer` is created,
used and released by the worker thread alone, for the server's whole life; the simulation lives
there too. The event loop talks to the worker through a queue of commands: each is applied
between two frames, through the same ``Simulation`` setters and render-settings rules the API and
the CLI use, and answers through a :class:`concurrent.futures.Future`.

Frames are drawn only while a page is watching, one frame ahead of the slowest thing that
matters: after publishing a frame the worker waits until a viewer has taken it, so a page that
cannot keep up throttles the simulation instead of piling frames up in memory.
"""

from __future__ import annotations

import io
import math
import queue
import shutil
import sys
import tempfile
import threading
import time
from concurrent.futures import Future
from dataclasses import dataclass, replace
from pathlib import Path, PurePosixPath
from typing import Any, Protocol

import numpy as np

from ..assets import UploadedFiles
from ..errors import ClothsimError
from ..render.camera import cloth_size
from ..render.settings import SHADERS, RenderSettings
from ..scene import Scene, bundled_scene_names, check_field, load_scene, parse_scene
from ..sim.simulation import Simulation
from . import limits, protocol
from .orbit import Orbit
from .recorder import ClipRecorder

JPEG_QUALITY = 85
# How long the worker sleeps when nothing asks it for anything; it wakes at once on a command.
IDLE_WAIT_S = 0.5
#: Two frames in a row whose simulation took longer than this pause the simulation (the
#: estimate in :mod:`.limits` keeps most frames far below; a heap of folds can cost more).
SLOW_FRAME_S = 1.5
#: How long :meth:`Engine.stop` waits for the worker before leaving it to end with the process.
STOP_WAIT_S = 1.0
_STOP = object()


@dataclass(frozen=True)
class Frame:
    """One streamed frame: the JPEG and what the page shows beside it."""

    jpeg: bytes
    number: int
    width: int
    height: int
    render_ms: float
    paused: bool


class Viewers(Protocol):
    """Where the worker sends what it makes (called from the worker thread)."""

    def frame(self, frame: Frame) -> None: ...

    def message(self, message: dict[str, Any]) -> None: ...


def upload_label(name: str | None) -> str:
    """How errors name an uploaded scene: its base name, printable and short; never a path."""
    base = PurePosixPath(str(name or "").replace("\\", "/")).name
    if not base or not base.isprintable() or len(base) > 100:
        return "uploaded scene"
    return base


class Engine:
    """Owns the simulation, the renderer, the look, the camera and the recording.

    ``scene`` is the scene to start with (``name`` is how the page lists it); ``size`` the
    streamed image size. :meth:`start` creates the renderer in the worker thread and raises its
    one-line error if that fails; :meth:`stop` releases everything.
    """

    def __init__(self, scene: Scene, name: str, size: tuple[int, int] = (800, 800), samples: int = 4,
                 clip_folder: Path | None = None, settings: RenderSettings | None = None) -> None:
        self.scene_name = name
        self.size = (int(size[0]), int(size[1]))
        self.samples = samples
        self.clip_folder = clip_folder
        self.scenes: tuple[str, ...] = tuple(bundled_scene_names())
        limits.check_scene(scene, name)
        self.simulation = Simulation(scene)
        self.settings = settings or RenderSettings.from_scene(scene)
        self.orbit = self._initial_orbit()
        self.running = True
        self.error: str | None = None  # the blow-up that stopped the simulation, until R
        self.renderer: Any = None
        self.recorder: ClipRecorder | None = None
        self.clip: Path | None = None
        self.clip_count = 0
        self.viewers: Viewers | None = None
        self._watching = 0
        self._taken = True
        self._dirty = True
        self._step_once = False
        self._commands: queue.SimpleQueue = queue.SimpleQueue()
        self._wake = threading.Event()
        self._ready = threading.Event()
        self._start_error: BaseException | None = None
        self._thread: threading.Thread | None = None
        self._uploads: Path | None = None  # the current uploaded scene's files
        self._upload_count = 0
        self._slow_frames = 0

    # -- called from other threads --------------------------------------------------------
    def start(self) -> None:
        """Start the worker thread and wait until its renderer exists (or raise why not)."""
        self._thread = threading.Thread(target=self._main, name="clothsim-serve-engine", daemon=True)
        self._thread.start()
        self._ready.wait()
        if self._start_error is not None:
            self._thread.join()
            raise self._start_error

    def stop(self, timeout: float | None = STOP_WAIT_S) -> bool:
        """Stop the worker: a recording is dropped, the renderer and its context released.

        Waits at most ``timeout`` seconds (None: for ever) for the frame in progress to end, and
        returns whether the worker has ended; one that has not (a frame still running) ends with
        the process, as it is a daemon thread.
        """
        if self._thread is None:
            return True
        self._commands.put(_STOP)
        self._wake.set()
        self._thread.join(timeout)
        if self._thread.is_alive():
            return False
        self._thread = None
        return True

    def submit(self, kind: str, **payload: Any) -> Future:
        """Queue a command (``set``, ``look``, ``scene``, ``upload``, ``snapshot``, ...) for the
        next gap between frames; the future gets its result or its ClothsimError."""
        future: Future = Future()
        self._commands.put((kind, payload, future))
        self._wake.set()
        return future

    def watch(self, delta: int) -> None:
        """A page started (+1) or stopped (-1) watching; a new one gets the current frame."""
        self._commands.put(("watch", {"delta": delta}, None))
        self._wake.set()

    def frame_taken(self) -> None:
        """A viewer took the last frame: the next one may be drawn."""
        self._taken = True
        self._wake.set()

    # -- the worker thread ----------------------------------------------------------------
    def _main(self) -> None:
        try:
            from ..render.renderer import Renderer, RenderSizeError

            try:
                self.renderer = Renderer(*self.size, samples=self.samples)
            except RenderSizeError as exc:
                raise ClothsimError(f"--size: {exc}") from None
        except BaseException as exc:  # noqa: BLE001 - handed to the thread that called start()
            self._start_error = exc
            self._ready.set()
            return
        self._ready.set()
        try:
            self._loop()
        finally:
            self._drop_uploads()
            # Whatever was still queued behind the stop gets an answer, so that nobody waits forever.
            while True:
                try:
                    command = self._commands.get_nowait()
                except queue.Empty:
                    break
                if command is not _STOP and command[2] is not None:
                    command[2].set_exception(ClothsimError("clothsim serve is stopping"))
            if self.recorder is not None:
                self.recorder.abort()
                self.recorder = None
            self.renderer.release()
            self.renderer = None

    def _loop(self) -> None:
        while True:
            self._wake.wait(IDLE_WAIT_S)
            self._wake.clear()
            while True:
                try:
                    command = self._commands.get_nowait()
                except queue.Empty:
                    break
                if command is _STOP:
                    return
                self._apply(*command)
            if self._watching <= 0 or not self._taken:
                continue
            advance = (self.running and self.error is None) or self._step_once
            if advance or self._dirty:
                try:
                    self._produce(advance)
                except Exception as exc:  # noqa: BLE001 - nothing a frame meets may end the server
                    self._dirty = False
                    self._say({"type": "error", "message": _line(exc)})
                    continue
                if self.running:
                    self._wake.set()  # go on as soon as the frame is taken

    def _apply(self, kind: str, payload: dict[str, Any], future: Future | None) -> None:
        try:
            result = getattr(self, f"_do_{kind}")(**payload)
        except ClothsimError as exc:
            if future is not None:
                future.set_exception(exc)
            return
        except Exception as exc:  # noqa: BLE001 - a bug must not end the server; say so and go on
            if future is not None:
                future.set_exception(ClothsimError(_line(exc)))
            return
        if future is not None:
            future.set_result(result)

    def _produce(self, advance: bool) -> None:
        sim = self.simulation
        if advance:
            self._step_once = False
            started = time.perf_counter()
            try:
                sim.step(1)
            except Exception as exc:  # noqa: BLE001 - the server goes on; the page shows why it stopped
                self._stopped(exc)
            took = time.perf_counter() - started
            # Two in a row: the first frame of a scene, or after a change of plan, may include
            # compiling its kernels (seconds, once).
            self._slow_frames = self._slow_frames + 1 if took > SLOW_FRAME_S else 0
            if self._slow_frames >= 2 and self.running:
                self._slow_frames = 0
                self.running = False
                self._say({"type": "error", "message": (
                    f"paused: a frame took {took:.1f} s to simulate, more than the server allows "
                    f"({SLOW_FRAME_S:g} s); lower simulation_steps or load a smaller scene, then press P")})
                self._broadcast_state()
        self._dirty = False
        try:
            image = self._render()
        except Exception as exc:  # noqa: BLE001
            self._say({"type": "error", "message": _line(exc)})
            return
        if self.recorder is not None:
            try:
                self._record(image)
            except Exception as exc:  # noqa: BLE001 - a failed clip is dropped; the stream goes on
                self._drop_recording(_line(exc))
        jpeg = _encode(image, "JPEG", quality=JPEG_QUALITY)
        self._taken = False
        if self.viewers is not None:
            self.viewers.frame(Frame(jpeg, sim.frame, image.shape[1], image.shape[0],
                                     1e3 * sum(self.renderer.timings.values()), not self.running))

    def _stopped(self, exc: BaseException) -> None:
        """The simulation failed (a blow-up): stop it, and show why until R restarts it."""
        self.error = _line(exc)
        self.running = False
        self._say({"type": "error", "message": self.error})
        self._broadcast_state()

    def _render(self) -> np.ndarray:
        target = self.orbit.target(self.simulation.positions)
        settings = replace(self.settings, camera_position=tuple(float(c) for c in self.orbit.position(target)),
                           camera_target=tuple(float(c) for c in target))
        return self.renderer.render(self.simulation, settings=settings)

    def _initial_orbit(self) -> Orbit:
        # The scene's render.camera, else the renderer's default view (following the cloth).
        sim, s = self.simulation, self.settings
        cloth = sim.scene.cloth
        fixed = None if s.camera_target is None else np.asarray(s.camera_target, dtype=np.float64)
        # a mesh cloth has no width or height: the view follows its rest points' largest extent
        width, height = (cloth.width, cloth.height) if not cloth.is_mesh else (cloth_size(cloth),) * 2
        if s.camera_position is None:
            return Orbit.course_default(width, height, fixed)
        target = fixed if fixed is not None else sim.initial_positions.mean(axis=0)
        if np.allclose(s.camera_position, target):
            return Orbit.course_default(width, height, fixed)
        return Orbit.looking(np.asarray(s.camera_position), target, fixed=fixed is not None)

    def _say(self, message: dict[str, Any]) -> None:
        if self.viewers is not None:
            self.viewers.message(message)

    def _broadcast_state(self) -> None:
        self._say(self.state())

    def state(self) -> dict[str, Any]:
        """Everything the page's controls show, as one JSON-ready ``state`` message."""
        sim, s = self.simulation, self.settings
        return {
            "type": "state", "scene": self.scene_name, "scenes": list(self.scenes), "shaders": list(SHADERS),
            "frame": sim.frame, "paused": not self.running, "error": self.error,
            "recording": None if self.recorder is None else self.recorder.path.suffix[1:],
            "size": list(self.size),
            "sim": {name: _jsonable(getattr(sim, name)) for name in protocol.SIM_FIELDS},
            "look": {"shader": s.shader, "color": "#%02x%02x%02x" % tuple(round(255 * c) for c in s.color),
                     "phong.k_a": s.k_a, "phong.k_d": s.k_d, "phong.k_s": s.k_s, "phong.p": s.p,
                     "phong.terms": list(s.terms), "normal_scaling": s.normal_scaling,
                     "height_scaling": s.height_scaling},
        }

    # -- commands (run in the worker thread, between frames) -------------------------------
    def _changed(self) -> None:
        self._dirty = True
        self._broadcast_state()

    def _do_watch(self, delta: int) -> None:
        self._watching += delta
        if delta > 0:
            self._dirty = True
            self._taken = True  # a new page has had no frame yet

    def _do_state(self) -> dict[str, Any]:
        return self.state()

    def _do_set(self, field: str, value: Any) -> None:
        if field == "simulation_steps":
            steps = check_field("simulation", field, value)
            limits.check_substeps(self.simulation.scene, steps)
        setattr(self.simulation, field, value)  # the API setter: checked, re-planned
        self._changed()

    def _do_look(self, field: str, value: Any) -> None:
        self.settings = self.settings.with_overrides(protocol.look_overrides(field, value), source=protocol.SOURCE)
        self._changed()

    def _do_toggle_pause(self) -> None:
        if self.error is not None:
            raise ClothsimError("the simulation blew up; press R to restart it (lower ks or raise the substeps first)")
        self.running = not self.running
        self._changed()

    def _do_step(self) -> None:
        if self.error is not None:
            raise ClothsimError("the simulation blew up; press R to restart it")
        if not self.running:
            self._step_once = True

    def _do_restart(self) -> None:
        self.simulation.reset()
        self.error = None
        self._changed()

    def _do_reset_camera(self) -> None:
        self.orbit = self._initial_orbit()
        self._dirty = True

    def _do_rotate(self, dx: float, dy: float) -> None:
        self.orbit.rotate(dx, dy)
        self._dirty = True

    def _do_pan(self, dx: float, dy: float) -> None:
        self.orbit.pan(dx, dy, self.settings.fov, self.size[1])
        self._dirty = True

    def _do_zoom(self, factor: float) -> None:
        self.orbit.zoom(factor)
        self._dirty = True

    def _do_scene(self, name: str) -> None:
        if name not in self.scenes:  # the message rules allow only these; never a path
            raise ClothsimError(f"scene: no bundled scene named {name!r}")
        self._load(load_scene(name), name)

    def _do_upload(self, text: str, name: str | None = None, files: dict[str, bytes] | None = None) -> str:
        """Load an uploaded scene. The files it names (meshes, images) come from ``files`` (base
        name -> bytes, uploaded with it) or the bundled assets, never from the server's disk."""
        label = upload_label(name)
        folder = self._upload_folder()
        try:
            uploaded = UploadedFiles.store(folder, files or {})
            scene = parse_scene(text, label, files=uploaded)
            self._load(scene, label, uploaded)
        except BaseException:
            shutil.rmtree(folder, ignore_errors=True)
            raise
        self._drop_uploads()
        self._uploads = folder
        return label

    def _upload_folder(self) -> Path:
        if self.clip_folder is None:
            self.clip_folder = Path(tempfile.mkdtemp(prefix="clothsim-serve-"))
        self._upload_count += 1
        return self.clip_folder / f"upload-{self._upload_count}"

    def _drop_uploads(self) -> None:
        if self._uploads is not None:
            shutil.rmtree(self._uploads, ignore_errors=True)
            self._uploads = None

    def _load(self, scene: Scene, name: str, files: UploadedFiles | None = None) -> None:
        # Everything that can fail is built before anything is replaced: a bad scene leaves the
        # running simulation as it was. The bounds come first, before any array is allocated.
        limits.check_scene(scene, name)
        # A scene with a render object brings its look; otherwise the page's look stays.
        settings = RenderSettings.from_scene(scene, files) if scene.render else self.settings
        simulation = Simulation(scene)
        self.simulation, self.settings, self.scene_name = simulation, settings, name
        self.error = None
        self.orbit = self._initial_orbit()
        self._changed()
        if files is None:
            self._drop_uploads()

    def _do_snapshot(self) -> bytes:
        return _encode(self._render(), "PNG")

    def _do_record(self, action: str, format: str = "mp4") -> None:  # noqa: A002 - the message's key
        if action == "start":
            if self.recorder is not None:
                raise ClothsimError("already recording; stop the clip first")
            if self.clip_folder is None:
                raise ClothsimError("this server has no folder for clips")
            self.clip_count += 1
            path = self.clip_folder / f"clothsim-{self.clip_count}.{format}"
            self.recorder = ClipRecorder(path, self.simulation.frames_per_sec)
            self._changed()
        elif self.recorder is None:
            raise ClothsimError("not recording")
        else:
            self._finish_clip()

    def _record(self, image: np.ndarray) -> None:
        assert self.recorder is not None
        try:
            full = self.recorder.add(image)
        except ClothsimError as exc:
            self._drop_recording(str(exc))
            return
        if full:
            self._finish_clip()

    def _drop_recording(self, message: str) -> None:
        if self.recorder is not None:
            self.recorder.abort()
            self.recorder = None
        self._say({"type": "error", "message": message})
        self._broadcast_state()

    def _finish_clip(self) -> None:
        recorder, self.recorder = self.recorder, None
        assert recorder is not None
        try:
            path = recorder.finish()
        finally:
            self._broadcast_state()
        if self.clip is not None and self.clip != path:
            self.clip.unlink(missing_ok=True)
        self.clip = path
        self._say({"type": "clip", "id": self.clip_count, "name": f"clothsim-{self.scene_name_stem()}{path.suffix}",
                   "frames": recorder.frames})

    def scene_name_stem(self) -> str:
        """The scene's name without a ``.json``, for download file names."""
        stem = PurePosixPath(self.scene_name).stem
        return "".join(c if c.isalnum() or c in "-_" else "_" for c in stem) or "scene"


def _encode(image: np.ndarray, fmt: str, **options: Any) -> bytes:
    from PIL import Image

    buf = io.BytesIO()
    Image.fromarray(image, "RGB").save(buf, format=fmt, **options)
    return buf.getvalue()


def _line(exc: BaseException) -> str:
    """The one line a page shows for an error; an unexpected one also goes to stderr, as one line."""
    if isinstance(exc, ClothsimError):
        return str(exc)
    if isinstance(exc, MemoryError):
        line = "out of memory"
    else:
        line = "internal error: " + " ".join(f"{type(exc).__name__}: {exc}".split())[:300]
    print(f"clothsim serve: {line}", file=sys.stderr, flush=True)
    return line


def _jsonable(value: Any) -> Any:
    if isinstance(value, tuple):
        return [_jsonable(v) for v in value]
    if isinstance(value, float) and not math.isfinite(value):
        return None
    return value

