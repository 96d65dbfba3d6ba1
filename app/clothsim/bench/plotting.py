"""Saving the benchmarks' matplotlib figures."""

from __future__ import annotations

from pathlib import Path
from typing import Any

from ..atomic import atomic_output


def save_grid_figure(fig: Any, axes: Any, used: int, dest: str | Path) -> None:
    """Hide the unused panels of a subplot grid, then write the figure as PNG atomically and close it."""
    import matplotlib.pyplot as plt

    for ax in list(axes.flat)[used:]:
        ax.set_visible(False)
    fig.tight_layout()
    with atomic_output(dest) as tmp:
        fig.savefig(tmp, dpi=72, format="png")
    plt.close(fig)
