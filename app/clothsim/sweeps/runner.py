"""One run of a sweep, as a worker executes it: simulate, sample the positions, draw the images.

:func:`run` takes a :class:`Task` and returns a plain dict of arrays and images; it writes no
file (results travel back to the caller, which writes the output), so the same function runs in
a local worker process, on a Dask worker on another machine, or in the caller's own process.

A contact-sheet cell is the image ``clothsim render SCENE --frames F -o x.png`` writes: the same
settings, the same renderer, and the same rest rule (once the cloth is at rest, ``render`` stops
simulating and draws the resting state for every later frame). The sampled positions do not use
the rest rule: they are the states ``clothsim simulate --frames f`` computes, cast to float32.
"""

from __future__ import annotations

import threading
import time
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from ..errors import ClothsimError
from ..scene import Scene

__all__ = ["Task", "run", "sample_frames"]

_local = threading.local()  # one renderer per size and thread, kept for the process's lifetime


@dataclass(frozen=True)
class Task:
    """What a worker needs for one run. ``settings`` (a RenderSettings) is None when nothing is drawn."""

    id: str
    scene: Scene
    frames: int  # F: positions are sampled at 0, every, 2*every, ..., F
    every: int = 1
    positions: bool = True  # sample positions (a dataset); a contact sheet needs only the cells
    cells: tuple[int, ...] = ()  # frames drawn as contact-sheet cells
    video: bool = False  # draw every sampled frame too
    settings: Any = None
    size: tuple[int, int] = (256, 256)
    samples: int = 4  # multisampling
    threads: int | None = None  # Numba threads for this run (None: leave as is)
    views: int = 0  # cameras of a dataset's views (0: none)
    channels: tuple[str, ...] = ()  # of render.channels.CHANNELS
    view_seed: tuple[int, ...] = (0,)  # drawn cameras come from numpy.random.default_rng(view_seed)
    write_to: str | None = None  # a dataset's OUT (folder or fsspec URL): the worker writes the run's files there
    extra: dict[str, Any] = field(default_factory=dict)


def sample_frames(frames: int, every: int) -> list[int]:
    """0, K, 2K, ... and always the last frame F."""
    numbers = list(range(0, frames + 1, every))
    if numbers[-1] != frames:
        numbers.append(frames)
    return numbers


def renderer(size: tuple[int, int], samples: int) -> Any:
    """This thread's renderer of that size, made on first use and reused by later runs."""
    cache = getattr(_local, "renderers", None)
    if cache is None:
        cache = _local.renderers = {}
    key = (int(size[0]), int(size[1]), int(samples))
    if key not in cache:
        from ..render.renderer import Renderer

        cache[key] = Renderer(key[0], key[1], samples=key[2])
    return cache[key]


def _one_line(exc: BaseException) -> str:
    if isinstance(exc, ClothsimError):
        text = str(exc)
    elif isinstance(exc, MemoryError):
        text = "out of memory"
    else:
        text = f"{type(exc).__name__}: {exc}"
    return " ".join(text.split()) or type(exc).__name__


def run(task: Task) -> dict[str, Any]:
    """Simulate one run; returns ``status`` ``done`` or ``failed`` (with a one-line ``error``),
    ``positions`` float32 (T, N, 3), ``pinned``, ``nw``/``nh`` (and for a mesh cloth ``surface``
    and ``rest``, its initial positions), ``cells`` {frame: image},
    ``video`` (V, H, W, 3) uint8 or None, and ``seconds``."""
    start = time.perf_counter()
    result: dict[str, Any] = {"id": task.id, "status": "done", "error": None, "positions": None,
                              "pinned": None, "nw": None, "nh": None, "cells": {}, "video": None,
                              "views": None, "render_seconds": 0.0}
    try:
        _simulate(task, result)
    except Exception as exc:  # a blow-up, a bad value met only at run time, a driver failure
        result.update(status="failed", error=_one_line(exc), positions=None, cells={}, video=None, views=None)
    except MemoryError as exc:
        result.update(status="failed", error=_one_line(exc), positions=None, cells={}, video=None, views=None)
    if task.write_to is not None and result["status"] == "done":
        try:
            _write(task, result)
        except Exception as exc:  # noqa: BLE001 - a full disk, a lost connection: not the run's fault
            # Not a property of the run's parameters: the sweep reports it and does not record
            # it, so the same command writes the run again.
            result.update(status="failed", error=f"cannot write its files: {_one_line(exc)}", positions=None,
                          views=None, video=None, write_failed=True)
    result["seconds"] = time.perf_counter() - start
    return result


