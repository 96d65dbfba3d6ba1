"""``clothsim bench serve``: frames per second that ``clothsim serve`` streams, against the renderer alone.

For each image size, in the same run and the same process: the baseline loop (one simulation
frame and one ``Renderer.render`` per image, as the server does), the same loop with the JPEG
encode added, and the server itself with a WebSocket client on this machine counting the frames
it receives. Each is timed over the same number of seconds after a warm-up, the three taking
turns in every repeat; the medians of the repeats are printed.
"""

from __future__ import annotations

import argparse
import asyncio
import statistics
import time

from ..commands import add_command
from ..errors import ClothsimError
from ..render.settings import SHADERS, parse_size


def add_parser(bench_sub: argparse._SubParsersAction) -> None:
    """Register ``clothsim bench serve``."""
    p = add_command(bench_sub, "serve", "frames/s streamed by clothsim serve vs the renderer alone",
                    "Frames per second of the renderer alone (simulate + render), with the JPEG encode, and "
                    "streamed by clothsim serve to a WebSocket client on this machine; medians of repeats, per "
                    "image size. The default scene is the one clothsim serve opens.")
    p.add_argument("--sizes", default="512x512,800x800", metavar="LIST", help="image sizes (default 512x512,800x800)")
    p.add_argument("--shader", default="phong", choices=SHADERS, help="look (default phong)")
    p.add_argument("--seconds", type=float, default=5.0, metavar="S", help="timed seconds per repeat (default 5)")
    p.add_argument("--repeats", type=int, default=3, metavar="R", help="repeats; the median is shown (default 3)")
    p.set_defaults(func=run)


def run(args: argparse.Namespace) -> int:
    """Body of ``clothsim bench serve``."""
    try:
        import aiohttp  # noqa: F401
    except ImportError:
        from ..serve.command import EXTRA_HINT

        raise ClothsimError(EXTRA_HINT) from None
    from ..render.settings import RenderSettings
    from ..scene import load_scene

    try:
        sizes = [parse_size(s) for s in args.sizes.split(",") if s.strip()]
    except ValueError as exc:
        raise ClothsimError(f"--sizes: {exc}") from None
    if args.seconds <= 0 or args.repeats < 1:
        raise ClothsimError("--seconds must be > 0 and --repeats >= 1")
    scene = load_scene(args.scene)
    settings = RenderSettings.from_scene(scene).with_overrides({"shader": args.shader})
    print(f"bench serve: {args.scene}, {args.shader}, {args.seconds:g} s x {args.repeats} repeats per figure; medians")
    print(f"{'size':<11}{'render':>9}{'+JPEG':>9}{'streamed':>10}{'vs render':>11}   (frames per second)")
    for width, height in sizes:
        base, enc, streamed = [], [], []
        for _ in range(args.repeats):  # interleaved, so that a slow spell of the machine hits all three
            base.append(_baseline(scene, settings, (width, height), args.seconds, jpeg=False))
            enc.append(_baseline(scene, settings, (width, height), args.seconds, jpeg=True))
            streamed.append(asyncio.run(_streamed(scene, args.scene, settings, (width, height), args.seconds)))
        b, e, s = statistics.median(base), statistics.median(enc), statistics.median(streamed)
        print(f"{f'{width}x{height}':<11}{b:>9.1f}{e:>9.1f}{s:>10.1f}{s / b:>10.0%}")
    return 0


def _baseline(scene, settings, size: tuple[int, int], seconds: float, jpeg: bool) -> float:  # noqa: ANN001
    from ..render.renderer import Renderer
    from ..serve.engine import JPEG_QUALITY, _encode
    from ..sim.simulation import Simulation

    sim = Simulation(scene)
    with Renderer(*size, samples=settings.samples) as renderer:
        sim.step(1)
        renderer.render(sim, settings=settings)  # compiles the program, builds the buffers
        frames, start = 0, time.perf_counter()
        while time.perf_counter() - start < seconds:
            sim.step(1)
            image = renderer.render(sim, settings=settings)
            if jpeg:
                _encode(image, "JPEG", quality=JPEG_QUALITY)
            frames += 1
        return frames / (time.perf_counter() - start)


async def _streamed(scene, name: str, settings, size: tuple[int, int], seconds: float) -> float:  # noqa: ANN001
    import aiohttp

    from ..serve.app import Server

    server = Server(scene, name, port=0, size=size, samples=settings.samples, settings=settings)
    await server.start()
    try:
        async with aiohttp.ClientSession() as session:
            ws_url = server.url.replace("http://", "ws://").replace("/?token=", "/ws?token=")
            async with session.ws_connect(ws_url, max_msg_size=0) as ws:
                await _count(ws, 1.0)  # the first frames build the GL resources
                return await _count(ws, seconds)
    finally:
        await server.stop()


async def _count(ws, seconds: float) -> float:  # noqa: ANN001
    import aiohttp

    frames, start = 0, time.perf_counter()
    while (elapsed := time.perf_counter() - start) < seconds:
        try:
            msg = await asyncio.wait_for(ws.receive(), timeout=max(seconds - elapsed, 0.001))
        except asyncio.TimeoutError:
            break
        if msg.type == aiohttp.WSMsgType.BINARY:
            frames += 1
        elif msg.type in (aiohttp.WSMsgType.CLOSED, aiohttp.WSMsgType.ERROR):
            raise ClothsimError("bench serve: the server closed the connection")
    return frames / (time.perf_counter() - start)
