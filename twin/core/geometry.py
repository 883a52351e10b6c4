"""Planar poses, angles, and the camera model that turns patch columns into bearing wedges.

Conventions (shared by every module): map frame x right, y up, metres, origin at the room's
lower-left corner; yaw counter-clockwise from +x, radians. Pan is positive to the left. Image
columns are pixels from the left edge of the image (0 … width).
"""

from __future__ import annotations

import functools
import math
from dataclasses import dataclass

import numpy as np

from twin.core.errors import InputError
from twin.core.lens import Lens


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
    """The head camera: pixels ↔ bearings, through an ideal pinhole or a real ``Lens``.

    ``hfov`` is the horizontal field of view in radians. Without a lens (the default) the camera
    is the ideal pinhole: a column at pixel ``u`` (0 at the left edge) sees the bearing
    ``atan((width/2 - u) / f)`` relative to the optical axis, positive to the left, with
    ``f = (width/2) / tan(hfov/2)`` the focal length in pixels. Because the mapping is an
    arctangent, equal-width patch columns are slightly narrower in angle at the image edges;
    using it (rather than a linear split of the field of view) keeps wedges true.

    With a ``lens`` (``twin.core.lens``: intrinsics and OpenCV distortion, built with
    ``CameraModel.with_lens``) every pixel goes through the lens; ``hfov`` is then the field
    across the principal row, as the lens gives it. Pixel coordinates here are measured from the
    image's edges (pixel i spans [i, i + 1]); the lens's own are OpenCV's (centres at integers).
    """

    width: int = 320
    height: int = 240
    hfov: float = math.radians(45.0)
    lens: Lens | None = None

    def __post_init__(self) -> None:
        if self.width <= 0 or self.height <= 0:
            raise InputError(f"camera image size must be positive, got {self.width}x{self.height}")
        if not 0.0 < self.hfov < math.pi:
            raise InputError(f"camera hfov must be in (0, pi) radians, got {self.hfov!r}")
        if self.lens is not None and abs(self.hfov - self._lens_hfov(self.lens)) > 1e-9:
            raise InputError(
                "camera hfov disagrees with its lens; build it with CameraModel.with_lens"
            )

    @classmethod
    def with_lens(cls, width: int, height: int, lens: Lens) -> CameraModel:
        """The camera of a ``width`` x ``height`` image seen through ``lens``."""
        return cls(width, height, cls._lens_hfov_of(width, height, lens), lens)

    @staticmethod
    def _lens_hfov_of(width: int, height: int, lens: Lens) -> float:
        x, _ = lens.pixel_to_normalized(np.array([-0.5, width - 0.5]), np.full(2, lens.cy))
        return float(np.arctan(-x[0]) - np.arctan(-x[1]))

    def _lens_hfov(self, lens: Lens) -> float:
        return self._lens_hfov_of(self.width, self.height, lens)

    @property
    def focal_px(self) -> float:
        """Focal length in pixels (the lens's horizontal one, if it has a lens)."""
        if self.lens is not None:
            return self.lens.fx
        return (self.width / 2.0) / math.tan(self.hfov / 2.0)

    @property
    def vfov(self) -> float:
        """Vertical field of view in radians, for square pixels (MuJoCo's ``fovy``); through the
        lens, the field across its principal column."""
        if self.lens is not None:
            _, elevation = self.pixel_rays(
                np.full(2, self.lens.cx + 0.5), np.array([0.0, float(self.height)]), 0.0
            )
            return float(elevation[0] - elevation[1])
        return 2.0 * math.atan((self.height / 2.0) / self.focal_px)

    def normalized(self, u: np.ndarray, v: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Ideal normalized image coordinates (x right, y down, per unit of depth) of pixel
        positions ``u``, ``v`` measured from the image's left and top edges."""
        u = np.asarray(u, dtype=float)
        v = np.asarray(v, dtype=float)
        if self.lens is None:
            f = self.focal_px
            return (u - self.width / 2.0) / f, (v - self.height / 2.0) / f
        return self.lens.pixel_to_normalized(u - 0.5, v - 0.5)

    def column_bearing(self, u: float | np.ndarray) -> float | np.ndarray:
        """Bearing (radians, positive left) of pixel column ``u`` relative to the optical axis;
        through a lens, on the principal row (a distorted column is not one bearing: ``wedges``
        covers all its rows)."""
        if self.lens is None:
            return np.arctan((self.width / 2.0 - np.asarray(u, dtype=float)) / self.focal_px)
        u = np.asarray(u, dtype=float)
        x, _ = self.lens.pixel_to_normalized(u - 0.5, np.full(u.shape, self.lens.cy))
        return np.arctan(-x)

    def bearing_column(self, bearing: float | np.ndarray) -> float | np.ndarray:
        """Pixel column that sees ``bearing`` (radians relative to the optical axis); through a
        lens, where the level ray of that bearing lands (the inverse of ``column_bearing`` but for
        the bend tangential distortion gives the principal row: 1e-4 px for the VC-C4's)."""
        b = np.asarray(bearing, dtype=float)
        if self.lens is None:
            return self.width / 2.0 - self.focal_px * np.tan(b)
        u, _ = self.lens.normalized_to_pixel(-np.tan(b), np.zeros(b.shape))
        return u + 0.5

    def pixel_rays(
        self, u: np.ndarray, v: np.ndarray, tilt: float = 0.0
    ) -> tuple[np.ndarray, np.ndarray]:
        """(bearing, elevation) in radians of the rays through pixel positions ``u``, ``v``
        (from the image's left and top edges; arrays of one shape) for the head tilted up by
        ``tilt`` radians: the bearing about the head's pan axis relative to its pan heading
        (positive left), the elevation above the horizontal. Through the lens, if any; the
        camera's small offset from the tilt axis is neglected (1.7 cm on the Peoplebot)."""
        require_finite("tilt", tilt)
        x, y = self.normalized(u, v)
        c, s = math.cos(tilt), math.sin(tilt)
        forward = c + y * s
        up = s - y * c
        bearing = np.arctan2(-x, forward)
        elevation = np.arctan2(up, np.hypot(forward, x))
        return bearing, elevation

    def ray_pixels(
        self, bearing: np.ndarray, elevation: np.ndarray, tilt: float = 0.0
    ) -> tuple[np.ndarray, np.ndarray]:
        """Where rays land in the image: the inverse of ``pixel_rays``. ``bearing`` (relative to
        the pan heading, positive left) and ``elevation`` (above the horizontal) in radians, the
        head tilted up by ``tilt``; returns pixel positions (u, v) from the image's left and top
        edges, through the lens if any, NaN for rays behind the camera. What a visibility model
        needs to look a point up in a depth image the lens has bent."""
        require_finite("tilt", tilt)
        b = np.asarray(bearing, dtype=float)
        e = np.asarray(elevation, dtype=float)
        ahead, left, up = np.cos(e) * np.cos(b), np.cos(e) * np.sin(b), np.sin(e)
        c, s = math.cos(tilt), math.sin(tilt)
        depth = ahead * c + up * s
        with np.errstate(divide="ignore", invalid="ignore"):
            x = np.where(depth > 0.0, -left / depth, np.nan)
            y = np.where(depth > 0.0, (ahead * s - up * c) / depth, np.nan)
        if self.lens is None:
            f = self.focal_px
            return self.width / 2.0 + f * x, self.height / 2.0 + f * y
        u, v = self.lens.normalized_to_pixel(x, y)
        return u + 0.5, v + 0.5

    def wedges(
        self,
        pose: Pose2D,
        pan: float,
        column_spans: np.ndarray,
        tilt: float = 0.0,
        rows: tuple[float, float] | None = None,
    ) -> np.ndarray:
        """Bearing intervals in the map frame of patch columns spanning the given pixels.

        ``column_spans`` is an (n, 2) array of [u0, u1] pixel ranges, u0 < u1 (columns may
        overlap, as patches with a stride smaller than their width do). The result is an (n, 2)
        array of [a0, a1] with a0 < a1, radians, for a camera at ``pose`` panned by ``pan``
        (left positive): the left pixel edge u0 gives the larger bearing a1.

        For a level ideal pinhole a column is one bearing interval. Tilted (``tilt`` radians,
        up positive) or through a distorting lens it is not: the interval is then the one that
        covers every pixel of the column over ``rows`` ([v0, v1] pixels from the top edge; the
        whole frame by default), from the bearings along its edges at every pixel row.
        """
        spans = np.asarray(column_spans, dtype=float)
        if spans.ndim != 2 or spans.shape[1] != 2 or spans.shape[0] == 0:
            raise InputError(f"column_spans must be an (n, 2) array, got shape {spans.shape}")
        if not np.all(np.isfinite(spans)) or np.any(spans[:, 1] <= spans[:, 0]):
            raise InputError("column_spans must be finite pixel ranges [u0, u1] with u0 < u1")
        require_finite("pan", pan)
        require_finite("tilt", tilt)
        axis = pose.yaw + pan
        if self.lens is None and tilt == 0.0:
            return np.stack(
                [axis + self.column_bearing(spans[:, 1]), axis + self.column_bearing(spans[:, 0])],
                axis=1,
            )
        v0, v1 = (0.0, float(self.height)) if rows is None else (float(rows[0]), float(rows[1]))
        if not (math.isfinite(v0) and math.isfinite(v1) and v0 < v1):
            raise InputError(f"rows must be a pixel range [v0, v1] with v0 < v1, got {rows}")
        relative = _relative_wedges(self, float(tilt), spans.tobytes(), spans.shape[0], v0, v1)
        return axis + relative


@functools.lru_cache(maxsize=64)
def _relative_wedges(
    camera: CameraModel, tilt: float, spans_bytes: bytes, n: int, v0: float, v1: float
) -> np.ndarray:
    """Wedges relative to the pan heading (n, 2), cached: a survey asks for the same columns
    at the same tilt at every view, and each costs an undistortion of every edge pixel."""
    spans = np.frombuffer(spans_bytes, dtype=float).reshape(n, 2)
    rows = np.linspace(v0, v1, max(2, math.ceil(v1 - v0) + 1))
    if camera.lens is not None and v0 < camera.lens.cy + 0.5 < v1:  # a bulge's extreme
        rows = np.append(rows, camera.lens.cy + 0.5)
    u = np.repeat(spans.reshape(-1), rows.size)
    v = np.tile(rows, 2 * n)
    bearing, _ = camera.pixel_rays(u, v, tilt)
    bearing = bearing.reshape(n, 2 * rows.size)
    result = np.stack([bearing.min(axis=1), bearing.max(axis=1)], axis=1)
    result.setflags(write=False)
    return result


def is_wall(name: str) -> bool:
    """Whether a scene body is a wall between rooms (the scenes name them ``wall_*``): drawn in
    the viewer and the grid images like furniture, but not labelled, since a wall reads as one
    and a dozen wall names hid an apartment's grid."""
    return name.startswith("wall_")


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
