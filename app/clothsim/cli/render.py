"""CLI subcommands of the renderer: ``render``, ``info`` and ``bench render``.

Nothing here imports moderngl at import time: commands that only simulate must never load
libEGL, so the GL side is imported inside the functions that draw.
"""

from __future__ import annotations

import argparse
import contextlib
import statistics
import sys
import time
from typing import Any

from .. import validate as V
from ..commands import add_command, add_output
from ..errors import ClothsimError
from ..render.settings import SHADERS, TERMS, RenderSettings, parse_size
from ..scene import MAX_FPS, MIN_FPS

DEFAULT_SCENE = "pinned2"
DEFAULT_FRAMES = 90


def add_parsers(sub: argparse._SubParsersAction, bench_sub: argparse._SubParsersAction) -> None:
    """Register ``render`` and ``info`` on ``sub`` and ``render`` on the ``bench`` subparsers."""
    p = add_command(sub, "render", "simulate a scene and render it to .png/.gif/.mp4 or a folder of PNGs",
                    "Simulate SCENE and render it headless (EGL). A .png gets the state after --frames frames; "
                    ".gif, .mp4 and folders get every --every-th frame from the start. Flags override the "
                    "scene's optional \"render\" object.", scene=DEFAULT_SCENE)
    add_output(p, ".png, .gif, .mp4, or a directory (no suffix or trailing /) for numbered PNGs")
    p.add_argument("--shader", choices=SHADERS, help="look (default: scene, else phong)")
    p.add_argument("--frames", type=int, default=DEFAULT_FRAMES, metavar="N",
                   help=f"frames to simulate (default {DEFAULT_FRAMES}: one second at 90 frames/s)")
    p.add_argument("--every", type=int, metavar="K",
                   help="keep every K-th frame in an animation (default: 3 for .gif/.mp4, 1 for folders)")
    p.add_argument("--no-rest", action="store_true",
                   help="keep simulating a cloth that is at rest (by default, once no point moves more than "
                        "simulation.rest_tolerance per frame for rest_frames frames, later frames reuse the image)")
    p.add_argument("--profile", action="store_true",
                   help="print where the time went: simulation, rendering, frames reused at rest")
    p.add_argument("--video-fps", type=float, metavar="F",
                   help="playback rate of .gif/.mp4 (default: the scene's frames_per_sec / K, real time)")
    p.add_argument("--size", metavar="WxH", help="image size in pixels (default: scene, else 800x800)")
    p.add_argument("--samples", type=int, metavar="N", help="multisampling samples per pixel, 0 for none (default 4)")
    g = p.add_argument_group("camera and light")
    g.add_argument("--camera-position", nargs=3, type=float, metavar=("X", "Y", "Z"))
    g.add_argument("--camera-target", nargs=3, type=float, metavar=("X", "Y", "Z"),
                   help="default: the cloth's centroid, followed frame by frame")
    g.add_argument("--fov", type=float, metavar="DEG", help="vertical field of view (default 35)")
    g.add_argument("--light-position", nargs=3, type=float, metavar=("X", "Y", "Z"), help="default 0.5 2 2")
    g.add_argument("--light-intensity", nargs=3, type=float, metavar=("R", "G", "B"), help="default 3 3 3")
    m = p.add_argument_group("material")
    m.add_argument("--color", metavar="COLOUR", help="cloth colour, #rrggbb or r,g,b in 0..1 (sRGB)")
    m.add_argument("--background", metavar="COLOUR", help="background colour, #rrggbb or r,g,b")
    m.add_argument("--ka", type=float, help="Blinn-Phong ambient coefficient k_a (default 0.1)")
    m.add_argument("--kd", type=float, help="diffuse coefficient k_d (default 1.0)")
    m.add_argument("--ks", type=float, help="specular coefficient k_s (default 0.5)")
    m.add_argument("--shininess", type=float, metavar="P", help="specular exponent p (default 100)")
    m.add_argument("--ambient-intensity", nargs=3, type=float, metavar=("R", "G", "B"), help="I_a (default 1 1 1)")
    m.add_argument("--terms", metavar="LIST",
                   help=f"Blinn-Phong terms to keep, comma-separated from {','.join(TERMS)} (default all)")
    m.add_argument("--normal-scaling", type=float, metavar="K_N", help="bump normal scaling (default 2.0)")
    m.add_argument("--height-scaling", type=float, metavar="K_H", help="bump/displacement height (default 0.1)")
    m.add_argument("--reflectivity", type=float, metavar="R", help="custom look: cubemap share 0..1 (default 0.35)")
    m.add_argument("--sphere-resolution", nargs=2, type=int, metavar=("LAT", "LONG"),
                   help="sphere mesh rings and segments (default 40 40)")
    m.add_argument("--texture", metavar="IMAGE", help="colour texture image (default: built-in tartan)")
    m.add_argument("--height-map", metavar="IMAGE", help="height map image, red/grey channel (default: built-in quilt)")
    m.add_argument("--cubemap", nargs=6, metavar="FACE", help="six images: +x -x +y -y +z -z (default: built-in sky)")
    m.add_argument("--color-by-family", action="store_true",
                   help="wireframe: colour structural, shearing and bending springs differently")
    try:
        from ..commands import add_scene_overrides
    except ImportError:  # pragma: no cover - the simulate command is always there
        pass
    else:
        add_scene_overrides(p)
    p.set_defaults(func=run_render)

    info = sub.add_parser("info", help="print the OpenGL vendor, renderer and version the renderer gets")
    info.set_defaults(func=run_info)

    b = bench_sub.add_parser("render", help="frames per second per shader, and where a frame's time goes",
                             description="Render a scene with each shader and report frames per second of "
                                         "render + read-back, and the share of a frame (simulation included) "
                                         "spent in simulation, mesh update, upload, draw and read-back; then "
                                         "a clip end to end with the first look (phong if listed): "
                                         "--frames frames simulated and drawn, the simulation overlapped and "
                                         "serial, against drawing alone and the driver's fill limit, each with "
                                         "the process's CPU time per image and the cores it kept busy. "
                                         "Medians over repeats.")
    b.add_argument("scene", nargs="?", default="sphere", help="scene (default: sphere)")
    b.add_argument("--size", default="800x800", metavar="WxH", help="image size (default 800x800)")
    b.add_argument("--samples", type=int, default=4, metavar="N", help="multisampling samples, 0 for none (default 4)")
    b.add_argument("--frames", type=int, default=60, metavar="N", help="timed frames per repeat (default 60)")
    b.add_argument("--repeats", type=int, default=5, metavar="R", help="repeats; the median is shown (default 5)")
    b.add_argument("--warmup", type=int, default=60, metavar="N",
                   help="frames simulated before timing, so the cloth is draped, not flat (default 60)")
    b.add_argument("--shaders", default=",".join(SHADERS), metavar="LIST", help="comma-separated looks (default: all)")
    b.set_defaults(func=run_bench_render)


