"""The accumulator grid (paper, Section 1): one confidence layer per object over the map.

Each view fuses one bearing interval ("sensor wedge") per image patch column, projected from the
robot's known position; every cell gains in proportion to how much of it the column's wedge
covers (supersampled, ``twin.core.coverage``), weighted by the rule's per-column weight
(``twin.core.fusion``). Over many views the wedges through an object reinforce its cell, while cells
crossed only incidentally stay low; ``peaks`` reads the maxima back in metres.

Layers are indexed [row, col] with row 0 at ``y_min`` (map y up); cell (row, col) spans
x in [x_min + col c, x_min + (col + 1) c), y likewise, with c the cell size in metres.

Viewpoint bias (paper, Section 4): a cell seen again and again from the same direction gains
evidence just for being seen often, so with several views per stop the paper's sum parks its
estimate where views overlap; and repeated views from one direction are not independent
evidence, which makes probabilistic sums overconfident. With ``direction_bins`` B > 1 the grid
files every view's contribution to a cell under the direction from the cell to the camera (B
equal sectors of 2 pi / B, ``direction_bin``), and reads each sector as at most one full view:
its mean weight if it was seen at least once in full, its partial sum otherwise. The rule then
reads the sum over sectors, so a cell seen from many directions still gains (triangulation) and
one seen many times from one direction does not. B = 1 is the paper's grid, unchanged.
"""

from __future__ import annotations

import json
import math
import os
import zipfile
from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass
from pathlib import Path

import numpy as np
from numba import njit

from twin.core.coverage import NO_VISIBILITY, add_coverage
from twin.core.errors import FileFormatError, InputError
from twin.core.fusion import Accumulate, FusionRule, make_rule
from twin.core.geometry import require_finite

# The header's array name is the store's; the grid peeks at it to pick which version to load.
from twin.core.store import _HEADER_KEY, load_arrays, save_arrays
from twin.core.visibility import ColumnVisibility

GRID_FORMAT = "accumulator-grid"
# Version 2 stores the per-direction sums (direction_bins > 1); a grid of one direction bin is
# still written as version 1, byte for byte the arrays older versions of twin wrote and read.
GRID_FORMAT_VERSION = 2
GRID_FORMAT_VERSIONS = (1, 2)
# Each bin is a full copy of a layer's two sums per object, so memory grows with B; 64 sectors
# (5.6 degrees each) is already finer than a camera's pose is known.
MAX_DIRECTION_BINS = 64

Prior = float | np.ndarray | Callable[[np.ndarray, np.ndarray], np.ndarray]


@dataclass(frozen=True)
class GridSpec:
    """Where the grid lies: extent in metres and square cells of ``cell_size`` metres."""

    x_min: float
    y_min: float
    x_max: float
    y_max: float
    cell_size: float

    def __post_init__(self) -> None:
        require_finite("grid extent", self.x_min, self.y_min, self.x_max, self.y_max)
        require_finite("cell_size", self.cell_size)
        if self.cell_size <= 0.0:
            raise InputError(f"cell_size must be positive, got {self.cell_size!r} m")
        for axis, lo, hi in (("x", self.x_min, self.x_max), ("y", self.y_min, self.y_max)):
            span = hi - lo
            if span <= 0.0:
                raise InputError(f"grid extent along {axis} must be positive, got {lo}..{hi} m")
            cells = span / self.cell_size
            if abs(cells - round(cells)) > 1e-6 * max(1.0, cells):
                raise InputError(
                    f"grid extent along {axis} ({span:g} m) is not a whole number of "
                    f"{self.cell_size:g} m cells; adjust the extent or the cell size"
                )

    @property
    def nx(self) -> int:
        return round((self.x_max - self.x_min) / self.cell_size)

    @property
    def ny(self) -> int:
        return round((self.y_max - self.y_min) / self.cell_size)

    @property
    def shape(self) -> tuple[int, int]:
        return self.ny, self.nx

    def cell_centers(self) -> tuple[np.ndarray, np.ndarray]:
        """Arrays X, Y of shape (ny, nx): the centre of every cell in metres."""
        xs = self.x_min + (np.arange(self.nx) + 0.5) * self.cell_size
        ys = self.y_min + (np.arange(self.ny) + 0.5) * self.cell_size
        return np.meshgrid(xs, ys)

    def cell_center(self, row: int, col: int) -> tuple[float, float]:
        return (
            self.x_min + (col + 0.5) * self.cell_size,
            self.y_min + (row + 0.5) * self.cell_size,
        )


