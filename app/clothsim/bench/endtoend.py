"""The end of ``clothsim bench render``: frames per second of a whole clip, as ``clothsim render`` makes it.

Four figures, each the median over repeats, timed round-robin (one repeat of each in turn) so that
a slow period of a shared machine hits them all alike:

- ``overlapped``: the clip as ``clothsim render`` makes it, the simulation a few drawn frames
  ahead in its thread (:func:`clothsim.render.pipeline.clip_frames`);
- ``serial``: the same clip with the simulation in the drawing thread, one step after the other;
- ``render only``: the same states drawn and read back with no simulation (recorded once);
- ``driver limit``: those states drawn with a constant-colour fragment shader, what the driver
  fills at this size and sampling whatever the look computes.

Frames per second are drawn frames (the clip's output) per second of wall time, from the first
simulated frame to the last image read back; encoding the output is not included. Beside them, the
process's CPU time per image (every thread: the simulation's team, llvmpipe's rasterisers, Python)
and the cores it kept busy on average: a clip can be no faster than its CPU time per image
divided by the cores there are.
"""

from __future__ import annotations

import statistics
import time
from collections.abc import Callable
from typing import Any

from ..render.pipeline import AHEAD, ClipStats, clip_frames
from ..render.programs import LOOKS, read_source
from ..scene import load_scene

#: The driver-limit look: the vertex stage of the timed look, one constant colour per fragment.
FLAT_FRAGMENT = "#version 330 core\nout vec4 out_color;\nvoid main() { out_color = vec4(0.5, 0.5, 0.5, 1.0); }\n"


def run_end_to_end(scene_name: str, size: tuple[int, int], samples: int, look: str, frames: int, every: int,
                   repeats: int, make_renderer: Callable[..., Any]) -> int:
    """Print the four figures for ``look`` on ``scene_name``; returns the exit status."""
    from ..sim.simulation import Simulation

    scene = load_scene(scene_name)
    renderer = make_renderer(size, samples, size_label="--size")
    flat = make_renderer(size, samples, size_label="--size",
                         sources={look: (read_source(LOOKS[look][0]), FLAT_FRAGMENT)})
    try:
        settings = renderer.settings_for(scene)
        states = list(clip_frames(Simulation(scene), frames, every, False, None, ClipStats(), ahead=0))
        for r in (renderer, flat):
            r.render(states[0], look, settings)  # programs, buffers, textures

        def clip(ahead: int) -> tuple[float, float]:
            sim = Simulation(scene)
            t0, c0 = time.perf_counter(), time.process_time()
            n = 0
            for state in clip_frames(sim, frames, every, False, None, ClipStats(), ahead=ahead):
                renderer.render(state, look, settings)
                n += 1
            return n / (time.perf_counter() - t0), (time.process_time() - c0) / n

        def draw_only(r: Any) -> tuple[float, float]:
            t0, c0 = time.perf_counter(), time.process_time()
            for state in states:
                r.render(state, look, settings)
            return len(states) / (time.perf_counter() - t0), (time.process_time() - c0) / len(states)

        variants: dict[str, Callable[[], tuple[float, float]]] = {
            "overlapped": lambda: clip(AHEAD),
            "serial": lambda: clip(0),
            "render only": lambda: draw_only(renderer),
            "driver limit": lambda: draw_only(flat),
        }
        clip(AHEAD)  # the simulation's kernels, warm
        runs: dict[str, list[float]] = {k: [] for k in variants}
        cpu: dict[str, list[float]] = {k: [] for k in variants}
        for _ in range(repeats):
            for name, fn in variants.items():
                fps, seconds = fn()
                runs[name].append(fps)
                cpu[name].append(seconds)
        info = renderer.info()
        aa = f"{renderer.samples}x MSAA" if renderer.samples else "no MSAA"
        print(f"end to end: {scene_name}, {look}, {size[0]}x{size[1]}, {aa}, "
              f"{info['renderer']} ({info['version']})")
        print(f"a clip of {frames} frames from the start, every {every} drawn ({len(states)} images); {repeats} "
              "repeats round-robin; medians of images per second (simulate + draw + read back, no encoding), "
              "of the process's CPU ms per image (all threads) and of the cores it kept busy")
        print(f"{'':<14}{'fps':>8}{'min':>8}{'max':>8}{'vs render only':>16}{'vs limit':>10}{'CPU ms':>8}{'cores':>7}")
        only = statistics.median(runs["render only"])
        limit = statistics.median(runs["driver limit"])
        for name, values in runs.items():
            m = statistics.median(values)
            busy = statistics.median(c * f for c, f in zip(cpu[name], values))
            print(f"{name:<14}{m:>8.1f}{min(values):>8.1f}{max(values):>8.1f}{m / only:>16.0%}{m / limit:>10.0%}"
                  f"{1e3 * statistics.median(cpu[name]):>8.2f}{busy:>7.2f}")
    finally:
        flat.release()
        renderer.release()
    return 0

