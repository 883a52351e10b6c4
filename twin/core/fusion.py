"""Fusion rules: how one view's column values change a grid layer, and how a layer is read.

Every rule keeps the same two sums per cell, so that all rules are driven by one coverage pass:

* ``evidence`` = initial prior + sum over views and columns of weight(column) x coverage;
* ``observed`` = sum over views and columns of coverage (how much the cell has been seen).

A rule only chooses the per-column weight and how the two sums are read as a confidence map:

* ``accumulate`` (the paper, Section 1.3): weight = the column's match value; read = evidence.
* ``normalized``: the paper's sum divided by how much the cell was observed, i.e. the mean match
  of the views that saw the cell. Cells seen less than ``min_observed`` (in units of full-cell
  coverage) read 0, because one glancing view would otherwise make a cell certain.
* ``logodds``: a binary detector model with false-positive rate P_fp and false-negative rate
  P_fn. A column fires when its value reaches ``threshold``; a fired column adds
  log((1 - P_fn) / P_fp) to its cells, a silent one log(P_fn / (1 - P_fp)) (negative evidence).
  Rates are clamped to [``RATE_EPS``, 1 - ``RATE_EPS``] so the weights stay finite.
* ``calibrated``: the detector's measured score distributions on and off the object
  (``twin.rfch.calibration.ScoreCalibration``) as a table of log-likelihood ratios per score
  bin; each column adds the LLR of its score's bin. The evidence is then the log posterior odds
  of each cell holding the object, up to the prior (``twin.core.confidence`` reads it as a
  probability). The table is plain numbers (``edges``, ``llr``) so that core needs no detector.

``read`` is element-wise: each output cell depends only on that cell's evidence and observed
sums, so it accepts stacked layers of any shape (e.g. trials x checkpoints x rows x cols, as the
Monte Carlo reads a whole chunk at once) and returns an array of that shape; it must not modify
its inputs (several rules may read the same sums).

The paper's rule is the reference; the others are measured against it (``twin montecarlo``).
"""

from __future__ import annotations

import itertools
import math
from dataclasses import asdict, dataclass
from typing import Any, ClassVar, Protocol

import numpy as np

from twin.core.errors import InputError

RATE_EPS = 1e-3


class FusionRule(Protocol):
    """What the grid needs from a rule."""

    name: ClassVar[str]

    def column_weights(self, values: np.ndarray) -> np.ndarray:
        """Per-column increment per unit of coverage, for column values in [0, 1]."""
        ...

    def read(self, evidence: np.ndarray, observed: np.ndarray) -> np.ndarray:
        """The confidence map of a layer from its two sums.

        Element-wise over arrays of any (equal) shape; returns that shape and leaves the inputs
        unchanged.
        """
        ...

    def params(self) -> dict[str, Any]:
        """The rule's parameters (for headers and results), JSON-serializable."""
        ...


@dataclass(frozen=True)
class Accumulate:
    """The paper's rule: every covered cell gains the column's value times its coverage."""

    name: ClassVar[str] = "accumulate"

    def column_weights(self, values: np.ndarray) -> np.ndarray:
        return np.asarray(values, dtype=float)

    def read(self, evidence: np.ndarray, observed: np.ndarray) -> np.ndarray:
        return evidence

    def params(self) -> dict[str, Any]:
        return {}


@dataclass(frozen=True)
class Normalized:
    """The paper's sum divided by how much each cell has been observed."""

    name: ClassVar[str] = "normalized"
    min_observed: float = 1.0

    def __post_init__(self) -> None:
        if not (math.isfinite(self.min_observed) and self.min_observed >= 0.0):
            raise InputError(f"min_observed must be >= 0, got {self.min_observed!r}")

    def column_weights(self, values: np.ndarray) -> np.ndarray:
        return np.asarray(values, dtype=float)

    def read(self, evidence: np.ndarray, observed: np.ndarray) -> np.ndarray:
        seen = (observed > 0.0) & (observed >= self.min_observed)
        return np.divide(evidence, observed, out=np.zeros_like(evidence), where=seen)

    def params(self) -> dict[str, Any]:
        return asdict(self)


