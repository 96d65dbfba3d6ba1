"""``clothsim serve`` under misuse: uploads that name server files, pipes and devices; errors inside
frames and recordings; work that would stall every page; foreign pages; malformed requests; and
stopping whatever the server is doing. Each case goes through the real server (HTTP, WebSocket,
or the CLI in a subprocess)."""

from __future__ import annotations

import asyncio
import builtins
import io
import json
import os
import re
import signal
import socket
import subprocess
import sys
import time
import urllib.error
import urllib.request
from pathlib import Path

import numpy as np
import pytest
from PIL import Image

pytest.importorskip("aiohttp", reason="the serve tests need the 'serve' extra (aiohttp)")
import aiohttp  # noqa: E402

from clothsim import validate as V  # noqa: E402
from conftest import SCENES, error_line, run_cli  # noqa: E402
from serve_support import ServerThread, parse_frame  # noqa: E402

SIZE = (96, 96)
PINNED2 = json.loads((SCENES / "pinned2.json").read_text())
CUBE_OBJ = "\n".join(
    [f"v {x} {y} {z}" for x in (-0.2, 0.2) for y in (-0.2, 0.2) for z in (-0.2, 0.2)]
    + [f"f {a} {b} {c}" for a, b, c in ((1, 2, 4), (1, 4, 3), (5, 7, 8), (5, 8, 6), (1, 5, 6), (1, 6, 2),
                                        (3, 4, 8), (3, 8, 7), (1, 3, 7), (1, 7, 5), (2, 6, 8), (2, 8, 4))]) + "\n"


@pytest.fixture(scope="module")
def server():
    with ServerThread("pinned2", size=SIZE) as st:
        yield st


def _post(st: ServerThread, body: bytes, name: str = "x.json", headers: dict | None = None,
          content_type: str = "application/json") -> tuple[int, dict]:
    request = urllib.request.Request(f"{st.base}/scene?token={st.token}&name={name}", data=body, method="POST",
                                     headers={"Content-Type": content_type, **(headers or {})})
    try:
        with urllib.request.urlopen(request, timeout=60) as r:
            return r.status, json.loads(r.read())
    except urllib.error.HTTPError as err:
        return err.code, json.loads(err.read())


def _form(scene: dict | bytes, files: dict[str, bytes], scene_name: str = "up.json") -> tuple[bytes, str]:
    """A multipart/form-data body as a browser's FormData sends it."""
    boundary = "----clothsimtestboundary7MA4YWxk"
    parts = [(("scene", scene_name), scene if isinstance(scene, bytes) else json.dumps(scene).encode())]
    parts += [(("file", name), data) for name, data in files.items()]
    out = b""
    for (field, filename), data in parts:
        out += (f"--{boundary}\r\nContent-Disposition: form-data; name=\"{field}\"; filename=\"{filename}\"\r\n"
                "Content-Type: application/octet-stream\r\n\r\n").encode() + data + b"\r\n"
    return out + f"--{boundary}--\r\n".encode(), f"multipart/form-data; boundary={boundary}"


def _with(**objects: object) -> dict:
    return {"cloth": PINNED2["cloth"], **objects}


def _mesh(path: str) -> dict:
    return {"path": path, "translate": [0.5, 0.3, 0.5], "friction": 0.2}


def _png(seed: int = 3, size: int = 16) -> bytes:
    rng = np.random.default_rng(seed)
    buf = io.BytesIO()
    Image.fromarray(rng.integers(0, 255, (size, size, 3), dtype=np.uint8), "RGB").save(buf, format="PNG")
    return buf.getvalue()


# -- uploads reach no server file ------------------------------------------------------------

