"""A contact sheet: one cell per run (and per listed frame), pasted unscaled, labelled outside.

Rows are the first swept field's values; columns are the other fields' combinations, and within
each the listed frames (labelled with their time). A single field with a single frame is one
row. A sampled sweep has one row per run, labelled with its parameters. Each column label sits
above its column, each row label left of its row, and the legend (which field is which) in the
top band, so no label covers an image.
"""

from __future__ import annotations

import itertools
from dataclasses import dataclass
from typing import Any

import numpy as np

from ..validate import shown

__all__ = ["Layout", "SheetSpec", "compose", "plan"]

GAP = 6  # pixels between cells
PAD = 8  # around labels and the sheet
BACKGROUND = (255, 255, 255)
INK = (20, 20, 20)
FAILED = (244, 214, 214)  # a failed run: pale red, unlike any floor or sky


@dataclass(frozen=True)
class SheetSpec:
    """What goes where: ``slots[r][c]`` = (run id, frame) of each cell, and the labels."""

    row_labels: list[str]
    col_labels: list[str]
    legend: str
    slots: list[list[tuple[str, int]]]


def _short(fields: list[str]) -> dict[str, str]:
    """Field paths as labels show them: the last component, unless two fields share it."""
    last = [f.rsplit(".", 1)[-1] for f in fields]
    return {f: (s if last.count(s) == 1 else f) for f, s in zip(fields, last)}


def _value(v: Any) -> str:
    if isinstance(v, float):
        return f"{v:.4g}"
    return shown(v).strip('"')


def plan(runs: list[Any], space: dict[str, list[Any]], frames: list[int], fps: float, sampled: bool) -> SheetSpec:
    """The layout of a sweep's runs (``runs`` in id order, each with ``.id`` and ``.params``)."""
    fields = list(space)
    short = _short(fields)
    times = [f"t = {f / fps:.2f} s (frame {f})" for f in frames]
    multi = len(frames) > 1
    if sampled:
        rows = [[(r.id, f) for f in frames] for r in runs]
        row_labels = [f"{r.id}\n" + "\n".join(f"{short[k]} = {_value(v)}" for k, v in r.params.items()) for r in runs]
        col_labels = times
        legend = "\n".join(f"{short[f]}: {f}" for f in fields if short[f] != f)
        return SheetSpec(row_labels, col_labels, legend, rows)
    by_params = {tuple(r.params[f] for f in fields): r.id for r in runs}
    values = [space[f] for f in fields]
    if len(fields) == 1 and not multi:
        row_labels = [""]
        col_labels = [f"{short[fields[0]]} = {_value(v)}" for v in values[0]]
        slots = [[(by_params[(v,)], frames[0]) for v in values[0]]]
        return SheetSpec(row_labels, col_labels, _legend(fields, short), slots)
    row_values = values[0]
    col_combos = list(itertools.product(*values[1:]))
    row_labels = [f"{short[fields[0]]} = {_value(v)}" for v in row_values]
    col_labels, slots = [], [[] for _ in row_values]
    for combo in col_combos:
        head = "\n".join(f"{short[f]} = {_value(v)}" for f, v in zip(fields[1:], combo))
        for f, t in zip(frames, times):
            col_labels.append("\n".join(x for x in (head, t if multi else "") if x))
            for i, rv in enumerate(row_values):
                slots[i].append((by_params[(rv, *combo)], f))
    return SheetSpec(row_labels, col_labels, _legend(fields, short), slots)


def _legend(fields: list[str], short: dict[str, str]) -> str:
    if len(fields) == 1:
        return fields[0]
    return f"rows: {fields[0]}\ncolumns: {', '.join(fields[1:])}"


