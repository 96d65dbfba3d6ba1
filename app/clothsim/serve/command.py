"""``clothsim serve``: the course's interactive program as a page in a browser.

aiohttp (the ``serve`` extra) is imported only when the command runs.
"""

from __future__ import annotations

import argparse
import asyncio
import ipaddress
import signal
import sys
from pathlib import Path

from .. import validate as V
from ..errors import ClothsimError
from ..render.settings import SHADERS, RenderSettings

EXTRA_HINT = "clothsim serve needs the 'serve' extra (aiohttp): pip install 'clothsim[serve]'"
DEFAULT_PORT = 8000


def add_parser(sub: argparse._SubParsersAction) -> None:
    """Register ``clothsim serve``."""
    p = sub.add_parser(
        "serve", help="the interactive GUI in a browser: a local web server streaming the renderer's frames",
        description="Start a local web server that runs SCENE and streams the headless renderer's frames to a "
                    "page with the course GUI's controls (parameters, shaders, P/N/R/SPACE, camera, scenes, "
                    "image and clip downloads). Prints the URL to open, with its access token; Ctrl-C stops it. "
                    "From another machine: ssh -L 8000:127.0.0.1:8000 SERVER, then open the URL locally.")
    p.add_argument("scene", nargs="?", default="pinned2", help="scene file or bundled scene name (default: pinned2)")
    p.add_argument("--port", type=int, default=DEFAULT_PORT, metavar="N",
                   help=f"TCP port (default {DEFAULT_PORT}; 0 picks a free one)")
    p.add_argument("--host", default="127.0.0.1", metavar="ADDRESS",
                   help="address to listen on (default 127.0.0.1: this machine only; reach it over ssh -L)")
    p.add_argument("--size", metavar="WxH", help="streamed image size in pixels (default: scene, else 800x800)")
    p.add_argument("--samples", type=int, metavar="N", help="multisampling samples per pixel, 0 for none (default 4)")
    p.add_argument("--shader", choices=SHADERS, help="look to start with (default: scene, else phong)")
    p.add_argument("--allow-origin", action="append", default=[], metavar="URL",
                   help="also accept pages served from URL (scheme://host[:port]), e.g. behind a reverse proxy; "
                        "repeatable. By default only pages of this server may open its WebSocket or upload")
    p.set_defaults(func=run_serve)


def run_serve(args: argparse.Namespace) -> int:
    """Body of ``clothsim serve``: serve until Ctrl-C (or SIGTERM), then release everything."""
    try:
        import aiohttp  # noqa: F401
    except ImportError:
        raise ClothsimError(EXTRA_HINT) from None
    from ..scene import bundled_scene_names, load_scene

    port = V.check(V.integer(ge=0, le=65535), args.port, "--port")
    host = _host(args.host)
    origins = tuple(_origin(o) for o in args.allow_origin)
    scene = load_scene(args.scene)
    overrides = {k: v for k, v in (("size", args.size), ("samples", args.samples), ("shader", args.shader))
                 if v is not None}
    settings = RenderSettings.from_scene(scene).with_overrides(overrides, label=lambda f: f"--{f.split('[')[0]}")
    name = args.scene if args.scene in bundled_scene_names() else Path(scene.path).name
    if not ipaddress.ip_address(host).is_loopback:
        print(f"clothsim: warning: --host {host} lets other machines reach the server; anyone who has the URL "
              "(its token) can drive it", file=sys.stderr)
    return asyncio.run(_serve(scene, name, host, port, settings, origins))


def _host(text: str) -> str:
    try:
        return str(ipaddress.ip_address(text))
    except ValueError:
        if text == "localhost":
            return "127.0.0.1"
        raise ClothsimError(f"--host: expected an IP address such as 127.0.0.1, got {V.shown(text)}") from None


def _origin(text: str) -> str:
    """``--allow-origin``'s value as browsers write an Origin header: ``scheme://host[:port]``."""
    from urllib.parse import urlsplit

    try:
        parts = urlsplit(text)
        _ = parts.port  # a port that is not a number raises here
    except ValueError:
        parts = None
    if (parts is None or parts.scheme not in ("http", "https") or not parts.hostname or parts.username
            or parts.path not in ("", "/") or parts.query or parts.fragment):
        raise ClothsimError(f"--allow-origin: expected scheme://host[:port] such as https://example.org, got "
                            f"{V.shown(text)}")
    return f"{parts.scheme}://{parts.netloc}".lower()


async def _serve(scene, name: str, host: str, port: int, settings: RenderSettings,  # noqa: ANN001
                 origins: tuple[str, ...] = ()) -> int:
    from .app import Server

    loop = asyncio.get_running_loop()
    stop = asyncio.Event()
    for sig in (signal.SIGINT, signal.SIGTERM):
        loop.add_signal_handler(sig, stop.set)
    server = Server(scene, name, host, port, settings.size, settings.samples, settings=settings,
                    allow_origins=origins)
    url = await server.start()
    print(f"clothsim: serving {name} at {url}", flush=True)
    try:
        await stop.wait()
    finally:
        await server.stop()
    print("clothsim: stopped", file=sys.stderr)
    return 0