@dataclass(frozen=True)
class Peak:
    """A local maximum of a layer: its cell, the cell's centre in metres, and its value."""

    row: int
    col: int
    x: float
    y: float
    value: float


@dataclass(frozen=True)
class Peaks:
    """The strongest local maxima of a layer, strongest first.

    ``ratio`` is the first peak's value over the second's: how much the map prefers its best
    hypothesis. It is ``inf`` when the second peak is not positive (and the first is), and
    ``nan`` when there is no positive peak at all.
    """

    peaks: tuple[Peak, ...]

    @property
    def best(self) -> Peak:
        return self.peaks[0]

    @property
    def ratio(self) -> float:
        if not self.peaks or self.peaks[0].value <= 0.0:
            return math.nan
        if len(self.peaks) < 2 or self.peaks[1].value <= 0.0:
            return math.inf
        return self.peaks[0].value / self.peaks[1].value


def direction_bin(dx: np.ndarray, dy: np.ndarray, bins: int) -> np.ndarray:
    """The direction sector (0 .. bins - 1) of each vector (dx, dy), in metres.

    Sector b is the half-open bearing interval of width 2 pi / bins centred on b 2 pi / bins
    (counter-clockwise from +x): with 4 bins, 0 is east, 1 north, 2 west, 3 south. Centring
    the sectors puts the compass directions, along which views are often taken, mid-sector
    rather than on a boundary. A zero vector falls in sector 0. The grid bins each cell by the
    vector from its centre to the camera.
    """
    x, y = np.broadcast_arrays(np.asarray(dx, dtype=float), np.asarray(dy, dtype=float))
    out = np.empty(x.size, dtype=np.intp)
    _sectors(np.ravel(x), np.ravel(y), int(bins), out)
    return out.reshape(x.shape)


@njit(cache=True, inline="always")
def _sector(dx: float, dy: float, bins: int) -> int:
    # One definition for ``direction_bin`` and the scatter, so they bin boundaries alike.
    return math.floor(math.atan2(dy, dx) * bins / (2.0 * math.pi) + 0.5) % bins


@njit(cache=True)
def _sectors(dx, dy, bins, out) -> None:
    for k in range(dx.shape[0]):
        out[k] = _sector(dx[k], dy[k], bins)


@njit(cache=True)
def _scatter_by_direction(evidence, observed, objects, delta, ox, oy, x0, y0, cell) -> None:
    """Add one view's (K + 1, ny, nx) ``delta`` (K objects' evidence, then the coverage) to the
    (objects, bins, ny, nx) sums of ``objects``, each cell in the bin of its direction to the
    camera at (ox, oy); the grid's corner (x0, y0) and cell size are in metres. One pass over
    the cells: the bins are found only for cells the view saw, and nothing is allocated."""
    bins = evidence.shape[1]
    k = objects.shape[0]
    for r in range(delta.shape[1]):
        dy = oy - (y0 + (r + 0.5) * cell)
        for c in range(delta.shape[2]):
            seen = delta[k, r, c]
            if seen == 0.0:
                continue  # no coverage, so no evidence either
            b = _sector(ox - (x0 + (c + 0.5) * cell), dy, bins)
            for q in range(k):
                evidence[objects[q], b, r, c] += delta[q, r, c]
                observed[objects[q], b, r, c] += seen


