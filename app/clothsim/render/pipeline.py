"""The frames of a rendered clip: which states are drawn, with the simulation run ahead in a thread.

:func:`clip_frames` yields the states a clip draws, in order: frame 0 and every ``every``-th frame
after it (or only the last state, for a still image), each as a :class:`Snapshot`, or ``None``
where the cloth is at rest and the previous image is reused. With ``ahead`` > 0 a thread
simulates up to ``ahead`` drawn frames beyond the one being drawn: the renderer waits for the
driver without the GIL (see waits.py), and the Numba kernels of the simulation run in that time.
The states are copies taken where the serial loop would have drawn them, so the images, and the
files made from them, are the same bytes either way.
"""

from __future__ import annotations

import queue
import threading
import time
from collections.abc import Iterator
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from ..cloth import Springs
from ..jit.compile import warm_side_kernels
from ..scene import Scene
from . import mesh  # registers the drawing's kernel for warm_side_kernels

#: Drawn frames the simulation thread may run ahead of the drawing; two keep it busy through a
#: long draw without holding more than a few copies of the positions.
AHEAD = 2


@dataclass(frozen=True)
class Snapshot:
    """A simulation's state at one frame: what :meth:`Renderer.render` reads from it."""

    scene: Scene
    nw: int  # 0 for a mesh cloth (drawn from ``surface``)
    nh: int
    positions: np.ndarray
    springs: Springs
    live_springs: Springs
    time: float
    frame: int
    surface: Any = None  # a mesh cloth's clothsim.cloth.Surface (computed once by the Simulation)

    @classmethod
    def of(cls, sim: Any) -> "Snapshot":
        # (a grid's surface is not read: a grid is drawn from nw x nh)
        surface = getattr(sim, "surface", None) if sim.nw == 0 else None
        return cls(scene=sim.scene, nw=sim.nw, nh=sim.nh, positions=np.array(sim.positions, dtype=np.float64),
                   springs=sim.springs, live_springs=sim.live_springs, time=float(sim.time), frame=int(sim.frame),
                   surface=surface)


@dataclass
class ClipStats:
    """What a clip cost: seconds simulating (in whichever thread), frames simulated and when the
    cloth came to rest (None if it did not)."""

    simulate_s: float = 0.0
    simulated: int = 0
    rested_at: int | None = None
    progress: Any = field(default=None, repr=False)  # called with 1 after every simulated frame


def clip_frames(sim: Any, frames: int, every: int, still: bool, rest: Any, stats: ClipStats,
                ahead: int = AHEAD) -> Iterator[Snapshot | None]:
    """The states to draw, in order (see the module docstring).

    ``still``: only the state after ``frames`` frames; otherwise frame 0 and every ``every``-th.
    ``rest`` is a :class:`~clothsim.sim.rest.RestDetector` already fed the initial state, or None
    to simulate every frame. ``ahead`` 0 runs the simulation in the caller's thread.
    """
    plan = _Plan(sim, frames, every, still, rest, stats)
    if ahead <= 0 or still:  # a still image draws once, at the end: nothing to overlap
        yield from plan.events()
        return
    yield from _threaded(plan, ahead)


class _Stopped(Exception):
    """The consumer is gone: the simulation thread ends before its next frame."""


class _Plan:
    """The serial order of simulating and drawing; a drawn state is taken where it is due."""

    def __init__(self, sim: Any, frames: int, every: int, still: bool, rest: Any, stats: ClipStats) -> None:
        self.sim, self.frames, self.every, self.still, self.rest, self.stats = sim, frames, every, still, rest, stats
        self.drawn = False
        self.frozen = False
        self.stop: threading.Event | None = None  # set by the consumer of a threaded plan

    def advance(self) -> None:
        # A cloth at rest is not simulated any further: its state (and so its image) stays put.
        if self.stop is not None and self.stop.is_set():
            raise _Stopped
        stats, sim = self.stats, self.sim
        if stats.rested_at is None:
            t0 = time.perf_counter()
            sim.step(1)
            stats.simulate_s += time.perf_counter() - t0
            stats.simulated += 1
            if self.rest is not None and self.rest.update(sim._pos) and sim.time >= sim.colliders_still_after:
                stats.rested_at = sim.frame
        if stats.progress is not None:
            stats.progress(1)

    def draw(self) -> Snapshot | None:
        reuse = self.drawn and self.frozen
        self.drawn = True
        self.frozen = self.stats.rested_at is not None
        return None if reuse else Snapshot.of(self.sim)

    def events(self) -> Iterator[Snapshot | None]:
        if self.still:
            for _ in range(self.frames):
                self.advance()
            yield self.draw()
            return
        yield self.draw()
        for frame in range(1, self.frames + 1):
            self.advance()
            if frame % self.every == 0:
                yield self.draw()


_DONE = object()


def _threaded(plan: _Plan, ahead: int) -> Iterator[Snapshot | None]:
    """Run ``plan`` in a thread, ``ahead`` drawn frames at most before the consumer; its errors
    reach the consumer in order, and a consumer that stops early stops the thread."""
    out: queue.Queue[Any] = queue.Queue(maxsize=ahead)
    stop = threading.Event()
    plan.stop = stop

    def put(item: Any) -> bool:
        while not stop.is_set():
            try:
                out.put(item, timeout=0.05)
                return True
            except queue.Full:
                continue
        return False

    def run() -> None:
        try:
            for event in plan.events():
                if not put(("frame", event)):
                    return
        except _Stopped:
            return
        except BaseException as exc:  # handed over, raised again in the consumer's thread
            put(("error", exc))
            return
        put(("done", _DONE))

    # Numba's compiling and cache loading is not thread-safe: the drawing's first call of its
    # kernel, loading it, at the moment the thread's first frame loads the simulation's, failed
    # in Numba's typing registry ("generator already executing"; seen once in CI). So the kernels
    # this thread's consumer calls are loaded before the thread starts.
    if getattr(plan.sim.scene.cloth, "is_mesh", False):
        mesh.register_surface_warm()
    warm_side_kernels()
    worker = threading.Thread(target=run, name="clothsim-simulate", daemon=True)
    worker.start()
    try:
        while True:
            kind, item = out.get()
            if kind == "frame":
                yield item
            elif kind == "error":
                raise item
            else:
                return
    finally:
        stop.set()
        worker.join()
