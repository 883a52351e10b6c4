"""What a column score says about the object: its log-likelihood ratio, measured per detector.

A fixed threshold turns a score into fired/silent and throws the rest away. Here the detector's
own score distributions are measured instead: column scores (max over the column's patches, in
[0, 1]) on the object (positive columns of ``column_truth``) and off it (negative columns), as
histograms over fixed bins. The log-likelihood ratio of a score s,

    LLR(s) = log(p(s | column on the object) / p(s | column off the object)),

is what a column adds to the log posterior odds of its cells holding the object (fusion rule
``calibrated``). The estimate is made safe in three steps:

* Smoothing: each bin gets a prior pseudo-sample of ``prior_weight`` columns, split between on
  and off in proportion to the class totals. On its own that pseudo-sample has LLR 0 in every
  bin, so a sparse bin is pulled towards "no evidence" rather than towards the class imbalance
  (plain add-one smoothing would give an empty bin log(N_off / N_on), often +3, from nothing).
* Monotonicity: a higher match must never be weaker evidence, so the per-bin LLRs are replaced
  by their weighted isotonic (non-decreasing) fit (pool-adjacent-violators), each bin weighted
  by the inverse variance of its log ratio (1 / (1/n_on + 1/n_off), smoothed counts): a bin
  whose ratio rests on two columns yields to its well-measured neighbours. Bins with no column
  at all take the value of the nearest measured bin below (or above, at the bottom).
* Clipping to ±``max_abs_llr`` (4 by default, a likelihood ratio of 55): the calibration views
  are other scenes than the one surveyed and the columns of one view are not independent, so a
  ratio beyond what a few hundred positives can measure would let one column decide a cell.

The bins are fixed: ``bins`` equal bins over [0, 1] (25 by default, 0.04 wide: RFCH scores of
rendered frames lie mostly below 0.5, where positives and negatives overlap over some ten
bins), or explicit edges. Fixed edges keep the table readable and comparable between models.
"""

from __future__ import annotations

import itertools
import math
from collections.abc import Sequence
from dataclasses import dataclass
from functools import cached_property
from typing import Any

import numpy as np

from twin.core.errors import InputError
from twin.core.fusion import Calibrated

CALIBRATION_KIND = "rfch-score-calibration"
CALIBRATION_VERSION = 1
DEFAULT_BINS = 25
DEFAULT_PRIOR_WEIGHT = 4.0  # columns of pseudo-sample per bin
DEFAULT_MAX_ABS_LLR = 4.0  # nats
# Distance bands of the on-object tables (m). Through the paper's camera (45 degrees over 320
# pixels) an object 0.15 m wide spans about 39 pixels at 1.5 m, 23 at 2.5 m and 17 at 3.5 m:
# from more than a 32-pixel patch to half of one, so its match fades band by band.
DEFAULT_RANGES: tuple[float, ...] = (1.5, 2.5, 3.5)