def test_an_uploaded_scene_opens_no_server_path_and_shows_no_content(server, tmp_path, monkeypatch):
    fifo = tmp_path / "fifo"
    os.mkfifo(fifo)
    engine = server.engine
    before = engine.simulation
    opened: list[str] = []
    real_open, real_os_open = builtins.open, os.open

    def spy_open(file, *a, **k):  # noqa: ANN001, ANN002, ANN003
        opened.append(str(file))
        return real_open(file, *a, **k)

    def spy_os_open(path, *a, **k):  # noqa: ANN001, ANN002, ANN003
        opened.append(str(path))
        return real_os_open(path, *a, **k)
    monkeypatch.setattr(builtins, "open", spy_open)
    monkeypatch.setattr(os, "open", spy_os_open)
    answers = {}
    for path in ("/etc/shadow", "/etc/hostname", "/proc/self/environ", "/proc/self/cmdline",
                 "../../../../etc/hostname", "/dev/stdin", "/dev/kmsg", str(fifo), "/no/such/file.obj"):
        started = time.monotonic()
        status, body = _post(server, json.dumps(_with(mesh=_mesh(path))).encode())
        assert time.monotonic() - started < 10  # a pipe or a device is never opened, so nothing blocks
        assert status == 400
        answers[path] = body["error"]
    for path in ("/etc/hostname", "/proc/self/environ", "/dev/stdin", str(fifo)):
        status, body = _post(server, json.dumps(_with(render={"textures": {"height": path}})).encode())
        assert status == 400 and "the server opens no other file" in body["error"]
    # Every answer has one shape, whether the path exists or not: it names the field and the
    # name the client wrote, and nothing read from any file.
    for path, message in answers.items():
        assert message == (f'x.json: mesh.path: {V.shown(path)}: an uploaded scene may name only the OBJ files uploaded '
                           "with it (uploaded: none) or a bundled one (cape.obj, drum.obj, skirt.obj, torus.obj, towel.obj); the server opens no other file")
    # What was opened: the kernel's memory figures (the grid-size check) and the server's own folder.
    ours = ("/proc/meminfo", "/sys/fs/cgroup/", "/proc/self/cgroup", str(server.server._folder))
    assert opened and not [p for p in opened if not p.startswith(ours)]
    assert engine.simulation is before


def test_a_scene_uploaded_with_its_mesh_and_texture_loads_and_draws(server):
    cloth = dict(PINNED2["cloth"], num_width_points=20, num_height_points=20, pinned=[[0, 0], [19, 0]])
    scene = {"cloth": cloth, "mesh": _mesh("meshes/cube.obj"),
             "render": {"shader": "texture", "textures": {"color": "look.png"}}}
    body, kind = _form(scene, {"cube.obj": CUBE_OBJ.encode(), "look.png": _png()})
    assert _post(server, body, content_type=kind) == (200, {"ok": True, "scene": "up.json"})
    engine = server.engine
    assert engine.scene_name == "up.json" and len(engine.simulation.scene.meshes) == 1
    mesh = engine.simulation.scene.meshes[0]
    assert mesh.closed and len(mesh.triangles) == 12
    texture = Path(engine.settings.color_texture)
    assert texture.is_file() and texture.read_bytes() == _png()  # stored by the server, under its own name
    assert texture.name == "1.png" and texture.parent.parent == server.server._folder
    png = urllib.request.urlopen(f"{server.base}/image.png?token={server.token}", timeout=120).read()
    image = np.asarray(Image.open(io.BytesIO(png)).convert("RGB"))
    assert image.shape == (*SIZE, 3) and image.std() > 5  # the cloth, drawn with the uploaded texture

    # The bundled mesh needs no upload; a later upload replaces the stored files of the one before.
    old_folder = texture.parent
    assert _post(server, json.dumps(_with(mesh=_mesh("torus.obj"))).encode()) == (200, {"ok": True, "scene": "x.json"})
    assert engine.simulation.scene.meshes[0].file.endswith("torus.obj") and not old_folder.exists()


def test_a_mesh_cloth_uploaded_with_its_obj_simulates_and_draws(server):
    from clothsim.objshapes import sheet_obj

    cloth = {"mesh": {"path": "sheet.obj", "translate": [0.0, 1.0, 0.0]}, "pinned_vertices": [0, 11],
             "thickness": 0.01, "density": 150, "ks": 5000, "damping": 0.2}
    body, kind = _form({"cloth": cloth}, {"sheet.obj": sheet_obj(1.0, 1.0, 12, 12).encode()})
    assert _post(server, body, content_type=kind) == (200, {"ok": True, "scene": "up.json"})
    engine = server.engine
    assert engine.scene_name == "up.json" and engine.simulation.scene.cloth.is_mesh
    assert engine.simulation.num_points == 144
    # the scene as the server read it (its mesh from the stored upload) simulates: it falls, held
    # at its pins (the server steps only while a page watches)
    from clothsim.sim import Simulation

    sim = Simulation(engine.simulation.scene)
    start = sim.positions.copy()
    sim.step(5)
    moved = sim.positions - start
    assert moved[:, 1].min() < -1e-4 and np.abs(moved[[0, 11]]).max() == 0.0
    png = urllib.request.urlopen(f"{server.base}/image.png?token={server.token}", timeout=120).read()
    image = np.asarray(Image.open(io.BytesIO(png)).convert("RGB"))
    assert image.shape == (*SIZE, 3) and image.std() > 5  # the cloth, drawn


