"""What the integrator studies (``bench accuracy``, ``bench stability``) share: their common options,
their sizes for a full or a ``--quick`` run, and saving their matplotlib figures."""

from __future__ import annotations

import argparse
from pathlib import Path
from typing import Any

from ..atomic import atomic_output
from ..scene import INTEGRATORS


def add_study_options(p: argparse.ArgumentParser, figure: str, png: str, runs: str) -> None:
    """The options of an integrator study: which integrators, its figure (``figure``, written to
    ``png`` by default) and a JSON file of its ``runs``."""
    p.add_argument("--integrators", nargs="*", choices=INTEGRATORS, default=None, help="default: all four")
    p.add_argument("--png", default=png, help=f"{figure} (default {png})")
    p.add_argument("--json", default=None, help=f"write {runs} as JSON")


def study_sizes(args: argparse.Namespace, **sizes: tuple[float, float]) -> list:
    """Each named option's value, else its (quick, full) default for a ``--quick`` or a full run."""
    return [getattr(args, name) or (quick if args.quick else full) for name, (quick, full) in sizes.items()]


def save_grid_figure(fig: Any, axes: Any, used: int, dest: str | Path) -> None:
    """Hide the unused panels of a subplot grid, then write the figure as PNG atomically and close it."""
    import matplotlib.pyplot as plt

    for ax in list(axes.flat)[used:]:
        ax.set_visible(False)
    fig.tight_layout()
    with atomic_output(dest) as tmp:
        fig.savefig(tmp, dpi=72, format="png")
    plt.close(fig)