@dataclass(frozen=True)
class ScoreCalibration:
    """Histograms of column scores on and off the object, and the LLR table they give.

    ``edges`` (B+1,) increasing bin edges over the score range; ``on_counts`` / ``off_counts``
    (B,) columns per bin; ``auc`` the area under the ROC of the raw scores (NaN if unknown);
    ``min_cover`` the ``column_truth`` cover that defined a positive column.
    """

    edges: tuple[float, ...]
    on_counts: tuple[int, ...]
    off_counts: tuple[int, ...]
    prior_weight: float = DEFAULT_PRIOR_WEIGHT
    max_abs_llr: float = DEFAULT_MAX_ABS_LLR
    auc: float = math.nan
    min_cover: float = 0.25
    # Distance bands: K-1 increasing edges (m) and, per band, the on-object counts per bin.
    ranges: tuple[float, ...] = ()
    range_on_counts: tuple[tuple[int, ...], ...] = ()

    def __post_init__(self) -> None:
        edges = tuple(float(e) for e in self.edges)
        on = tuple(int(c) for c in self.on_counts)
        off = tuple(int(c) for c in self.off_counts)
        if len(edges) < 2 or not all(math.isfinite(e) for e in edges):
            raise InputError(f"calibration edges must be >= 2 finite numbers, got {edges!r}")
        if any(b <= a for a, b in itertools.pairwise(edges)):
            raise InputError("calibration edges must increase strictly; give sorted bin edges")
        if len(on) != len(edges) - 1 or len(off) != len(edges) - 1:
            raise InputError(
                f"calibration has {len(edges) - 1} bins but {len(on)} on-object and "
                f"{len(off)} off-object counts; give one count per bin"
            )
        if min(on + off) < 0 or sum(on) == 0 or sum(off) == 0:
            raise InputError(
                f"calibration needs columns on and off the object, got {sum(on)} on and "
                f"{sum(off)} off; give views where the object covers some columns only"
            )
        if not (math.isfinite(self.prior_weight) and self.prior_weight > 0.0):
            raise InputError(f"prior_weight must be > 0 columns, got {self.prior_weight!r}")
        if not (math.isfinite(self.max_abs_llr) and self.max_abs_llr > 0.0):
            raise InputError(f"max_abs_llr must be > 0, got {self.max_abs_llr!r}")
        ranges = tuple(float(r) for r in self.ranges)
        by_range = tuple(tuple(int(c) for c in row) for row in self.range_on_counts)
        if by_range and (
            len(by_range) != len(ranges) + 1 or any(len(row) != len(on) for row in by_range)
        ):
            raise InputError(
                f"calibration has {len(ranges)} range edges but {len(by_range)} rows of "
                "on-object counts; give one row of counts per distance band"
            )
        if any(b <= a for a, b in itertools.pairwise(ranges)) or any(r <= 0 for r in ranges):
            raise InputError("calibration ranges must be increasing positive distances (m)")
        object.__setattr__(self, "edges", edges)
        object.__setattr__(self, "on_counts", on)
        object.__setattr__(self, "off_counts", off)
        object.__setattr__(self, "auc", float(self.auc))
        object.__setattr__(self, "ranges", ranges)
        object.__setattr__(self, "range_on_counts", by_range)

    # ---------------------------------------------------------------- building
    @classmethod
    def from_columns(
        cls,
        scores: np.ndarray,
        truth: np.ndarray,
        bins: int | Sequence[float] = DEFAULT_BINS,
        prior_weight: float = DEFAULT_PRIOR_WEIGHT,
        max_abs_llr: float = DEFAULT_MAX_ABS_LLR,
        min_cover: float = 0.25,
        distances: np.ndarray | None = None,
        ranges: Sequence[float] = DEFAULT_RANGES,
    ) -> ScoreCalibration:
        """Histogram column ``scores`` (in [0, 1]) by ``truth`` (1 on, 0 off, -1 left out).

        ``bins``: a number of equal bins over [0, 1], or explicit increasing edges. Scores
        outside the edges count in the end bins. ``min_cover`` is recorded, not used: it is the
        ``column_truth`` setting that made ``truth``. ``distances`` (metres, one per column:
        how far the object was from the camera) split the on-object columns into the distance
        bands that ``ranges`` (increasing metres) cut, one table per band.
        """
        from twin.rfch.roc import roc_curve

        scores = np.asarray(scores, dtype=float).ravel()
        truth = np.asarray(truth).ravel()
        if scores.shape != truth.shape:
            raise InputError(
                f"got {scores.size} column scores but {truth.size} truth labels; "
                "give one label per column"
            )
        if not np.all(np.isfinite(scores)):
            raise InputError("column scores must be finite; check the detector's output")
        if isinstance(bins, (int, np.integer)):
            if bins < 2:
                raise InputError(f"a calibration needs at least 2 bins, got {bins}")
            edges = np.linspace(0.0, 1.0, int(bins) + 1)
        else:
            edges = np.asarray(bins, dtype=float)
        keep = truth >= 0
        scores, positive = scores[keep], truth[keep] == 1
        index = _bin_index(scores, edges)
        n_bins = len(edges) - 1
        on = np.bincount(index[positive], minlength=n_bins)
        off = np.bincount(index[~positive], minlength=n_bins)
        by_range: tuple[tuple[int, ...], ...] = ()
        if distances is not None:
            distances = np.asarray(distances, dtype=float).ravel()
            if distances.shape != truth.shape:
                raise InputError(
                    f"got {distances.size} distances for {truth.size} columns; give one per column"
                )
            band = np.searchsorted(np.asarray(ranges, dtype=float), distances[keep], side="right")
            by_range = tuple(
                tuple(np.bincount(index[positive & (band == k)], minlength=n_bins).tolist())
                for k in range(len(ranges) + 1)
            )
        auc = math.nan
        if positive.any() and (~positive).any():
            auc = roc_curve(scores, positive.astype(np.int8)).auc
        return cls(
            tuple(edges.tolist()),
            tuple(on.tolist()),
            tuple(off.tolist()),
            prior_weight,
            max_abs_llr,
            auc,
            min_cover,
            tuple(ranges) if by_range else (),
            by_range,
        )

    # ---------------------------------------------------------------- the table
    @property
    def positives(self) -> int:
        return sum(self.on_counts)

    @property
    def negatives(self) -> int:
        return sum(self.off_counts)

    def table(self) -> np.ndarray:
        """(B,) LLR per bin in nats: smoothed, made non-decreasing, clipped (module docstring)."""
        return self._table.copy()

    def range_tables(self) -> np.ndarray:
        """(K, B) LLR per distance band and bin (each band's on-object columns against all the
        off-object ones, made the same way as ``table``); (0, B) without bands."""
        return np.array([self._llr(row) for row in self.range_on_counts]).reshape(
            len(self.range_on_counts), len(self.on_counts)
        )

    @cached_property
    def _table(self) -> np.ndarray:
        return self._llr(self.on_counts)

    def _llr(self, on_counts: Sequence[int]) -> np.ndarray:
        on = np.asarray(on_counts, dtype=float)
        off = np.asarray(self.off_counts, dtype=float)
        if on.sum() == 0:
            return np.zeros(len(on))  # no object seen at this distance: no evidence either way
        n_on, n_off = on.sum(), off.sum()
        total = n_on + n_off
        # Pseudo-counts split by class totals: the pseudo-sample alone has LLR 0 in every bin.
        a_on = self.prior_weight * n_on / total
        a_off = self.prior_weight * n_off / total
        s_on, s_off = on + a_on, off + a_off
        raw = np.log(s_on / s_on.sum()) - np.log(s_off / s_off.sum())
        weight = 1.0 / (1.0 / s_on + 1.0 / s_off)
        measured = (on + off) > 0
        fitted = np.empty_like(raw)
        fitted[measured] = isotonic(raw[measured], weight[measured])
        # Bins without a column: the nearest measured bin below (above, at the bottom end);
        # this keeps the table non-decreasing.
        index = np.flatnonzero(measured)
        below = np.searchsorted(index, np.arange(len(raw)), side="right") - 1
        fitted = fitted[index[np.maximum(below, 0)]]
        return np.clip(fitted, -self.max_abs_llr, self.max_abs_llr)

    def llr(self, scores: np.ndarray) -> np.ndarray:
        """LLR (nats) of each score: the table value of its bin; same shape as ``scores``."""
        scores = np.asarray(scores, dtype=float)
        return self._table[_bin_index(scores, np.asarray(self.edges))]

    def rule(self, by_distance: bool = False) -> Calibrated:
        """The ``calibrated`` fusion rule with this table (plain numbers, for twin.core); with
        ``by_distance`` the table of each distance band (measured no better in the twin's living
        room than the pooled table, README "How sure is it?": so not the default)."""
        if not by_distance or not self.range_on_counts:
            return Calibrated(edges=self.edges, llr=tuple(self.table().tolist()))
        return Calibrated(
            edges=self.edges,
            llr=tuple(self.table().tolist()),
            ranges=self.ranges,
            range_llr=tuple(tuple(row) for row in self.range_tables().tolist()),
        )

    # ---------------------------------------------------------------- files and reports
    def to_json(self) -> dict[str, Any]:
        """JSON-serializable form; ``llr`` is included for readers and recomputed on load."""
        return {
            "kind": CALIBRATION_KIND,
            "version": CALIBRATION_VERSION,
            "edges": list(self.edges),
            "on_counts": list(self.on_counts),
            "off_counts": list(self.off_counts),
            "prior_weight": self.prior_weight,
            "max_abs_llr": self.max_abs_llr,
            "auc": None if math.isnan(self.auc) else self.auc,
            "min_cover": self.min_cover,
            "llr": self.table().tolist(),
            "ranges": list(self.ranges),
            "range_on_counts": [list(row) for row in self.range_on_counts],
        }

    @classmethod
    def from_json(cls, data: dict[str, Any]) -> ScoreCalibration:
        """Inverse of ``to_json``; a wrong kind, version or field is a one-line ``InputError``."""
        if not isinstance(data, dict) or data.get("kind") != CALIBRATION_KIND:
            raise InputError(f"not a {CALIBRATION_KIND} record; re-measure the calibration")
        if data.get("version") != CALIBRATION_VERSION:
            raise InputError(
                f"{CALIBRATION_KIND} version {data.get('version')!r} is not "
                f"{CALIBRATION_VERSION}; re-measure the calibration"
            )
        try:
            auc = data.get("auc")
            return cls(
                tuple(data["edges"]),
                tuple(data["on_counts"]),
                tuple(data["off_counts"]),
                float(data["prior_weight"]),
                float(data["max_abs_llr"]),
                math.nan if auc is None else float(auc),
                float(data["min_cover"]),
                tuple(data.get("ranges", ())),
                tuple(tuple(row) for row in data.get("range_on_counts", ())),
            )
        except (KeyError, TypeError, ValueError) as exc:
            raise InputError(f"bad {CALIBRATION_KIND} record ({exc}); re-measure it") from exc

    def summary(self) -> dict[str, Any]:
        """Counts, AUC and the LLR range, for logs and result files."""
        table = self.table()
        return {
            "positives": self.positives,
            "negatives": self.negatives,
            "auc": None if math.isnan(self.auc) else round(self.auc, 4),
            "bins": len(self.on_counts),
            "llr_min": round(float(table.min()), 3),
            "llr_max": round(float(table.max()), 3),
        }

    def describe(self) -> str:
        """One line: positives, negatives, AUC, LLR range."""
        s = self.summary()
        auc = "n/a" if s["auc"] is None else f"{s['auc']:.3f}"
        return (
            f"{s['positives']} positive and {s['negatives']} negative columns, AUC {auc}, "
            f"LLR {s['llr_min']:+.2f} to {s['llr_max']:+.2f} over {s['bins']} bins"
        )

    def table_text(self) -> str:
        """The LLR table as aligned text: bin, columns on and off, LLR (nats)."""
        lines = ["score bin        on     off     LLR"]
        for (lo, hi), on, off, value in zip(
            itertools.pairwise(self.edges),
            self.on_counts,
            self.off_counts,
            self.table(),
            strict=True,
        ):
            lines.append(f"[{lo:.3f}, {hi:.3f})  {on:5d}  {off:6d}  {value:+6.2f}")
        if self.range_on_counts:
            bounds = [0.0, *self.ranges, math.inf]
            names = [f"{a:g}-{b:g} m" for a, b in itertools.pairwise(bounds)]
            counts = zip(names, self.range_on_counts, strict=True)
            bands = ", ".join(f"{name} ({sum(row)} on)" for name, row in counts)
            lines.append(f"LLR by the object's distance: {bands}")
            for (lo, hi), *values in zip(
                itertools.pairwise(self.edges), *self.range_tables(), strict=True
            ):
                lines.append(f"[{lo:.3f}, {hi:.3f})  " + "  ".join(f"{v:+6.2f}" for v in values))
        return "\n".join(lines)