def local_maxima(values: np.ndarray, k: int, separation: int = 1) -> list[tuple[int, int]]:
    """(row, col) of the ``k`` largest local maxima, at least ``separation + 1`` cells apart.

    A local maximum is at least as large as its 8 neighbours. Plateaus and near neighbours are
    thinned greedily, largest first; equal values are taken in raster order (row, then col).
    """
    padded = np.pad(values, 1, constant_values=-np.inf)
    ny, nx = values.shape
    is_max = np.ones(values.shape, dtype=bool)
    for dr in (-1, 0, 1):
        for dc in (-1, 0, 1):
            if dr or dc:
                is_max &= values >= padded[1 + dr : 1 + dr + ny, 1 + dc : 1 + dc + nx]
    rows, cols = np.nonzero(is_max)
    order = np.lexsort((cols, rows, -values[rows, cols]))
    chosen: list[tuple[int, int]] = []
    for index in order:
        r, c = int(rows[index]), int(cols[index])
        if all(max(abs(r - pr), abs(c - pc)) > separation for pr, pc in chosen):
            chosen.append((r, c))
            if len(chosen) == k:
                break
    return chosen


class AccumulatorGrid:
    """One accumulator layer per named object over a rectangular map region.

    ``rule`` decides how column values become cell increments (default: the paper's
    ``accumulate``); ``supersample`` is the sub-cells per cell side used for coverage (the
    paper's 10); ``prior`` sets the initial evidence: a number, an (ny, nx) array, a function
    of the cell-centre arrays (X, Y) in metres, or a mapping from object name to any of these.

    ``direction_bins`` (B, 1 .. 64) corrects viewpoint bias (see the module docstring): with
    B > 1 the sums are kept per direction sector from the cell to the camera and each sector
    counts at most as one full view. B = 1 (the default) is the paper's grid exactly. The prior
    is added once to the corrected evidence, not averaged with the views.

    ``baseline`` (per object an (ny, nx) array, in the rule's weight units, >= 0) is what a view
    adds to a cell of this room when the object is not there — a fruit bowl that looks like the
    sought box gains every time it is seen. Each view's gain at a cell is reduced by it, in
    proportion to how much of the cell the view saw, so only what is more than the room's usual
    look counts.
    """

    def __init__(
        self,
        objects: Sequence[str],
        spec: GridSpec,
        rule: FusionRule | Mapping[str, FusionRule] | None = None,
        supersample: int = 10,
        prior: Prior | Mapping[str, Prior] | None = None,
        direction_bins: int = 1,
        baseline: Mapping[str, np.ndarray] | None = None,
    ) -> None:
        names = list(objects)
        if not names:
            raise InputError("a grid needs at least one object name")
        if len(set(names)) != len(names) or not all(isinstance(n, str) and n for n in names):
            raise InputError(f"object names must be distinct non-empty strings, got {names!r}")
        if not isinstance(supersample, int | np.integer) or supersample < 1:
            raise InputError(f"supersample must be a positive integer, got {supersample!r}")
        if (
            not isinstance(direction_bins, int | np.integer)
            or isinstance(direction_bins, bool)
            or not 1 <= direction_bins <= MAX_DIRECTION_BINS
        ):
            raise InputError(
                f"direction_bins must be an integer from 1 to {MAX_DIRECTION_BINS} "
                f"(1: no viewpoint correction), got {direction_bins!r}"
            )
        self.spec = spec
        self.objects: tuple[str, ...] = tuple(names)
        self.rules = _rules_per_object(names, rule)
        self.supersample = int(supersample)
        self.direction_bins = int(direction_bins)
        self._index = {name: i for i, name in enumerate(names)}
        # Sums per (object, direction bin, row, col). With one bin the prior starts bin 0's
        # evidence, as it always did; with more it is kept apart, since the correction divides
        # each bin's evidence by how often the bin was seen and the prior was never seen.
        shape = (len(names), self.direction_bins, *spec.shape)
        self._evidence = np.zeros(shape)
        self._observed = np.zeros(shape)
        self._prior = np.zeros((len(names), *spec.shape))
        self._baseline = np.zeros((len(names), *spec.shape))
        for name, layer in (baseline or {}).items():
            values = np.asarray(layer, dtype=float)
            if values.shape != spec.shape or not np.all(np.isfinite(values)) or values.min() < 0:
                raise InputError(
                    f"the baseline of {name!r} must be finite values >= 0 of the grid's shape "
                    f"{spec.shape}, got shape {values.shape}"
                )
            self._baseline[self._object_index(name)] = values
        self._views = np.zeros(len(names), dtype=np.int64)
        if prior is not None:
            for name in names:
                i = self._index[name]
                layer = self._prior_layer(name, prior)
                if self.direction_bins == 1:
                    self._evidence[i, 0] = layer
                else:
                    self._prior[i] = layer

    # -- reading -------------------------------------------------------------------------

    @property
    def baselines(self) -> dict[str, np.ndarray]:
        """The objects that have a room baseline, and a copy of it (see the class docstring)."""
        return {
            name: self._baseline[i].copy()
            for name, i in self._index.items()
            if self._baseline[i].any()
        }

    @property
    def rule(self) -> FusionRule:
        """The grid's rule: the first object's (every object's rule is of the same kind, with
        parameters of its own where a detector calibrates each object apart)."""
        return self.rules[self.objects[0]]

    def layer(self, name: str) -> np.ndarray:
        """The confidence map of ``name`` as the rule reads it (a new (ny, nx) array).

        The rule reads ``evidence(name)`` and ``observed(name)``: with direction bins, the sums
        corrected for viewpoint bias.
        """
        return np.array(self.rules[name].read(*self._sums(self._object_index(name))))

    def evidence(self, name: str) -> np.ndarray:
        """``name``'s evidence sum per cell (a new (ny, nx) array), in the rule's weight units.

        With one direction bin: prior + sum over views of weight x coverage. With B > 1: prior
        + sum over bins b of evidence_b / max(observed_b, 1), i.e. each direction's mean
        weight, or its partial sum if that direction has seen less than one full cell.
        """
        return np.array(self._sums(self._object_index(name))[0])

    def observed(self, name: str) -> np.ndarray:
        """How much each cell of ``name`` has been seen (a new (ny, nx) array), in full-cell views.

        With one direction bin: the sum of coverage over views. With B > 1: the sum over bins
        of min(observed_b, 1), i.e. the number of directions that saw the cell, each counting
        at most one full view.
        """
        return np.array(self._sums(self._object_index(name))[1])

    def evidence_by_direction(self, name: str) -> np.ndarray:
        """The raw per-direction evidence sums of ``name``: a new (B, ny, nx) array.

        Bin b holds sum of weight x coverage over the views whose camera lay in sector b seen
        from the cell (``direction_bin``). With B > 1 the prior is not included; with one bin it
        is, as in the version-1 file.
        """
        return self._evidence[self._object_index(name)].copy()

    def observed_by_direction(self, name: str) -> np.ndarray:
        """The raw per-direction coverage sums of ``name``: a new (B, ny, nx) array.

        In full-cell views; bin b as in ``evidence_by_direction``.
        """
        return self._observed[self._object_index(name)].copy()

    def views(self, name: str) -> int:
        """How many views have been fused into ``name``'s layer."""
        return int(self._views[self._object_index(name)])

    def peaks(self, name: str, k: int = 3, min_separation: float = 0.0) -> Peaks:
        """The ``k`` strongest local maxima of ``name``'s layer, in metres.

        Peaks closer than ``min_separation`` metres (Chebyshev, at least one cell) to a stronger
        one are dropped: one object's blob spans several cells, and its shoulders should not
        count as a second hypothesis.
        """
        if k < 1:
            raise InputError(f"k must be at least 1, got {k!r}")
        if not (math.isfinite(min_separation) and min_separation >= 0.0):
            raise InputError(f"min_separation must be >= 0 metres, got {min_separation!r}")
        separation = max(1, math.ceil(min_separation / self.spec.cell_size - 1e-9))
        values = self.layer(name)
        found = []
        for row, col in local_maxima(values, k, separation):
            x, y = self.spec.cell_center(row, col)
            found.append(Peak(row, col, x, y, float(values[row, col])))
        return Peaks(tuple(found))

    # -- updating ------------------------------------------------------------------------

    def coverage(
        self, origin: tuple[float, float], intervals: np.ndarray, max_range: float | None = None
    ) -> np.ndarray:
        """(n, ny, nx) fraction of every cell covered by each of the n wedges."""
        ox, oy, wedges, reach = self._check_view(origin, intervals, max_range)
        out = np.zeros((len(wedges), *self.spec.shape))
        self._add(out, ox, oy, wedges, np.eye(len(wedges)), reach)
        return out

    def fuse(
        self,
        name: str,
        origin: tuple[float, float],
        intervals: np.ndarray,
        values: np.ndarray,
        max_range: float | None = None,
    ) -> None:
        """Fuse one view into ``name``'s layer (see ``fuse_all``)."""
        self.fuse_all(origin, intervals, {name: values}, max_range)

    def fuse_all(
        self,
        origin: tuple[float, float],
        intervals: np.ndarray,
        values: Mapping[str, np.ndarray],
        max_range: float | None = None,
        visibility: ColumnVisibility | None = None,
    ) -> None:
        """Fuse one view into several layers with a single coverage pass.

        ``origin`` is the camera's (x, y) in metres; ``intervals`` an (n, 2) array of bearing
        intervals [a0, a1] (radians, map frame, a0 <= a1, at most 2 pi wide), one per patch
        column; ``values[name]`` the n column match values in [0, 1]; ``max_range`` (metres)
        limits the wedges, which otherwise reach to the grid's edge; ``visibility`` (one profile
        per column) scales each cell's coverage, and its observed count, by how visible the
        cell was to the column (none: every cell in a wedge is visible, as the paper assumes).

        With direction bins each cell's share goes to the bin of the direction from the cell's
        centre to ``origin``; the coverage pass is the same single pass either way.
        """
        ox, oy, wedges, reach = self._check_view(origin, intervals, max_range)
        if visibility is not None and visibility.profiles.shape[0] != len(wedges):
            raise InputError(
                f"visibility has {visibility.profiles.shape[0]} column profiles for "
                f"{len(wedges)} wedges; give one per patch column"
            )
        if not values:
            raise InputError("values must name at least one object")
        indices = [self._object_index(name) for name in values]
        rows = [self._check_values(name, v, len(wedges)) for name, v in values.items()]
        rules = [self.rules[name] for name in values]
        delta = np.zeros((len(rows) + 1, *self.spec.shape))
        if all(getattr(rule, "ranged", False) for rule in rules):
            # The rule's weight depends on the cell's distance (and visibility) too: one
            # weight profile per object row. The observed row counts the views over the cell
            # (its visibility is in the weights already), so that direction bins average the
            # evidence of the views from one direction, seen or not.
            seen = visibility or ColumnVisibility.everywhere(
                len(wedges), reach if reach > 0 else self._farthest(ox, oy)
            )
            profiles = np.stack(
                [
                    rule.weight_profiles(v, seen.profiles, seen.step)
                    for rule, v in zip(rules, rows, strict=True)
                ]
                + [np.ones_like(seen.profiles), seen.profiles]
            )
            delta = np.zeros((len(rows) + 2, *self.spec.shape))
            weights = np.ones((len(rows) + 2, len(wedges)))
            self._add(delta, ox, oy, wedges, weights, reach, profiles, seen.step)
            seen_share = delta[-1]
            delta = delta[:-1]
        else:
            weights = np.stack(
                [rule.column_weights(v) for rule, v in zip(rules, rows, strict=True)]
                + [np.ones(len(wedges))]
            )
            shared = None if visibility is None else visibility.profiles[None]
            self._add(delta, ox, oy, wedges, weights, reach, shared, getattr(visibility, "step", 1))
            seen_share = delta[-1]
        for k, i in enumerate(indices):
            if self._baseline[i].any():
                delta[k] -= self._baseline[i] * seen_share
        if self.direction_bins == 1:
            for k, i in enumerate(indices):
                self._evidence[i, 0] += delta[k]
                self._observed[i, 0] += delta[-1]
                self._views[i] += 1
            return
        objects = np.array(indices, dtype=np.intp)
        _scatter_by_direction(
            self._evidence, self._observed, objects, delta, ox, oy,
            self.spec.x_min, self.spec.y_min, self.spec.cell_size,
        )  # fmt: skip
        self._views[objects] += 1

    # -- files ---------------------------------------------------------------------------

    def save(self, path: str | os.PathLike[str], compress: bool = True) -> Path:
        """Write the grid atomically as ``.npz`` with a JSON header (``compress=False``: faster,
        larger; ``twin.core.store.save_arrays``).

        A grid of one direction bin is written in format version 1 (the arrays older versions
        of twin read); one of B > 1 bins in version 2, which adds ``direction_bins`` to the
        header, keeps (objects, B, ny, nx) sums and the prior apart as (objects, ny, nx).
        """
        header = {
            "extent": [self.spec.x_min, self.spec.y_min, self.spec.x_max, self.spec.y_max],
            "cell_size": self.spec.cell_size,
            "supersample": self.supersample,
            "objects": list(self.objects),
            "rule": {"name": self.rule.name, **self.rule.params()},
        }
        if any(self.rules[name] != self.rule for name in self.objects):
            header["rules"] = {
                name: {"name": rule.name, **rule.params()} for name, rule in self.rules.items()
            }
        extra = {"baseline": self._baseline} if self._baseline.any() else {}
        if self.direction_bins == 1:
            arrays = {
                "evidence": self._evidence[:, 0],
                "observed": self._observed[:, 0],
                "views": self._views,
                **extra,
            }
            return save_arrays(path, GRID_FORMAT, 1, header, arrays, compress)
        header["direction_bins"] = self.direction_bins
        arrays = {
            "evidence": self._evidence,
            "observed": self._observed,
            "prior": self._prior,
            "views": self._views,
            **extra,
        }
        return save_arrays(path, GRID_FORMAT, GRID_FORMAT_VERSION, header, arrays, compress)

    @classmethod
    def load(cls, path: str | os.PathLike[str]) -> AccumulatorGrid:
        """Read a grid written by ``save`` (format version 1 or 2).

        A version-1 file is a grid of one direction bin. Any defect is a one-line
        ``FileFormatError``.
        """
        version = _stored_version(path)
        # JSON's true and 1.0 equal 1 in Python; only a true integer picks the reader.
        if type(version) is not int or version not in GRID_FORMAT_VERSIONS:
            version = GRID_FORMAT_VERSION  # so that load_arrays names the defect
        header, arrays = load_arrays(path, GRID_FORMAT, version)
        try:
            spec = GridSpec(*header["extent"], header["cell_size"])
            specs = header.get("rules") or dict.fromkeys(header["objects"], header["rule"])
            rules = {}
            for name, rule_spec in specs.items():
                params = dict(rule_spec)
                rules[name] = make_rule(params.pop("name"), **params)
            grid = cls(
                header["objects"],
                spec,
                rules,
                int(header["supersample"]),
                direction_bins=header["direction_bins"] if version >= 2 else 1,
            )
            n = len(grid.objects)
            bins = grid.direction_bins
            evidence = np.asarray(arrays["evidence"], dtype=float)
            observed = np.asarray(arrays["observed"], dtype=float)
            views = np.asarray(arrays["views"])
            if version == 1:
                evidence, observed = evidence[:, None], observed[:, None]
                prior = np.zeros((n, *spec.shape))
            else:
                prior = np.asarray(arrays["prior"], dtype=float)
            expected = (n, bins, *spec.shape)
            if evidence.shape != expected or observed.shape != expected:
                raise ValueError(f"layer arrays are not of shape {expected}")
            if prior.shape != (n, *spec.shape):
                raise ValueError(f"the prior is not of shape {(n, *spec.shape)}")
            if views.shape != (n,) or not np.issubdtype(views.dtype, np.integer):
                raise ValueError("the view counts do not match the objects")
            if not (np.all(np.isfinite(evidence)) and np.all(np.isfinite(prior))):
                raise ValueError("the evidence is not finite")
            if not (np.all(np.isfinite(observed)) and np.all(observed >= 0.0)):
                raise ValueError("the observed counts are not finite and non-negative")
            baseline = np.asarray(arrays.get("baseline", np.zeros((n, *spec.shape))), dtype=float)
            if baseline.shape != (n, *spec.shape) or not np.all(np.isfinite(baseline)):
                raise ValueError("the baseline is not a finite layer per object")
        except (KeyError, TypeError, ValueError, IndexError, InputError) as exc:
            raise FileFormatError(
                f"{path}: grid file is inconsistent ({exc}); re-create it"
            ) from exc
        if version >= 2 and bins == 1:
            # One bin keeps its prior in the evidence, as version 1 does.
            evidence = evidence + prior[:, None]
            prior = np.zeros_like(prior)
        grid._evidence = np.ascontiguousarray(evidence)
        grid._observed = np.ascontiguousarray(observed)
        grid._prior = np.ascontiguousarray(prior)
        grid._baseline = np.ascontiguousarray(baseline)
        grid._views = views.astype(np.int64)
        return grid

    # -- internals -----------------------------------------------------------------------

    def _object_index(self, name: str) -> int:
        try:
            return self._index[name]
        except KeyError:
            raise InputError(
                f"unknown object {name!r}; this grid has {', '.join(self.objects)}"
            ) from None

    def _sums(self, i: int) -> tuple[np.ndarray, np.ndarray]:
        """Object ``i``'s (evidence, observed) as the rule reads them: corrected with bins."""
        if self.direction_bins == 1:
            return self._evidence[i, 0], self._observed[i, 0]
        seen = self._observed[i]
        # A bin seen at least once in full gives its mean weight and counts as one view; a bin
        # seen less keeps its partial sums, so a glancing view stays a glancing view. (Memory
        # bound: 2 B layers are read; measured no faster as a compiled single pass.)
        evidence = self._evidence[i] / np.maximum(seen, 1.0)
        return self._prior[i] + evidence.sum(axis=0), np.minimum(seen, 1.0).sum(axis=0)

    def _farthest(self, ox: float, oy: float) -> float:
        """Metres from (ox, oy) to the grid's farthest corner (a profile's reach over it)."""
        spec = self.spec
        return max(
            math.hypot(x - ox, y - oy)
            for x in (spec.x_min, spec.x_max)
            for y in (spec.y_min, spec.y_max)
        )

    def _add(self, out, ox, oy, wedges, weights, reach, profiles=None, step=1.0) -> None:
        """Coverage into ``out``; ``profiles`` (1 or k, n, bins) scale it per cell (kernel)."""
        if profiles is None:
            profiles, step = NO_VISIBILITY, 1.0
        add_coverage(
            out, ox, oy, np.ascontiguousarray(wedges[:, 0]), np.ascontiguousarray(wedges[:, 1]),
            np.ascontiguousarray(weights, dtype=float), self.spec.x_min, self.spec.y_min,
            self.spec.cell_size, self.supersample, reach, profiles, step,
        )  # fmt: skip

    @staticmethod
    def _check_view(origin, intervals, max_range):
        try:
            ox, oy = (float(v) for v in origin)
        except (TypeError, ValueError):
            raise InputError(f"origin must be (x, y) in metres, got {origin!r}") from None
        require_finite("origin", ox, oy)
        wedges = np.asarray(intervals, dtype=float)
        if wedges.ndim != 2 or wedges.shape[1] != 2 or len(wedges) == 0:
            raise InputError(f"intervals must be an (n, 2) array, got shape {wedges.shape}")
        if not np.all(np.isfinite(wedges)):
            raise InputError("intervals must be finite radians")
        width = wedges[:, 1] - wedges[:, 0]
        if np.any(width < 0.0):
            raise InputError("each interval must be [a0, a1] with a0 <= a1 (radians)")
        if np.any(width > 2.0 * math.pi + 1e-12):
            raise InputError("an interval is wider than 2 pi; split it or check the units")
        reach = 0.0
        if max_range is not None:
            reach = float(max_range)
            if not (math.isfinite(reach) and reach > 0.0):
                raise InputError(
                    f"max_range must be a positive number of metres, got {max_range!r}"
                )
        return ox, oy, wedges, reach

    @staticmethod
    def _check_values(name: str, values: np.ndarray, n: int) -> np.ndarray:
        array = np.asarray(values, dtype=float)
        if array.shape != (n,):
            raise InputError(
                f"values for {name!r} must be one per interval ({n}), got {array.shape}"
            )
        if not np.all(np.isfinite(array)) or np.any((array < 0.0) | (array > 1.0)):
            raise InputError(f"values for {name!r} must be finite match values in [0, 1]")
        return array

    def _prior_layer(self, name: str, prior) -> np.ndarray:
        chosen = prior.get(name, 0.0) if isinstance(prior, Mapping) else prior
        if callable(chosen):
            chosen = chosen(*self.spec.cell_centers())
        try:
            layer = np.broadcast_to(np.asarray(chosen, dtype=float), self.spec.shape)
        except ValueError:
            raise InputError(
                f"prior for {name!r} must be a number or an array of shape {self.spec.shape}"
            ) from None
        if not np.all(np.isfinite(layer)):
            raise InputError(f"prior for {name!r} must be finite")
        return layer