@dataclass(frozen=True)
class LogOdds:
    """Binary detector model: fired columns add positive, silent ones negative log-odds."""

    name: ClassVar[str] = "logodds"
    p_fp: float = 0.1
    p_fn: float = 0.3
    threshold: float = 0.5

    def __post_init__(self) -> None:
        for key in ("p_fp", "p_fn", "threshold"):
            value = getattr(self, key)
            if not (math.isfinite(value) and 0.0 <= value <= 1.0):
                raise InputError(f"logodds {key} must be in [0, 1], got {value!r}")

    @property
    def fired_weight(self) -> float:
        return logodds_weights(self.p_fp, self.p_fn)[0]

    @property
    def silent_weight(self) -> float:
        return logodds_weights(self.p_fp, self.p_fn)[1]

    def column_weights(self, values: np.ndarray) -> np.ndarray:
        fired = np.asarray(values, dtype=float) >= self.threshold
        return np.where(fired, self.fired_weight, self.silent_weight)

    def read(self, evidence: np.ndarray, observed: np.ndarray) -> np.ndarray:
        return evidence

    def params(self) -> dict[str, Any]:
        return asdict(self)


@dataclass(frozen=True)
class Calibrated:
    """Each column adds the log-likelihood ratio of its score: log p(s | on) / p(s | off).

    ``edges`` (B+1 increasing numbers) bin the score; ``llr`` (B numbers, nats) is each bin's
    ratio, pooled over distances. Scores beyond the edges take the end bins. Evidence summed
    over views and columns is the log posterior odds of each cell up to the prior; read returns
    it unchanged. No defaults: a table only means something for the detector it was measured on
    (``ScoreCalibration.rule()`` builds this rule from a model's calibration).

    A detector weakens with distance (a far object covers few pixels of a patch), so a
    calibration may hold one table per distance band: ``ranges`` (K-1 increasing metres) cut
    the distance from the camera into K bands and ``range_llr`` (K rows of B) gives each band's
    table. In the grid the rule is *ranged*: each cell gets the table of its own distance, and
    its visibility v (the share of an object there the camera could see, ``ColumnVisibility``)
    mixes the two hypotheses rather than scaling the ratio: with the object there, the column's
    score comes from the on-distribution with probability v and from the off-distribution
    otherwise, so the cell gains log(v LR + 1 - v): 0 where hidden, the full LLR where wholly
    seen (``weight_profiles``). ``column_weights`` (the pooled table, as if every cell were
    fully seen) serves callers without distances, such as the Monte Carlo.
    """

    name: ClassVar[str] = "calibrated"
    ranged: ClassVar[bool] = True  # the grid asks weight_profiles for per-cell weights
    edges: tuple[float, ...]
    llr: tuple[float, ...]
    ranges: tuple[float, ...] = ()
    range_llr: tuple[tuple[float, ...], ...] = ()

    def __post_init__(self) -> None:
        # Lists come back from the grid header's JSON; keep tuples so the rule stays hashable.
        try:
            edges = tuple(float(e) for e in self.edges)
            llr = tuple(float(v) for v in self.llr)
            ranges = tuple(float(r) for r in self.ranges)
            range_llr = tuple(tuple(float(v) for v in row) for row in self.range_llr)
        except (TypeError, ValueError) as exc:
            raise InputError(f"calibrated edges and llr must be numbers: {exc}") from None
        if len(edges) < 2 or len(llr) != len(edges) - 1:
            raise InputError(
                f"calibrated needs B+1 edges and B llr values, got {len(edges)} and {len(llr)}; "
                "take both from ScoreCalibration.rule()"
            )
        if range_llr and (
            len(range_llr) != len(ranges) + 1 or any(len(row) != len(llr) for row in range_llr)
        ):
            raise InputError(
                f"calibrated range tables: {len(ranges)} range edges need {len(ranges) + 1} "
                f"rows of {len(llr)} values, got {[len(row) for row in range_llr]}"
            )
        if ranges and not range_llr:
            raise InputError("calibrated ranges need their range_llr tables")
        numbers = edges + llr + ranges + tuple(v for row in range_llr for v in row)
        if not all(math.isfinite(v) for v in numbers):
            raise InputError("calibrated edges and llr must be finite")
        if any(b <= a for a, b in itertools.pairwise(edges)):
            raise InputError("calibrated edges must increase strictly")
        if any(b <= a for a, b in itertools.pairwise(ranges)) or any(r <= 0 for r in ranges):
            raise InputError("calibrated ranges must be increasing positive distances (m)")
        object.__setattr__(self, "edges", edges)
        object.__setattr__(self, "llr", llr)
        object.__setattr__(self, "ranges", ranges)
        object.__setattr__(self, "range_llr", range_llr)

    def _score_bins(self, values: np.ndarray) -> np.ndarray:
        index = np.searchsorted(np.asarray(self.edges), values, side="right") - 1
        return np.clip(index, 0, len(self.llr) - 1)

    def column_weights(self, values: np.ndarray) -> np.ndarray:
        return np.asarray(self.llr)[self._score_bins(np.asarray(values, dtype=float))]

    def weight_profiles(
        self, values: np.ndarray, visibility: np.ndarray, step: float
    ) -> np.ndarray:
        """(n, bins) weight of each column's cells over distance (bins of ``step`` metres):
        log(v LR + 1 - v), with LR the ratio of the column's score in the table of the bin's
        distance band and v the column's visibility profile (n, bins) in [0, 1]."""
        values = np.asarray(values, dtype=float)
        visibility = np.asarray(visibility, dtype=float)
        scores = self._score_bins(values)  # (n,)
        if self.range_llr:
            centres = (np.arange(visibility.shape[1]) + 0.5) * step
            band = np.searchsorted(np.asarray(self.ranges), centres, side="right")  # (bins,)
            ratio = np.asarray(self.range_llr)[band[None, :], scores[:, None]]
        else:
            ratio = np.broadcast_to(np.asarray(self.llr)[scores][:, None], visibility.shape)
        return np.log1p(visibility * np.expm1(ratio))

    def read(self, evidence: np.ndarray, observed: np.ndarray) -> np.ndarray:
        return evidence

    def params(self) -> dict[str, Any]:
        out: dict[str, Any] = {"edges": list(self.edges), "llr": list(self.llr)}
        if self.range_llr:
            out["ranges"] = list(self.ranges)
            out["range_llr"] = [list(row) for row in self.range_llr]
        return out


def logodds_weights(p_fp: float, p_fn: float) -> tuple[float, float]:
    """(fired, silent) log-odds increments of a detector with rates clamped away from 0 and 1."""
    p_fp = min(max(p_fp, RATE_EPS), 1.0 - RATE_EPS)
    p_fn = min(max(p_fn, RATE_EPS), 1.0 - RATE_EPS)
    return math.log((1.0 - p_fn) / p_fp), math.log(p_fn / (1.0 - p_fp))


RULES: dict[str, type] = {rule.name: rule for rule in (Accumulate, Normalized, LogOdds, Calibrated)}


def make_rule(name: str, **params: Any) -> FusionRule:
    """Build a rule by name; unknown names or parameters are one-line ``InputError``s."""
    if name not in RULES:
        raise InputError(f"unknown fusion rule {name!r}; choose one of {', '.join(RULES)}")
    try:
        return RULES[name](**params)
    except TypeError as exc:
        raise InputError(f"bad parameters for fusion rule {name!r}: {exc}") from exc
