"""Rest detection: the cloth is at rest once no point moved more than a tolerance per frame
for a number of consecutive frames."""

from __future__ import annotations

import numpy as np
from numba import njit

from ..jit import EXACT
from ..jit.compile import on_warm


@njit(**EXACT)
def max_displacement(a: np.ndarray, b: np.ndarray) -> float:
    """Largest Euclidean distance between matching columns of two (3, N) arrays."""
    best = 0.0
    for p in range(a.shape[1]):
        dx = a[0, p] - b[0, p]
        dy = a[1, p] - b[1, p]
        dz = a[2, p] - b[2, p]
        d2 = dx * dx + dy * dy + dz * dz
        if d2 > best:
            best = d2
    return np.sqrt(best)


class RestDetector:
    """Feed it the (3, N) state after every frame; ``update`` returns True once at rest."""

    def __init__(self, tolerance: float, frames: int) -> None:
        self.tolerance = tolerance
        self.frames = frames
        self._previous: np.ndarray | None = None
        self._quiet = 0
        self.last_displacement = float("inf")

    def update(self, state: np.ndarray) -> bool:
        """Record a frame; True when the last ``frames`` frames all moved less than the tolerance."""
        if self._previous is None:
            self._previous = state.copy()
            return False
        self.last_displacement = max_displacement(state, self._previous)
        self._previous[...] = state
        self._quiet = self._quiet + 1 if self.last_displacement < self.tolerance else 0
        return self._quiet >= self.frames


def _warm() -> None:
    state = np.zeros((3, 4))
    max_displacement(state, state)


on_warm("2 rest detector", _warm)
