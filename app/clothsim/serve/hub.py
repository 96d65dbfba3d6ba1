"""The pages watching the engine: the newest frame and the text messages, sent to each page in turn.

The engine calls :class:`Hub` from its worker thread; the Hub moves everything onto the event
loop, where each page's :class:`Viewer` task sends the newest frame (skipping those it was too
slow for) and the text messages queued for it, and tells the engine when it took a frame.
"""

from __future__ import annotations

import asyncio
import contextlib
import collections
import json
import struct
from typing import Any

from aiohttp import web

from .engine import Engine, Frame

# Text messages waiting for a page that does not read; older ones are dropped past this.
MAX_PENDING_TEXTS = 256


class Viewer:
    """One page's WebSocket: a sender task writes the newest frame and queued texts in turn."""

    def __init__(self, ws: web.WebSocketResponse, hub: "Hub") -> None:
        self.ws = ws
        self.hub = hub
        self.texts: collections.deque[str] = collections.deque(maxlen=MAX_PENDING_TEXTS)
        self.frame_waiting = False
        self.wake = asyncio.Event()
        self.task: asyncio.Task | None = None

    def send_text(self, text: str) -> None:
        self.texts.append(text)
        self.wake.set()

    async def run(self) -> None:
        try:
            while not self.ws.closed:
                await self.wake.wait()
                self.wake.clear()
                while self.texts:
                    await self.ws.send_str(self.texts.popleft())
                if self.frame_waiting and self.hub.latest is not None:
                    self.frame_waiting = False
                    payload = self.hub.latest_payload
                    self.hub.engine.frame_taken()
                    await self.ws.send_bytes(payload)
        except (ConnectionError, RuntimeError):
            # The page went away while a frame was on its way: the connection's handler ends it.
            await self.ws.close()


class Hub:
    """The pages watching the engine; the engine's frames and messages arrive here from its thread."""

    def __init__(self, engine: Engine, loop: asyncio.AbstractEventLoop) -> None:
        self.engine = engine
        self.loop = loop
        self.viewers: set[Viewer] = set()
        self.latest: Frame | None = None
        self.latest_payload = b""

    # called by the engine, in its thread
    def frame(self, frame: Frame) -> None:
        self._call(self._on_frame, frame)

    def message(self, message: dict[str, Any]) -> None:
        self._call(self.broadcast, json.dumps(message))

    def _call(self, callback: Any, *args: Any) -> None:
        # A frame that outlived the server (stop does not wait for a slow one) has nobody to tell.
        with contextlib.suppress(RuntimeError):
            self.loop.call_soon_threadsafe(callback, *args)

    # on the event loop
    def _on_frame(self, frame: Frame) -> None:
        self.latest = frame
        self.latest_payload = frame_payload(frame)
        if not self.viewers:
            self.engine.frame_taken()
        for v in self.viewers:
            v.frame_waiting = True
            v.wake.set()

    def broadcast(self, text: str) -> None:
        for v in self.viewers:
            v.send_text(text)


def frame_payload(frame: Frame) -> bytes:
    """A binary WebSocket message: 4-byte big-endian header length, JSON header, JPEG."""
    header = json.dumps({"frame": frame.number, "width": frame.width, "height": frame.height,
                         "render_ms": round(frame.render_ms, 2), "paused": frame.paused}).encode()
    return struct.pack(">I", len(header)) + header + frame.jpeg
