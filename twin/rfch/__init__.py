"""Receptive Field Cooccurrence Histograms: a fast, object-specific score for every patch.

The method is ``specs/rfch.md`` (Ekvall & Kragic 2005): per-pixel colour + Gaussian-derivative
descriptor, a k-means codebook per object with per-cluster rejection radii, cooccurrence
histograms of label pairs within d_max, and histogram intersection as the degree of match.

``RFCH`` is one object's model (train, save, load, scores); ``Detector`` scores several objects
on one frame, sharing the descriptor pass; ``PatchGrid`` gives the patch boxes and the column
pixel spans that ``CameraModel.wedges`` turns into bearings.
"""

from twin.rfch.detector import Detector
from twin.rfch.model import RFCH
from twin.rfch.params import PatchGrid, RFCHParams

__all__ = ["RFCH", "Detector", "PatchGrid", "RFCHParams"]
