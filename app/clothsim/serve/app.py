"""The web server: one static page, one WebSocket per page, and three download/upload endpoints.

Every request needs the server's token (``?token=...``); without it the answer is an empty 403.
A WebSocket or an upload that a browser sends from another site's page (its ``Origin`` is not
this server, nor one allowed with ``--allow-origin``) is refused with 403 too: the token in a
leaked URL is not enough to drive the server from a foreign page.

The routes never take a path from the request: the page is one file shipped in the package,
scenes are picked from the bundled names, an uploaded scene may name only the files uploaded
with it (:mod:`clothsim.assets`), and the two downloads (the image, the last clip) come from
the engine.
"""

from __future__ import annotations

import asyncio
import contextlib
import hmac
import json
import logging
import secrets
import sys
import shutil
import tempfile
from importlib import resources
from pathlib import Path
from typing import Any

from aiohttp import BodyPartReader, WSCloseCode, WSMsgType, web

from ..assets import base_name
from ..errors import ClothsimError
from ..render.settings import RenderSettings
from ..scene import Scene
from .engine import Engine, upload_label
from .hub import Hub, Viewer
from .protocol import error_reply, parse_message

#: Largest uploaded scene file (the bundled ones are 342-3101 bytes; a long pinned list stays far below).
MAX_SCENE_BYTES = 1 << 20
#: Largest upload in all: the scene and the meshes and images that come with it.
MAX_UPLOAD_BYTES = 32 << 20
#: Most files an upload may bring beside its scene.
MAX_UPLOAD_FILES = 16
#: Largest WebSocket message from the page (its messages are a few dozen bytes).
MAX_MESSAGE_BYTES = 64 << 10
# How long stopping waits for requests in progress (a download) before closing them: Ctrl-C and
# SIGTERM must end the server within about 2 s whatever it is doing.
SHUTDOWN_TIMEOUT_S = 0.5
HEADERS = {
    "Cache-Control": "no-store",
    "Referrer-Policy": "no-referrer",
    "X-Content-Type-Options": "nosniff",
}
PAGE_HEADERS = {
    **HEADERS,
    # The page's own inline script and style, images from its own blobs, connections to this server.
    "Content-Security-Policy": "default-src 'none'; script-src 'unsafe-inline'; style-src 'unsafe-inline'; "
                               "img-src blob: data:; connect-src 'self'; frame-ancestors 'none'; "
                               "base-uri 'none'; form-action 'none'",
}


TOKEN = web.AppKey("token", str)
HUB = web.AppKey("hub", Hub)
PAGE = web.AppKey("page", bytes)
ORIGINS = web.AppKey("origins", frozenset)


def page_html() -> bytes:
    """The page, read from the package."""
    return resources.files(__package__).joinpath("static/index.html").read_bytes()


@web.middleware
async def _token_check(request: web.Request, handler: Any) -> web.StreamResponse:
    token = request.app[TOKEN]
    given = request.query.get("token", "")
    if not hmac.compare_digest(given.encode(), token.encode()):
        return web.Response(status=403)
    return await handler(request)


async def _index(request: web.Request) -> web.Response:
    return web.Response(body=request.app[PAGE], content_type="text/html", charset="utf-8", headers=PAGE_HEADERS)


def _foreign_origin(request: web.Request) -> bool:
    """True when a browser sent this request from a page of another site.

    Browsers send ``Origin`` with every WebSocket handshake and cross-site POST; a client that
    sends none is not a browser page and has the token, which is the credential.
    """
    origin = request.headers.get("Origin")
    if origin is None:
        return False
    origin = origin.rstrip("/").lower()
    return origin != f"{request.scheme}://{request.host}".lower() and origin not in request.app[ORIGINS]


async def _socket(request: web.Request) -> web.StreamResponse:
    if _foreign_origin(request):
        return web.Response(status=403, text="clothsim serve: WebSocket from a foreign origin "
                                             "(start the server with --allow-origin for a proxy)\n")
    hub: Hub = request.app[HUB]
    engine = hub.engine
    ws = web.WebSocketResponse(max_msg_size=MAX_MESSAGE_BYTES, heartbeat=30.0)
    await ws.prepare(request)
    viewer = Viewer(ws, hub)
    hub.viewers.add(viewer)
    viewer.task = asyncio.ensure_future(viewer.run())
    engine.watch(+1)
    try:
        state = await asyncio.wrap_future(engine.submit("state"))
        viewer.send_text(json.dumps(state))
        async for msg in ws:
            if msg.type == WSMsgType.TEXT:
                _handle(viewer, msg.data)
            elif msg.type == WSMsgType.BINARY:
                viewer.send_text(error_reply("message: expected JSON text, got binary data"))
            elif msg.type == WSMsgType.ERROR:
                break
    finally:
        hub.viewers.discard(viewer)
        engine.watch(-1)
        viewer.task.cancel()
        with contextlib.suppress(asyncio.CancelledError, ConnectionError, RuntimeError):
            await viewer.task
        await ws.close()
    return ws


