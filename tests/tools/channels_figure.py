"""Draw docs/images/dataset_channels.png: one run's channels side by side from two of its views.

    .venv/bin/python tests/tools/channels_figure.py [OUT.png]

Runs a sweep of one run with ``views=2`` into a temporary folder, reads it back with
``clothsim.datasets`` and lays out, per view (a row): RGB, depth, world normals (xyz -> rgb), the mask (one colour per id) and the flow to the next sampled
frame (hue = direction, brightness = speed; the usual colour wheel). Depth is shaded by its
inverse, near bright, far dark, the background black.
"""

from __future__ import annotations

import colorsys
import sys
import tempfile
from pathlib import Path

import numpy as np
from PIL import Image, ImageDraw

import clothsim
from clothsim.datasets import open_dataset

# A cloth pinned at two corners falls past a sphere and swings over a floor: both of its sides,
# two colliders and plenty of motion in one frame.
SCENE = {
    "cloth": {"width": 1.0, "height": 1.0, "num_width_points": 30, "num_height_points": 30, "thickness": 0.0095,
              "orientation": 0, "pinned": [[0, 29], [29, 29]], "damping": 0.2, "density": 150.0, "ks": 5000.0},
    "sphere": {"origin": [0.5, -0.35, 0.45], "radius": 0.22, "friction": 0.3},
    "plane": {"point": [0.0, -0.75, 0.0], "normal": [0.0, 1.0, 0.0], "friction": 0.5},
    "simulation": {"simulation_steps": 30},
}
MASK_COLORS = np.array([[0, 0, 0], [230, 160, 40], [60, 120, 230], [200, 60, 60], [70, 190, 90], [180, 90, 200],
                        [220, 220, 80], [80, 200, 200]], dtype=np.uint8)


def depth_image(depth: np.ndarray) -> np.ndarray:
    seen = depth > 0
    out = np.zeros(depth.shape + (3,), dtype=np.uint8)
    if seen.any():
        # Shaded by inverse depth, near bright: a floor reaching far away leaves the cloth's range.
        inv = np.where(seen, 1.0 / np.where(seen, depth, 1.0), 0.0)
        lo, hi = float(inv[seen].min()), float(inv[seen].max())
        g = (inv - lo) / max(hi - lo, 1e-9)
        v = (40 + 215 * g).clip(0, 255).astype(np.uint8)
        out[seen] = v[seen, None]
    return out


def normal_image(normal: np.ndarray) -> np.ndarray:
    n = normal.astype(np.float32)
    seen = np.any(n != 0, axis=-1)
    out = ((n * 0.5 + 0.5) * 255).clip(0, 255).astype(np.uint8)
    out[~seen] = 0
    return out


def flow_image(flow: np.ndarray) -> np.ndarray:
    mag = np.hypot(flow[..., 0], flow[..., 1])
    scale = max(float(np.percentile(mag[mag > 0], 99)) if (mag > 0).any() else 1.0, 1e-6)
    hue = (np.arctan2(-flow[..., 1], flow[..., 0]) / (2 * np.pi)) % 1.0
    val = np.clip(mag / scale, 0, 1)
    rgb = np.array([colorsys.hsv_to_rgb(h, 1.0, v) for h, v in zip(hue.ravel(), val.ravel())]).reshape(flow.shape[:2] + (3,))
    return (rgb * 255).astype(np.uint8)


def main(out: Path) -> None:
    with tempfile.TemporaryDirectory() as tmp:
        # Seed 2 draws one camera above the cloth and one that sees its back.
        clothsim.sweep(SCENE, {"cloth.ks": [5000]}, f"{tmp}/ds", frames=60, every=10, views=2, size=(256, 256),
                       workers=1, samples=1, seed=2)
        data = open_dataset(f"{tmp}/ds")
        run = next(iter(data))
    v = run.views
    t = 5  # frame 50: the cloth swings down past the sphere
    cols = ["rgb", "depth", "normal", "mask", "flow"]
    size, label_h = 256, 22
    sheet = Image.new("RGB", (len(cols) * size, 2 * (size + label_h)), (255, 255, 255))
    draw = ImageDraw.Draw(sheet)
    for view in range(2):
        tiles = [v["rgb"][view, t], depth_image(v["depth"][view, t]), normal_image(v["normal"][view, t]),
                 MASK_COLORS[v["mask"][view, t] % len(MASK_COLORS)], flow_image(v["flow"][view, t])]
        y = view * (size + label_h)
        for c, (name, tile) in enumerate(zip(cols, tiles)):
            draw.text((c * size + 6, y + 5), f"view {view}: {name}", fill=(0, 0, 0))
            sheet.paste(Image.fromarray(tile), (c * size, y + label_h))
    sheet.save(out, optimize=True)


if __name__ == "__main__":
    main(Path(sys.argv[1]) if len(sys.argv) > 1 else Path(__file__).resolve().parents[2] / "docs" / "images" / "dataset_channels.png")
