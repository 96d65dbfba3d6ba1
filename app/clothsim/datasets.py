"""Reading a ``clothsim sweep`` dataset as NumPy arrays.

A dataset folder (``clothsim sweep SCENE ... -o DIR``) holds ``meta.json`` (every field
described), ``manifest.jsonl`` (one line per finished run) and ``runs/``. This module needs only
NumPy, and Pillow for the RGB images; the format is plain enough to read without it too
(docs/datasets.md shows how)::

    from clothsim.datasets import open_dataset

    data = open_dataset("clips/")
    for run in data.runs("train"):
        run.arrays["world_pos"]       # (T, N, 3) float32, metres
        run.views["depth"]            # (V, T, H, W) float32, metres (with --views)
"""

from __future__ import annotations

import json
import os
from collections.abc import Iterator
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from .errors import ClothsimError

__all__ = ["Dataset", "Run", "open_dataset", "SPLITS", "ALIASES"]

SPLITS = ("train", "valid", "test")
# MeshGraphNets' names of the run file's members that are stored under another name.
ALIASES = {"world_pos": "positions"}
_META = "meta.json"
_MANIFEST = "manifest.jsonl"


@dataclass
class Run:
    """One finished run: its ``id``, ``params`` (field path -> value), ``split``, the run file's
    ``arrays`` (``positions``/``world_pos``, ``frames``, ``faces``/``cells``, ``uv``, ``mesh_pos``,
    ``node_type``, ``pinned``, ``scene`` as a dict) and, with views, ``views``: ``rgb`` (V, T, H, W,
    3) uint8, ``depth``, ``normal``, ``mask``, ``flow`` (those written) and ``cameras`` (a list of
    dicts with ``K``, ``world_to_camera_opencv``, ``view_opengl``, ``projection_opengl``, ...)."""

    id: str
    params: dict[str, Any]
    split: str
    arrays: dict[str, Any]
    views: dict[str, Any] | None = field(default=None)


class Dataset:
    """An opened dataset folder; see :func:`open_dataset`."""

    def __init__(self, path: Path, meta: dict[str, Any], records: dict[str, dict[str, Any]]) -> None:
        self.path = path
        self.meta = meta
        self._records = records
        splits = meta.get("splits", {}).get("runs", {})
        self._split = {rid: name for name in SPLITS for rid in splits.get(name, [])}

    def ids(self, split: str | None = None) -> list[str]:
        """The ids of the finished (``done``) runs, in order; only those of ``split`` if given."""
        if split is not None and split not in SPLITS:
            raise ClothsimError(f"split: expected one of {', '.join(SPLITS)}, got {split!r}")
        return [rid for rid in sorted(self._records)
                if self._records[rid].get("status") == "done" and (split is None or self._split.get(rid) == split)]

    def __len__(self) -> int:
        return len(self.ids())

    def __iter__(self) -> Iterator[Run]:
        return self.runs()

    def runs(self, split: str | None = None, *, views: bool = True) -> Iterator[Run]:
        """Every finished run (of ``split``), loaded one at a time; ``views=False`` skips images."""
        for rid in self.ids(split):
            yield self.load(rid, views=views)

    def load(self, run_id: str, *, views: bool = True) -> Run:
        """One run by id, its arrays read whole into memory."""
        record = self._records.get(run_id)
        if record is None or record.get("status") != "done":
            raise ClothsimError(f"{self.path}: no finished run {run_id!r}")
        arrays = load_run_file(self.path / "runs" / f"{run_id}.npz")
        view_data = None
        if views and self.meta.get("views"):
            view_data = load_views(self.path / "runs" / run_id, arrays["frames"], self.meta["views"]["count"])
        return Run(run_id, dict(record.get("params") or {}), self._split.get(run_id, ""), arrays, view_data)


def open_dataset(path: str | os.PathLike[str]) -> Dataset:
    """Open the dataset folder ``path``: reads ``meta.json`` and the manifest (a run's last
    complete line counts); runs are read when iterated or loaded."""
    root = Path(path)
    try:
        meta = json.loads((root / _META).read_text(encoding="utf-8"))
    except FileNotFoundError:
        raise ClothsimError(f"{root}: not a clothsim dataset (no {_META})") from None
    except (OSError, ValueError) as exc:
        raise ClothsimError(f"{root}/{_META}: cannot read: {' '.join(str(exc).split())}") from None
    records: dict[str, dict[str, Any]] = {}
    try:
        text = (root / _MANIFEST).read_text(encoding="utf-8", errors="replace")
    except FileNotFoundError:
        text = ""
    for line in text.splitlines():
        try:
            record = json.loads(line)
        except ValueError:
            continue  # a line torn by a crash
        if isinstance(record, dict) and isinstance(record.get("id"), str):
            records[record["id"]] = record
    return Dataset(root, meta, records)


def load_run_file(path: str | os.PathLike[str]) -> dict[str, Any]:
    """A run's ``.npz`` as a dict of arrays, with MeshGraphNets' names added where the file
    stores a field under another (``world_pos`` is ``positions``) and ``scene`` parsed."""
    with np.load(path, allow_pickle=False) as data:
        arrays: dict[str, Any] = {k: data[k] for k in data.files}
    for alias, name in ALIASES.items():
        if alias not in arrays and name in arrays:
            arrays[alias] = arrays[name]
    if "cells" not in arrays and "faces" in arrays:
        arrays["cells"] = arrays["faces"]
    if "scene" in arrays:
        arrays["scene"] = json.loads(str(arrays["scene"]))
    return arrays


def load_views(folder: str | os.PathLike[str], frames: np.ndarray, count: int) -> dict[str, Any]:
    """A run's views folder: ``cameras`` (list of dicts), ``rgb`` (V, T, H, W, 3) uint8 if written,
    and the members of ``channels.npz``."""
    from PIL import Image

    root = Path(folder)
    out: dict[str, Any] = {"cameras": json.loads((root / "cameras.json").read_text(encoding="utf-8"))}
    first = root / f"rgb_v0_{int(frames[0]):05d}.png"
    if first.is_file():
        out["rgb"] = np.stack([np.stack([np.asarray(Image.open(root / f"rgb_v{v}_{int(f):05d}.png").convert("RGB"))
                                         for f in frames]) for v in range(count)])
    if (root / "channels.npz").is_file():
        with np.load(root / "channels.npz", allow_pickle=False) as data:
            out.update({k: data[k] for k in data.files})
    return out