def _handle(viewer: Viewer, text: str) -> None:
    engine = viewer.hub.engine
    try:
        command = parse_message(text, engine.scenes)
    except ClothsimError as exc:
        viewer.send_text(error_reply(str(exc)))
        return
    kind = command.pop("type")
    future = asyncio.wrap_future(engine.submit(kind, **command))

    def done(f: asyncio.Future) -> None:
        exc = f.exception()
        if exc is not None:
            viewer.send_text(error_reply(str(exc)))

    future.add_done_callback(done)


class _UploadError(Exception):
    def __init__(self, message: str, status: int = 400) -> None:
        super().__init__(message)
        self.status = status


async def _upload(request: web.Request) -> web.Response:
    """POST /scene: a scene file as the body (``?name=`` its file name), or a multipart form with
    the scene in a part named ``scene`` and the meshes and images it names in parts ``file``."""
    engine: Engine = request.app[HUB].engine
    if _foreign_origin(request):
        return _json({"error": "upload: sent from a page of another site"}, 403)
    try:
        if request.content_type == "multipart/form-data":
            name, body, files = await _read_form(request)
        else:
            name, body, files = request.query.get("name"), await _read_limited(request.content, MAX_SCENE_BYTES,
                                                                              "the scene file"), {}
        try:
            text = body.decode("utf-8")
        except UnicodeDecodeError as exc:
            raise _UploadError(f"{upload_label(name)}: cannot read scene file: not UTF-8 text "
                               f"({exc.reason} at byte {exc.start})") from None
        label = await asyncio.wrap_future(engine.submit("upload", text=text, name=name, files=files))
    except _UploadError as exc:
        return _json({"error": str(exc)}, exc.status)
    except ClothsimError as exc:
        return _json({"error": str(exc)}, 400)
    return _json({"ok": True, "scene": label}, 200)


async def _read_limited(stream: Any, limit: int, what: str, bound: int | None = None) -> bytes:
    """Read ``stream`` whole, or raise 413 once it passes ``limit`` bytes (``bound`` is the size
    named in the message, when the limit is what is left of a larger one)."""
    read = getattr(stream, "read_chunk", None) or stream.read  # a form part, or the request body
    data = bytearray()
    while True:
        chunk = await read(1 << 16)
        if not chunk:
            return bytes(data)
        data += chunk
        if len(data) > limit:
            raise _UploadError(f"upload: {what} is larger than {_size(limit if bound is None else bound)}", 413)


async def _read_form(request: web.Request) -> tuple[str | None, bytes, dict[str, bytes]]:
    """The scene part and the file parts of a multipart upload, each read within its limits."""
    reader = await request.multipart()
    name: str | None = None
    scene: bytes | None = None
    files: dict[str, bytes] = {}
    total = 0
    while (part := await reader.next()) is not None:
        if not isinstance(part, BodyPartReader):
            raise _UploadError("upload: nested multipart parts are not accepted")
        if part.name == "scene":
            if scene is not None:
                raise _UploadError("upload: more than one scene part")
            name = part.filename or request.query.get("name")
            scene = await _read_limited(part, MAX_SCENE_BYTES, "the scene file")
            total += len(scene)
        elif part.name == "file":
            label = base_name(part.filename or "")
            if not label or not label.isprintable() or len(label) > 100:
                raise _UploadError("upload: a file part needs a printable file name of at most 100 characters")
            if label in files:
                raise _UploadError(f"upload: two files named {label!r}")
            if len(files) >= MAX_UPLOAD_FILES:
                raise _UploadError(f"upload: more than {MAX_UPLOAD_FILES} files beside the scene")
            files[label] = await _read_limited(part, MAX_UPLOAD_BYTES - total, "the upload", MAX_UPLOAD_BYTES)
            total += len(files[label])
        else:
            raise _UploadError(f"upload: unknown form field {str(part.name)[:40]!r} (expected scene, file)")
    if scene is None:
        raise _UploadError("upload: no scene part (the scene file goes in a part named 'scene')")
    return name, scene, files


def _size(n: int) -> str:
    return f"{n >> 20} MiB" if n >= 1 << 20 else f"{n >> 10} KiB"


async def _image(request: web.Request) -> web.Response:
    engine: Engine = request.app[HUB].engine
    try:
        png = await asyncio.wrap_future(engine.submit("snapshot"))
    except ClothsimError as exc:
        return _json({"error": str(exc)}, 500)
    name = f"clothsim-{engine.scene_name_stem()}-{engine.simulation.frame:05d}.png"
    return web.Response(body=png, content_type="image/png",
                        headers={**HEADERS, "Content-Disposition": f'attachment; filename="{name}"'})


