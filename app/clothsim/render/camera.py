"""View and projection matrices (row-major NumPy; transpose when handing them to GL)."""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any

import numpy as np

# Default view direction from the target: above and in front (+z) of the cloth, turned a
# little to the side so that both a hanging cloth (pinned2) and a drape (sphere) read in depth.
DEFAULT_AZIMUTH_DEG = 25.0
DEFAULT_ELEVATION_DEG = 35.0
VIEW_DISTANCE_FACTOR = 2.0 * 0.9  # distance = 2 * 0.9 * max(width, height), as in the course (cloth_size)
# Images are drawn upside down (clip-space y negated) so that GL's bottom-up rows read back as a
# top-down image with no copy.
FLIP_Y = np.diag([1.0, -1.0, 1.0, 1.0])


@dataclass(frozen=True)
class Camera:
    """A perspective camera looking from ``position`` at ``target`` with +y up."""

    position: np.ndarray  # (3,)
    target: np.ndarray  # (3,)
    fov_deg: float = 35.0
    near: float = 0.01
    far: float = 100.0

    def view(self) -> np.ndarray:
        """World -> eye matrix (4, 4) float64."""
        f = self.target - self.position
        f = f / np.linalg.norm(f)
        up = np.array([0.0, 1.0, 0.0])
        if abs(float(f @ up)) > 0.999:  # looking straight up or down: any other up will do
            up = np.array([0.0, 0.0, -1.0])
        s = np.cross(f, up)
        s /= np.linalg.norm(s)
        u = np.cross(s, f)
        m = np.eye(4)
        m[0, :3], m[1, :3], m[2, :3] = s, u, -f
        m[:3, 3] = -m[:3, :3] @ self.position
        return m

    def projection(self, aspect: float) -> np.ndarray:
        """Eye -> clip matrix for a vertical field of view (OpenGL's -1..1 depth)."""
        f = 1.0 / math.tan(math.radians(self.fov_deg) / 2.0)
        n, fa = self.near, self.far
        m = np.zeros((4, 4))
        m[0, 0] = f / aspect
        m[1, 1] = f
        m[2, 2] = (fa + n) / (n - fa)
        m[2, 3] = 2.0 * fa * n / (n - fa)
        m[3, 2] = -1.0
        return m

    def view_projection(self, aspect: float) -> np.ndarray:
        """Projection @ view."""
        return self.projection(aspect) @ self.view()


def default_target(positions: np.ndarray) -> np.ndarray:
    """The cloth's centroid: the default camera follows the cloth wherever it falls."""
    return positions.mean(axis=0)


def cloth_size(cloth: Any) -> float:
    """The size the default view distance follows: a grid cloth's ``max(width, height)``, a mesh
    cloth's largest extent of its rest points' bounding box (it has no width or height)."""
    if getattr(cloth, "is_mesh", False):
        points = np.asarray(cloth.mesh.points, dtype=np.float64).reshape(-1, 3)
        return float((points.max(axis=0) - points.min(axis=0)).max()) if points.size else 0.0
    return max(cloth.width, cloth.height)


def default_position(target: np.ndarray, width: float, height: float) -> np.ndarray:
    """Camera position at the course's view distance, above-front of ``target``."""
    az = math.radians(DEFAULT_AZIMUTH_DEG)
    el = math.radians(DEFAULT_ELEVATION_DEG)
    direction = np.array([math.sin(az) * math.cos(el), math.sin(el), math.cos(az) * math.cos(el)])
    return target + VIEW_DISTANCE_FACTOR * max(width, height) * direction