@pytest.mark.parametrize("files, scene, status, message", [
    ({"cube.obj": b"root:*:20228:0:99999:7:::\n"}, _with(mesh=_mesh("cube.obj")), 400,
     "up.json: mesh.path: cube.obj: line 1: unsupported line: it does not start with an OBJ keyword (read: v, f; "
     "ignored: g, mtllib, o, s, usemtl, vn, vp, vt, comments)"),
    ({"look.png": b"not an image"}, _with(render={"textures": {"color": "look.png"}}), 400,
     'up.json: render.textures.color: "look.png": cannot read image: cannot identify image file \'look.png\''),
    ({"a.obj": CUBE_OBJ.encode(), "b.obj": b"x" * (32 << 20)}, _with(), 413,
     "upload: the upload is larger than 32 MiB"),
])
def test_bad_uploaded_files_are_one_line_naming_the_field(server, files, scene, status, message):
    body, kind = _form(scene, files)
    assert _post(server, body, content_type=kind) == (status, {"error": message})


def test_an_uploaded_image_too_large_is_refused_before_drawing(server):
    buf = io.BytesIO()
    Image.new("L", (5000, 4000)).save(buf, format="PNG")
    body, kind = _form(_with(render={"textures": {"height": "big.png"}}), {"big.png": buf.getvalue()})
    assert _post(server, body, content_type=kind) == (400, {"error": (
        'up.json: render.textures.height: "big.png": image is 5000x4000 pixels, more than an upload may bring '
        "(16777216 pixels, e.g. 4096x4096)")})


def test_the_cli_refuses_a_mesh_path_that_is_a_pipe(tmp_path):
    fifo = tmp_path / "shape.obj"
    os.mkfifo(fifo)
    (tmp_path / "s.json").write_text(json.dumps(_with(mesh=_mesh("shape.obj"))))
    r = run_cli("simulate", str(tmp_path / "s.json"), "--frames", "1", timeout=60)
    assert error_line(r) == f"clothsim: error: {tmp_path / 's.json'}: mesh.path: shape.obj: not a regular file"


# -- bounded work ----------------------------------------------------------------------------

async def _ws(st: ServerThread, session: aiohttp.ClientSession, **kw: object):  # noqa: ANN202
    return await session.ws_connect(f"{st.base.replace('http://', 'ws://')}/ws?token={st.token}", **kw)


async def _next(ws, kind: str, timeout: float = 60.0) -> dict:  # noqa: ANN001
    deadline = time.monotonic() + timeout
    while True:
        msg = await ws.receive(timeout=max(deadline - time.monotonic(), 0.01))
        if msg.type == aiohttp.WSMsgType.TEXT:
            data = json.loads(msg.data)
            if data["type"] == kind:
                return data
        elif msg.type != aiohttp.WSMsgType.BINARY:
            raise AssertionError(f"connection ended: {msg}")


def test_work_that_would_stall_every_page_is_refused_with_its_bound(server):
    engine = server.engine
    assert _post(server, json.dumps(_with()).encode())[0] == 200  # pinned2's cloth, spec self-collision

    async def page() -> str:
        async with aiohttp.ClientSession() as s, await _ws(server, s) as ws:
            await _next(ws, "state")
            await ws.send_str(json.dumps({"type": "set", "field": "simulation_steps", "value": 1000000}))
            return (await _next(ws, "error"))["message"]
    assert asyncio.run(page()) == (
        "simulation_steps: 1000000 substeps a frame would take about 375 s a frame for this scene (2500 points, "
        "verlet, self-collision spec); clothsim serve keeps a frame under 1 s: at most 2666 substeps here")
    assert engine.simulation.simulation_steps == 30

    started = time.monotonic()
    huge = dict(PINNED2["cloth"], num_width_points=1500, num_height_points=1500)
    assert _post(server, json.dumps({"cloth": huge}).encode(), name="huge.json") == (400, {"error": (
        "huge.json: cloth: a 1500x1500 grid has 2250000 points; clothsim serve simulates at most 65536 (e.g. 256x256)")})
    slow = {"cloth": PINNED2["cloth"], "simulation": {"simulation_steps": 10 ** 6}}
    status, body = _post(server, json.dumps(slow).encode(), name="slow.json")
    assert status == 400 and body["error"].startswith("slow.json: simulation.simulation_steps: 1000000 substeps a "
                                                      "frame would take about 375 s")
    assert time.monotonic() - started < 5  # refused before anything was allocated or run


