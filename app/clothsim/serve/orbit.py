"""The browser's camera: an orbit around a target, turned by dragging, panned and zoomed.

It only produces the ``camera_position`` and ``camera_target`` that :class:`RenderSettings`
already takes, so the renderer draws exactly as it does for ``clothsim render --camera-*``.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np

from ..render.camera import DEFAULT_AZIMUTH_DEG, DEFAULT_ELEVATION_DEG, VIEW_DISTANCE_FACTOR, default_target

# Radians turned per pixel dragged: a drag across an 800-pixel image turns the view ~230 degrees,
# about what the course's window does.
RADIANS_PER_PIXEL = 0.005
# Kept off the poles, where the view's up vector (+y) would be parallel to the view direction.
MAX_ELEVATION = math.radians(89.0)
MIN_DISTANCE, MAX_DISTANCE = 1e-3, 1e4


@dataclass
class Orbit:
    """Camera at ``distance`` from its target, ``azimuth`` around +y (0 = looking from +z) and
    ``elevation`` above the horizon, both in radians.

    The target is ``fixed`` when a scene names one; otherwise it is the cloth's current centroid,
    as for ``clothsim render``, so the view follows a falling cloth. Panning adds ``offset``.
    """

    azimuth: float
    elevation: float
    distance: float
    fixed: np.ndarray | None = None
    offset: np.ndarray = field(default_factory=lambda: np.zeros(3))

    @classmethod
    def course_default(cls, width: float, height: float, fixed: np.ndarray | None = None) -> "Orbit":
        """The renderer's default view of a ``width`` x ``height`` cloth."""
        return cls(math.radians(DEFAULT_AZIMUTH_DEG), math.radians(DEFAULT_ELEVATION_DEG),
                   VIEW_DISTANCE_FACTOR * max(width, height), fixed)

    @classmethod
    def looking(cls, position: np.ndarray, target: np.ndarray, fixed: bool) -> "Orbit":
        """The orbit whose camera sits at ``position`` looking at ``target`` (a scene's camera);
        with ``fixed`` false the target then follows the cloth's centroid."""
        offset = np.asarray(position, dtype=np.float64) - np.asarray(target, dtype=np.float64)
        distance = float(np.linalg.norm(offset))
        elevation = math.asin(max(-1.0, min(1.0, offset[1] / distance))) if distance > 0 else 0.0
        return cls(math.atan2(offset[0], offset[2]), max(-MAX_ELEVATION, min(MAX_ELEVATION, elevation)),
                   max(distance, MIN_DISTANCE), np.asarray(target, dtype=np.float64).copy() if fixed else None)

    def target(self, positions: np.ndarray) -> np.ndarray:
        """Where the camera looks, for the cloth at ``positions``."""
        base = self.fixed if self.fixed is not None else default_target(positions)
        return base + self.offset

    def direction(self) -> np.ndarray:
        """Unit vector from the target towards the camera."""
        ce = math.cos(self.elevation)
        return np.array([math.sin(self.azimuth) * ce, math.sin(self.elevation), math.cos(self.azimuth) * ce])

    def position(self, target: np.ndarray) -> np.ndarray:
        """Where the camera is, looking at ``target``."""
        return target + self.distance * self.direction()

    def rotate(self, dx: float, dy: float) -> None:
        """Turn the view as a drag of (dx, dy) pixels does: right turns it left, down raises it."""
        self.azimuth = math.remainder(self.azimuth - dx * RADIANS_PER_PIXEL, math.tau)
        self.elevation = max(-MAX_ELEVATION, min(MAX_ELEVATION, self.elevation + dy * RADIANS_PER_PIXEL))

    def pan(self, dx: float, dy: float, fov_deg: float, image_height: int) -> None:
        """Move the target so that the point under the pointer follows a drag of (dx, dy) pixels."""
        forward = -self.direction()
        right = np.cross(forward, np.array([0.0, 1.0, 0.0]))
        right /= np.linalg.norm(right)
        up = np.cross(right, forward)
        metres_per_pixel = 2.0 * self.distance * math.tan(math.radians(fov_deg) / 2.0) / max(image_height, 1)
        self.offset = self.offset + metres_per_pixel * (-dx * right + dy * up)

    def zoom(self, factor: float) -> None:
        """Scale the distance to the target (a factor below 1 comes closer)."""
        self.distance = max(MIN_DISTANCE, min(MAX_DISTANCE, self.distance * factor))
