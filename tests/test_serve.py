"""``clothsim serve`` without a browser: the token, the stream, the messages, uploads, downloads,
a blow-up, reconnects, and the command line."""

from __future__ import annotations

import asyncio
import gc
import io
import json
import os
import re
import signal
import subprocess
import sys
import threading
import time
import urllib.error
import urllib.request
from pathlib import Path

import numpy as np
import pytest

from clothsim.scene import bundled_scene_names
from PIL import Image

from clothsim.serve.app import MAX_SCENE_BYTES

pytest.importorskip("aiohttp", reason="the serve tests need the 'serve' extra (aiohttp)")
import aiohttp  # noqa: E402

from conftest import SCENES, error_line, run_cli  # noqa: E402
from serve_support import ServerThread, parse_frame  # noqa: E402

SIZE = (128, 128)


def _http(url: str, data: bytes | None = None) -> tuple[int, bytes, dict[str, str]]:
    request = urllib.request.Request(url, data=data, method="POST" if data is not None else "GET")
    try:
        with urllib.request.urlopen(request, timeout=60) as r:
            return r.status, r.read(), dict(r.headers)
    except urllib.error.HTTPError as err:
        return err.code, err.read(), dict(err.headers)


async def _next_frame(ws, texts: list | None = None, timeout: float = 120.0):  # noqa: ANN001, ANN202
    """The next binary frame (header, image); text messages met on the way go to ``texts``."""
    deadline = time.monotonic() + timeout
    while True:
        msg = await ws.receive(timeout=max(deadline - time.monotonic(), 0.01))
        if msg.type == aiohttp.WSMsgType.BINARY:
            header, jpeg = parse_frame(msg.data)
            return header, np.asarray(Image.open(io.BytesIO(jpeg)).convert("RGB"))
        if msg.type == aiohttp.WSMsgType.TEXT:
            if texts is not None:
                texts.append(json.loads(msg.data))
            continue
        raise AssertionError(f"connection ended: {msg}")


async def _next_text(ws, kind: str, timeout: float = 120.0, where: list | None = None) -> dict:  # noqa: ANN001
    """The next text message of ``kind`` (frames on the way are skipped)."""
    deadline = time.monotonic() + timeout
    while True:
        msg = await ws.receive(timeout=max(deadline - time.monotonic(), 0.01))
        if msg.type == aiohttp.WSMsgType.TEXT:
            data = json.loads(msg.data)
            if where is not None:
                where.append(data)
            if data["type"] == kind:
                return data
        elif msg.type != aiohttp.WSMsgType.BINARY:
            raise AssertionError(f"connection ended: {msg}")


async def _state_where(ws, test, timeout: float = 60.0) -> dict:  # noqa: ANN001
    """The first state message that passes ``test`` (the connection's first state may come late)."""
    deadline = time.monotonic() + timeout
    while True:
        state = await _next_text(ws, "state", timeout=max(deadline - time.monotonic(), 0.01))
        if test(state):
            return state


async def _frame_not(ws, number: int) -> dict:  # noqa: ANN001
    """The header of the first frame whose number is not ``number``."""
    while True:
        header, _ = await _next_frame(ws)
        if header["frame"] != number:
            return header


def _ws_url(st: ServerThread) -> str:
    return f"{st.base.replace('http://', 'ws://')}/ws?token={st.token}"


@pytest.fixture
def server():
    with ServerThread("pinned2", size=SIZE) as st:
        yield st


def test_every_request_without_the_token_gets_an_empty_403(server):
    good = server.token
    for path in ("/", "/ws", "/image.png", "/clip", "/no-such-page", "/static/index.html", "/../pyproject.toml"):
        for query in ("", "?token=", "?token=wrong", f"?token={good[:-1]}", f"?token={good}x", f"?tok={good}"):
            status, body, _ = _http(server.base + path + query)
            assert (status, body) == (403, b""), (path, query)
    status, body, _ = _http(server.base + "/scene?token=nope", data=b"{}")
    assert (status, body) == (403, b"")

    async def socket() -> None:
        async with aiohttp.ClientSession() as s:
            with pytest.raises(aiohttp.WSServerHandshakeError) as err:
                await s.ws_connect(f"{server.base.replace('http://', 'ws://')}/ws?token=wrong")
            assert err.value.status == 403
    asyncio.run(socket())
    assert server.engine.simulation.frame == 0  # nobody got in, nothing ran
    status, body, headers = _http(f"{server.base}/?token={good}")
    assert status == 200 and b"<canvas" in body and "Content-Security-Policy" in headers
    assert _http(f"{server.base}/no-such-page?token={good}")[0] == 404