def test_a_frame_slower_than_the_bound_pauses_the_simulation(server, monkeypatch):
    from clothsim.serve import engine as engine_module

    monkeypatch.setattr(engine_module, "SLOW_FRAME_S", 0.0)

    async def page() -> tuple[str, dict]:
        async with aiohttp.ClientSession() as s, await _ws(server, s) as ws:
            message = (await _next(ws, "error"))["message"]  # after the second slow frame
            state = await _next(ws, "state")
            return message, state
    message, state = asyncio.run(page())
    assert re.fullmatch(r"paused: a frame took \d+\.\d s to simulate, more than the server allows \(0 s\); lower "
                        r"simulation_steps or load a smaller scene, then press P", message), message
    assert state["paused"]
    server.engine.submit("toggle_pause").result(30)


# -- never dead ------------------------------------------------------------------------------

def test_a_gif_of_a_very_slow_clip_and_an_unexpected_error_leave_the_engine_running(server, monkeypatch, capfd):
    engine = server.engine

    async def frame(ws) -> None:  # noqa: ANN001
        while (await ws.receive(timeout=60)).type != aiohttp.WSMsgType.BINARY:
            pass

    async def page() -> list[str]:
        errors = []
        async with aiohttp.ClientSession() as s, await _ws(server, s) as ws:
            await _next(ws, "state")
            # The review's case: 1000 s a frame (the cloth blows up at that step, and the page says
            # so), a GIF recording, the camera turned twice; each frame's GIF delay is over 655.35 s.
            await ws.send_str(json.dumps({"type": "set", "field": "frames_per_sec", "value": 0.001}))
            await ws.send_str(json.dumps({"type": "record", "action": "start", "format": "gif"}))
            await frame(ws)
            for _ in range(2):
                await ws.send_str(json.dumps({"type": "rotate", "dx": 40, "dy": 0}))
                await frame(ws)
            await ws.send_str(json.dumps({"type": "record", "action": "stop"}))
            clip = await _next(ws, "clip", timeout=60)
            assert clip["frames"] >= 2
            clip_frames.append(clip["frames"])
            # An error no rule expected, inside a frame: one line on the page and on stderr.
            monkeypatch.setattr(engine_module, "_encode", _boom)
            await ws.send_str(json.dumps({"type": "rotate", "dx": 5, "dy": 0}))
            errors.append((await _next(ws, "error"))["message"])
            monkeypatch.undo()
            await ws.send_str(json.dumps({"type": "rotate", "dx": 5, "dy": 0}))
            header = None
            while header is None:
                msg = await ws.receive(timeout=60)
                if msg.type == aiohttp.WSMsgType.BINARY:
                    header, _ = parse_frame(msg.data)
        return errors

    from clothsim.serve import engine as engine_module
    clip_frames: list[int] = []
    errors = asyncio.run(page())
    assert errors == ["internal error: OverflowError: int too big to convert"]
    err = capfd.readouterr().err
    assert "clothsim serve: internal error: OverflowError: int too big to convert\n" in err and "Traceback" not in err
    gif = Image.open(engine.clip)
    durations = []
    for i in range(gif.n_frames):
        gif.seek(i)
        durations.append(gif.info["duration"])
    # 1000 s a frame, each split into delays the format can hold
    assert max(durations) == 655350 and sum(durations) == 1_000_000 * clip_frames[0]
    assert engine._thread.is_alive() and engine.submit("state").result(30)["type"] == "state"
    engine.submit("set", field="frames_per_sec", value=90).result(30)
    engine.submit("restart").result(30)


def _boom(*args: object, **kwargs: object) -> bytes:
    raise OverflowError("int too big to convert")


def test_stop_returns_within_two_seconds_while_a_frame_is_still_running(monkeypatch):
    with ServerThread("pinned2", size=SIZE) as st:
        engine = st.engine
        state = engine.submit("state").result(30)
        assert state["type"] == "state"
        monkeypatch.setattr(type(engine.simulation), "step", lambda self, frames=1: time.sleep(4))
        engine.watch(+1)
        time.sleep(0.5)  # the worker is inside its four-second frame now
        started = time.monotonic()
        st.call(st.server.stop())
        took = time.monotonic() - started
        st.server.stop = _nothing  # already stopped
    assert took < 2.0, took


async def _nothing() -> None:
    return None


# -- foreign pages and malformed requests ----------------------------------------------------

def _serve_cli(*extra: str) -> tuple[subprocess.Popen, str]:
    env = dict(os.environ)
    env.pop("DISPLAY", None)
    proc = subprocess.Popen([sys.executable, "-m", "clothsim", "serve", "pinned2", "--port", "0", "--size", "64x64",
                             "--samples", "0", *extra], stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True,
                            env=env)
    line = proc.stdout.readline()
    m = re.fullmatch(r"clothsim: serving pinned2 at (http://127\.0\.0\.1:\d+/\?token=[\w-]+)\n", line)
    if not m:
        proc.kill()
        raise AssertionError(line + proc.stderr.read())
    return proc, m[1]


