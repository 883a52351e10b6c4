"""A real lens: pinhole intrinsics plus OpenCV's radial-tangential (Brown-Conrady) distortion.

Conventions are OpenCV's, so a calibration (``cv2.calibrateCamera``) can be stored and used as
is: pixel coordinates put the *centre* of pixel (i, j) at (u, v) = (i, j) (``twin.core.geometry``
measures columns from the left *edge*, so its ``u`` is this ``u + 0.5``); normalized image
coordinates are (x, y) = (X/Z, Y/Z) in the camera frame (x right, y down, z forward).

The distortion maps an ideal normalized point (x, y) to the distorted one the sensor sees::

    r2 = x^2 + y^2
    radial = 1 + k1 r2 + k2 r2^2 + k3 r2^3
    xd = x radial + 2 p1 x y + p2 (r2 + 2 x^2)
    yd = y radial + p1 (r2 + 2 y^2) + 2 p2 x y

``undistort`` inverts it by fixed-point iteration (x <- (xd - tangential(x)) / radial(x)),
started at the distorted point. For a lens whose distortion is a contraction there (any
realistic lens inside its own frame: |d(distortion)/dx| well below 1), the error shrinks by a
constant factor per iteration; iteration stops when the step is below ``tolerance`` (1e-12 in
normalized units by default, i.e. 1e-9 px for a focal length of 400 px) or after
``max_iterations``. For the VC-C4 lens of the twin (k1 = -0.20, corners at r = 0.56) 13
iterations reach 1e-12; ``tests/test_lens.py`` checks ``distort(undistort(p)) == p`` to 1e-9
over the whole frame. numpy only: the core imports no OpenCV.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from twin.core.errors import InputError


@dataclass(frozen=True)
class Lens:
    """Intrinsics (pixels, OpenCV convention) and distortion coefficients (dimensionless)."""

    fx: float
    fy: float
    cx: float
    cy: float
    k1: float = 0.0
    k2: float = 0.0
    p1: float = 0.0
    p2: float = 0.0
    k3: float = 0.0

    def __post_init__(self) -> None:
        values = (self.fx, self.fy, self.cx, self.cy, *self.coefficients)
        if not all(math.isfinite(v) for v in values):
            raise InputError(f"lens parameters must be finite, got {values}")
        if self.fx <= 0.0 or self.fy <= 0.0:
            raise InputError(
                f"lens focal lengths must be positive pixels, got {self.fx}, {self.fy}"
            )

    # -- construction ---------------------------------------------------------------------------
    @classmethod
    def pinhole(cls, width: int, height: int, hfov: float) -> Lens:
        """The ideal lens of a ``width`` x ``height`` image with horizontal field ``hfov``
        (radians): square pixels, principal point at the image centre, no distortion."""
        f = (width / 2.0) / math.tan(hfov / 2.0)
        return cls(f, f, (width - 1) / 2.0, (height - 1) / 2.0)

    @classmethod
    def from_opencv(cls, matrix: np.ndarray, coefficients: np.ndarray) -> Lens:
        """From a 3x3 camera matrix and OpenCV's distortion vector (k1, k2, p1, p2[, k3, ...];
        coefficients beyond k3 must be zero: this model has no rational or prism terms)."""
        k = np.asarray(matrix, dtype=float)
        d = np.ravel(np.asarray(coefficients, dtype=float))
        if d.size > 5 and np.any(d[5:] != 0.0):
            raise InputError("only k1, k2, p1, p2, k3 distortion is supported")
        d = np.pad(d[:5], (0, max(0, 5 - d.size)))
        return cls(k[0, 0], k[1, 1], k[0, 2], k[1, 2], *(float(v) for v in d))

    @classmethod
    def from_lists(cls, intrinsics: tuple[float, ...], distortion: tuple[float, ...]) -> Lens:
        """From config lists: [fx, fy, cx, cy] and [k1, k2, p1, p2, k3]."""
        if len(intrinsics) != 4 or len(distortion) != 5:
            raise InputError(
                "a lens needs intrinsics [fx, fy, cx, cy] and distortion [k1, k2, p1, p2, k3]"
            )
        return cls(*(float(v) for v in intrinsics), *(float(v) for v in distortion))

    # -- views ----------------------------------------------------------------------------------
    @property
    def coefficients(self) -> tuple[float, float, float, float, float]:
        """OpenCV's order: (k1, k2, p1, p2, k3)."""
        return (self.k1, self.k2, self.p1, self.p2, self.k3)

    @property
    def intrinsics(self) -> tuple[float, float, float, float]:
        return (self.fx, self.fy, self.cx, self.cy)

    @property
    def matrix(self) -> np.ndarray:
        """The 3x3 camera matrix K."""
        return np.array([[self.fx, 0.0, self.cx], [0.0, self.fy, self.cy], [0.0, 0.0, 1.0]])

    @property
    def is_distorted(self) -> bool:
        return any(c != 0.0 for c in self.coefficients)

    # -- the mapping ----------------------------------------------------------------------------
    def distort(self, x: np.ndarray, y: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Ideal normalized points -> distorted normalized points (element-wise arrays)."""
        x = np.asarray(x, dtype=float)
        y = np.asarray(y, dtype=float)
        r2 = x * x + y * y
        radial = 1.0 + r2 * (self.k1 + r2 * (self.k2 + r2 * self.k3))
        xy = x * y
        xd = x * radial + 2.0 * self.p1 * xy + self.p2 * (r2 + 2.0 * x * x)
        yd = y * radial + self.p1 * (r2 + 2.0 * y * y) + 2.0 * self.p2 * xy
        return xd, yd

    def undistort(
        self,
        xd: np.ndarray,
        yd: np.ndarray,
        *,
        tolerance: float = 1e-12,
        max_iterations: int = 50,
    ) -> tuple[np.ndarray, np.ndarray]:
        """Distorted normalized points -> ideal ones, by fixed-point iteration (see the module
        docstring for its accuracy). Raises ``InputError`` if it has not converged, which
        happens only far outside the lens's frame, where the polynomial folds back."""
        xd = np.asarray(xd, dtype=float)
        yd = np.asarray(yd, dtype=float)
        if not self.is_distorted:
            return xd.copy(), yd.copy()
        x, y = xd.copy(), yd.copy()
        for _ in range(max_iterations):
            r2 = x * x + y * y
            radial = 1.0 + r2 * (self.k1 + r2 * (self.k2 + r2 * self.k3))
            xy = x * y
            dx = 2.0 * self.p1 * xy + self.p2 * (r2 + 2.0 * x * x)
            dy = self.p1 * (r2 + 2.0 * y * y) + 2.0 * self.p2 * xy
            nx, ny = (xd - dx) / radial, (yd - dy) / radial
            step = max(
                float(np.max(np.abs(nx - x), initial=0.0)),
                float(np.max(np.abs(ny - y), initial=0.0)),
            )
            x, y = nx, ny
            if step < tolerance:
                return x, y
        raise InputError(
            f"lens undistortion did not converge in {max_iterations} iterations (last step "
            f"{step:.1e}); the points lie outside the range where this lens model is invertible"
        )

    def pixel_to_normalized(self, u: np.ndarray, v: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Pixels (OpenCV convention: pixel centres at integers) -> ideal normalized points."""
        xd = (np.asarray(u, dtype=float) - self.cx) / self.fx
        yd = (np.asarray(v, dtype=float) - self.cy) / self.fy
        return self.undistort(xd, yd)

    def normalized_to_pixel(self, x: np.ndarray, y: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Ideal normalized points -> pixels (OpenCV convention) through the distortion."""
        xd, yd = self.distort(x, y)
        return self.fx * xd + self.cx, self.fy * yd + self.cy
