"""Draw docs/images/stress_sheet.png: the self-collision stress set, the spec's hash beside the
contact mode, a few frames of each run, each cell labelled with its crossing count.

    .venv/bin/python tests/tools/stress_sheet.py [OUT.png] [--grid N] [--frames A,B,C]

Rows: one per stress run (``clothsim.bench.stress``); columns: each listed frame in each mode, the
modes side by side. A run that blows up leaves its later cells pale red. Crossings are counted
exactly (``Simulation.crossings``) on the state drawn.
"""

from __future__ import annotations

import argparse
from pathlib import Path

import numpy as np
from PIL import Image, ImageDraw

from clothsim.bench.stress import FOLDING_SCENES as STRESS_SCENES, StressRun
from clothsim.errors import SimulationBlowUp
from clothsim.render import Renderer

MODES = ("spec", "contact")
CELL = 200
LABEL_W = 100
HEADER_H = 22
CAPTION_H = 18


def run_cells(renderer: Renderer, scene: str, mode: str, grid: int, frames: list[int]) -> list[tuple[np.ndarray | None, str]]:
    """The images (None after a blow-up) and captions of one run at ``frames``."""
    run = StressRun(scene, mode, grid)
    cells: list[tuple[np.ndarray | None, str]] = []
    blew_up = None
    for target in frames:
        while blew_up is None and run.frames < target:
            try:
                run.frame()
            except SimulationBlowUp:
                blew_up = run.frames + 1
        if blew_up is not None:
            cells.append((None, f"blew up at frame {blew_up}"))
            continue
        cells.append((renderer.render(run.sim), f"{run.crossings()} crossings"))
    return cells


def main() -> int:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("out", nargs="?", default=str(Path(__file__).resolve().parents[2] / "docs/images/stress_sheet.png"))
    p.add_argument("--grid", type=int, default=50)
    p.add_argument("--frames", default="60,150,300")
    args = p.parse_args()
    frames = [int(f) for f in args.frames.split(",")]
    renderer = Renderer(CELL, CELL, samples=4)
    runs = {(scene, mode): run_cells(renderer, scene, mode, args.grid, frames) for scene in STRESS_SCENES
            for mode in MODES}
    columns = [(k, f, mode) for k, f in enumerate(frames) for mode in MODES]
    width = LABEL_W + CELL * len(columns)
    height = 2 * HEADER_H + len(STRESS_SCENES) * (CELL + CAPTION_H)
    sheet = Image.new("RGB", (width, height), (255, 255, 255))
    draw = ImageDraw.Draw(sheet)
    draw.text((4, 4), f"{args.grid}x{args.grid} points; crossings = edges through triangles they share no point "
                      "with, counted on the state drawn", fill=(0, 0, 0))
    for c, (_, f, mode) in enumerate(columns):
        draw.text((LABEL_W + c * CELL + 4, HEADER_H + 4), f"frame {f}, self_collision: {mode}", fill=(0, 0, 0))
    for r, scene in enumerate(STRESS_SCENES):
        y = 2 * HEADER_H + r * (CELL + CAPTION_H)
        draw.text((6, y + CELL // 2 - 6), scene, fill=(0, 0, 0))
        for c, (k, _, mode) in enumerate(columns):
            image, caption = runs[scene, mode][k]
            x = LABEL_W + c * CELL
            if image is None:
                draw.rectangle([x, y, x + CELL - 1, y + CELL - 1], fill=(250, 215, 215))
            else:
                sheet.paste(Image.fromarray(image), (x, y))
            bad = image is None or not caption.startswith("0 ")
            draw.text((x + 4, y + CELL + 3), caption, fill=(170, 0, 0) if bad else (0, 0, 0))
    Path(args.out).parent.mkdir(parents=True, exist_ok=True)
    tmp = Path(args.out).with_suffix(".tmp.png")
    sheet.save(tmp, optimize=True)
    tmp.replace(args.out)
    print(args.out)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
