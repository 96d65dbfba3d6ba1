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
    ``positions`` float32 (T, N, 3), ``pinned``, ``nw``/``nh``, ``cells`` {frame: image},
    ``video`` (V, H, W, 3) uint8 or None, and ``seconds``."""
    start = time.perf_counter()
    result: dict[str, Any] = {"id": task.id, "status": "done", "error": None, "positions": None,
                              "pinned": None, "nw": None, "nh": None, "cells": {}, "video": None}
    try:
        _simulate(task, result)
    except Exception as exc:  # a blow-up, a bad value met only at run time, a driver failure
        result.update(status="failed", error=_one_line(exc), positions=None, cells={}, video=None)
    except MemoryError as exc:
        result.update(status="failed", error=_one_line(exc), positions=None, cells={}, video=None)
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
    wanted = sample_frames(task.frames, task.every) if (task.positions or task.video) else []
    wanted_set = set(wanted)
    cells = sorted(set(task.cells))
    draw = renderer(task.size, task.samples) if (cells or task.video) else None

    def image() -> np.ndarray:
        return draw.render(sim, settings=task.settings)

    samples = np.empty((len(wanted), sim.nw * sim.nh, 3), dtype=np.float32) if task.positions else None
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