def test_the_stream_shows_a_changing_image_and_the_controls_drive_the_same_simulation(server):
    engine = server.engine

    async def page() -> None:
        async with aiohttp.ClientSession() as s, s.ws_connect(_ws_url(server)) as ws:
            state = await _next_text(ws, "state")
            assert state["scene"] == "pinned2" and state["sim"]["ks"] == 5000 and state["paused"] is False
            first, image0 = await _next_frame(ws)
            assert image0.shape == (*SIZE[::-1], 3) and image0.std() > 5  # cloth on a background
            header = first
            while header["frame"] < 40:  # the camera follows the centroid: wait until the cloth swings
                header, image = await _next_frame(ws)
            assert header["frame"] > first["frame"] and np.abs(image.astype(int) - image0).mean() > 0.5

            # ks, through the Simulation setter, between frames
            await ws.send_str(json.dumps({"type": "set", "field": "ks", "value": 500}))
            state = await _next_text(ws, "state")
            assert state["sim"]["ks"] == 500 and engine.simulation.ks == 500
            await ws.send_str(json.dumps({"type": "set", "field": "ks", "value": -1}))
            assert (await _next_text(ws, "error"))["message"] == "cloth.ks: must be >= 0, got -1"
            assert engine.simulation.ks == 500
            await ws.send_str(json.dumps({"type": "set", "field": "gravity", "value": [0, -1, 0]}))
            assert (await _next_text(ws, "state"))["sim"]["gravity"] == [0, -1, 0]
            await ws.send_str(json.dumps({"type": "set", "field": "enable_bending", "value": False}))
            await _next_text(ws, "state")
            assert engine.simulation.enable_bending is False and engine.simulation.gravity == (0, -1, 0)

            # P freezes the frame number, N adds exactly one, R goes back to 0
            await ws.send_str('{"type": "toggle_pause"}')
            assert (await _next_text(ws, "state"))["paused"] is True
            paused_at = engine.simulation.frame
            await asyncio.sleep(0.5)
            assert engine.simulation.frame == paused_at
            await ws.send_str('{"type": "step"}')
            header = await _frame_not(ws, paused_at)  # frames drawn before the pause may still be on their way
            assert header["frame"] == paused_at + 1
            await asyncio.sleep(0.3)
            assert engine.simulation.frame == paused_at + 1
            await ws.send_str('{"type": "restart"}')
            assert (await _next_text(ws, "state"))["frame"] == 0
            assert (await _frame_not(ws, paused_at + 1))["frame"] == 0

            # the look and the camera redraw a paused frame
            await ws.send_str(json.dumps({"type": "look", "field": "shader", "value": "wireframe"}))
            assert (await _next_text(ws, "state"))["look"]["shader"] == "wireframe"
            _, wire = await _next_frame(ws)
            await ws.send_str(json.dumps({"type": "look", "field": "shader", "value": "normal"}))
            _, normal = await _next_frame(ws)
            assert np.abs(wire.astype(int) - normal).mean() > 5
            await ws.send_str(json.dumps({"type": "rotate", "dx": 150, "dy": 0}))
            header, turned = await _next_frame(ws)
            assert header["frame"] == 0 and np.abs(turned.astype(int) - normal).mean() > 2
            await ws.send_str('{"type": "reset_camera"}')
            _, back = await _next_frame(ws)
            assert np.abs(back.astype(int) - normal).mean() < 1

            # malformed messages get an error reply, and the page goes on
            for bad in ("nonsense", '{"type": "zoom", "factor": "big"}', json.dumps({"type": "look", "field": "phong.p",
                                                                                     "value": 0})):
                await ws.send_str(bad)
                assert (await _next_text(ws, "error"))["message"].startswith(("message:", "message: phong.p"))
            await ws.send_bytes(b"\x00\x01")
            assert (await _next_text(ws, "error"))["message"] == "message: expected JSON text, got binary data"
            await ws.send_str('{"type": "step"}')
            header, _ = await _next_frame(ws)
            assert header["frame"] == 1

            # a bundled scene by name (never a path)
            await ws.send_str(json.dumps({"type": "scene", "name": "pinned4"}))
            state = await _next_text(ws, "state")
            assert state["scene"] == "pinned4" and engine.simulation.scene.path.endswith("pinned4.json")
            await ws.send_str(json.dumps({"type": "scene", "name": "/etc/passwd"}))
            assert (await _next_text(ws, "error"))["message"].startswith("message: name: expected one of: ")
    asyncio.run(page())


