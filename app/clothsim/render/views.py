"""Cameras of a dataset's views: drawn around the cloth from a seed, and their parameters in
OpenCV's and OpenGL's conventions.

OpenCV: x right, y down, z forward (into the scene); ``x_cam = R @ x_world + t``; a point
projects to pixel ``(u, v) = (fx x/z + cx, fy y/z + cy)``, with pixel centres at integer
coordinates (the top-left pixel's centre is (0, 0)). OpenGL: x right, y up, the camera looks
down -z; ``view`` maps world to eye coordinates, ``projection`` eye to clip coordinates
(depth -1..1), and normalised device coordinates map to the image with y up.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any

import numpy as np

from .camera import Camera

__all__ = ["ViewCamera", "draw_cameras", "frame_bounds", "ELEVATION_RANGE_DEG", "DISTANCE_RANGE"]

# Drawn cameras: anywhere around the cloth, from a little above its centre to well above it,
# at a distance that keeps the cloth's whole path in view with some margin.
ELEVATION_RANGE_DEG = (10.0, 60.0)
DISTANCE_RANGE = (1.1, 1.5)  # x the distance at which the bounding sphere just fills the view


@dataclass(frozen=True)
class ViewCamera:
    """A fixed pinhole camera of ``width`` x ``height`` pixels looking from ``position`` at
    ``target`` with +y up and a vertical field of view ``fov_deg``."""

    position: tuple[float, float, float]
    target: tuple[float, float, float]
    fov_deg: float
    width: int
    height: int
    near: float = 0.01
    far: float = 100.0

    def camera(self) -> Camera:
        """The renderer's camera of this view."""
        return Camera(np.asarray(self.position, dtype=np.float64), np.asarray(self.target, dtype=np.float64),
                      self.fov_deg, self.near, self.far)

    def focal(self) -> float:
        """Focal length in pixels (the same along x and y: square pixels)."""
        return (self.height / 2.0) / math.tan(math.radians(self.fov_deg) / 2.0)

    def intrinsics(self) -> np.ndarray:
        """OpenCV's K (3, 3) float64: pixel centres at integer coordinates."""
        f = self.focal()
        return np.array([[f, 0.0, self.width / 2.0 - 0.5], [0.0, f, self.height / 2.0 - 0.5], [0.0, 0.0, 1.0]])

    def view_gl(self) -> np.ndarray:
        """OpenGL's world -> eye matrix (4, 4)."""
        return self.camera().view()

    def projection_gl(self) -> np.ndarray:
        """OpenGL's eye -> clip matrix (4, 4) for this image's aspect ratio."""
        return self.camera().projection(self.width / self.height)

    def world_to_camera_cv(self) -> np.ndarray:
        """OpenCV's extrinsics [R | t] as a (4, 4) matrix: OpenGL's view with y and z negated."""
        return np.diag([1.0, -1.0, -1.0, 1.0]) @ self.view_gl()

    def as_dict(self) -> dict[str, Any]:
        """Everything about the camera as JSON-able lists (the dataset's ``cameras.json``)."""
        w2c = self.world_to_camera_cv()
        return {
            "width": self.width, "height": self.height, "fov_y_deg": self.fov_deg,
            "position": list(self.position), "target": list(self.target), "up": [0.0, 1.0, 0.0],
            "near": self.near, "far": self.far,
            "K": self.intrinsics().tolist(),
            "world_to_camera_opencv": w2c.tolist(),
            "camera_to_world_opencv": np.linalg.inv(w2c).tolist(),
            "view_opengl": self.view_gl().tolist(),
            "projection_opengl": self.projection_gl().tolist(),
        }


def frame_bounds(positions: np.ndarray) -> tuple[np.ndarray, float]:
    """Centre and radius of the bounding sphere (of the axis-aligned box) of points ``(..., 3)``:
    every sampled frame of a run, so that the cameras keep the cloth's whole path in view."""
    pts = np.asarray(positions, dtype=np.float64).reshape(-1, 3)
    lo, hi = pts.min(axis=0), pts.max(axis=0)
    centre = (lo + hi) / 2.0
    return centre, max(float(np.linalg.norm(hi - lo)) / 2.0, 1e-3)


def draw_cameras(seed: tuple[int, ...], count: int, centre: np.ndarray, radius: float, fov_deg: float,
                 width: int, height: int, near: float = 0.01, far: float = 100.0) -> list[ViewCamera]:
    """``count`` cameras around ``centre`` looking at it, drawn from ``numpy.random.default_rng(seed)``.

    Each draws an azimuth (uniform over the circle), an elevation (uniform in
    :data:`ELEVATION_RANGE_DEG`) and a distance factor (uniform in :data:`DISTANCE_RANGE`) in
    that order, so camera k of a seed is the same whatever ``count`` is. NumPy's generator gives
    the same numbers on every platform.
    """
    rng = np.random.default_rng(list(seed))
    draws = rng.random((count, 3))
    half = math.radians(fov_deg) / 2.0
    if width < height:  # the narrower field of view decides what fits
        half = math.atan(math.tan(half) * width / height)
    fit = radius / math.sin(half)
    cams = []
    for a, e, d in draws:
        az = 2.0 * math.pi * float(a)
        el = math.radians(ELEVATION_RANGE_DEG[0] + (ELEVATION_RANGE_DEG[1] - ELEVATION_RANGE_DEG[0]) * float(e))
        dist = fit * (DISTANCE_RANGE[0] + (DISTANCE_RANGE[1] - DISTANCE_RANGE[0]) * float(d))
        direction = np.array([math.sin(az) * math.cos(el), math.sin(el), math.cos(az) * math.cos(el)])
        pos = np.asarray(centre, dtype=np.float64) + dist * direction
        cams.append(ViewCamera(tuple(float(x) for x in pos), tuple(float(x) for x in centre),  # type: ignore[arg-type]
                               float(fov_deg), int(width), int(height), near, max(far, 4.0 * dist)))
    return cams
