"""The pinhole camera: its rays, and where world points land in its image.

Image convention: pixel (row, col) covers ``[col, col + 1) x [row, row + 1)`` in continuous image
coordinates (u along columns to the right, v along rows downwards); its centre is
``(col + 0.5, row + 0.5)``. The camera looks along ``forward``; ``right`` is horizontal and
``up = right x forward``, so with no roll the horizon is level. A camera looking straight down
with yaw 0 has north at the top of its image, as the ground rasters do.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np


@dataclass(frozen=True)
class Camera:
    """A pinhole camera.

    position : (x, y, z) of the pinhole. [m]
    yaw : azimuth of the view direction, from north towards east. [rad]
    pitch : elevation of the view direction, in [-pi/2, pi/2], negative looking down. [rad]
    vertical_fov : full vertical field of view, in (0, pi). [rad]
    width, height : image size. [pixel]
    """

    position: tuple[float, float, float]
    yaw: float
    pitch: float
    vertical_fov: float
    width: int
    height: int

    def __post_init__(self):
        if not (0.0 < self.vertical_fov < np.pi):
            raise ValueError(f"vertical_fov must lie in (0, pi) rad, got {self.vertical_fov}")
        if not (-np.pi / 2 <= self.pitch <= np.pi / 2):
            raise ValueError(f"pitch must lie in [-pi/2, pi/2] rad, got {self.pitch}")
        if self.width < 1 or self.height < 1:
            raise ValueError(f"image size must be positive, got {self.width} x {self.height}")

    @classmethod
    def look_at(cls, position, target, *, vertical_fov: float, width: int, height: int) -> "Camera":
        """The camera at ``position`` [m] looking at ``target`` [m] (level, no roll)."""
        d = np.asarray(target, dtype=np.float64) - np.asarray(position, dtype=np.float64)
        if not np.any(d):
            raise ValueError("target and position coincide")
        yaw = float(np.arctan2(d[0], d[1]) % (2 * np.pi))
        pitch = float(np.arctan2(d[2], np.hypot(d[0], d[1])))
        return cls(tuple(float(v) for v in position), yaw, pitch, vertical_fov, width, height)

    @property
    def focal(self) -> float:
        """Focal length in pixels: pixels per unit of tan(angle) off the axis. [pixel]"""
        return 0.5 * self.height / np.tan(0.5 * self.vertical_fov)

    @property
    def basis(self) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Unit (right, up, forward) vectors in world coordinates. A straight-down view takes
        its right from the yaw, so yaw 0 puts east on the right and north at the top."""
        cy, sy = np.cos(self.yaw), np.sin(self.yaw)
        cp, sp = np.cos(self.pitch), np.sin(self.pitch)
        forward = np.array([cp * sy, cp * cy, sp])
        right = np.array([cy, -sy, 0.0])
        return right, np.cross(right, forward), forward


def image_rays(camera: Camera, u, v) -> np.ndarray:
    """World directions (..., 3), not normalised, through image points (u, v) [pixel]: the
    point on the image plane at distance 1 along ``forward``. [m per m of depth]"""
    right, up, forward = camera.basis
    x = (np.asarray(u, dtype=np.float64) - 0.5 * camera.width) / camera.focal
    y = (0.5 * camera.height - np.asarray(v, dtype=np.float64)) / camera.focal
    return forward + x[..., None] * right + y[..., None] * up


def pixel_rays(camera: Camera) -> np.ndarray:
    """Directions (height, width, 3) through every pixel centre, as ``image_rays``."""
    v, u = np.mgrid[0:camera.height, 0:camera.width] + 0.5
    return image_rays(camera, u, v)


def project_points(camera: Camera, points) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Image coordinates (u, v) [pixel] and depth along ``forward`` [m] of world points
    (..., 3) [m]. Points at depth <= 0 are behind the pinhole; their (u, v) are meaningless."""
    right, up, forward = camera.basis
    d = np.asarray(points, dtype=np.float64) - np.asarray(camera.position)
    depth = d @ forward
    safe = np.where(np.abs(depth) > 1e-12, depth, 1e-12)
    u = 0.5 * camera.width + camera.focal * (d @ right) / safe
    v = 0.5 * camera.height - camera.focal * (d @ up) / safe
    return u, v, depth
