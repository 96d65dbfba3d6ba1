"""Images too large for the driver or the memory: one clear error, and nothing left allocated."""

from __future__ import annotations

import json

import pytest

pytest.importorskip("moderngl")

from clothsim.errors import ClothsimError  # noqa: E402
from clothsim.render import renderer as renderer_module  # noqa: E402
from clothsim.render.context import create_context  # noqa: E402
from clothsim.render.renderer import Renderer, RenderSizeError, framebuffer_bytes  # noqa: E402

from conftest import SCENES, run_cli  # noqa: E402


@pytest.fixture(scope="module")
def gl_info():
    try:
        ctx = create_context()
    except ClothsimError as exc:
        pytest.skip(str(exc))
    try:
        yield dict(ctx.info)
    finally:
        ctx.release()


class _Context:
    """A real context whose reported limits can be lowered; records whether it was released."""

    def __init__(self, info_changes: dict) -> None:
        self.real = create_context()
        self.info = {**self.real.info, **info_changes}
        self.released = False

    def __getattr__(self, name):
        return getattr(self.real, name)

    def __enter__(self):
        return self.real.__enter__()

    def __exit__(self, *exc):
        return self.real.__exit__(*exc)

    def release(self) -> None:
        self.released = True
        self.real.release()


@pytest.fixture
def contexts(monkeypatch, gl_info):
    """Every context a Renderer creates in the test, with lowered limits if asked for."""
    made: list[_Context] = []
    limits: dict = {}

    def create():
        made.append(_Context(limits))
        return made[-1]

    monkeypatch.setattr(renderer_module, "create_context", create)
    return made, limits


def _all_released(ctx: _Context) -> None:
    import moderngl

    assert ctx.released
    assert isinstance(ctx.real.mglo, moderngl.InvalidObject)  # the EGL context itself is gone


def test_a_later_failure_releases_the_context_and_framebuffers(contexts, monkeypatch):
    made, _ = contexts

    def failing_programs(*args, **kwargs):
        raise RuntimeError("programs failed")

    monkeypatch.setattr(renderer_module, "Programs", failing_programs)
    with pytest.raises(RuntimeError, match="programs failed"):
        Renderer(64, 48)
    assert len(made) == 1
    _all_released(made[0])


def test_framebuffers_are_released_one_by_one(contexts, monkeypatch):
    """A framebuffer refused by the driver is a size error, and what was made before it is
    released one by one, not left to whatever the driver does with a destroyed context."""
    import moderngl

    made, _ = contexts
    created = []
    real_framebuffer = moderngl.Context.framebuffer

    def second_framebuffer_fails(self, *args, **kwargs):
        if created:
            raise moderngl.Error("the framebuffer is not complete (INCOMPLETE_ATTACHMENT)")
        created.append(real_framebuffer(self, *args, **kwargs))
        return created[-1]

    monkeypatch.setattr(moderngl.Context, "framebuffer", second_framebuffer_fails)
    with pytest.raises(RenderSizeError, match="64x48"):
        Renderer(64, 48)
    _all_released(made[0])
    assert len(created) == 1 and isinstance(created[0].mglo, moderngl.InvalidObject)


def test_size_beyond_the_driver_limit_is_refused_before_allocating(contexts, monkeypatch):
    made, limits = contexts
    limits["GL_MAX_RENDERBUFFER_SIZE"] = 1024
    monkeypatch.setattr(renderer_module.Renderer, "_framebuffers",
                        lambda self: pytest.fail("allocated a framebuffer past the driver's limit"))
    with pytest.raises(RenderSizeError) as info:
        Renderer(2048, 64)
    assert "2048x64" in str(info.value) and "1024x1024 at most" in str(info.value)
    _all_released(made[0])


@pytest.mark.parametrize("driver", ["this one", "a GPU's"])
def test_size_beyond_the_memory_is_refused_with_both_amounts(contexts, gl_info, monkeypatch, driver):
    made, limits = contexts
    assert framebuffer_bytes(4096, 4096, 4) == 4096 * 4096 * (4 * 8 + 4 + 3)  # 4 samples of colour + depth,
    # resolve, read-back; a GPU keeps its framebuffers in its own memory: only the read-back counts
    assert framebuffer_bytes(4096, 4096, 4, software=False) == 4096 * 4096 * 3
    if driver != "this one":
        limits["GL_RENDERER"] = "NVIDIA H100 80GB HBM3/PCIe/SSE2"  # as that driver names itself
    renderer_name = str(limits.get("GL_RENDERER", gl_info.get("GL_RENDERER", "")))
    software = renderer_module._is_software(renderer_name)
    need = framebuffer_bytes(4096, 4096, 4, software=software)
    monkeypatch.setattr(renderer_module, "available_memory", lambda: need - 1)
    monkeypatch.setattr(renderer_module.Renderer, "_framebuffers",
                        lambda self: pytest.fail("allocated a framebuffer past the memory"))
    with pytest.raises(RenderSizeError) as info:
        Renderer(4096, 4096, samples=4)
    message = str(info.value)
    assert "\n" not in message
    if driver != "this one":
        assert "needs about 48 MiB" in message and "48 MiB available" in message
    elif "llvmpipe" in made[0].info.get("GL_RENDERER", ""):
        assert "needs about 0.6 GiB" in message and "0.6 GiB available" in message
    _all_released(made[0])


def test_a_renderer_that_fits_still_works(contexts):
    made, _ = contexts
    r = Renderer(32, 16, samples=4)
    try:
        assert r.width == 32 and r.height == 16 and not made[0].released
    finally:
        r.release()
    _all_released(made[0])


def _assert_size_error(r, label: str) -> None:
    assert r.returncode == 2, r.stderr
    assert "Traceback" not in r.stderr
    lines = r.stderr.strip().splitlines()
    assert len(lines) == 1, r.stderr
    assert lines[0].startswith(f"clothsim: error: {label}: image size 16384x16384"), lines[0]
    assert "smaller size" in lines[0]


@pytest.fixture(scope="module")
def too_large(gl_info):
    """16384x16384 with 4x multisampling (8 GiB of framebuffer) fails on llvmpipe, whose buffers
    stop at 2 GiB; a GPU with the memory draws it, so there is nothing to refuse."""
    if "llvmpipe" not in str(gl_info.get("GL_RENDERER", "")).lower():
        pytest.skip(f"{gl_info.get('GL_RENDERER')} may well allocate a 16384x16384 4x framebuffer")


def test_cli_too_large_size_is_one_line(tmp_path, too_large):
    out = tmp_path / "x.png"
    r = run_cli("render", "pinned2", "--frames", "1", "--size", "16384x16384", "-o", str(out), cwd=tmp_path)
    _assert_size_error(r, "--size")
    assert list(tmp_path.iterdir()) == []


def test_cli_too_large_scene_size_names_the_field(tmp_path, too_large):
    scene = json.loads((SCENES / "pinned2.json").read_text())
    scene["render"] = {"size": [16384, 16384]}
    path = tmp_path / "big.json"
    path.write_text(json.dumps(scene))
    out = tmp_path / "frames"
    r = run_cli("render", str(path), "--frames", "1", "-o", str(out), cwd=tmp_path)
    _assert_size_error(r, f"{path}: render.size")
    assert list(tmp_path.iterdir()) == [path]
