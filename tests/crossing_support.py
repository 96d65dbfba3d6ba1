"""A brute-force reference for the crossing counter, and the stress runs that count crossings frame by frame."""

from __future__ import annotations

from dataclasses import dataclass
from fractions import Fraction

import numpy as np

from clothsim.sim.crossings import mesh_edges


def _orient(a: np.ndarray, b: np.ndarray, c: np.ndarray, d: np.ndarray) -> np.ndarray:
    """det[a-d; b-d; c-d] for broadcast (..., 3) arrays (exact for small integer coordinates in int64)."""
    u, v, w = a - d, b - d, c - d
    return (u[..., 0] * (v[..., 1] * w[..., 2] - v[..., 2] * w[..., 1])
            - u[..., 1] * (v[..., 0] * w[..., 2] - v[..., 2] * w[..., 0])
            + u[..., 2] * (v[..., 0] * w[..., 1] - v[..., 1] * w[..., 0]))


def brute_force_pairs(points: np.ndarray, triangles: np.ndarray) -> set[tuple[int, int]]:
    """Every (edge index, triangle index) crossing, testing all E x T pairs at once."""
    tris = np.asarray(triangles).reshape(-1, 3)
    edges = mesh_edges(tris)
    p = points[edges[:, 0]][:, None, :]
    q = points[edges[:, 1]][:, None, :]
    a, b, c = (points[tris[:, k]][None, :, :] for k in range(3))
    sp, sq = np.sign(_orient(a, b, c, p)), np.sign(_orient(a, b, c, q))
    s1, s2, s3 = np.sign(_orient(p, q, a, b)), np.sign(_orient(p, q, b, c)), np.sign(_orient(p, q, c, a))
    shares = ((edges[:, None, 0:1] == tris[None, :, :]) | (edges[:, None, 1:2] == tris[None, :, :])).any(axis=2)
    hit = (sp * sq < 0) & (s1 != 0) & (s1 == s2) & (s2 == s3) & ~shares
    return {(int(e), int(t)) for e, t in zip(*np.nonzero(hit))}


def _exact_sign(a, b, c, d) -> int:  # noqa: ANN001
    """Sign of det[a-d; b-d; c-d] in rational arithmetic (each float is an exact rational)."""
    m = [[Fraction(float(x)) - Fraction(float(y)) for x, y in zip(r, d)] for r in (a, b, c)]
    det = (m[0][0] * (m[1][1] * m[2][2] - m[1][2] * m[2][1]) - m[0][1] * (m[1][0] * m[2][2] - m[1][2] * m[2][0])
           + m[0][2] * (m[1][0] * m[2][1] - m[1][1] * m[2][0]))
    return (det > 0) - (det < 0)


def exact_brute_force_pairs(points: np.ndarray, triangles: np.ndarray) -> set[tuple[int, int]]:
    """:func:`brute_force_pairs` in exact rational arithmetic, pair by pair (small meshes only)."""
    tris = np.asarray(triangles).reshape(-1, 3)
    edges = mesh_edges(tris)
    out = set()
    for e, (i, j) in enumerate(edges):
        p, q = points[i], points[j]
        for t, (ia, ib, ic) in enumerate(tris):
            if {int(i), int(j)} & {int(ia), int(ib), int(ic)}:
                continue
            a, b, c = points[ia], points[ib], points[ic]
            if _exact_sign(a, b, c, p) * _exact_sign(a, b, c, q) >= 0:
                continue
            s = (_exact_sign(p, q, a, b), _exact_sign(p, q, b, c), _exact_sign(p, q, c, a))
            if s[0] != 0 and s[0] == s[1] == s[2]:
                out.add((e, t))
    return out


# ----------------------------------------------------------------------------------------------
# The stress set, frame by frame

#: Grid and frames of the tests (the benchmark uses 50 x 50 and longer runs).
STRESS_GRID = 20
STRESS_FRAMES = 120
#: The twist in tests: each edge a full turn in 1.2 s (done by frame 117 of 120), on a 16 x 16
#: grid: its pins are put in place through the API before every substep, so the contact mode builds
#: its reference at every substep there, and 20 x 20 takes 40-90 s (docs/history/self-collision-limits.md has both).
STRESS_TWIST_SECONDS = 1.2
STRESS_TWIST_GRID = 16
#: The driven runs in tests: 30 x 30, where the box's heap already folds through itself without
#: self-collision (at 20 x 20 its folds are too few to cross).
STRESS_DRIVEN_GRID = 30


@dataclass
class StressRecord:
    """Crossings at the end of each frame run, and the frame that blew up (None if none)."""

    scene: str
    mode: str
    counts: list[int]
    blew_up: int | None

    def summary(self) -> str:
        worst = int(np.argmax(self.counts)) if self.counts else 0
        most = self.counts[worst] if self.counts else 0
        end = f", blew up at frame {self.blew_up}" if self.blew_up is not None else ""
        return (f"{self.mode} on {self.scene}: max {most} crossings (frame {worst + 1}), "
                f"final {self.counts[-1] if self.counts else 0}{end}")


def stress_record(scene: str, mode: str, frames: int = STRESS_FRAMES, grid: int | None = None) -> StressRecord:
    """Run stress scene ``scene`` in ``mode`` and count crossings at the end of every frame, on
    ``grid`` points a side (default STRESS_GRID, the twist STRESS_TWIST_GRID)."""
    from clothsim.bench.stress import DRIVEN_SCENES, StressRun
    from clothsim.errors import SimulationBlowUp

    if grid is None:
        grid = STRESS_TWIST_GRID if scene == "twist" else STRESS_DRIVEN_GRID if scene in DRIVEN_SCENES else STRESS_GRID
    run = StressRun(scene, mode, grid, twist_seconds=STRESS_TWIST_SECONDS)
    counts: list[int] = []
    for f in range(1, frames + 1):
        try:
            run.frame()
        except SimulationBlowUp:
            return StressRecord(scene, mode, counts, f)
        counts.append(run.crossings())
    return StressRecord(scene, mode, counts, None)
