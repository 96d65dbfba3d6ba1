"""Golden-image tests: every look on a fixed draped cloth, compared with reviewed PNGs.

Regenerate after an intended change (then LOOK at every image before committing):

    CLOTHSIM_UPDATE_GOLDENS=1 pytest tests/test_render_golden.py
"""

from __future__ import annotations

import itertools
import tempfile
from pathlib import Path

import numpy as np
import pytest

pytest.importorskip("moderngl")

from clothsim.errors import ClothsimError  # noqa: E402
from clothsim.render.programs import read_source  # noqa: E402
from clothsim.render.settings import SHADERS  # noqa: E402

from render_support import (GOLDEN_DIR, GOLDEN_SIZE, draped_state, image_difference,  # noqa: E402
                            images_match, save_failure, updating_goldens)


@pytest.fixture(scope="module")
def renderer():
    from clothsim.render.renderer import Renderer

    try:
        r = Renderer(GOLDEN_SIZE, GOLDEN_SIZE)
    except ClothsimError as exc:
        pytest.skip(f"no OpenGL: {exc}")
    yield r
    r.release()


@pytest.fixture(scope="module")
def state():
    return draped_state()


@pytest.fixture(scope="module")
def images(renderer, state):
    return {look: renderer.render(state, look) for look in SHADERS}


def _golden(look: str) -> np.ndarray:
    from PIL import Image

    path = GOLDEN_DIR / f"{look}.png"
    if not path.is_file():
        pytest.fail(f"missing golden {path}; create it with CLOTHSIM_UPDATE_GOLDENS=1")
    return np.asarray(Image.open(path).convert("RGB"))


@pytest.mark.parametrize("look", SHADERS)
def test_golden(look, images):
    actual = images[look]
    if updating_goldens():
        from PIL import Image

        GOLDEN_DIR.mkdir(exist_ok=True)
        Image.fromarray(actual).save(GOLDEN_DIR / f"{look}.png")
        return
    expected = _golden(look)
    if not images_match(actual, expected):
        folder = save_failure(look, actual, expected, Path(tempfile.mkdtemp(prefix="clothsim-golden-")))
        mean, pct = image_difference(actual, expected)
        pytest.fail(f"{look}: image differs from golden (mean {mean:.2f}, p99.5 {pct:.1f}); see {folder}")


def test_looks_differ_from_each_other(images):
    """Each look must differ from every other by more than the golden tolerance."""
    for a, b in itertools.combinations(SHADERS, 2):
        assert not images_match(images[a], images[b]), f"{a} and {b} render alike"


def test_rendering_is_deterministic(renderer, state, images):
    for look in ("phong", "custom", "wireframe"):
        assert np.array_equal(renderer.render(state, look), images[look])


def test_broken_shader_is_caught(state):
    """Flip the normal in the vertex stage: the comparison must flag the phong image."""
    from clothsim.render.renderer import Renderer

    vert = read_source("mesh.vert").replace("normalize(mat3(u_model) * in_normal)",
                                            "-normalize(mat3(u_model) * in_normal)")
    assert "-normalize" in vert
    broken = Renderer(GOLDEN_SIZE, GOLDEN_SIZE, sources={"phong": (vert, read_source("phong.frag"))})
    try:
        assert not images_match(broken.render(state, "phong"), _golden("phong"))
    finally:
        broken.release()


def test_missing_specular_is_caught(renderer, state):
    from clothsim.render.settings import RenderSettings

    no_spec = RenderSettings(terms=("ambient", "diffuse"))
    assert not images_match(renderer.render(state, "phong", settings=no_spec), _golden("phong"))


def test_zero_samples_turns_antialiasing_off(state, images):
    """``samples=0`` draws the same picture into a plain framebuffer: only edge pixels differ."""
    from clothsim.render.renderer import Renderer

    plain = Renderer(GOLDEN_SIZE, GOLDEN_SIZE, samples=0)
    try:
        assert plain.samples == 0
        img = plain.render(state, "phong")
    finally:
        plain.release()
    diff = np.abs(img.astype(np.int16) - images["phong"].astype(np.int16)).max(axis=2)
    assert 0 < np.count_nonzero(diff) < 0.05 * diff.size
    assert diff.mean() < 1.0


def test_renderers_side_by_side(renderer, state, images):
    """Each renderer draws in its own context, whichever was created or released last."""
    from clothsim.render.renderer import Renderer

    other = Renderer(GOLDEN_SIZE // 2, GOLDEN_SIZE // 2, samples=0)
    try:
        small = other.render(state, "normal")
        assert np.array_equal(renderer.render(state, "phong"), images["phong"])
        assert np.array_equal(other.render(state, "normal"), small)
    finally:
        other.release()
    assert np.array_equal(renderer.render(state, "custom"), images["custom"])
