"""A digital twin of a mobile robot that localizes objects from bearing-only visual detection.

The method is the accumulator grid of "Object Localization using Bearing Only Visual Detection"
(see README.md): noisy per-column detector scores, projected from known robot poses as bearing
wedges, are fused into a map-space grid whose maxima mark the objects.
"""

__version__ = "0.1.0"