def font(cell_height: int) -> Any:
    from PIL import ImageFont

    size = max(11, min(16, cell_height // 9))
    try:
        return ImageFont.load_default(size=size)
    except TypeError:  # Pillow < 10.1: the fixed bitmap font
        return ImageFont.load_default()


@dataclass(frozen=True)
class Layout:
    """Pixel geometry of a sheet: cells of ``cell`` (w, h) in ``rows`` x ``cols`` slots."""

    cell: tuple[int, int]
    rows: int
    cols: int
    left: int  # width of the row-label margin
    top: int  # height of the column-label margin
    col_width: int  # a slot is at least a cell wide, wider if its label is

    @property
    def size(self) -> tuple[int, int]:
        w = self.left + self.cols * self.col_width + (self.cols - 1) * GAP + PAD
        h = self.top + self.rows * self.cell[1] + (self.rows - 1) * GAP + PAD
        return w, h

    def cell_box(self, row: int, col: int) -> tuple[int, int, int, int]:
        """(left, top, right, bottom) of the cell at ``row``, ``col`` (right/bottom exclusive)."""
        x = self.left + col * (self.col_width + GAP) + (self.col_width - self.cell[0]) // 2
        y = self.top + row * (self.cell[1] + GAP)
        return x, y, x + self.cell[0], y + self.cell[1]


def _text_size(draw: Any, text: str, f: Any) -> tuple[int, int]:
    if not text:
        return 0, 0
    box = draw.multiline_textbbox((0, 0), text, font=f, spacing=3)
    return box[2] - box[0], box[3] - box[1]


def layout(spec: SheetSpec, cell: tuple[int, int]) -> Layout:
    from PIL import Image, ImageDraw

    draw = ImageDraw.Draw(Image.new("RGB", (1, 1)))
    f = font(cell[1])
    row_w = max((_text_size(draw, t, f)[0] for t in spec.row_labels), default=0)
    col_w = max((_text_size(draw, t, f)[0] for t in spec.col_labels), default=0)
    col_h = max((_text_size(draw, t, f)[1] for t in spec.col_labels), default=0)
    leg_w, leg_h = _text_size(draw, spec.legend, f)
    left = row_w + 2 * PAD
    top = leg_h + col_h + 3 * PAD  # the legend on top, the column labels under it
    return Layout(cell, len(spec.slots), len(spec.slots[0]), left, top, max(cell[0], col_w + 4))


def compose(spec: SheetSpec, images: dict[tuple[str, int], np.ndarray | None], cell: tuple[int, int]) -> np.ndarray:
    """The sheet as an (H, W, 3) uint8 image; a missing image (a failed run) is a pale red cell."""
    from PIL import Image, ImageDraw

    geo = layout(spec, cell)
    sheet = Image.new("RGB", geo.size, BACKGROUND)
    draw = ImageDraw.Draw(sheet)
    f = font(cell[1])
    draw.multiline_text((PAD, PAD), spec.legend, fill=(90, 90, 90), font=f, spacing=3)
    for c, text in enumerate(spec.col_labels):
        x0, _, x1, _ = geo.cell_box(0, c)
        w, h = _text_size(draw, text, f)
        draw.multiline_text(((x0 + x1 - w) // 2, geo.top - PAD - h), text, fill=INK, font=f, spacing=3,
                            align="center")
    for r, text in enumerate(spec.row_labels):
        _, y0, _, y1 = geo.cell_box(r, 0)
        w, h = _text_size(draw, text, f)
        draw.multiline_text((geo.left - PAD - w, (y0 + y1 - h) // 2), text, fill=INK, font=f, spacing=3,
                            align="right")
    for r, row in enumerate(spec.slots):
        for c, key in enumerate(row):
            box = geo.cell_box(r, c)
            image = images.get(key)
            if image is None:
                draw.rectangle((box[0], box[1], box[2] - 1, box[3] - 1), fill=FAILED)
                w, h = _text_size(draw, "failed", f)
                draw.text(((box[0] + box[2] - w) // 2, (box[1] + box[3] - h) // 2), "failed", fill=INK, font=f)
            else:
                sheet.paste(Image.fromarray(np.ascontiguousarray(image)), box[:2])
    return np.asarray(sheet)