def _bin_index(scores: np.ndarray, edges: np.ndarray) -> np.ndarray:
    """Bin of each score; scores beyond the edges fall in the end bins."""
    index = np.searchsorted(edges, scores, side="right") - 1
    return np.clip(index, 0, len(edges) - 2)


def isotonic(values: np.ndarray, weights: np.ndarray) -> np.ndarray:
    """Weighted least-squares non-decreasing fit of ``values`` (pool-adjacent-violators)."""
    values = np.asarray(values, dtype=float)
    weights = np.asarray(weights, dtype=float)
    if values.shape != weights.shape or values.ndim != 1:
        raise InputError("isotonic needs 1-D values and weights of equal length")
    if np.any(weights <= 0.0):
        raise InputError("isotonic weights must be positive")
    means: list[float] = []
    masses: list[float] = []
    sizes: list[int] = []
    for value, weight in zip(values.tolist(), weights.tolist(), strict=True):
        means.append(value)
        masses.append(weight)
        sizes.append(1)
        # Pool the last two blocks while they violate the order.
        while len(means) > 1 and means[-2] > means[-1]:
            mass = masses[-2] + masses[-1]
            mean = (means[-2] * masses[-2] + means[-1] * masses[-1]) / mass
            size = sizes[-2] + sizes[-1]
            del means[-1], masses[-1], sizes[-1]
            means[-1], masses[-1], sizes[-1] = mean, mass, size
    return np.repeat(np.array(means), sizes)