def test_uploads_are_parsed_in_memory_and_a_bad_one_leaves_the_simulation_running(server, tmp_path, monkeypatch):
    engine = server.engine
    url = f"{server.base}/scene?token={server.token}&name="
    sim_before = engine.simulation
    opened: list[str] = []
    real_open = open

    def spy(file, *a, **k):  # noqa: ANN001, ANN002, ANN003
        opened.append((str(file), (a[0] if a else k.get("mode", "r"))))
        return real_open(file, *a, **k)
    scene = json.loads((SCENES / "pinned4.json").read_text())
    scene["cloth"]["ks"] = -3
    status, body, _ = _http(url + "broken.json", json.dumps(scene).encode())
    assert status == 400
    assert json.loads(body) == {"error": "broken.json: cloth.ks: must be >= 0, got -3"}
    assert engine.simulation is sim_before
    for text, name, message in (
        (b"{", "../../x/bad.json", "bad.json: not valid JSON: Expecting property name enclosed in double quotes at line 1 column 2"),
        (b"\xff", "s.json", "s.json: cannot read scene file: not UTF-8 text (invalid start byte at byte 0)"),
        (json.dumps({"cloth": json.loads((SCENES / "pinned2.json").read_text())["cloth"],
                     "render": {"textures": {"color": "/etc/hostname"}}}).encode(), "t.json",
         't.json: render.textures.color: "/etc/hostname": an uploaded scene may name only the image files '
         "uploaded with it (uploaded: none) (none is bundled); the server opens no other file"),
    ):
        status, body, _ = _http(url + name, text)
        assert (status, json.loads(body)) == (400, {"error": message})
    status, body, _ = _http(url + "big.json", b" " * (MAX_SCENE_BYTES + 1))
    assert (status, json.loads(body)) == (413, {"error": "upload: the scene file is larger than 1 MiB"})
    assert engine.simulation is sim_before

    monkeypatch.setattr("builtins.open", spy)
    scene["cloth"]["ks"] = 800
    status, body, _ = _http(url + "mine.json", json.dumps(scene).encode())
    assert (status, json.loads(body)) == (200, {"ok": True, "scene": "mine.json"})
    assert engine.simulation is not sim_before and engine.simulation.ks == 800 and engine.scene_name == "mine.json"
    # parsed from memory: the only files read are the kernel's memory figures (the grid-size check)
    assert opened and all(path.startswith(("/proc/", "/sys/fs/cgroup/")) and mode == "r" for path, mode in opened)


def test_image_and_clip_downloads(server):
    status, body, headers = _http(f"{server.base}/image.png?token={server.token}")
    assert status == 200 and headers["Content-Type"] == "image/png"
    assert re.fullmatch(r'attachment; filename="clothsim-pinned2-\d{5}\.png"', headers["Content-Disposition"])
    image = Image.open(io.BytesIO(body))
    assert image.format == "PNG" and image.size == SIZE and np.asarray(image).std() > 5
    assert _http(f"{server.base}/clip?token={server.token}")[0] == 404  # nothing recorded yet

    async def record(fmt: str) -> dict:
        async with aiohttp.ClientSession() as s, s.ws_connect(_ws_url(server)) as ws:
            await _next_frame(ws)
            await ws.send_str(json.dumps({"type": "record", "action": "start", "format": fmt}))
            await _state_where(ws, lambda st: st["recording"] == fmt)
            await ws.send_str(json.dumps({"type": "record", "action": "start", "format": fmt}))
            assert (await _next_text(ws, "error"))["message"] == "already recording; stop the clip first"
            for _ in range(6):
                await _next_frame(ws)
            await ws.send_str(json.dumps({"type": "record", "action": "stop"}))
            return await _next_text(ws, "clip")
    for fmt in ("gif", "mp4"):
        clip = asyncio.run(record(fmt))
        assert clip["name"] == f"clothsim-pinned2.{fmt}" and clip["frames"] >= 6
        status, body, headers = _http(f"{server.base}/clip?token={server.token}")
        assert status == 200 and headers["Content-Disposition"] == f'attachment; filename="clothsim-pinned2.{fmt}"'
        if fmt == "gif":
            gif = Image.open(io.BytesIO(body))
            assert gif.format == "GIF" and gif.size == SIZE and gif.n_frames >= 2
        else:
            assert body[4:8] == b"ftyp" and len(body) > 1000
    # only the last clip is kept, in the server's own temporary folder
    assert [p.suffix for p in server.engine.clip_folder.iterdir()] == [".mp4"]


