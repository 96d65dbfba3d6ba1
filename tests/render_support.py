"""Shared pieces of the render tests: a fixed cloth state and a tolerant image comparison."""

from __future__ import annotations

import os
from dataclasses import dataclass
from pathlib import Path
from collections.abc import Iterator
from typing import Any, NamedTuple

import numpy as np

from clothsim.cloth import Springs, all_springs, grid_positions, pinned_mask
from clothsim.scene import Scene, scene_from_dict

GOLDEN_DIR = Path(__file__).parent / "golden"
GOLDEN_SIZE = 256
UPDATE_ENV = "CLOTHSIM_UPDATE_GOLDENS"

# Tolerances, in 8-bit steps. The same GL program on another driver or CPU rasterises edges and
# filters textures slightly differently: those differences are small on average and confined to
# the pixels along silhouettes and texel boundaries. A real change (a wrong normal, a missing
# term, a moved camera) shifts a large area by far more. So: the mean must stay within one step,
# all but the worst 0.5% of pixel-channels (about 330 values at 256x256, roughly an edge's length)
# within 8 steps, and no more than 10% of them may be off by 3 steps or more.
#
# The last rule is the one that sees a small shift of a whole region: +3 on every cloth pixel
# (41-46% of the image) moves the mean by only 1.2-1.4, and on the wireframe, whose white lines
# cannot get brighter, by 0.58, under the first rule's limit; it puts 19% (wireframe) to 46% of
# the pixel-channels 3 steps off. Measured against it (tests/test_render_golden.py): the same
# renders with anti-aliasing off differ by 3+ steps in at most 2.5% of the pixel-channels of the
# shaded looks, Mesa's softpipe (another rasteriser, other texture filtering) in at most 7.6%,
# and a 1/64-pixel shift of the whole image in at most 2.1%. The wireframe is the exception to
# "noise stays near edges": at 256x256 its 48x48 lines leave almost no pixel far from an edge, so
# a 1/256-pixel shift already takes its p99.5 to 19.
MEAN_TOLERANCE = 1.0
PERCENTILE = 99.5
PERCENTILE_TOLERANCE = 8.0
SHIFT_STEPS = 3
SHIFT_SHARE = 0.10


@dataclass
class FixedState:
    """The attributes the renderer reads from a Simulation, for a state that never changes."""

    scene: Scene
    nw: int
    nh: int
    positions: np.ndarray
    springs: Springs
    pinned: np.ndarray
    frame: int = 0

    @property
    def live_springs(self) -> Springs:
        return self.springs


def draped_state() -> FixedState:
    """A cloth draped analytically over a sphere above a floor: no simulator involved, so the
    goldens pin the renderer alone."""
    scene = scene_from_dict({
        "cloth": {"width": 1.0, "height": 1.0, "num_width_points": 48, "num_height_points": 48,
                  "thickness": 0.01, "orientation": 0, "damping": 0.2, "density": 150.0, "ks": 5000.0},
        "sphere": {"origin": [0.5, 0.0, 0.5], "radius": 0.22, "friction": 0.3},
        "plane": {"point": [0.5, -0.35, 0.5], "normal": [0.0, 1.0, 0.0], "friction": 0.5},
    }, "<golden>")
    nw = nh = 48
    pos = grid_positions(scene.cloth, 0)
    x, z = pos[:, 0] - 0.5, pos[:, 2] - 0.5
    r = np.hypot(x, z)
    theta = np.arctan2(z, x)
    # A dome over the sphere that falls into six folds towards the edges.
    y = 0.235 * np.exp(-(r / 0.3) ** 2) - 0.3 * np.clip(r - 0.2, 0.0, None) ** 1.2
    y += 0.04 * np.sin(6 * theta) * np.clip(r - 0.15, 0.0, None)
    pull = 1.0 - 0.25 * np.clip(r - 0.2, 0.0, None)  # the hem gathers inwards as it hangs
    pos[:, 0] = 0.5 + x * pull
    pos[:, 1] = y
    pos[:, 2] = 0.5 + z * pull
    start = grid_positions(scene.cloth, 0)
    return FixedState(scene=scene, nw=nw, nh=nh, positions=pos, springs=all_springs(nw, nh, start),
                      pinned=pinned_mask(scene.cloth))


class Difference(NamedTuple):
    """How far two images are apart, over every pixel channel, in 8-bit steps."""

    mean: float  # mean absolute difference
    pct: float  # its 99.5th percentile
    shifted: float  # share of pixel-channels off by SHIFT_STEPS or more

    def __str__(self) -> str:
        return f"mean {self.mean:.2f}, p99.5 {self.pct:.1f}, {self.shifted:.1%} off by {SHIFT_STEPS}+"


def image_difference(actual: np.ndarray, expected: np.ndarray) -> Difference:
    """The three figures the tolerances above bound."""
    if actual.shape != expected.shape:
        return Difference(float("inf"), float("inf"), 1.0)
    d = np.abs(actual.astype(np.int16) - expected.astype(np.int16)).astype(np.float64)
    return Difference(float(d.mean()), float(np.percentile(d, PERCENTILE)), float((d >= SHIFT_STEPS).mean()))


def images_match(actual: np.ndarray, expected: np.ndarray) -> bool:
    """Whether ``actual`` is ``expected`` up to driver noise (see the tolerances above)."""
    d = image_difference(actual, expected)
    return d.mean <= MEAN_TOLERANCE and d.pct <= PERCENTILE_TOLERANCE and d.shifted <= SHIFT_SHARE


def save_failure(name: str, actual: np.ndarray, expected: np.ndarray, folder: Path) -> Path:
    """Write actual, expected and a x8 amplified difference image; returns the folder."""
    from PIL import Image

    folder.mkdir(parents=True, exist_ok=True)
    Image.fromarray(actual).save(folder / f"{name}-actual.png")
    Image.fromarray(expected).save(folder / f"{name}-expected.png")
    if actual.shape == expected.shape:
        diff = np.abs(actual.astype(np.int16) - expected.astype(np.int16)) * 8
        Image.fromarray(np.clip(diff, 0, 255).astype(np.uint8)).save(folder / f"{name}-diff-x8.png")
    return folder


def updating_goldens() -> bool:
    return os.environ.get(UPDATE_ENV, "") not in ("", "0")


def golden_renderer() -> Iterator[Any]:
    """A renderer at the goldens' size (a module-scoped fixture's body: ``pytest.fixture`` of it),
    skipping where there is no OpenGL."""
    import pytest

    pytest.importorskip("moderngl")
    from clothsim.errors import ClothsimError
    from clothsim.render.renderer import Renderer

    try:
        r = Renderer(GOLDEN_SIZE, GOLDEN_SIZE)
    except ClothsimError as exc:
        pytest.skip(f"no OpenGL: {exc}")
    yield r
    r.release()
