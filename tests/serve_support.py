"""Helpers of the serve tests: a server in a background thread, a headless Chromium, frame parsing."""

from __future__ import annotations

import asyncio
import json
import shutil
import struct
import threading
from typing import Any

CHROMIUM = next((p for p in (shutil.which("chromium"), shutil.which("chromium-browser")) if p), None)
CHROMEDRIVER = shutil.which("chromedriver")
NO_BROWSER = ("no headless browser: install Debian's chromium and chromium-driver "
              "(apt-get install chromium chromium-driver) to run the browser tests")


class ServerThread:
    """A :class:`clothsim.serve.app.Server` on its own event loop in a thread, as the CLI runs it."""

    def __init__(self, scene: str = "pinned2", size: tuple[int, int] = (256, 256), samples: int = 0,
                 **kwargs: Any) -> None:
        from clothsim.render.settings import RenderSettings
        from clothsim.scene import load_scene
        from clothsim.serve.app import Server

        loaded = load_scene(scene)
        settings = RenderSettings.from_scene(loaded).with_overrides({"size": list(size), "samples": samples})
        self.server = Server(loaded, scene, port=0, size=size, samples=samples, settings=settings, **kwargs)
        self.loop = asyncio.new_event_loop()
        self.thread = threading.Thread(target=self.loop.run_forever, name="test-serve-loop", daemon=True)

    @property
    def engine(self):  # noqa: ANN201
        return self.server.engine

    def call(self, coroutine: Any, timeout: float = 120) -> Any:
        return asyncio.run_coroutine_threadsafe(coroutine, self.loop).result(timeout)

    def __enter__(self) -> "ServerThread":
        self.thread.start()
        self.url = self.call(self.server.start())
        self.base, self.token = self.url.split("/?token=")
        return self

    def __exit__(self, *exc: object) -> None:
        self.call(self.server.stop())
        self.loop.call_soon_threadsafe(self.loop.stop)
        self.thread.join(10)
        self.loop.close()


def parse_frame(data: bytes) -> tuple[dict[str, Any], bytes]:
    """A binary frame message: its JSON header and its JPEG bytes."""
    n = struct.unpack(">I", data[:4])[0]
    return json.loads(data[4:4 + n]), data[4 + n:]


def chromium(window: tuple[int, int] = (1280, 900)):  # noqa: ANN201
    """A headless Chromium driven by Selenium through Debian's chromedriver."""
    from selenium import webdriver

    options = webdriver.ChromeOptions()
    options.binary_location = CHROMIUM
    for arg in ("--headless=new", "--no-sandbox", "--disable-dev-shm-usage", "--disable-gpu",
                f"--window-size={window[0]},{window[1]}", "--force-device-scale-factor=1"):
        options.add_argument(arg)
    return webdriver.Chrome(options=options, service=webdriver.ChromeService(executable_path=CHROMEDRIVER))