def test_a_blow_up_shows_its_error_and_restarts(server):
    engine = server.engine

    async def page() -> None:
        async with aiohttp.ClientSession() as s, s.ws_connect(_ws_url(server)) as ws:
            await _next_frame(ws)
            await ws.send_str(json.dumps({"type": "set", "field": "ks", "value": 1e12}))
            error = await _next_text(ws, "error")
            assert error["message"].startswith("simulation blew up at frame ") and "\n" not in error["message"]
            state = await _next_text(ws, "state")
            assert state["error"] == error["message"] and state["paused"] is True
            frozen = engine.simulation.frame
            assert np.isfinite(engine.simulation.positions).all()  # the state before the bad frame
            await ws.send_str('{"type": "toggle_pause"}')
            assert (await _next_text(ws, "error"))["message"].startswith("the simulation blew up; press R")
            assert engine.simulation.frame == frozen
            await ws.send_str(json.dumps({"type": "set", "field": "ks", "value": 5000}))
            await ws.send_str('{"type": "restart"}')
            await ws.send_str('{"type": "toggle_pause"}')
            state = await _state_where(ws, lambda st: st["paused"] is False)
            assert state["error"] is None and state["frame"] == 0
            header, _ = await _next_frame(ws)
            header, _ = await _next_frame(ws)
            assert header["frame"] >= 1 and engine.error is None
    asyncio.run(page())


def test_a_failure_inside_a_frame_is_shown_and_the_server_goes_on(server, monkeypatch):
    renderer_render = None

    def broken(*args, **kwargs):  # noqa: ANN002, ANN003, ANN202
        monkeypatch.setattr(server.engine.renderer, "render", renderer_render)  # fails once
        raise RuntimeError("no more buffers")

    async def page() -> None:
        nonlocal renderer_render
        async with aiohttp.ClientSession() as s, s.ws_connect(_ws_url(server)) as ws:
            await _next_frame(ws)
            renderer_render = server.engine.renderer.render
            monkeypatch.setattr(server.engine.renderer, "render", broken)
            assert (await _next_text(ws, "error"))["message"] == "internal error: RuntimeError: no more buffers"
            first, _ = await _next_frame(ws)
            header, _ = await _next_frame(ws)
            assert header["frame"] > first["frame"]
    asyncio.run(page())


def _rss() -> int:
    with open("/proc/self/statm") as f:
        return int(f.read().split()[1]) * os.sysconf("SC_PAGE_SIZE")


def _gl_objects(renderer) -> int:  # noqa: ANN001
    """GL objects the renderer holds beyond its fixed framebuffers and programs."""
    cloth = 3 if renderer._cloth is not None else 0
    return (cloth + len(renderer._vaos) + len(renderer._textures) + 2 * len(renderer._spheres)
            + 2 * len(renderer._planes) + (renderer._spring_ibo is not None) + len(renderer.programs._cache))