def _stored_version(path: str | os.PathLike[str]) -> object:
    """The format version in a grid file's header, or None if it cannot be read.

    Only the small header member is decompressed; ``load_arrays`` then reports any defect.
    """
    try:
        with np.load(path, allow_pickle=False) as archive:
            header = json.loads(archive[_HEADER_KEY].tobytes().decode("utf-8"))
        return header.get("version")
    except (OSError, ValueError, KeyError, TypeError, AttributeError, EOFError, zipfile.BadZipFile):
        return None


def _rules_per_object(
    names: list[str], rule: FusionRule | Mapping[str, FusionRule] | None
) -> dict[str, FusionRule]:
    """One rule for every object, or one per object (all of one kind: a grid reads all its
    layers the same way, e.g. the calibrated rule with each model's own likelihood ratios)."""
    if rule is None or not isinstance(rule, Mapping):
        shared = rule if rule is not None else Accumulate()
        return dict.fromkeys(names, shared)
    missing = [name for name in names if name not in rule]
    if missing or len(rule) != len(names):
        raise InputError(
            f"give one fusion rule per object: the grid holds {names}, the rules name "
            f"{sorted(rule)}"
        )
    kinds = {rule[name].name for name in names}
    if len(kinds) != 1:
        raise InputError(
            f"a grid's objects must share one kind of fusion rule, got {sorted(kinds)}"
        )
    return {name: rule[name] for name in names}
