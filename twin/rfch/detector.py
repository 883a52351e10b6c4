"""Several RFCH models scoring one frame, sharing every step that does not depend on the object.

Shared per frame: the input checks, the descriptor pass (Gaussian blurs, derivatives,
chromaticity — once per distinct descriptor setting, normally once), its sampling, and the patch
bounds. Per object: labelling against its own codebook, pair counting and intersection — and both
of those only do real work on samples that the object's rejection radius accepts, so an object
whose colours are rare in the frame costs little. Labels are NOT taken from a merged codebook:
that would make one object's scores depend on which other objects are loaded.
"""

from __future__ import annotations

import time
from collections.abc import Sequence

import numpy as np

from twin.errors import InputError
from twin.rfch import kernels
from twin.rfch.descriptor import check_image, raw_descriptors, sample_bounds
from twin.rfch.model import RFCH
from twin.rfch.params import PatchGrid


class Detector:
    """Scores every patch of a frame for each of ``models`` (one layer per object)."""

    def __init__(self, models: Sequence[RFCH]) -> None:
        self.models = list(models)
        if not self.models:
            raise InputError("a Detector needs at least one RFCH model")
        for model in self.models:
            if not isinstance(model, RFCH):
                raise InputError(f"Detector models must be RFCH, got {type(model).__name__}")
        grids = {model.params.grid for model in self.models}
        if len(grids) != 1:
            raise InputError(
                "all models of a Detector must use the same patch size and stride, got "
                + ", ".join(f"{g.size}/{g.stride}" for g in grids)
                + "; re-train them with equal --patch-size and --stride"
            )
        self.grid: PatchGrid = grids.pop()
        self._widths = {
            (m.params.d_max, m.params.sample_step): kernels.half_widths(
                m.params.d_max, m.params.sample_step
            )
            for m in self.models
        }
        self._flat = [m.flat_histograms() for m in self.models]

    @property
    def names(self) -> list[str]:
        return [model.name for model in self.models]

    def patch_boxes(self, shape: tuple[int, ...]) -> np.ndarray:
        """(rows, cols, 4) patch boxes [x0, y0, x1, y1] in px for a frame of ``shape``."""
        return self.grid.boxes(shape)

    def column_spans(self, width: int) -> np.ndarray:
        """(cols, 2) pixel spans [u0, u1] of the patch columns, for ``CameraModel.wedges``."""
        return self.grid.column_spans(width)

    def column_edges(self, width: int) -> np.ndarray:
        """Left and right pixel edge of each patch column: the same as ``column_spans``."""
        return self.column_spans(width)

    def scores(self, image: np.ndarray, timings: dict[str, float] | None = None) -> np.ndarray:
        """(objects, rows, cols) float32 degrees of match in [0, 1].

        If ``timings`` is given, seconds spent per stage are added to it under "check",
        "descriptor", "labelling" and "pairs+intersection" (the last two are fused in one loop).
        """
        clock = time.perf_counter
        t0 = clock()
        image = check_image(image, "frame")
        rows_px = self.grid.starts(image.shape[0])
        cols_px = self.grid.starts(image.shape[1])
        t1 = clock()
        # One descriptor pass per distinct (descriptor setting, sample step): normally one.
        descriptors: dict[tuple, np.ndarray] = {}
        elapsed_desc = 0.0
        elapsed_label = 0.0
        elapsed_pairs = 0.0
        out = np.empty((len(self.models), len(rows_px), len(cols_px)), dtype=np.float32)
        for index, model in enumerate(self.models):
            params = model.params
            key = (params.descriptor_key, params.sample_step)
            t = clock()
            if key not in descriptors:
                descriptors[key] = raw_descriptors(image, params, params.sample_step)
            t_desc = clock()
            labels = model.label(descriptors[key])
            t_label = clock()
            step = params.sample_step
            out[index] = kernels.patch_scores(
                labels,
                self._widths[(params.d_max, step)],
                sample_bounds(rows_px, self.grid.size, step),
                sample_bounds(cols_px, self.grid.size, step),
                self._flat[index],
            )
            t_pairs = clock()
            elapsed_desc += t_desc - t
            elapsed_label += t_label - t_desc
            elapsed_pairs += t_pairs - t_label
        if timings is not None:
            for stage, seconds in (
                ("check", t1 - t0),
                ("descriptor", elapsed_desc),
                ("labelling", elapsed_label),
                ("pairs+intersection", elapsed_pairs),
            ):
                timings[stage] = timings.get(stage, 0.0) + seconds
        return out