def test_a_page_that_leaves_stops_its_stream_and_ten_reconnects_leak_nothing(server):
    engine = server.engine

    async def visit(frames: int) -> None:
        async with aiohttp.ClientSession() as s, s.ws_connect(_ws_url(server)) as ws:
            for _ in range(frames):
                await _next_frame(ws)

    def server_tasks() -> int:
        return server.call(_count_tasks())

    asyncio.run(visit(3))  # warm: kernels, programs, buffers
    time.sleep(0.3)
    stopped_at = engine.simulation.frame
    time.sleep(0.5)
    assert engine.simulation.frame == stopped_at  # nobody watching: nothing simulated or drawn
    assert engine._watching == 0 and not server.server.engine.viewers.viewers
    gc.collect()
    before = (threading.active_count(), server_tasks(), _gl_objects(engine.renderer), _rss())
    for _ in range(10):
        asyncio.run(visit(2))
    time.sleep(0.3)
    gc.collect()
    after = (threading.active_count(), server_tasks(), _gl_objects(engine.renderer), _rss())
    assert after[:3] == before[:3], (before, after)
    assert after[3] - before[3] < 8 * 2**20, (before, after)  # bytes of resident memory
    assert engine._watching == 0 and not engine.viewers.viewers


async def _count_tasks() -> int:
    return len([t for t in asyncio.all_tasks() if t is not asyncio.current_task()])


def test_cli_prints_the_url_and_stops_cleanly_on_ctrl_c():
    env = dict(os.environ)
    env.pop("DISPLAY", None)
    proc = subprocess.Popen([sys.executable, "-m", "clothsim", "serve", "pinned2", "--port", "0", "--size", "64x64",
                             "--samples", "0"], stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True, env=env)
    try:
        line = proc.stdout.readline()
        m = re.fullmatch(r"clothsim: serving pinned2 at (http://127\.0\.0\.1:(\d+)/\?token=([\w-]{20,}))\n", line)
        assert m, line
        url, port = m[1], m[2]
        assert _http(f"http://127.0.0.1:{port}/")[:2] == (403, b"")
        assert _http(url)[0] == 200

        async def page_open_during_ctrl_c() -> tuple[int | None, float]:
            async with aiohttp.ClientSession() as s, s.ws_connect(url.replace("http://", "ws://").replace(
                    "/?token=", "/ws?token=")) as ws:
                await _next_text(ws, "state")
                proc.send_signal(signal.SIGINT)
                start = time.monotonic()
                while True:
                    msg = await ws.receive(timeout=60)
                    if msg.type not in (aiohttp.WSMsgType.TEXT, aiohttp.WSMsgType.BINARY):
                        return ws.close_code, time.monotonic() - start
        code, seconds = asyncio.run(page_open_during_ctrl_c())
        assert code == 1001 and seconds < 10  # the page is told the server went away, at once
        out, err = proc.communicate(timeout=120)
    finally:
        if proc.poll() is None:
            proc.kill()
            proc.wait()
    assert proc.returncode == 0, err
    assert err.strip().splitlines()[-1] == "clothsim: stopped" and "Traceback" not in err


@pytest.mark.parametrize("args, message", [
    (("--port", "70000"), "clothsim: error: --port: must be <= 65535, got 70000"),
    (("--host", "example.com"), 'clothsim: error: --host: expected an IP address such as 127.0.0.1, got "example.com"'),
    (("--size", "0x64"), "clothsim: error: --size: must be >= 1, got 0"),
    (("--samples", "3"), "clothsim: error: --samples: must be 0 (no multisampling) or a power of two (1, 2, 4, 8, 16), got 3"),
    (("nosuch.json",), "clothsim: error: nosuch.json: no such scene file (bundled scenes: "
                       + ", ".join(sorted(bundled_scene_names())) + ")"),
])
def test_cli_bad_input_is_one_line(args, message):
    assert error_line(run_cli("serve", *args)) == message


def test_cli_without_aiohttp_names_the_extra(monkeypatch, capsys):
    from clothsim.cli import main

    monkeypatch.setitem(sys.modules, "aiohttp", None)  # import aiohttp raises ImportError
    assert main(["serve", "--port", "0"]) == 2
    assert capsys.readouterr().err == ("clothsim: error: clothsim serve needs the 'serve' extra (aiohttp): "
                                       "pip install 'clothsim[serve]'\n")


def test_the_page_is_shipped_in_the_package():
    import clothsim.serve

    page = Path(clothsim.serve.__file__).parent / "static" / "index.html"
    text = page.read_text()
    # one static file: no external script, style or font to fetch (the server has no internet)
    assert not re.search(r"""(src|href)=["']?(https?:)?//""", text) and "@import" not in text
