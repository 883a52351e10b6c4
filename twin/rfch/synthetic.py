"""Test frames with known answers: an object cut-out pasted at a known place, pose and lighting.

Used by the tests (hand-made scenes), ``benchmarks/bench_rfch.py`` and
``benchmarks/rfch_quality.py`` (real photographs as objects and backgrounds). Every random choice
comes from the caller's ``numpy.random.Generator``.
"""

from __future__ import annotations

import cv2
import numpy as np


def cloudy_background(rng: np.random.Generator, height: int, width: int) -> np.ndarray:
    """H×W×3 uint8 frame of smooth random colour blobs plus fine noise (a cluttered stand-in)."""
    coarse = rng.uniform(40, 215, size=(max(height // 24, 2), max(width // 24, 2), 3))
    frame = cv2.resize(coarse.astype(np.float32), (width, height), interpolation=cv2.INTER_CUBIC)
    frame += rng.normal(0.0, 6.0, size=frame.shape).astype(np.float32)
    return np.clip(frame, 0, 255).astype(np.uint8)


def striped_object(size: int = 40) -> tuple[np.ndarray, np.ndarray]:
    """A size×size multicoloured disc (rings of saturated colours): image and bool mask."""
    yy, xx = np.mgrid[0:size, 0:size].astype(np.float32) - (size - 1) / 2.0
    radius = np.hypot(yy, xx)
    palette = np.array(
        [[220, 30, 40], [250, 210, 20], [30, 60, 200], [20, 160, 60]], dtype=np.float32
    )
    ring = (radius / 4.0).astype(int) % len(palette)
    image = palette[ring]
    # A little shading gives the derivative responses something besides ring edges.
    image *= (0.85 + 0.15 * np.cos(xx / 3.0))[..., None]
    mask = radius <= size / 2.0 - 0.5
    image[~mask] = 128
    return np.clip(image, 0, 255).astype(np.uint8), mask


def paste(
    frame: np.ndarray,
    obj: np.ndarray,
    mask: np.ndarray,
    centre_xy: tuple[float, float],
    scale: float = 1.0,
    angle_deg: float = 0.0,
    gain: float = 1.0,
) -> tuple[np.ndarray, np.ndarray]:
    """Paste ``obj`` (its ``mask`` pixels) into a copy of ``frame``; return (frame, object mask).

    The object is scaled, rotated about its centre by ``angle_deg`` (counter-clockwise) and its
    brightness multiplied by ``gain`` before it is placed with its centre at ``centre_xy`` (px).
    """
    h, w = frame.shape[:2]
    oh, ow = obj.shape[:2]
    matrix = cv2.getRotationMatrix2D(((ow - 1) / 2.0, (oh - 1) / 2.0), angle_deg, scale)
    matrix[:, 2] += np.array(centre_xy) - np.array([(ow - 1) / 2.0, (oh - 1) / 2.0])
    warped = cv2.warpAffine(
        obj.astype(np.float32) * np.float32(gain), matrix, (w, h), flags=cv2.INTER_LINEAR
    )
    cover = cv2.warpAffine(mask.astype(np.float32), matrix, (w, h), flags=cv2.INTER_LINEAR)
    out = frame.astype(np.float32) * (1.0 - cover[..., None]) + warped * cover[..., None]
    return np.clip(out + 0.5, 0, 255).astype(np.uint8), cover >= 0.5