# -- render --------------------------------------------------------------------------------------
def cli_overrides(args: argparse.Namespace) -> dict[str, Any]:
    """The render flags given on the command line, as a ``render``-shaped dict."""
    o: dict[str, Any] = {}
    if args.shader:
        o["shader"] = args.shader
    if args.size:
        o["size"] = args.size
    if args.samples is not None:
        o["samples"] = args.samples
    cam = {k: v for k, v in (("position", args.camera_position), ("target", args.camera_target),
                             ("fov", args.fov)) if v is not None}
    if cam:
        o["camera"] = cam
    light = {k: v for k, v in (("position", args.light_position), ("intensity", args.light_intensity))
             if v is not None}
    if light:
        o["light"] = light
    for key, value in (("color", args.color), ("background", args.background)):
        if value is not None:
            o[key] = _colour_arg(value)
    phong = {k: v for k, v in (("k_a", args.ka), ("k_d", args.kd), ("k_s", args.ks), ("p", args.shininess),
                               ("I_a", args.ambient_intensity), ("terms", args.terms)) if v is not None}
    if phong:
        o["phong"] = phong
    for key in ("normal_scaling", "height_scaling", "reflectivity", "sphere_resolution"):
        value = getattr(args, key)
        if value is not None:
            o[key] = value
    tex = {k: v for k, v in (("color", args.texture), ("height", args.height_map), ("cubemap", args.cubemap))
           if v is not None}
    if tex:
        o["textures"] = tex
    if args.color_by_family:
        o["wireframe"] = {"color_by_family": True}
    return o


# JSON field -> the flag that sets it, so that errors name what the user typed.
_FLAGS = {
    "shader": "--shader", "size": "--size", "samples": "--samples", "camera.position": "--camera-position",
    "camera.target": "--camera-target", "camera.fov": "--fov", "light.position": "--light-position",
    "light.intensity": "--light-intensity", "color": "--color", "background": "--background",
    "phong.k_a": "--ka", "phong.k_d": "--kd", "phong.k_s": "--ks", "phong.p": "--shininess",
    "phong.I_a": "--ambient-intensity", "phong.terms": "--terms", "normal_scaling": "--normal-scaling",
    "height_scaling": "--height-scaling", "reflectivity": "--reflectivity",
    "sphere_resolution": "--sphere-resolution", "textures.color": "--texture", "textures.height": "--height-map",
    "textures.cubemap": "--cubemap",
}


