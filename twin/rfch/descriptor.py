"""Input checks and the per-pixel RFCH descriptor ("receptive field responses").

The raw descriptor of a pixel is [r, g, responses…]: normalized colour r = R/(R+G+B),
g = G/(R+G+B), then for each Gaussian scale σ the rotation-invariant responses of the intensity
image (gradient magnitude |∇L_σ| and/or Laplacian L_σ,xx + L_σ,yy). It is computed once per
frame and shared by every object; each model's z-scoring is an affine map applied while labelling.
"""

from __future__ import annotations

import cv2
import numpy as np

from twin.core.errors import InputError
from twin.rfch.params import RFCHParams

_MEAN_RGB = np.full((1, 3), 1.0 / 3.0, dtype=np.float32)


def check_image(image: object, what: str = "image") -> np.ndarray:
    """Return ``image`` as an H×W×3 uint8 RGB array or raise a one-line ``InputError``.

    A constant frame is refused: it carries no colour or structure, so any score on it would be
    meaningless (a covered lens or a dead camera), and a silent zero would hide that.
    """
    if not isinstance(image, np.ndarray):
        raise InputError(f"{what} must be a numpy array, got {type(image).__name__}")
    if image.dtype.kind in "fc" and not np.all(np.isfinite(image)):
        raise InputError(f"{what} contains NaN or infinite values; pass a finite uint8 RGB frame")
    if image.ndim != 3 or image.shape[2] != 3:
        raise InputError(f"{what} must be H×W×3 RGB, got shape {image.shape}")
    if image.dtype != np.uint8:
        raise InputError(
            f"{what} must be uint8 (0…255), got dtype {image.dtype}; convert it with "
            "np.clip(x, 0, 255).astype(np.uint8) if it holds 0…255 values"
        )
    if image.shape[0] < 2 or image.shape[1] < 2:
        raise InputError(f"{what} is too small ({image.shape[0]}×{image.shape[1]} px)")
    # Cheap first: a few scattered pixels almost always differ; only then compare them all.
    probe = image[:: max(image.shape[0] // 7, 1), :: max(image.shape[1] // 7, 1)].reshape(-1, 3)
    if np.all(probe == probe[0]) and np.all(image == image[0, 0]):
        raise InputError(
            f"{what} is constant (every pixel is RGB {tuple(int(v) for v in image[0, 0])}); "
            "check the camera or the file"
        )
    return image


def check_mask(mask: object, shape: tuple[int, ...], what: str = "mask") -> np.ndarray:
    """Return ``mask`` as an H×W bool array matching ``shape`` or raise an ``InputError``."""
    if not isinstance(mask, np.ndarray):
        raise InputError(f"{what} must be a numpy bool array, got {type(mask).__name__}")
    if mask.dtype != np.bool_:
        raise InputError(f"{what} must be dtype bool, got {mask.dtype}; pass (mask != 0)")
    if mask.shape != tuple(shape[:2]):
        raise InputError(
            f"{what} has shape {mask.shape} but its image is {shape[0]}×{shape[1]}; "
            "masks must match their images pixel for pixel"
        )
    if not mask.any():
        raise InputError(f"{what} is empty (no object pixel); mark the object with True")
    return mask


def raw_descriptors(image: np.ndarray, params: RFCHParams, step: int = 1) -> np.ndarray:
    """h×w×D float32 raw descriptor of a checked frame at every ``step``-th pixel, starting at
    (0, 0) (see the module docstring for the order); step 1 gives the full H×W×D.

    Blurs run on the full frame (the responses must not depend on the step); colour and the
    per-pixel responses are computed only at the sampled pixels, in one compiled pass
    (``kernels.sampled_responses``). Derivatives are central differences of the
    Gaussian-smoothed (log) intensity, which equal Gaussian-derivative filtering to within the
    blur's own width at σ ≥ 1 and cost a fraction of it.
    """
    from twin.rfch import kernels

    height, width = image.shape[:2]
    if params.responses:
        full = image.astype(np.float32)
        intensity = cv2.transform(full, _MEAN_RGB)  # (R + G + B) / 3 per pixel
        if params.log_intensity:
            intensity = np.log(intensity + np.float32(params.intensity_offset))
        else:
            intensity = intensity * np.float32(1.0 / 255.0)
        smooth = np.empty((len(params.sigmas), height, width), dtype=np.float32)
        for index, sigma in enumerate(params.sigmas):
            cv2.GaussianBlur(
                intensity, (0, 0), sigma, dst=smooth[index], borderType=cv2.BORDER_REFLECT
            )
    else:
        smooth = np.empty((0, height, width), dtype=np.float32)
    return kernels.sampled_responses(
        image,
        smooth,
        np.asarray(params.sigmas, dtype=np.float64),
        "gradient" in params.responses,
        "laplacian" in params.responses,
        step,
    )


def sample(array: np.ndarray, step: int) -> np.ndarray:
    """Every ``step``-th pixel in each direction, starting at pixel (0, 0), contiguous."""
    return np.ascontiguousarray(array[::step, ::step])


def sample_bounds(starts: np.ndarray, size: int, step: int) -> np.ndarray:
    """(n, 2) half-open sample-index ranges of pixel ranges [s, s + size) on a step grid."""
    lo = -(-starts // step)
    hi = -(-(starts + size) // step)
    return np.stack([lo, hi], axis=1).astype(np.int64)
