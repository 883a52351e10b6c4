"""What the VC-C4 does to a picture that MuJoCo's renderer does not: a lens that bends straight
lines, auto exposure and white balance that lag and clip, sensor and analog noise, motion blur
while the head or base turns, and JPEG.

``CameraEffects`` is a chain applied to each rendered frame. It is usable outside ``SimCamera``
(e.g. to pass a detector's calibration frames through the same camera): render the undistorted
frame at ``canvas`` (a wider, ideal pinhole with the lens's focal length), then
``apply(image, depth, rng, rates, dt)``. Auto exposure and white balance keep state between
frames (a real camera's control loops); ``reset`` forgets it.

Default numbers and where they come from (``EffectSettings``):
- Field of view: 47.5 degrees horizontal at the VC-C4's wide end (Canon's datasheet: 1/4" CCD,
  f = 4-64 mm, horizontal angle of view 47.5 degrees to 3.0 degrees).
- Distortion: k1 = -0.20, k2 = 0.03, p1 = 5e-4, p2 = -3e-4, principal point (+2.1, -1.4) px off
  centre. Canon publishes no distortion for the VC-C4; these are typical of OpenCV calibrations
  of 1/4"-CCD zoom and CCTV lenses at a 45-50 degree wide end (k1 between -0.15 and -0.35, small
  k2, tangential terms below 1e-3, principal points a few pixels off): about 3 % barrel at the
  frame's left and right edges, 5 % in its corners.
- Exposure: 1/60 s (an NTSC field); auto exposure aims at a mean of 45 % of full scale (18 %
  grey in sRGB) with a 0.3 s time constant and gains 0.25-4 (a CCD camera's AGC of +12 dB).
- White balance: grey world, applying 80 % of its correction with a 1 s time constant and a
  residual cast of +3 % red, -3 % blue (cameras of the time left a warm cast indoors).
- Noise: read noise 1.0 DN and shot noise of variance 0.02 DN per DN of signal at gain 1: about
  1.7 DN at mid-grey, an S/N near 46 dB on a full-scale signal. An assumption: we have no
  VC-C4 noise figure here; 1/4" CCD security cameras of its time list 46-50 dB. The auto
  exposure's gain multiplies it.
- Analog look: chroma blurred over 3 px horizontally (NTSC chroma has about a third of the
  luma's bandwidth, ~1.3 vs 4.2 MHz).
- JPEG at quality 80 (a capture or video server's usual setting).
Everything random comes from the ``rng`` given (``SimCamera`` seeds its own from a config seed).
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import cv2
import numpy as np

from twin.core.errors import InputError
from twin.core.lens import Lens

VIDEO_FRAME_S = 1.0 / 30.0  # NTSC frame period: the control loops' step when no time is given


def vcc4_lens(width: int = 320, height: int = 240, hfov: float = math.radians(47.5)) -> Lens:
    """The twin's VC-C4 lens at the wide end for a ``width`` x ``height`` frame: the distortion
    above, the focal length chosen so that the field across the principal row is ``hfov``."""
    return lens_for_field(width, height, hfov, VCC4_DISTORTION, VCC4_CENTRE_OFFSET)


VCC4_DISTORTION = (-0.20, 0.03, 5e-4, -3e-4, 0.0)  # k1, k2, p1, p2, k3 (see the module docstring)
VCC4_CENTRE_OFFSET = (2.1, -1.4)  # px at 320 x 240, principal point minus the image centre


def lens_for_field(
    width: int,
    height: int,
    hfov: float,
    distortion: tuple[float, ...],
    centre_offset: tuple[float, float] = (0.0, 0.0),
) -> Lens:
    """A lens with square pixels, the given distortion and principal point offset (pixels at
    320 wide, scaled with the width), whose field across the principal row is ``hfov``."""
    if not 0.0 < hfov < math.radians(170.0):
        raise InputError(f"a lens's field of view must be in (0, 170) degrees, got {hfov!r}")
    scale = width / 320.0
    cx = (width - 1) / 2.0 + centre_offset[0] * scale
    cy = (height - 1) / 2.0 + centre_offset[1] * scale

    def field_of(f: float) -> float:
        lens = Lens(f, f, cx, cy, *distortion)
        x, _ = lens.pixel_to_normalized(np.array([-0.5, width - 0.5]), np.full(2, cy))
        return float(np.arctan(-x[0]) - np.arctan(-x[1]))

    ideal = (width / 2.0) / math.tan(hfov / 2.0)
    lo, hi = 0.8 * ideal, 1.25 * ideal  # the field shrinks as the focal length grows
    for _ in range(100):
        mid = math.sqrt(lo * hi)
        lo, hi = (mid, hi) if field_of(mid) > hfov else (lo, mid)
    f = math.sqrt(lo * hi)
    return Lens(f, f, cx, cy, *distortion)


@dataclass(frozen=True)
class EffectSettings:
    """Which effects run and their parameters (see the module docstring for the defaults).
    ``lens`` None: no distortion (the frame is rendered at its own size)."""

    lens: Lens | None = None
    motion_blur: bool = True
    exposure_s: float = 0.01667  # 1/60 s, as the config gives it (16.67 ms)
    auto_exposure: bool = True
    exposure_target: float = 0.45
    exposure_time_constant_s: float = 0.3
    gain_range: tuple[float, float] = (0.25, 4.0)
    white_balance: bool = True
    white_balance_strength: float = 0.8
    white_balance_time_constant_s: float = 1.0
    white_balance_cast: tuple[float, float] = (1.03, 0.97)
    noise: bool = True
    read_noise_dn: float = 1.0
    shot_noise_dn: float = 0.02
    analog: bool = True
    jpeg_quality: int = 80

    @classmethod
    def ideal(cls) -> EffectSettings:
        """Every effect off: ``apply`` returns its input unchanged."""
        return cls(
            lens=None,
            motion_blur=False,
            auto_exposure=False,
            white_balance=False,
            noise=False,
            analog=False,
            jpeg_quality=0,
        )

    @property
    def is_ideal(self) -> bool:
        """True when no effect runs (whatever the parameters of the ones switched off)."""
        switches = (self.motion_blur, self.auto_exposure, self.white_balance, self.noise,
                    self.analog, self.jpeg_quality > 0)  # fmt: skip
        return self.lens is None and not any(switches)


@dataclass
class _Control:
    """A camera control loop's state: its value, converging to each frame's target."""

    value: np.ndarray | None = None

    def follow(self, target: np.ndarray, dt: float, time_constant: float) -> np.ndarray:
        """First-order lag in the log domain (gains are ratios); the first frame starts settled,
        as a camera switched on before the run has."""
        if self.value is None or time_constant <= 0.0:
            self.value = target
        else:
            keep = math.exp(-max(dt, 0.0) / time_constant)
            self.value = np.exp(np.log(target) + (np.log(self.value) - np.log(target)) * keep)
        return self.value


@dataclass
class CameraEffects:
    """The effects chain for ``width`` x ``height`` output frames (see the module docstring)."""

    settings: EffectSettings
    width: int
    height: int
    _exposure: _Control = field(default_factory=_Control, init=False, repr=False)
    _balance: _Control = field(default_factory=_Control, init=False, repr=False)

    def __post_init__(self) -> None:
        lens = self.settings.lens
        self._maps: tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray] | None = None
        self.canvas_size = (self.width, self.height)
        self.canvas_focal = 0.0
        if lens is None:
            return
        # The ideal frame that holds every ray of the distorted one: square pixels, the lens's
        # larger focal length (no loss of detail at the centre), centred, 2 px of margin.
        f = max(lens.fx, lens.fy)
        w, h = self.width, self.height
        u = np.concatenate([np.arange(w), np.full(h, -0.5), np.full(h, w - 0.5), np.arange(w)])
        v = np.concatenate([np.full(w, -0.5), np.arange(h), np.arange(h), np.full(w, h - 0.5)])
        x, y = lens.pixel_to_normalized(u, v)
        half_w = math.ceil(float(np.abs(x).max()) * f + 2.0)
        half_h = math.ceil(float(np.abs(y).max()) * f + 2.0)
        self.canvas_size = (2 * half_w, 2 * half_h)
        self.canvas_focal = f
        uu, vv = np.meshgrid(
            np.arange(self.width, dtype=float), np.arange(self.height, dtype=float)
        )
        x, y = lens.pixel_to_normalized(uu, vv)
        map_x = (f * x + (2 * half_w - 1) / 2.0).astype(np.float32)
        map_y = (f * y + (2 * half_h - 1) / 2.0).astype(np.float32)
        fixed = cv2.convertMaps(map_x, map_y, cv2.CV_16SC2)
        self._maps = (map_x, map_y, *fixed)

    @property
    def canvas_fovy(self) -> float:
        """Vertical field of view (radians) to render the canvas at (MuJoCo's ``fovy``); only
        meaningful with a lens."""
        if self.settings.lens is None:
            raise InputError("without a lens the frame is rendered at the camera's own field")
        return 2.0 * math.atan((self.canvas_size[1] / 2.0) / self.canvas_focal)

    def reset(self) -> None:
        """Forget the exposure and white balance the camera had settled on."""
        self._exposure = _Control()
        self._balance = _Control()

    # -- the chain ------------------------------------------------------------------------------
    def apply(
        self,
        image: np.ndarray,
        depth: np.ndarray | None,
        rng: np.random.Generator,
        rates: tuple[float, float] = (0.0, 0.0),
        dt: float | None = None,
    ) -> tuple[np.ndarray, np.ndarray | None]:
        """One frame through the camera: ``image`` H x W x 3 uint8 RGB rendered at
        ``canvas_size`` (depth likewise, metres along rays, or None); ``rates`` the camera's
        (horizontal, vertical) angular rates in rad/s during the exposure (pan + base yaw, tilt);
        ``dt`` seconds since the previous frame (None: one video frame). Returns the frame as
        the camera delivers it (``width`` x ``height``) and the depth seen through the same lens.
        """
        s = self.settings
        if image.shape != (self.canvas_size[1], self.canvas_size[0], 3) or image.dtype != np.uint8:
            raise InputError(
                f"camera effects: the frame is {image.shape} {image.dtype}, expected "
                f"{self.canvas_size[1]}x{self.canvas_size[0]}x3 uint8; render at the effects' "
                "canvas_size (and canvas_fovy)"
            )
        if depth is not None and depth.shape != image.shape[:2]:
            raise InputError(f"camera effects: depth is {depth.shape}, the image {image.shape}")
        dt = VIDEO_FRAME_S if dt is None else dt
        out = image
        if s.motion_blur:
            out = self.motion_blur(out, rates)
        if self._maps is not None:
            out, depth = self.distort(out, depth)
        if not (s.auto_exposure or s.white_balance or s.noise):
            return self._encode(out), depth
        pixels = out.astype(np.float32)
        gain = 1.0
        if s.auto_exposure:
            gain = self._exposure_gain(pixels, dt)
        if s.noise:
            sigma = cv2.sqrt(pixels * np.float32(s.shot_noise_dn) + np.float32(s.read_noise_dn**2))
            pixels += sigma * rng.standard_normal(pixels.shape, dtype=np.float32)
        if gain != 1.0:
            pixels *= np.float32(gain)
        if s.white_balance:
            np.clip(pixels, 0.0, 255.0, out=pixels)
            pixels *= self._balance_gains(pixels, dt)
        out = np.clip(np.rint(pixels), 0.0, 255.0).astype(np.uint8)
        return self._encode(out), depth

    def _encode(self, image: np.ndarray) -> np.ndarray:
        if self.settings.analog:
            image = self.analog_look(image)
        if self.settings.jpeg_quality > 0:
            image = self.jpeg(image, self.settings.jpeg_quality)
        return image

    # -- one effect each (public so tests and benchmarks can take them apart) ---------------------
    def distort(
        self, image: np.ndarray, depth: np.ndarray | None
    ) -> tuple[np.ndarray, np.ndarray | None]:
        """The canvas seen through the lens: bilinear for colour, nearest for depth (a depth
        between two surfaces would be neither, and visibility must stay true)."""
        assert self._maps is not None
        map_x, map_y, fixed_xy, fixed_frac = self._maps
        out = cv2.remap(
            image, fixed_xy, fixed_frac, cv2.INTER_LINEAR, borderMode=cv2.BORDER_REPLICATE
        )
        if depth is not None:
            depth = cv2.remap(
                depth, map_x, map_y, cv2.INTER_NEAREST, borderMode=cv2.BORDER_REPLICATE
            )
        return out, depth

    def blur_length(self, rates: tuple[float, float]) -> tuple[float, float]:
        """Blur streak (pixels, horizontal and vertical, signed as the rates) of a camera turning
        at ``rates`` rad/s during the exposure: rate x exposure time x focal length."""
        lens = self.settings.lens
        fx = lens.fx if lens is not None else self.width / 2.0 / math.tan(math.radians(22.5))
        fy = lens.fy if lens is not None else fx
        return (rates[0] * self.settings.exposure_s * fx, rates[1] * self.settings.exposure_s * fy)

    def motion_blur(self, image: np.ndarray, rates: tuple[float, float]) -> np.ndarray:
        """Average of the image along the streak a turning camera sweeps (no blur below 0.5 px)."""
        lx, ly = self.blur_length(rates)
        length = math.hypot(lx, ly)
        if length < 0.5:
            return image
        # the streak's bounding box only: a pan's streak is one row, cheap to filter
        width, height = 2 * math.ceil(abs(lx) / 2.0) + 1, 2 * math.ceil(abs(ly) / 2.0) + 1
        kernel = np.zeros((height, width), np.float32)
        cx, cy = (width - 1) / 2.0, (height - 1) / 2.0
        for t in np.linspace(-0.5, 0.5, 4 * max(width, height) + 1):  # splat points bilinearly
            x, y = cx + t * lx, cy + t * ly
            x0, y0 = math.floor(x), math.floor(y)
            fx, fy = x - x0, y - y0
            for dx, dy, w in ((0, 0, (1 - fx) * (1 - fy)), (1, 0, fx * (1 - fy)),
                              (0, 1, (1 - fx) * fy), (1, 1, fx * fy)):  # fmt: skip
                if w > 0.0 and 0 <= x0 + dx < width and 0 <= y0 + dy < height:
                    kernel[y0 + dy, x0 + dx] += w
        kernel /= kernel.sum()
        return cv2.filter2D(image, -1, kernel, borderType=cv2.BORDER_REPLICATE)

    def _exposure_gain(self, pixels: np.ndarray, dt: float) -> float:
        s = self.settings
        luma = float(np.dot(cv2.mean(pixels)[:3], (0.299, 0.587, 0.114)))
        target = np.clip(s.exposure_target * 255.0 / max(luma, 1.0), *s.gain_range)
        return float(self._exposure.follow(np.array(target), dt, s.exposure_time_constant_s))

    def _balance_gains(self, pixels: np.ndarray, dt: float) -> np.ndarray:
        """Grey world: red and blue gains that make the frame's mean grey, applied in part."""
        s = self.settings
        mean = np.maximum(np.array(cv2.mean(pixels)[:3]), 1.0)
        target = (mean[1] / mean) ** s.white_balance_strength
        gains = self._balance.follow(target, dt, s.white_balance_time_constant_s)
        cast = np.array([s.white_balance_cast[0], 1.0, s.white_balance_cast[1]])
        return (gains * cast).astype(np.float32)

    @staticmethod
    def analog_look(image: np.ndarray) -> np.ndarray:
        """Composite video's narrow chroma: colour blurred over 3 px along the line."""
        ycc = cv2.cvtColor(image, cv2.COLOR_RGB2YCrCb)
        ycc[..., 1:] = cv2.blur(
            np.ascontiguousarray(ycc[..., 1:]), (3, 1), borderType=cv2.BORDER_REPLICATE
        )
        return cv2.cvtColor(ycc, cv2.COLOR_YCrCb2RGB)

    @staticmethod
    def jpeg(image: np.ndarray, quality: int) -> np.ndarray:
        """Encode and decode as JPEG at ``quality`` (1-100)."""
        ok, buf = cv2.imencode(".jpg", image[..., ::-1], [cv2.IMWRITE_JPEG_QUALITY, int(quality)])
        if not ok:
            raise InputError(f"JPEG encoding failed at quality {quality}")
        return np.ascontiguousarray(cv2.imdecode(buf, cv2.IMREAD_COLOR)[..., ::-1])