def _flag_label(field: str) -> str:
    base = field.split("[")[0]
    return _FLAGS.get(base, field)


def _colour_arg(text: str) -> Any:
    if "," in text:
        try:
            return [float(c) for c in text.split(",")]
        except ValueError:
            return text
    return text


def run_render(args: argparse.Namespace) -> int:
    """``clothsim render``: simulate, draw and write the output atomically."""
    from .. import output
    from ..atomic import check_name
    from ..scene import load_scene

    check_name(args.output)  # a name too long would end the checks below in an OSError
    fmt = output.check_output(args.output)  # fail on an output we could not write before any work
    V.check(V.integer(ge=0), args.frames, "--frames")
    every = V.check(V.integer(ge=1), args.every, "--every") if args.every is not None else (1 if fmt == "dir" else 3)
    if args.video_fps is not None:
        V.check(V.number(ge=MIN_FPS, le=MAX_FPS), args.video_fps, "--video-fps")
    scene = load_scene(args.scene)
    try:
        from ..commands import apply_overrides
    except ImportError:  # pragma: no cover
        pass
    else:
        scene = apply_overrides(scene, args)
    settings = RenderSettings.from_scene(scene).with_overrides(cli_overrides(args), label=_flag_label)
    fps = args.video_fps if args.video_fps is not None else scene.simulation.frames_per_sec / every

    from ..render.pipeline import ClipStats, clip_frames
    from ..sim.rest import RestDetector
    from ..sim.simulation import Simulation

    sim = Simulation(scene)
    renderer = _renderer(settings.size, settings.samples, size_label=_size_label(args, scene))
    rest = None if args.no_rest else RestDetector(scene.simulation.rest_tolerance, scene.simulation.rest_frames)
    if rest is not None:
        rest.update(sim._pos)
    renderer.prepare(scene, settings.shader)
    stats = ClipStats()
    render_s = 0.0
    counts = {"rendered": 0, "reused": 0}
    image = None
    try:
        with output.open_output(args.output, fps) as sink, _progress(args.frames, settings.shader) as bar:
            stats.progress = bar.update
            # The simulation runs a few drawn frames ahead in a thread while the driver draws.
            with contextlib.closing(clip_frames(sim, args.frames, every, fmt == "png", rest, stats)) as states:
                for state in states:
                    if state is None:
                        counts["reused"] += 1
                    else:
                        t0 = time.perf_counter()
                        image = renderer.render(state, settings=settings)
                        render_s += time.perf_counter() - t0
                        counts["rendered"] += 1
                    sink(image)
    finally:
        renderer.release()
    rested_at = stats.rested_at
    timing = {"simulate": stats.simulate_s, "render": render_s}
    counts["simulated"] = stats.simulated
    if rested_at is not None:
        print(f"cloth at rest after frame {rested_at}; later frames reuse its image", file=sys.stderr)
    if args.profile:
        total = sum(timing.values()) or 1e-12
        print(f"{'part':<12}{'count':>8}{'total ms':>11}{'share':>8}")
        print(f"{'simulate':<12}{counts['simulated']:>8}{timing['simulate'] * 1e3:>11.1f}{timing['simulate'] / total:>8.1%}")
        print(f"{'render':<12}{counts['rendered']:>8}{timing['render'] * 1e3:>11.1f}{timing['render'] / total:>8.1%}")
        print(f"{'reused':<12}{counts['reused']:>8}   frames at rest: neither simulated nor drawn")
    print(f"wrote {args.output}", file=sys.stderr)
    return 0


def _size_label(args: argparse.Namespace, scene: Any) -> str:
    """What set the image size, as the user wrote it: the flag, else the scene's field."""
    if args.size is None and isinstance(scene.render, dict) and "size" in scene.render:
        return f"{scene.path}: render.size"
    return "--size"


def _renderer(size: tuple[int, int], samples: int, size_label: str, **kwargs: Any) -> Any:
    """A Renderer; an image too large for the driver or the memory names what set its size."""
    from ..render.renderer import Renderer, RenderSizeError

    try:
        return Renderer(*size, samples=samples, **kwargs)
    except RenderSizeError as exc:
        raise ClothsimError(f"{size_label}: {exc}") from None