async def _clip(request: web.Request) -> web.StreamResponse:
    engine: Engine = request.app[HUB].engine
    path = engine.clip
    if path is None or not path.is_file():
        return _json({"error": "no clip has been recorded yet"}, 404)
    kind = "video/mp4" if path.suffix == ".mp4" else "image/gif"
    name = f"clothsim-{engine.scene_name_stem()}{path.suffix}"
    return web.Response(body=path.read_bytes(), content_type=kind,
                        headers={**HEADERS, "Content-Disposition": f'attachment; filename="{name}"'})


def _json(data: dict[str, Any], status: int) -> web.Response:
    return web.json_response(data, status=status, headers=HEADERS)


def make_app(hub: Hub, token: str, allow_origins: tuple[str, ...] = ()) -> web.Application:
    """The aiohttp application: routes, token and origin checks, upload limits."""
    app = web.Application(middlewares=[_token_check], client_max_size=MAX_UPLOAD_BYTES)
    app[TOKEN] = token
    app[ORIGINS] = frozenset(o.rstrip("/").lower() for o in allow_origins)
    app[HUB] = hub
    app[PAGE] = page_html()
    app.router.add_get("/", _index)
    app.router.add_get("/ws", _socket)
    app.router.add_post("/scene", _upload)
    app.router.add_get("/image.png", _image)
    app.router.add_get("/clip", _clip)
    app.on_shutdown.append(_close_pages)
    return app


async def _close_pages(app: web.Application) -> None:
    # An open WebSocket keeps its handler running, and the server's shutdown waits for handlers.
    for viewer in list(app[HUB].viewers):
        await viewer.ws.close(code=WSCloseCode.GOING_AWAY, message=b"clothsim serve stopped")


class Server:
    """``clothsim serve`` as an object: start it in a running event loop, stop it, read its URL.

    ``scene`` and ``name`` are the scene to start with and how the page names it; ``port`` 0 picks
    a free port. The token is random unless given.
    """

    def __init__(self, scene: Scene, name: str, host: str = "127.0.0.1", port: int = 8000,
                 size: tuple[int, int] = (800, 800), samples: int = 4, token: str | None = None,
                 settings: RenderSettings | None = None, allow_origins: tuple[str, ...] = ()) -> None:
        self.host, self.port = host, port
        self.allow_origins = allow_origins
        self.token = token or secrets.token_urlsafe(24)
        self._folder = Path(tempfile.mkdtemp(prefix="clothsim-serve-"))
        self.engine = Engine(scene, name, size, samples, clip_folder=self._folder, settings=settings)
        self._runner: web.AppRunner | None = None

    @property
    def url(self) -> str:
        """The address to open, token included."""
        host = f"[{self.host}]" if ":" in self.host else self.host
        return f"http://{host}:{self.port}/?token={self.token}"

    async def start(self) -> str:
        """Create the renderer, start listening, and return :attr:`url`."""
        loop = asyncio.get_running_loop()
        try:
            await loop.run_in_executor(None, self.engine.start)
            hub = Hub(self.engine, loop)
            self.engine.viewers = hub
            _quiet_server_log()
            self._runner = web.AppRunner(make_app(hub, self.token, self.allow_origins), access_log=None,
                                         handle_signals=False, shutdown_timeout=SHUTDOWN_TIMEOUT_S)
            await self._runner.setup()
            site = web.TCPSite(self._runner, self.host, self.port)
            try:
                await site.start()
            except OSError as exc:
                raise ClothsimError(f"--port: cannot listen on {self.host}:{self.port}: "
                                    f"{exc.strerror or exc}") from None
            sockets = getattr(site._server, "sockets", None) or []  # noqa: SLF001 - the port 0 picked
            if sockets:
                self.port = int(sockets[0].getsockname()[1])
        except BaseException:
            await self.stop()
            raise
        return self.url

    async def stop(self) -> None:
        """Close every page's connection, stop the engine and remove the clips folder.

        Takes at most about 2 s: a frame still being simulated is left to end with the process.
        """
        if self._runner is not None:
            await self._runner.cleanup()
            self._runner = None
        await asyncio.get_running_loop().run_in_executor(None, self.engine.stop)
        shutil.rmtree(self._folder, ignore_errors=True)


class _OneLine(logging.Formatter):
    """aiohttp's server log as one line a record: a malformed request is not a crash to debug."""

    def format(self, record: logging.LogRecord) -> str:
        line = f"clothsim serve: {record.getMessage()}"
        if record.exc_info and record.exc_info[1] is not None:
            exc = record.exc_info[1]
            line += f": {type(exc).__name__}: {' '.join(str(exc).split())[:200]}"
        return line

    def formatException(self, ei: Any) -> str:  # noqa: N802 - logging's name
        return ""


def _quiet_server_log() -> None:
    log = logging.getLogger("aiohttp.server")
    if not any(isinstance(h.formatter, _OneLine) for h in log.handlers):
        handler = logging.StreamHandler(sys.stderr)
        handler.setFormatter(_OneLine())
        log.addHandler(handler)
        log.propagate = False
