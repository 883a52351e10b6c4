"""Receptive Field Cooccurrence Histograms: a fast, object-specific score for every patch.

The method is ``specs/rfch.md`` (Ekvall & Kragic 2005): per-pixel colour + Gaussian-derivative
descriptor, a k-means codebook per object with per-cluster rejection radii, cooccurrence
histograms of label pairs within d_max, and histogram intersection as the degree of match.

``RFCH`` is one object's model (train, save, load, scores); ``Detector`` scores several objects
on one frame, sharing the descriptor pass; ``PatchGrid`` gives the patch boxes and the column
pixel spans that ``CameraModel.wedges`` turns into bearings. ``ScoreCalibration`` is a model's
measured score distributions on and off its object and the log-likelihood ratio they give each
column score (the ``calibrated`` fusion rule).
"""

from __future__ import annotations

import importlib
from typing import TYPE_CHECKING, Any

if TYPE_CHECKING:
    from twin.rfch.calibration import ScoreCalibration
    from twin.rfch.detector import Detector
    from twin.rfch.model import RFCH
    from twin.rfch.params import PatchGrid, RFCHParams

__all__ = ["RFCH", "Detector", "PatchGrid", "RFCHParams", "ScoreCalibration"]

# Imported on first use: numba and OpenCV take a quarter second to load, and the command line
# reads the parameter defaults (twin.rfch.params) just to print its help.
_HOMES = {
    "RFCH": "twin.rfch.model",
    "Detector": "twin.rfch.detector",
    "PatchGrid": "twin.rfch.params",
    "RFCHParams": "twin.rfch.params",
    "ScoreCalibration": "twin.rfch.calibration",
}


def __getattr__(name: str) -> Any:
    if name in _HOMES:
        return getattr(importlib.import_module(_HOMES[name]), name)
    raise AttributeError(f"module 'twin.rfch' has no attribute {name!r}")
