"""Planar poses, angles, and the camera model that turns patch columns into bearing wedges.

Conventions (shared by every module): map frame x right, y up, metres, origin at the room's
lower-left corner; yaw counter-clockwise from +x, radians. Pan is positive to the left. Image
columns are pixels from the left edge of the image (0 … width).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from twin.core.errors import InputError


def wrap_angle(angle: float | np.ndarray) -> float | np.ndarray:
    """Wrap radians into [-pi, pi) (element-wise for arrays)."""
    return (angle + math.pi) % (2.0 * math.pi) - math.pi


def require_finite(name: str, *values: float) -> None:
    """Raise an ``InputError`` naming ``name`` unless every value is a finite number."""
    for value in values:
        if not math.isfinite(value):
            raise InputError(f"{name} must be finite, got {value!r}")


@dataclass(frozen=True)
class Pose2D:
    """A planar pose: position in metres and yaw in radians (map frame)."""

    x: float
    y: float
    yaw: float

    def __post_init__(self) -> None:
        require_finite("pose", self.x, self.y, self.yaw)

    def distance_to(self, other: Pose2D) -> float:
        return math.hypot(other.x - self.x, other.y - self.y)

    def heading_error_to(self, other: Pose2D) -> float:
        """Signed smallest angle (radians) that turns this yaw into ``other.yaw``."""
        return float(wrap_angle(other.yaw - self.yaw))

    def compose(self, local: Pose2D) -> Pose2D:
        """``local`` (a pose in this pose's frame) expressed in this pose's parent frame."""
        c, s = math.cos(self.yaw), math.sin(self.yaw)
        return Pose2D(
            self.x + c * local.x - s * local.y,
            self.y + s * local.x + c * local.y,
            float(wrap_angle(self.yaw + local.yaw)),
        )

    def relative(self, other: Pose2D) -> Pose2D:
        """``other`` (in the same frame as this pose) seen from this pose: the inverse of
        ``compose``, so ``a.compose(a.relative(b)) == b``."""
        c, s = math.cos(self.yaw), math.sin(self.yaw)
        dx, dy = other.x - self.x, other.y - self.y
        return Pose2D(c * dx + s * dy, -s * dx + c * dy, float(wrap_angle(other.yaw - self.yaw)))


@dataclass(frozen=True)
class CameraModel:
    """An ideal pinhole camera looking horizontally: pixel columns ↔ bearings.

    ``hfov`` is the horizontal field of view in radians. A column at pixel ``u`` (0 at the left
    edge) sees the bearing ``atan((width/2 - u) / f)`` relative to the optical axis, positive to
    the left, with ``f = (width/2) / tan(hfov/2)`` the focal length in pixels. Because the
    mapping is an arctangent, equal-width patch columns are slightly narrower in angle at the
    image edges; using it (rather than a linear split of the field of view) keeps wedges true.
    """

    width: int = 320
    height: int = 240
    hfov: float = math.radians(45.0)

    def __post_init__(self) -> None:
        if self.width <= 0 or self.height <= 0:
            raise InputError(f"camera image size must be positive, got {self.width}x{self.height}")
        if not 0.0 < self.hfov < math.pi:
            raise InputError(f"camera hfov must be in (0, pi) radians, got {self.hfov!r}")

    @property
    def focal_px(self) -> float:
        return (self.width / 2.0) / math.tan(self.hfov / 2.0)

    @property
    def vfov(self) -> float:
        """Vertical field of view in radians, for square pixels (MuJoCo's ``fovy``)."""
        return 2.0 * math.atan((self.height / 2.0) / self.focal_px)

    def column_bearing(self, u: float | np.ndarray) -> float | np.ndarray:
        """Bearing (radians, positive left) of pixel column ``u`` relative to the optical axis."""
        return np.arctan((self.width / 2.0 - np.asarray(u, dtype=float)) / self.focal_px)

    def bearing_column(self, bearing: float | np.ndarray) -> float | np.ndarray:
        """Pixel column that sees ``bearing`` (radians relative to the optical axis)."""
        return self.width / 2.0 - self.focal_px * np.tan(np.asarray(bearing, dtype=float))

    def wedges(self, pose: Pose2D, pan: float, column_spans: np.ndarray) -> np.ndarray:
        """Bearing intervals in the map frame of patch columns spanning the given pixels.

        ``column_spans`` is an (n, 2) array of [u0, u1] pixel ranges, u0 < u1 (columns may
        overlap, as patches with a stride smaller than their width do). The result is an (n, 2)
        array of [a0, a1] with a0 < a1, radians, for a camera at ``pose`` panned by ``pan``
        (left positive): the left pixel edge u0 gives the larger bearing a1.
        """
        spans = np.asarray(column_spans, dtype=float)
        if spans.ndim != 2 or spans.shape[1] != 2 or spans.shape[0] == 0:
            raise InputError(f"column_spans must be an (n, 2) array, got shape {spans.shape}")
        if not np.all(np.isfinite(spans)) or np.any(spans[:, 1] <= spans[:, 0]):
            raise InputError("column_spans must be finite pixel ranges [u0, u1] with u0 < u1")
        require_finite("pan", pan)
        axis = pose.yaw + pan
        return np.stack(
            [axis + self.column_bearing(spans[:, 1]), axis + self.column_bearing(spans[:, 0])],
            axis=1,
        )


@dataclass(frozen=True)
class Footprint:
    """A body's outline on the floor: convex polygon (n, 2) in map metres, CCW, and top height."""

    name: str
    polygon: np.ndarray
    top: float

    @property
    def aabb(self) -> tuple[float, float, float, float]:
        """(xmin, ymin, xmax, ymax) in metres."""
        lo, hi = self.polygon.min(axis=0), self.polygon.max(axis=0)
        return float(lo[0]), float(lo[1]), float(hi[0]), float(hi[1])
