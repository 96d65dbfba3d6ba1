"""Where the bundled data lives: ``scenes/`` and ``glsl/``.

An installed wheel carries them inside the package (``clothsim/scenes``, ``clothsim/glsl``); a
source checkout or editable install keeps them at the repository's top level.
"""

from __future__ import annotations

from functools import cache
from pathlib import Path

_PACKAGE = Path(__file__).resolve().parent


@cache
def data_dir(name: str) -> Path:
    """The directory of bundled ``name`` data (``"scenes"`` or ``"glsl"``)."""
    for candidate in (_PACKAGE / name, _PACKAGE.parent.parent / name):
        if candidate.is_dir():
            return candidate
    raise FileNotFoundError(f"bundled {name}/ directory not found next to {_PACKAGE}")