def test_foreign_origins_are_refused_and_bad_request_lines_leave_no_traceback():
    proc, url = _serve_cli("--allow-origin", "https://proxy.example:8443")
    try:
        ws_url = url.replace("http://", "ws://").replace("/?token=", "/ws?token=")
        host = url.split("/")[2]

        async def handshake(origin: str | None) -> int:
            headers = {} if origin is None else {"Origin": origin}
            async with aiohttp.ClientSession() as s:
                try:
                    async with s.ws_connect(ws_url, headers=headers) as ws:
                        await _next(ws, "state")
                        return 101
                except aiohttp.WSServerHandshakeError as exc:
                    return exc.status
        assert asyncio.run(handshake("http://evil.example")) == 403
        assert asyncio.run(handshake(f"http://{host.replace('127.0.0.1', 'localhost')}")) == 403
        assert asyncio.run(handshake(f"http://{host}")) == 101
        assert asyncio.run(handshake("https://proxy.example:8443")) == 101
        assert asyncio.run(handshake(None)) == 101
        upload = urllib.request.Request(url.replace("/?token=", "/scene?token="), data=b"{}", method="POST",
                                        headers={"Origin": "http://evil.example"})
        with pytest.raises(urllib.error.HTTPError) as err:
            urllib.request.urlopen(upload, timeout=30)
        assert err.value.code == 403

        port = int(host.split(":")[1])
        for raw in (b"\xff\xfe\xfd GET / HTTP/1.1\r\n\r\n", b"GET /\x00 HTTP/1.1\r\n\r\n", b"\x16\x03\x01\x02\x00"):
            with socket.create_connection(("127.0.0.1", port), timeout=10) as sock:
                sock.sendall(raw)
                sock.settimeout(10)
                answer = sock.recv(100)
            assert re.match(rb"HTTP/1\.[01] 400 ", answer) or answer == b"", answer
        proc.send_signal(signal.SIGINT)
        _, err = proc.communicate(timeout=30)
    finally:
        if proc.poll() is None:
            proc.kill()
            proc.wait()
    assert proc.returncode == 0 and "Traceback" not in err, err
    assert err.strip().splitlines()[-1] == "clothsim: stopped"


@pytest.mark.parametrize("how", [signal.SIGINT, signal.SIGTERM])
def test_the_cli_stops_within_two_seconds_with_a_page_watching(how):
    proc, url = _serve_cli()
    try:
        async def watch_then_signal() -> float:
            async with aiohttp.ClientSession() as s, s.ws_connect(
                    url.replace("http://", "ws://").replace("/?token=", "/ws?token=")) as ws:
                while True:  # frames are flowing
                    msg = await ws.receive(timeout=120)
                    if msg.type == aiohttp.WSMsgType.BINARY:
                        break
                started = time.monotonic()
                proc.send_signal(how)
                await asyncio.get_running_loop().run_in_executor(None, proc.wait)
                return time.monotonic() - started
        took = asyncio.run(watch_then_signal())
        err = proc.stderr.read()
    finally:
        if proc.poll() is None:
            proc.kill()
            proc.wait()
    assert proc.returncode == 0 and "Traceback" not in err, err
    assert took < 2.0, took


def test_the_served_scene_itself_is_bounded(tmp_path):
    path = tmp_path / "heavy.json"
    path.write_text(json.dumps({"cloth": PINNED2["cloth"], "simulation": {"simulation_steps": 100000}}))
    line = error_line(run_cli("serve", str(path), "--port", "0"))
    assert line.startswith(f"clothsim: error: heavy.json: simulation.simulation_steps: 100000 substeps a frame "
                           "would take about 37.5 s a frame"), line


def test_bad_allow_origin_is_one_line():
    assert error_line(run_cli("serve", "--allow-origin", "evil.example/path")) == (
        'clothsim: error: --allow-origin: expected scheme://host[:port] such as https://example.org, got '
        '"evil.example/path"')


def test_a_gif_with_a_very_low_frame_rate_is_written(tmp_path):
    r = run_cli("render", "pinned2", "--frames", "3", "--video-fps", "0.001", "--size", "64x64", "-o",
                str(tmp_path / "vf.gif"), timeout=120)
    assert r.returncode == 0 and "Traceback" not in r.stderr, r.stderr
    gif = Image.open(tmp_path / "vf.gif")
    durations = []
    for i in range(gif.n_frames):
        gif.seek(i)
        durations.append(gif.info["duration"])
    assert durations == [655350, 344650] * (len(durations) // 2) and len(durations) >= 2
