"""Several RFCH models scoring one frame, sharing every step that does not depend on the object.

Shared per frame: the input checks, the descriptor pass (Gaussian blurs, derivatives,
chromaticity — once per distinct descriptor setting, normally once), its sampling, and the patch
bounds. Per codebook: labelling and pair counting (only samples its rejection radii accept do
real work); per object: one intersection per patch. Objects trained on one codebook
(``Detector.train``, ``Detector.add``, ``RFCH.train_shared``) share labelling and pair counting;
models trained one by one each keep their own. The Detector never merges codebooks on its own:
that would make one object's scores depend on which other objects are loaded.
"""

from __future__ import annotations

import time
from collections.abc import Mapping, Sequence
from typing import Any

import numpy as np

from twin.core.errors import InputError
from twin.rfch import kernels
from twin.rfch.descriptor import check_image, raw_descriptors, sample_bounds
from twin.rfch.model import RFCH
from twin.rfch.params import PatchGrid, RFCHParams


class Detector:
    """Scores every patch of a frame for each of ``models`` (one layer per object)."""

    def __init__(self, models: Sequence[RFCH], share_cells: bool = True) -> None:
        """``share_cells=False`` forces the per-patch pair kernel (for tests and benchmarks)."""
        self.models = list(models)
        self.share_cells = share_cells
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
        # Models with one codebook are one group: labelled and pair-counted together.
        groups: dict[str, list[int]] = {}
        for index, model in enumerate(self.models):
            groups.setdefault(model.codebook_key, []).append(index)
        self._groups = []
        for members in groups.values():
            histograms = np.concatenate([self.models[i].flat_histograms() for i in members])
            owners = np.concatenate(
                [np.full(len(self.models[i].histograms), k) for k, i in enumerate(members)]
            ).astype(np.int64)
            self._groups.append((members, np.ascontiguousarray(histograms), owners))

    @classmethod
    def train(
        cls,
        objects: Mapping[str, tuple[Sequence[np.ndarray], Sequence[np.ndarray]]],
        **params: Any,
    ) -> Detector:
        """Train every object on ONE shared codebook: {name: (images, masks)} → a Detector.

        The natural way to detect several objects, and the fast one: each frame is labelled and
        its pairs counted once for all objects, so each extra object costs one histogram
        intersection per patch (docs/rfch.md). Keyword arguments are ``RFCHParams`` fields.
        Per-object models (``detector.models``) save and load like any ``RFCH``, and a Detector
        of the loaded files shares the codebook again (it groups models by ``codebook_key``).
        """
        return cls(RFCH.train_shared(objects, **params))

    def add(
        self,
        name: str,
        images: Sequence[np.ndarray],
        masks: Sequence[np.ndarray],
        **views: Any,
    ) -> Detector:
        """A new Detector with one more object, trained on this detector's (first) codebook.

        Only the new object's histogram is built; the codebook is not re-clustered, so the
        scores of the objects already here do not change, and the new object costs one
        intersection per patch. Its colours are only those the codebook already knows: an
        object unlike all the others is better trained with them (``Detector.train``).
        ``views`` may set the view parameters (``views``, ``view_similarity``,
        ``max_view_models``); the rest are the codebook's.
        """
        if name in self.names:
            raise InputError(f"the detector already has an object named {name!r}; pick another")
        model = RFCH.train(name, images, masks, codebook=self.models[0], **views)
        return Detector([*self.models, model], self.share_cells)

    @property
    def names(self) -> list[str]:
        return [model.name for model in self.models]

    @property
    def n_codebooks(self) -> int:
        """How many distinct codebooks the frame is labelled against (1 when all shared)."""
        return len(self._groups)

    def patch_boxes(self, shape: tuple[int, ...]) -> np.ndarray:
        """(rows, cols, 4) patch boxes [x0, y0, x1, y1] in px for a frame of ``shape``."""
        return self.grid.boxes(shape)

    def column_spans(self, width: int) -> np.ndarray:
        """(cols, 2) pixel spans [u0, u1] of the patch columns, for ``CameraModel.wedges``."""
        return self.grid.column_spans(width)

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
        stages = {"check": clock() - t0, "descriptor": 0.0, "labelling": 0.0}
        stages["pairs+intersection"] = 0.0
        # One descriptor pass per distinct (descriptor setting, sample step): normally one.
        descriptors: dict[tuple, np.ndarray] = {}
        out = np.empty((len(self.models), len(rows_px), len(cols_px)), dtype=np.float32)
        for members, histograms, owners in self._groups:
            model = self.models[members[0]]
            params = model.params
            key = (params.descriptor_key, params.sample_step)
            t = clock()
            if key not in descriptors:
                descriptors[key] = raw_descriptors(image, params, params.sample_step)
            t_desc = clock()
            labels = model.label(descriptors[key])
            t_label = clock()
            out[members] = self._patch_scores(
                labels, rows_px, cols_px, params, histograms, owners, len(members)
            )
            stages["descriptor"] += t_desc - t
            stages["labelling"] += t_label - t_desc
            stages["pairs+intersection"] += clock() - t_label
        if timings is not None:
            for stage, seconds in stages.items():
                timings[stage] = timings.get(stage, 0.0) + seconds
        return out

    def _patch_scores(
        self,
        labels: np.ndarray,
        rows_px: np.ndarray,
        cols_px: np.ndarray,
        params: RFCHParams,
        histograms: np.ndarray,
        owners: np.ndarray,
        n_objects: int,
    ) -> np.ndarray:
        """Pair counting and intersection: the shared-cell kernel where the grid allows it."""
        step = params.sample_step
        widths = kernels.half_widths(params.d_max, step)
        row_bounds = sample_bounds(rows_px, self.grid.size, step)
        col_bounds = sample_bounds(cols_px, self.grid.size, step)
        layout = kernels.cell_layout(row_bounds, col_bounds, len(widths) - 1)
        if layout is None or not self.share_cells:
            return kernels.patch_scores(
                labels, widths, row_bounds, col_bounds, histograms, owners, n_objects
            )
        cell, span, row_cells, col_cells = layout
        return kernels.cell_patch_scores(
            labels, widths, cell, span, row_cells, col_cells, histograms, owners, n_objects
        )