def _progress(total: int, desc: str) -> Any:
    try:
        from ..commands import progress
    except ImportError:  # pragma: no cover
        from tqdm import tqdm

        return tqdm(total=total, desc=desc, unit="frame", disable=not sys.stderr.isatty(), leave=False)
    return progress(total, desc)


# -- info ----------------------------------------------------------------------------------------
def run_info(args: argparse.Namespace) -> int:
    """``clothsim info``: what OpenGL the renderer gets."""
    from ..render.context import create_context, describe

    ctx = create_context()
    try:
        d = describe(ctx)
        print(f"GL vendor:    {d['vendor']}")
        print(f"GL renderer:  {d['renderer']}")
        print(f"GL version:   {d['version']}")
        print(f"version code: {d['version_code']} (the shaders need 330)")
        print(f"max samples:  {ctx.max_samples}")
    finally:
        ctx.release()
    return 0


# -- bench render --------------------------------------------------------------------------------
def run_bench_render(args: argparse.Namespace) -> int:
    """``clothsim bench render``: per-shader frames per second and a frame's time by stage."""
    from ..scene import load_scene
    from ..sim.simulation import Simulation
    from ..render.renderer import STAGES

    try:
        width, height = parse_size(args.size)
    except ValueError as exc:
        raise ClothsimError(f"--size: {exc}") from None
    shaders = [s.strip() for s in args.shaders.split(",") if s.strip()]
    for s in shaders:
        if s not in SHADERS:
            raise ClothsimError(f"--shaders: unknown shader {s!r} (expected some of: {', '.join(SHADERS)})")
    if args.frames < 1 or args.repeats < 1 or args.warmup < 0:
        raise ClothsimError("--frames and --repeats must be >= 1, --warmup >= 0")
    scene = load_scene(args.scene)
    renderer = _renderer((width, height), args.samples, size_label="--size", profile=True)
    try:
        info = renderer.info()
        aa = f"{renderer.samples}x MSAA" if renderer.samples else "no MSAA"
        print(f"bench render: {args.scene}, {width}x{height}, {aa}, "
              f"{info['renderer']} ({info['version']})")
        print(f"{args.frames} frames x {args.repeats} repeats per shader, round-robin, after {args.warmup} warm-up "
              "frames; medians; fps = render + read-back only; shares are of a whole frame incl. simulation")
        header = f"{'shader':<13}{'fps':>8}{'ms/frame':>10}{'sim':>7}" + "".join(f"{s:>9}" for s in STAGES)
        print(header)
        # Each look draws its own simulation of the same frames; one repeat of each in turn, so
        # that a slow spell of a shared machine hits every look alike (the ratios between looks
        # hold even when the figures move).
        sims = {}
        for look in shaders:
            sims[look] = Simulation(scene)
            sims[look].step(args.warmup)
            renderer.render(sims[look], look)  # compiles the program, builds buffers and textures
        fps_runs: dict[str, list[float]] = {look: [] for look in shaders}
        ms_runs: dict[str, list[float]] = {look: [] for look in shaders}
        shares: dict[str, list[dict[str, float]]] = {look: [] for look in shaders}
        for _ in range(args.repeats):
            for look in shaders:
                sim = sims[look]
                totals = dict.fromkeys(("sim", *STAGES), 0.0)
                for _ in range(args.frames):
                    t = time.perf_counter()
                    sim.step(1)
                    totals["sim"] += time.perf_counter() - t
                    renderer.render(sim, look)
                    for stage in STAGES:
                        totals[stage] += renderer.timings[stage]
                render_s = sum(totals[s] for s in STAGES)
                frame_s = render_s + totals["sim"]
                fps_runs[look].append(args.frames / render_s)
                ms_runs[look].append(1000.0 * frame_s / args.frames)
                shares[look].append({k: v / frame_s for k, v in totals.items()})
        for look in shaders:
            share = {k: statistics.median(s[k] for s in shares[look]) for k in ("sim", *STAGES)}
            print(f"{look:<13}{statistics.median(fps_runs[look]):>8.1f}{statistics.median(ms_runs[look]):>10.2f}"
                  f"{share['sim']:>7.0%}" + "".join(f"{share[s]:>9.0%}" for s in STAGES))
    finally:
        renderer.release()
    from ..bench.endtoend import run_end_to_end

    print()
    return run_end_to_end(args.scene, (width, height), args.samples, "phong" if "phong" in shaders else shaders[0],
                          args.frames, 1, args.repeats, _renderer)