def _simulate(task: Task, result: dict[str, Any]) -> None:
    if task.threads is not None:
        import numba

        numba.set_num_threads(min(task.threads, numba.config.NUMBA_NUM_THREADS))
    from ..sim import Simulation
    from ..sim.rest import RestDetector

    scene = task.scene
    sim = Simulation(scene)
    result.update(nw=sim.nw, nh=sim.nh, pinned=sim.pinned.copy())
    if scene.cloth.is_mesh:
        # What a mesh cloth's run file is made from (a grid's is its nw x nh).
        result.update(surface=sim.surface, rest=np.array(sim.initial_positions, dtype=np.float64))
    wanted = sample_frames(task.frames, task.every) if (task.positions or task.video) else []
    wanted_set = set(wanted)
    cells = sorted(set(task.cells))
    draw = renderer(task.size, task.samples) if (cells or task.video) else None
    render_time = 0.0

    def image() -> np.ndarray:
        nonlocal render_time
        t0 = time.perf_counter()
        picture = draw.render(sim, settings=task.settings)
        render_time += time.perf_counter() - t0
        return picture

    samples = np.empty((len(wanted), sim.positions.shape[0], 3), dtype=np.float32) if task.positions else None
    # What the views need to redraw a sampled frame later: its time (moving colliders) and the
    # springs then (the wireframe draws the live ones).
    moments: list[tuple[float, Any]] = []
    video: list[np.ndarray] = []
    images: dict[int, np.ndarray] = {}
    rest = RestDetector(scene.simulation.rest_tolerance, scene.simulation.rest_frames) if cells else None
    if rest is not None:
        rest.update(sim._pos)
    rest_image: np.ndarray | None = None
    last = max([*wanted, *cells], default=0)
    k = 0
    frame = 0
    while True:
        if frame in wanted_set:
            if samples is not None:
                samples[k] = sim.positions
            if task.views:
                moments.append((sim.time, sim.live_springs))
            k += 1
            if task.video:
                video.append(image())
        if frame in cells:
            images[frame] = rest_image if rest_image is not None else image()
        if frame >= last or (not wanted_set and rest_image is not None):
            break
        sim.step(1)
        frame += 1
        if rest is not None and rest_image is None and rest.update(sim._pos) and sim.time >= sim.colliders_still_after:
            rest_image = image() if any(c >= frame for c in cells) else np.zeros(0)
    for c in cells:  # frames after the cloth came to rest: its resting image
        if c not in images:
            images[c] = rest_image
    result["positions"] = samples
    result["cells"] = images
    result["video"] = np.stack(video) if video else None
    result["render_seconds"] = render_time
    if task.views and samples is not None:
        t0 = time.perf_counter()
        result["views"] = draw_views(task, sim, samples, moments)
        result["render_seconds"] += time.perf_counter() - t0


def _write(task: Task, result: dict[str, Any]) -> None:
    """Write the run's files into ``task.write_to`` and drop the arrays from the result: only
    the manifest line's facts travel back."""
    from .dataset import run_arrays
    from .params import scene_json
    from .store import encode_run, write_files

    frames = sample_frames(task.frames, task.every)
    arrays = run_arrays(result["positions"], result["nw"], result["nh"], result["pinned"], task.scene, frames,
                        scene_json(task.scene), result.get("surface"), result.get("rest"))
    files = encode_run(task.id, arrays, result["views"], frames, result["video"],
                       task.scene.simulation.frames_per_sec / task.every)
    write_files(task.write_to, files)
    result.update(positions=None, views=None, video=None, pinned=None, surface=None, rest=None,
                  written=f"runs/{task.id}.npz")


