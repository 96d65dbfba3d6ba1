"""Reading back what the OBJ exporter wrote (shared by the export tests)."""

from __future__ import annotations

from pathlib import Path

import numpy as np


def parse_obj(path: Path) -> dict[str, dict[str, np.ndarray]]:
    """A plain OBJ reader: per object, v/vt/vn as float32 and faces as (F, k, 3) 1-based indices."""
    objects: dict[str, dict[str, list]] = {}
    current = None
    for line in path.read_text(encoding="ascii").splitlines():
        if not line or line.startswith("#"):
            continue
        tag, *rest = line.split()
        if tag == "o":
            current = objects.setdefault(rest[0], {"v": [], "vt": [], "vn": [], "f": []})
        elif tag in ("v", "vt", "vn"):
            current[tag].append([np.float32(x) for x in rest])  # str -> float32, as a reader would
        elif tag == "f":
            current["f"].append([[int(i) for i in corner.split("/")] for corner in rest])
        else:
            assert tag == "s", line
    return {name: {"v": np.array(o["v"], dtype=np.float32).reshape(-1, 3),
                   "vt": np.array(o["vt"], dtype=np.float32).reshape(-1, 2),
                   "vn": np.array(o["vn"], dtype=np.float32).reshape(-1, 3),
                   "f": np.array(o["f"], dtype=np.int64)} for name, o in objects.items()}