@dataclass
class _Frame:
    """A sampled frame as the renderer reads a simulation (positions as the dataset stores them)."""

    scene: Scene
    nw: int
    nh: int
    positions: np.ndarray
    springs: Any
    live_springs: Any
    time: float
    surface: Any = None  # the cloth's Surface (a mesh cloth's triangles and UVs)


def view_cameras(task: Task, samples: np.ndarray) -> list[Any]:
    """The run's cameras: the scene's ``render.views`` (the first ``task.views``), or as many
    drawn around the bounding sphere of the cloth over every sampled frame from ``task.view_seed``."""
    from ..render.views import ViewCamera, draw_cameras, frame_bounds

    st = task.settings
    w, h = task.size
    if st.views:
        if len(st.views) < task.views:
            raise ClothsimError(f"--views {task.views}: the scene lists only {len(st.views)} in render.views")
        return [ViewCamera(tuple(pos), tuple(tgt), float(fov if fov is not None else st.fov), w, h, st.near, st.far)
                for pos, tgt, fov in st.views[:task.views]]
    centre, radius = frame_bounds(samples)
    return draw_cameras(task.view_seed, task.views, centre, radius, st.fov, w, h, st.near, st.far)


def draw_views(task: Task, sim: Any, samples: np.ndarray, moments: list[tuple[float, Any]]) -> dict[str, Any]:
    """Every view's channels at every sampled frame: ``rgb`` (V, T, H, W, 3) uint8, ``depth``
    (V, T, H, W) float32, ``normal`` (V, T, H, W, 3) float16, ``mask`` (V, T, H, W) uint8, ``flow``
    (V, T-1, H, W, 2) float32 (those asked for), and ``cameras`` (their dicts)."""
    cams = view_cameras(task, samples)
    draw = renderer(task.size, task.samples)
    w, h = task.size
    n_v, n_t = len(cams), samples.shape[0]
    want = set(task.channels)
    from ..render.channels import collider_ids

    ids = collider_ids(task.scene)
    out: dict[str, Any] = {"cameras": [{**c.as_dict(), "mask_ids": ids} for c in cams]}
    if "rgb" in want:
        out["rgb"] = np.empty((n_v, n_t, h, w, 3), dtype=np.uint8)
    data = want & {"depth", "normal", "mask", "flow"}
    if "depth" in want:
        out["depth"] = np.empty((n_v, n_t, h, w), dtype=np.float32)
    if "normal" in want:
        out["normal"] = np.empty((n_v, n_t, h, w, 3), dtype=np.float16)
    if "mask" in want:
        out["mask"] = np.empty((n_v, n_t, h, w), dtype=np.uint8)
    if "flow" in want:
        out["flow"] = np.empty((n_v, max(n_t - 1, 0), h, w, 2), dtype=np.float32)
    for t in range(n_t):
        now, live = moments[t]
        frame = _Frame(sim.scene, sim.nw, sim.nh, samples[t].astype(np.float64), sim.springs, live, now,
                       getattr(sim, "surface", None))
        following = samples[t + 1] if t + 1 < n_t else None
        for v, cam in enumerate(cams):
            if "rgb" in out:
                out["rgb"][v, t] = draw.render(frame, settings=task.settings, camera=cam.camera())
            if data:
                ch = draw.render_channels(frame, cam, following)
                if "depth" in out:
                    out["depth"][v, t] = ch.depth
                if "normal" in out:
                    out["normal"][v, t] = ch.normal
                if "mask" in out:
                    out["mask"][v, t] = ch.mask
                if "flow" in out and following is not None:
                    out["flow"][v, t] = ch.flow
    return out
