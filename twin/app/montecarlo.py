"""The paper's Section 3 evaluation: Monte Carlo over detector false-positive/negative rates.

An abstract world (Figure 3): an n x n grid of unit cells, one object in a random cell off the
outer edge. Every view puts the robot at a uniformly random point anywhere but in the object's
cell, with a uniformly random heading; its field of view is split into equal-angle wedges that
reach to the map's edge. A wedge whose angular span meets the object's cell (exactly, from the
cell's corners) fires with probability 1 - P_fn, any other wedge with probability P_fp; a fired
wedge has value 1.

The rules are ``twin.core.fusion``'s, named by ``--fusion`` (any registered rule, with the
parameters this sweep can supply: the setting's true P_fp and P_fn, --min-observed and, with
scores, the threshold and the score model's exact log-likelihood ratios). Each rule's weights of
the trials' wedge values (``column_weights``) name an evidence layer; rules whose weights agree
on every value of a batch of trials share one, and all share the ``observed`` layer, so one
coverage pass per view updates every rule. The layers are copied at each checkpoint, and each
rule's element-wise ``read`` turns a whole batch of trials x checkpoints into confidence maps.

After each checkpoint (by default 10, 25, 75 and 150 views of one trial: nested, so one trial
yields all view counts) the trial succeeds for a rule when that rule's maximal cell is the
object's cell or one of its 8 neighbours. Cells within 1e-9 (relative) of the maximum are tied;
ties are broken uniformly at random with one draw per checkpoint shared by all rules, so a flat
grid scores chance (about 9 / n^2), not a bias toward a corner.

Beyond the paper (both off by default, which leaves its results unchanged):

* **Occluders** (``occluders``: a fraction of the cells): that many blocking cells, uniformly
  among the cells other than the object's, per trial; the robot never stands in one. A cell is
  in view from the robot when the segment to its centre crosses no occluder cell (the cell
  itself aside: an occluder's near face is seen). The object is seen by a wedge when the wedge
  meets its cell and its centre is in view; a hidden object's wedge behaves as any other
  (fires with P_fp, or draws an off-object score). Every rule is then evaluated twice from the
  same coverage pass: ``visibility=none`` (blind, as the paper: the whole wedge updates) and
  ``visibility=known`` (a wedge updates only the cells in view: the exact per-cell test above,
  i.e. what the twin's ``ColumnVisibility`` approximates by profiles over distance).
* **Scores** (``scores="beta"``): a wedge's value is a continuous detector score, drawn from
  Beta(``score_on``) when the wedge sees the object and Beta(``score_off``) otherwise (defaults
  resembling the RFCH column scores measured on the twin's frames). The settings are then
  ``thresholds``: each gives ``logodds`` a detector that fires at value >= threshold, with the
  (P_fp, P_fn) that threshold has under the two distributions (the setting's rates in the
  results); ``calibrated`` gets the exact log-likelihood ratio log(p_on(v) / p_off(v)) of the
  two distributions in ``SCORE_BINS`` equal bins of value. The paper's rules weigh the value.

Randomness: trial t of setting (P_fp, P_fn) draws everything from
``SeedSequence(seed, spawn_key=(P_fp in 1e-9, P_fn in 1e-9, t))``, so a result depends only on
the seed, the setting and the trial index: not on the number of workers, the order in which
settings run, or which other settings are in the sweep. With scores, a trial draws from
``SeedSequence(seed, spawn_key=(SCORES_KEY, t))``: the threshold only decides what ``logodds``
sees, so every threshold is scored on the same worlds. Occluders are drawn first (only when
there are any), so a sweep without them draws exactly what the paper's did.
"""

from __future__ import annotations

import csv
import inspect
import io
import json
import math
from collections.abc import Callable, Iterable, Sequence
from dataclasses import dataclass, field
from functools import lru_cache, partial
from pathlib import Path

import numpy as np
from numba import njit

from twin.app.executors import Executor

# The coverage kernel's own wedge splitting and sample-index rules, so that this sweep's counts
# of a wedge's sample points in a cell are exactly ``add_coverage``'s.
from twin.core.coverage import (
    _contains_angle,
    _first_index_after,
    _first_index_at_or_after,
    wedge_pieces,
)
from twin.core.errors import InputError, TwinError
from twin.core.fusion import RULES, FusionRule, logodds_weights, make_rule
from twin.core.store import JsonLinesJournal, write_text_atomic

DEFAULT_RATES: tuple[float, ...] = tuple(round(0.1 * i, 1) for i in range(11))
DEFAULT_FUSION: tuple[str, ...] = ("accumulate", "normalized", "logodds")
# What a detector wedge's match value is when silent and when fired.
BINARY_VALUES = np.array([0.0, 1.0])
RESULT_COLUMNS: tuple[str, ...] = (
    "fusion",
    "pfp",
    "pfn",
    "views",
    "trials",
    "successes",
    "success_rate",
)
# How each rule is evaluated with occluders: blind (the paper's), or updating only cells in view.
VISIBILITIES: tuple[str, ...] = ("none", "known")
SCORES: tuple[str, ...] = ("binary", "beta")
# Beta(a, b) of a wedge's score on and off the object: like the RFCH column scores measured on
# the twin's frames (off mostly 0.02-0.15 with a tail to 0.3; on mostly 0.15-0.6).
DEFAULT_SCORE_ON: tuple[float, float] = (4.0, 8.0)
DEFAULT_SCORE_OFF: tuple[float, float] = (2.0, 20.0)
# Near the threshold the RFCH detector is run at (0.162: P_fp 0.10, P_fn 0.05 on rendered frames).
DEFAULT_THRESHOLDS: tuple[float, ...] = (0.16,)
# Equal bins of value over [0, 1] in which ``calibrated`` is given the score model's LLR.
SCORE_BINS = 200
# A bin's probability below this counts as this, so its LLR stays finite (|LLR| <= ~690).
_MASS_FLOOR = 1e-300
# Trials with scores are keyed apart from any (P_fp, P_fn) key (those are at most 1e9).
SCORES_KEY = 2**32
# At most this share of the cells may block: the object and the robot need free cells.
MAX_OCCLUDERS = 0.9
_TIE_RTOL = 1e-9
_RATE_KEY_SCALE = 1e9
# Checkpoint copies of the layers (and confidence maps) of one batch of trials stay below this.
_BATCH_BYTES = 32 * 1024 * 1024
_CDF_POINTS = 1 << 16  # trapezoid intervals over [0, 1] for a Beta CDF (error ~1e-9)
# Gauss-Legendre nodes per LLR bin: exact for integer shapes (polynomial densities) to a + b = 33.
_BIN_POINTS = 16


def _beta_pdf(a: float, b: float, x: np.ndarray) -> np.ndarray:
    """Density of Beta(a, b) at ``x`` in [0, 1], for a, b >= 1 (bounded, 0 or finite at ends)."""
    norm = math.lgamma(a) + math.lgamma(b) - math.lgamma(a + b)
    with np.errstate(divide="ignore", invalid="ignore"):
        log_x = np.where(x > 0.0, (a - 1.0) * np.log(x), 0.0 if a == 1.0 else -np.inf)
        log_1mx = np.where(x < 1.0, (b - 1.0) * np.log1p(-x), 0.0 if b == 1.0 else -np.inf)
    return np.exp(log_x + log_1mx - norm)


@lru_cache(maxsize=16)
def _beta_cdf_table(a: float, b: float) -> tuple[np.ndarray, np.ndarray]:
    """(x, CDF(x)) of Beta(a, b) on ``_CDF_POINTS`` intervals (trapezoids, normalized to 1)."""
    x = np.linspace(0.0, 1.0, _CDF_POINTS + 1)
    pdf = _beta_pdf(a, b, x)
    cdf = np.concatenate([[0.0], np.cumsum(0.5 * (pdf[1:] + pdf[:-1]))])
    return x, cdf / cdf[-1]


@dataclass(frozen=True)
class ScoreModel:
    """A continuous detector: a wedge's value is Beta(``on``) when it sees the object, else
    Beta(``off``); each a (a, b) shape pair with a, b >= 1."""

    on: tuple[float, float] = DEFAULT_SCORE_ON
    off: tuple[float, float] = DEFAULT_SCORE_OFF

    def rates(self, threshold: float) -> tuple[float, float]:
        """(P_fp, P_fn) of the detector that fires at value >= ``threshold``."""
        x, off = _beta_cdf_table(*self.off)
        _, on = _beta_cdf_table(*self.on)
        return 1.0 - float(np.interp(threshold, x, off)), float(np.interp(threshold, x, on))

    def calibration(self, bins: int = SCORE_BINS) -> tuple[tuple[float, ...], tuple[float, ...]]:
        """(edges, llr): ``bins`` equal bins of value over [0, 1] (``bins + 1`` edges) and each
        bin's log(P_on(bin) / P_off(bin)), the exact LLR of a value known to its bin."""
        return _calibration(self, bins)


@lru_cache(maxsize=16)
def _calibration(model: ScoreModel, bins: int) -> tuple[tuple[float, ...], tuple[float, ...]]:
    edges = np.linspace(0.0, 1.0, bins + 1)
    nodes, node_weights = np.polynomial.legendre.leggauss(_BIN_POINTS)
    at = edges[:-1, None] + (nodes + 1.0) / (2.0 * bins)  # Gauss-Legendre nodes in each bin
    on = np.maximum(_beta_pdf(*model.on, at) @ node_weights / (2.0 * bins), _MASS_FLOOR)
    off = np.maximum(_beta_pdf(*model.off, at) @ node_weights / (2.0 * bins), _MASS_FLOOR)
    return tuple(edges.tolist()), tuple(np.log(on / off).tolist())


@dataclass(frozen=True)
class SweepConfig:
    """One Monte Carlo sweep: settings, view counts, the abstract world and the rules.

    ``occluders`` is the fraction of cells that block (0: the paper's open world); ``scores``
    is "binary" (the paper's firing wedges, settings ``pfp`` x ``pfn``) or "beta" (continuous
    values from ``score_on`` / ``score_off``, settings ``thresholds``; ``pfp`` and ``pfn`` are
    then unused: the rates follow from each threshold).
    """

    pfp: tuple[float, ...] = DEFAULT_RATES
    pfn: tuple[float, ...] = DEFAULT_RATES
    views: tuple[int, ...] = (10, 25, 75, 150)
    trials: int = 100
    wedges: int = 8
    fov: float = math.radians(45.0)
    grid: int = 20
    supersample: int = 10
    fusion: tuple[str, ...] = DEFAULT_FUSION
    seed: int = 0
    min_observed: float = 1.0
    occluders: float = 0.0
    scores: str = "binary"
    score_on: tuple[float, float] = DEFAULT_SCORE_ON
    score_off: tuple[float, float] = DEFAULT_SCORE_OFF
    thresholds: tuple[float, ...] = DEFAULT_THRESHOLDS

    def __post_init__(self) -> None:
        for name in ("pfp", "pfn"):
            rates = getattr(self, name)
            if not rates or any(not (0.0 <= r <= 1.0) or math.isnan(r) for r in rates):
                raise InputError(f"--{name} must be rates in [0, 1], got {rates!r}")
        if not self.views or any(v < 1 for v in self.views):
            raise InputError(f"--views must be positive view counts, got {self.views!r}")
        _require(self.trials >= 1, f"--trials must be at least 1, got {self.trials}")
        _require(self.wedges >= 1, f"--wedges must be at least 1, got {self.wedges}")
        _require(
            0.0 < self.fov <= 2.0 * math.pi,
            f"--fov-deg must be in (0, 360], got {math.degrees(self.fov):g}",
        )
        _require(self.grid >= 3, f"--grid must be at least 3 cells per side, got {self.grid}")
        _require(self.supersample >= 1, f"--supersample must be >= 1, got {self.supersample}")
        _require(self.seed >= 0, f"--seed must be a non-negative integer, got {self.seed}")
        unknown = [f for f in self.fusion if f not in RULES]
        pending = " (calibrated is not in twin.core.fusion yet)" if "calibrated" in unknown else ""
        _require(
            bool(self.fusion) and not unknown,
            f"--fusion: unknown rule(s) {unknown or self.fusion!r}; choose from "
            f"{', '.join(RULES)}{pending}",
        )
        _require(
            len(set(self.fusion)) == len(self.fusion),
            f"--fusion names a rule twice: {', '.join(self.fusion)}",
        )
        _require(
            math.isfinite(self.min_observed) and self.min_observed >= 0.0,
            f"--min-observed must be a number >= 0 of full-cell views, got {self.min_observed!r}",
        )
        _require(
            0.0 <= self.occluders <= MAX_OCCLUDERS,
            f"--occluders must be a fraction of the cells in [0, {MAX_OCCLUDERS}], "
            f"got {self.occluders!r}",
        )
        _require(
            self.scores in SCORES,
            f"--scores must be one of {', '.join(SCORES)}, got {self.scores!r}",
        )
        for name in ("score_on", "score_off"):
            shape = getattr(self, name)
            flag = "--" + name.replace("_", "-")
            _require(
                len(shape) == 2 and all(math.isfinite(p) and p >= 1.0 for p in shape),
                f"{flag} must be Beta shape parameters A,B >= 1 (a bounded density), got {shape!r}",
            )
        _require(
            bool(self.thresholds)
            and all(0.0 < t < 1.0 for t in self.thresholds)
            and len(set(self.thresholds)) == len(self.thresholds),
            f"--threshold must be distinct values in (0, 1), got {self.thresholds!r}",
        )
        for pfp, pfn in self.settings():
            sweep_rules(self, pfp, pfn)  # a rule this sweep cannot parametrize fails here

    @property
    def checkpoints(self) -> tuple[int, ...]:
        return tuple(sorted(set(self.views)))

    @property
    def scored(self) -> bool:
        """Whether wedges carry continuous scores rather than the paper's 0/1."""
        return self.scores == "beta"

    @property
    def score_model(self) -> ScoreModel:
        return ScoreModel(self.score_on, self.score_off)

    @property
    def visibilities(self) -> tuple[str, ...]:
        """How each rule is evaluated: blind only, unless occluders can hide anything."""
        return VISIBILITIES if self.occluders > 0.0 else VISIBILITIES[:1]

    @property
    def evaluations(self) -> tuple[tuple[str, str], ...]:
        """(rule, visibility) pairs in the order of a result's rows of successes."""
        return tuple((rule, v) for rule in self.fusion for v in self.visibilities)

    @property
    def occluder_count(self) -> int:
        """Blocking cells per trial (at most all but the object's and one cell for the robot)."""
        return min(round(self.occluders * self.grid**2), self.grid**2 - 2)

    @property
    def result_columns(self) -> tuple[str, ...]:
        """``results.csv``'s columns: the paper's, plus visibility with occluders and the
        threshold with scores (so a paper's sweep writes exactly the paper's columns)."""
        extra = ("visibility",) if self.occluders > 0.0 else ()
        threshold = ("threshold",) if self.scored else ()
        return RESULT_COLUMNS[:1] + extra + threshold + RESULT_COLUMNS[1:]

    def settings(self) -> list[tuple[float, float]]:
        """(P_fp, P_fn) settings: the grid of rates, or with scores each threshold's rates."""
        if self.scored:
            return [self.score_model.rates(t) for t in self.thresholds]
        return [(pfp, pfn) for pfp in self.pfp for pfn in self.pfn]

    def threshold_of(self, setting: tuple[float, float]) -> float | None:
        """The threshold whose rates ``setting`` is (None without scores)."""
        if not self.scored:
            return None
        return dict(zip(self.settings(), self.thresholds, strict=True))[setting]

    def result(self, setting: tuple[float, float], successes: np.ndarray) -> SettingResult:
        """A setting's result from its summed successes (len(evaluations), len(checkpoints))."""
        return SettingResult(
            *setting, self.trials, self.checkpoints, self.fusion, successes,
            visibility=self.visibilities, threshold=self.threshold_of(setting),
        )  # fmt: skip


@dataclass(frozen=True)
class SettingResult:
    """Successes of every rule at every checkpoint, for one (P_fp, P_fn) setting.

    ``successes`` is (len(fusion) x len(visibility), len(checkpoints)): rule by rule, each
    rule's visibilities in turn (see ``SweepConfig.evaluations``).
    """

    pfp: float
    pfn: float
    trials: int
    checkpoints: tuple[int, ...]
    fusion: tuple[str, ...]
    successes: np.ndarray = field(repr=False)
    visibility: tuple[str, ...] = VISIBILITIES[:1]
    threshold: float | None = None

    def rows(self) -> list[dict[str, object]]:
        out = []
        pairs = [(rule, v) for rule in self.fusion for v in self.visibility]
        for r, (rule, visibility) in enumerate(pairs):
            for c, views in enumerate(self.checkpoints):
                hits = int(self.successes[r, c])
                row: dict[str, object] = {
                    "fusion": rule,
                    "visibility": visibility,
                    "pfp": self.pfp,
                    "pfn": self.pfn,
                    "views": views,
                    "trials": self.trials,
                    "successes": hits,
                    "success_rate": hits / self.trials,
                }
                if self.threshold is not None:
                    row["threshold"] = self.threshold
                out.append(row)
        return out


def _require(condition: bool, message: str) -> None:
    if not condition:
        raise InputError(message)


def _rule_for(name: str, offered: dict[str, object]) -> FusionRule:
    """Rule ``name`` with the parameters its constructor names among ``offered``; the others
    keep their defaults, and one without a default that the sweep cannot supply is an error."""
    accepted = inspect.signature(RULES[name]).parameters
    missing = [
        p.name
        for p in accepted.values()
        if p.default is p.empty
        and p.kind in (p.POSITIONAL_OR_KEYWORD, p.KEYWORD_ONLY)
        and p.name not in offered
    ]
    _require(
        not missing,
        f"--fusion {name}: the Monte Carlo cannot supply its parameter(s) {', '.join(missing)} "
        f"(it supplies {', '.join(offered)}); give them defaults or leave the rule out",
    )
    return make_rule(name, **{k: v for k, v in offered.items() if k in accepted})


def sweep_rules(config: SweepConfig, pfp: float, pfn: float) -> tuple[FusionRule, ...]:
    """The rules of ``config.fusion`` for one setting: each gets, if it takes them, the
    detector's true rates (``p_fp``, ``p_fn``), ``min_observed`` (full-cell views) and its exact
    log-likelihood ratios by bins of value (``edges``, ``llr``: the binary detector's two, or
    the score model's); with scores also the setting's ``threshold``."""
    offered: dict[str, object] = {"p_fp": pfp, "p_fn": pfn, "min_observed": config.min_observed}
    if config.scored:
        edges, llr = config.score_model.calibration()
        offered.update(threshold=config.threshold_of((pfp, pfn)), edges=edges, llr=llr)
    else:
        # The binary detector's exact LLR: a silent (0) and a fired (1) bin, logodds' weights.
        fired, silent = logodds_weights(pfp, pfn)
        offered.update(edges=(0.0, 0.5, 1.0), llr=(silent, fired))
    return tuple(_rule_for(name, offered) for name in config.fusion)


def evidence_layers(
    rules: Sequence[FusionRule], values: np.ndarray = BINARY_VALUES
) -> tuple[np.ndarray, tuple[int, ...]]:
    """The distinct weights of ``rules`` for the wedge ``values`` (any shape) as a
    (layers, *values.shape) array, and the layer of each rule: rules that weight every one of
    these values alike share one evidence sum (for the binary detector, [0, 1] decides)."""
    distinct: list[np.ndarray] = []
    layer_of = []
    for rule in rules:
        weights = np.asarray(rule.column_weights(values), dtype=float)
        if weights.shape != values.shape:
            raise TwinError(
                f"fusion rule {rule.name!r}: column_weights gave shape {weights.shape} for "
                f"{values.size} values; it must give one weight per column"
            )
        same = [k for k, seen in enumerate(distinct) if np.array_equal(seen, weights)]
        if not same:
            distinct.append(weights)
        layer_of.append(same[0] if same else len(distinct) - 1)
    return np.array(distinct, dtype=float).reshape(-1, *values.shape), tuple(layer_of)


def trial_rng(seed: int, pfp: float, pfn: float, trial: int) -> np.random.Generator:
    """The generator of one trial: a function of (seed, setting, trial) only."""
    key = (round(pfp * _RATE_KEY_SCALE), round(pfn * _RATE_KEY_SCALE), trial)
    return np.random.default_rng(np.random.SeedSequence(seed, spawn_key=key))


def sweep_trial_rng(config: SweepConfig, pfp: float, pfn: float, trial: int) -> np.random.Generator:
    """A trial's generator in ``config``'s sweep: ``trial_rng``, or with scores one keyed by the
    trial alone (the threshold changes no draw)."""
    if config.scored:
        return np.random.default_rng(
            np.random.SeedSequence(config.seed, spawn_key=(SCORES_KEY, trial))
        )
    return trial_rng(config.seed, pfp, pfn, trial)


_NO_SCORES = np.zeros((0, 0))


@dataclass(frozen=True)
class TrialDraws:
    """Everything random in one trial, drawn in a fixed order from its generator."""

    object_row: int
    object_col: int
    x: np.ndarray  # (V,) robot positions, cell units
    y: np.ndarray
    yaw: np.ndarray  # (V,) radians
    fire: np.ndarray  # (V, wedges) uniforms deciding each wedge's firing
    tie: np.ndarray  # (checkpoints,) uniforms breaking ties
    occluded: np.ndarray  # (n, n) bools, [row, col]: the blocking cells
    on: np.ndarray = field(default_factory=lambda: _NO_SCORES)  # (V, wedges) scores on / off
    off: np.ndarray = field(default_factory=lambda: _NO_SCORES)  # the object; (0, 0): binary


def draw_trial(config: SweepConfig, rng: np.random.Generator) -> TrialDraws:
    n = config.grid
    n_views = config.checkpoints[-1]
    object_row, object_col = (int(v) for v in rng.integers(1, n - 1, size=2))
    object_cell = object_row * n + object_col
    occluded = np.zeros((n, n), dtype=np.bool_)
    if config.occluder_count:  # no draw without occluders: the paper's stream stays as it was
        blocks = rng.choice(n * n - 1, size=config.occluder_count, replace=False)
        occluded.flat[blocks + (blocks >= object_cell)] = True
    # Uniform over the area outside the object's cell and the occluders: a uniform free cell,
    # then a point in it (without occluders, the k-th cell skipping the object's, as before).
    blocked = occluded.ravel().copy()
    blocked[object_cell] = True
    free = np.flatnonzero(~blocked)
    cell = free[rng.integers(0, free.size, size=n_views)]
    offset = rng.random((n_views, 2))
    draws = TrialDraws(
        object_row,
        object_col,
        x=cell % n + offset[:, 0],
        y=cell // n + offset[:, 1],
        yaw=rng.uniform(-math.pi, math.pi, size=n_views),
        fire=rng.random((n_views, config.wedges)),
        tie=rng.random(len(config.checkpoints)),
        occluded=occluded,
    )
    if not config.scored:
        return draws
    shape = (n_views, config.wedges)
    on = rng.beta(*config.score_on, size=shape)
    off = rng.beta(*config.score_off, size=shape)
    return TrialDraws(**{**draws.__dict__, "on": on, "off": off})


@njit(cache=True)
def _cell_span(px, py, col, row):
    """The unit cell (col, row) as seen from (px, py): the bearing of its centre and the least
    and greatest offsets of its corners' bearings from it (radians; the same for every wedge
    of a view, so computed once per view)."""
    centre = math.atan2(row + 0.5 - py, col + 0.5 - px)
    lo = math.inf
    hi = -math.inf
    for cx in (col + 0.0, col + 1.0):
        for cy in (row + 0.0, row + 1.0):
            d = (math.atan2(cy - py, cx - px) - centre + math.pi) % (2.0 * math.pi) - math.pi
            lo = min(lo, d)
            hi = max(hi, d)
    return centre, lo, hi


@njit(cache=True)
def _span_meets_wedge(centre, lo, hi, a0, a1) -> bool:
    """Whether the wedge [a0, a1] overlaps the span ``_cell_span`` gives (modulo 2 pi)."""
    start = (a0 - centre + math.pi) % (2.0 * math.pi) - math.pi
    width = a1 - a0
    for shift in (-2.0 * math.pi, 0.0, 2.0 * math.pi):
        if start + shift < hi and start + shift + width > lo:
            return True
    return False


@njit(cache=True)
def _wedge_meets_cell(px, py, a0, a1, col, row) -> bool:
    """Whether the wedge [a0, a1] from (px, py) meets the unit cell (col, row), exactly.

    The robot is outside the cell, so the cell's corners span less than pi as seen from it;
    the wedge meets the cell iff that span overlaps the wedge's span (modulo 2 pi).
    """
    centre, lo, hi = _cell_span(px, py, col, row)
    return _span_meets_wedge(centre, lo, hi, a0, a1)


@njit(cache=True)
def in_view(occluded, px, py, col, row) -> bool:
    """Whether the centre of cell (col, row) is in view from (px, py): the segment between
    them crosses no occluder cell but, perhaps, the target's own (grid traversal, cell units).

    The robot's own cell is never an occluder. A segment through a cell corner exactly (which
    random poses never give) steps along y first.
    """
    n_rows, n_cols = occluded.shape
    dx = col + 0.5 - px
    dy = row + 0.5 - py
    cx = int(px)  # robot positions are >= 0: truncation is the floor
    cy = int(py)
    step_x = 1 if dx > 0.0 else -1
    step_y = 1 if dy > 0.0 else -1
    # Segment parameter (0 at the robot, 1 at the centre) of the next x and y cell edges.
    t_x = ((cx + (step_x > 0)) - px) / dx if dx != 0.0 else math.inf
    t_y = ((cy + (step_y > 0)) - py) / dy if dy != 0.0 else math.inf
    dt_x = abs(1.0 / dx) if dx != 0.0 else math.inf
    dt_y = abs(1.0 / dy) if dy != 0.0 else math.inf
    for _ in range(n_rows + n_cols + 2):  # a segment crosses at most this many cells
        if cx == col and cy == row:
            return True
        if not (0 <= cx < n_cols and 0 <= cy < n_rows):
            return True  # rounding stepped past the target: nothing blocked before it
        if occluded[cy, cx]:
            return False
        if t_x < t_y:
            cx += step_x
            t_x += dt_x
        else:
            cy += step_y
            t_y += dt_y
    return True


@njit(cache=True)
def _wedge_values(
    fov, n_wedges, object_row, object_col, xs, ys, yaws, fire_u, pfp, pfn, occluded,
    any_occluders, on, off, scored, out,
):  # fmt: skip
    """out[v, w] = wedge w's value in view v: 1 or 0 as it fires (binary: with 1 - P_fn if it
    sees the object, else P_fp), or its score on or off the object. A wedge sees the object
    when it meets the object's cell and the cell's centre is in view."""
    wedge = fov / n_wedges
    for v in range(xs.shape[0]):
        centre, lo, hi = _cell_span(xs[v], ys[v], object_col, object_row)
        visible = True
        if any_occluders:
            visible = in_view(occluded, xs[v], ys[v], object_col, object_row)
        for w in range(n_wedges):
            a1 = yaws[v] + 0.5 * fov - w * wedge
            a0 = a1 - wedge
            hit = visible and _span_meets_wedge(centre, lo, hi, a0, a1)
            if scored:
                out[v, w] = on[v, w] if hit else off[v, w]
            else:
                out[v, w] = 1.0 if fire_u[v, w] < ((1.0 - pfn) if hit else pfp) else 0.0


@njit(cache=True, inline="always")
def _index_after(x, step, count):
    """``_first_index_after(x, 0, step, count)`` without branches (so a loop of them runs as
    vector instructions): the same float operations, the clipping done by min and max."""
    t = min(max(x / step - 0.5, -1.0), count + 0.0)
    return min(math.floor(t) + 1, count)


@njit(cache=True, inline="always")
def _index_at_or_after(x, step, count):
    """``_first_index_at_or_after(x, 0, step, count)`` without branches."""
    return math.ceil(min(max(x / step - 0.5, 0.0), count + 0.0))


@njit(cache=True)
def _fuse_view(state, px, py, a0, a1, weights, s, seeing, occluded, known, dys, lo, hi):
    """Add one view's wedges to ``state``: layer q of cell (row, col) gains weights[q, w] x
    (wedge w's coverage of the cell), for q < k = weights.shape[0]; with ``seeing`` layers
    k + q gain the same where the cell's centre is in view (``known`` caches ``in_view`` per
    cell for this view: -1 not yet asked).

    Exactly ``add_coverage``'s arithmetic (x0 = y0 = 0, unit cells, unlimited range): every
    sample row's run adds weight x (its points in the cell / s^2), rows in order, wedges in
    order, so the sums are the same floats to the last bit. What differs is only the order of
    the work: each wedge piece's run ends for all sample rows first (a division per end, in
    loops without branches that compile to vector instructions), then the adds.
    ``lo`` / ``hi`` are (wedges, 4, n s) scratch and ``dys`` (n s) scratch.
    """
    n_cols = state.shape[2] * s
    n_samples = state.shape[1] * s
    step = 1.0 / s
    pieces = wedge_pieces(a0, a1)
    split = n_samples  # the first sample row at or above the origin
    for j in range(n_samples):
        dys[j] = 0.0 + (j + 0.5) * step - py
    for j in range(n_samples):
        if dys[j] >= 0.0:
            split = j
            break
    for w in range(a0.shape[0]):
        for slot in range(4):
            cot_start = pieces[w, slot, 0]
            if math.isnan(cot_start):
                continue
            cot_end = pieces[w, slot, 1]
            if slot < 2:  # above the origin the bearing falls with x: x in (x(b1), x(b0)]
                for j in range(split, n_samples):
                    lo[w, slot, j] = _index_after(px + dys[j] * cot_end, step, n_cols)
                    hi[w, slot, j] = _index_after(px + dys[j] * cot_start, step, n_cols)
            else:  # below it rises: x in [x(b0), x(b1))
                for j in range(split):
                    lo[w, slot, j] = _index_at_or_after(px + dys[j] * cot_start, step, n_cols)
                    hi[w, slot, j] = _index_at_or_after(px + dys[j] * cot_end, step, n_cols)
    _add_runs(state, px, a0, a1, weights, s, pieces, dys, lo, hi, -1, occluded, known, py)
    if seeing:  # a second pass, so the blind one compiles without the visibility test
        _add_runs(state, px, a0, a1, weights, s, pieces, dys, lo, hi, 1, occluded, known, py)


@njit(cache=True, inline="always")
def _add_runs(state, px, a0, a1, weights, s, pieces, dys, lo, hi, seeing, occluded, known, py):
    """The adds of ``_fuse_view``: into layers 0..k-1 (``seeing`` < 0) or, for cells in view,
    k..2k-1 (``seeing`` > 0; an int, so numba compiles each pass's branch away)."""
    k = weights.shape[0]
    n_cols = state.shape[2] * s
    step = 1.0 / s
    scale = 1.0 / (s * s)
    # The wedge pieces above (0) and below (1) the origin, in add_coverage's order.
    active = np.empty((2, 2 * a0.shape[0], 2), dtype=np.int64)
    n_active = np.zeros(2, dtype=np.int64)
    for w in range(a0.shape[0]):
        for slot in range(4):
            if not math.isnan(pieces[w, slot, 0]):
                half = slot // 2
                active[half, n_active[half], 0] = w
                active[half, n_active[half], 1] = slot
                n_active[half] += 1
    for j in range(dys.shape[0]):
        dy = dys[j]
        row = j // s
        if dy == 0.0:
            # The row through the origin: bearing 0 to the right, pi to the left.
            right = _first_index_after(px, 0.0, step, n_cols)
            left = _first_index_at_or_after(px, 0.0, step, n_cols)
            for w in range(a0.shape[0]):
                if _contains_angle(a0[w], a1[w], 0.0):
                    _add_run(state, row, right, n_cols, s, scale, weights, w, k, seeing,
                             occluded, known, px, py)  # fmt: skip
                if _contains_angle(a0[w], a1[w], math.pi):
                    _add_run(state, row, 0, left, s, scale, weights, w, k, seeing, occluded,
                             known, px, py)  # fmt: skip
            continue
        half = 0 if dy > 0.0 else 1
        for p in range(n_active[half]):
            w = active[half, p, 0]
            slot = active[half, p, 1]
            _add_run(state, row, lo[w, slot, j], hi[w, slot, j], s, scale, weights, w, k,
                     seeing, occluded, known, px, py)  # fmt: skip


@njit(cache=True, inline="always")
def _add_run(state, row, i_lo, i_hi, s, scale, weights, w, k, seeing, occluded, known, px, py):
    """Add wedge w's sample points [i_lo, i_hi) of one sample row to the cells of ``row``,
    cell by cell (``add_coverage``'s head, full cells and tail, the same products)."""
    if i_hi <= i_lo:
        return
    for col in range(i_lo // s, (i_hi - 1) // s + 1):
        if seeing > 0:
            if known[row, col] < 0:
                known[row, col] = in_view(occluded, px, py, col, row)
            if not known[row, col]:
                continue
        cover = (min(i_hi, s * (col + 1)) - max(i_lo, s * col)) * scale
        base = k if seeing > 0 else 0
        for q in range(k):
            state[base + q, row, col] += weights[q, w] * cover


@njit(cache=True)
def _argmax_hits(values, tie_u, object_row, object_col) -> bool:
    """Whether the maximal cell (random among near-ties) is the object's cell or a neighbour."""
    top = values.max()
    tolerance = _TIE_RTOL * max(1.0, abs(top))
    n_tied = 0
    for v in values.flat:
        if v >= top - tolerance:
            n_tied += 1
    pick = min(int(tie_u * n_tied), n_tied - 1)
    ny, nx = values.shape
    seen = 0
    for r in range(ny):
        for c in range(nx):
            if values[r, c] >= top - tolerance:
                if seen == pick:
                    return abs(r - object_row) <= 1 and abs(c - object_col) <= 1
                seen += 1
    return False


@njit(cache=True)
def _score(confidence, tie_u, object_rows, object_cols, out) -> None:
    """out[t, c] = whether trial t's confidence map at checkpoint c hits its object."""
    for t in range(confidence.shape[0]):
        for c in range(confidence.shape[1]):
            out[t, c] = _argmax_hits(confidence[t, c], tie_u[t, c], object_rows[t], object_cols[t])


@njit(cache=True)
def _run_trial(n, supersample, fov, xs, ys, yaws, weights, occluded, seeing, checkpoints, out):
    """Fuse one trial's views; out[k, c] gets layer k at checkpoint c.

    ``weights`` (L, V, W) is each evidence layer's weight of wedge w in view v. Layers are the
    L evidence sums then the observed sum (weight 1), all (n, n) over cells; with ``seeing``
    the same L + 1 again, updated only where a cell's centre is in view (``in_view``).
    """
    n_evidence, _, n_wedges = weights.shape
    per_set = n_evidence + 1
    state = np.zeros((2 * per_set if seeing else per_set, n, n))
    view_weights = np.ones((per_set, n_wedges))  # the last row: observed
    known = np.empty((n, n), dtype=np.int8)
    dys = np.empty(n * supersample)
    lo = np.empty((n_wedges, 4, n * supersample), dtype=np.int64)
    hi = np.empty((n_wedges, 4, n * supersample), dtype=np.int64)
    a0 = np.empty(n_wedges)
    a1 = np.empty(n_wedges)
    wedge = fov / n_wedges
    c = 0
    for v in range(xs.shape[0]):
        for w in range(n_wedges):
            a1[w] = yaws[v] + 0.5 * fov - w * wedge
            a0[w] = a1[w] - wedge
            for q in range(n_evidence):
                view_weights[q, w] = weights[q, v, w]
        if seeing:
            known[:] = -1
        _fuse_view(state, xs[v], ys[v], a0, a1, view_weights, supersample, seeing, occluded,
                   known, dys, lo, hi)  # fmt: skip
        if v + 1 == checkpoints[c]:
            out[:, c] = state
            c += 1
            if c == checkpoints.shape[0]:
                break


def _batch_size(config: SweepConfig, n_layers: int) -> int:
    """Trials whose checkpoint copies and confidence maps fit in ``_BATCH_BYTES``."""
    per_trial = (n_layers + 2) * len(config.checkpoints) * config.grid**2 * 8
    return max(1, _BATCH_BYTES // per_trial)


def _run_batch(
    config: SweepConfig,
    pfp: float,
    pfn: float,
    trials: range,
    rules: Sequence[FusionRule],
) -> np.ndarray:
    """Successes (len(evaluations), len(trials), len(checkpoints)) of some trials, as bools."""
    n, checkpoints = config.grid, np.asarray(config.checkpoints, dtype=np.int64)
    n_views = checkpoints[-1]
    draws = [draw_trial(config, sweep_trial_rng(config, pfp, pfn, t)) for t in trials]
    values = np.empty((len(trials), n_views, config.wedges))
    for t, d in enumerate(draws):
        _wedge_values(
            config.fov, config.wedges, d.object_row, d.object_col, d.x, d.y, d.yaw, d.fire,
            pfp, pfn, d.occluded, config.occluder_count > 0, d.on, d.off, config.scored,
            values[t],
        )  # fmt: skip
    # Layers by the weights of this batch's values: continuous scores share a layer only
    # between rules that weigh every drawn value alike.
    weights, layer_of = evidence_layers(rules, values)
    weights = np.ascontiguousarray(np.moveaxis(weights, 0, 1))  # (trials, layers, V, W)
    seeing = config.occluder_count > 0
    per_set = weights.shape[1] + 1  # the evidence layers, then observed
    n_vis = len(config.visibilities)
    # Layer first, so each rule reads contiguous (trials, checkpoints, n, n) blocks.
    layers = np.zeros((n_vis * per_set, len(trials), len(checkpoints), n, n))
    for t, d in enumerate(draws):
        _run_trial(
            n, config.supersample, config.fov, d.x, d.y, d.yaw, weights[t], d.occluded, seeing,
            checkpoints, layers[:, t],
        )  # fmt: skip
    layers.flags.writeable = False  # shared by the rules' reads: none may change it
    ties = np.array([d.tie for d in draws])
    object_rows = np.array([d.object_row for d in draws], dtype=np.int64)
    object_cols = np.array([d.object_col for d in draws], dtype=np.int64)
    hits = np.empty((len(rules) * n_vis, len(trials), len(checkpoints)), dtype=np.bool_)
    for r, rule in enumerate(rules):
        for k in range(n_vis):  # blind, then (with occluders) the cells in view only
            observed = layers[k * per_set + per_set - 1]
            evidence = layers[k * per_set + layer_of[r]]
            confidence = np.asarray(rule.read(evidence, observed), dtype=float)
            if confidence.shape != observed.shape:
                raise TwinError(
                    f"fusion rule {rule.name!r}: read gave shape {confidence.shape} for layers "
                    f"of shape {observed.shape}; it must be element-wise"
                )
            _score(np.ascontiguousarray(confidence), ties, object_rows, object_cols,
                   hits[r * n_vis + k])  # fmt: skip
    return hits


def run_trial(config: SweepConfig, pfp: float, pfn: float, trial: int) -> np.ndarray:
    """Successes (len(config.evaluations), len(checkpoints)) of one trial, as booleans."""
    rules = sweep_rules(config, pfp, pfn)
    return _run_batch(config, pfp, pfn, range(trial, trial + 1), rules)[:, 0]


def run_trials(config: SweepConfig, pfp: float, pfn: float, start: int, stop: int) -> np.ndarray:
    """Summed successes (len(config.evaluations), len(checkpoints)) of trials start..stop-1."""
    rules = sweep_rules(config, pfp, pfn)
    successes = np.zeros((len(config.evaluations), len(config.checkpoints)), dtype=np.int64)
    size = _batch_size(config, len(config.visibilities) * (len(rules) + 1))
    for first in range(start, stop, size):
        trials = range(first, min(first + size, stop))
        successes += _run_batch(config, pfp, pfn, trials, rules).sum(axis=1)
    return successes


def run_setting(config: SweepConfig, setting: tuple[float, float]) -> SettingResult:
    """All trials of one (P_fp, P_fn) setting."""
    return config.result(setting, run_trials(config, *setting, 0, config.trials))


@dataclass(frozen=True)
class Chunk:
    """A task: trials ``start`` .. ``stop - 1`` of one setting (half-open range)."""

    pfp: float
    pfn: float
    start: int
    stop: int

    @property
    def setting(self) -> tuple[float, float]:
        return (self.pfp, self.pfn)


@dataclass(frozen=True)
class ChunkResult:
    """Summed successes of one chunk's trials; chunks of a setting add up to its result."""

    chunk: Chunk
    successes: np.ndarray = field(repr=False)  # (len(evaluations), len(checkpoints)) ints


def run_chunk(config: SweepConfig, chunk: Chunk) -> ChunkResult:
    """One task of a sweep (a module-level function, so local and Ray workers can import it)."""
    return ChunkResult(chunk, run_trials(config, chunk.pfp, chunk.pfn, chunk.start, chunk.stop))


def missing_ranges(trials: int, done: Iterable[tuple[int, int]]) -> list[tuple[int, int]]:
    """The half-open trial ranges of 0..trials-1 that no range in ``done`` covers."""
    covered = np.zeros(trials, dtype=bool)
    for start, stop in done:
        covered[start:stop] = True
    gaps: list[tuple[int, int]] = []
    trial = 0
    while trial < trials:
        if covered[trial]:
            trial += 1
            continue
        end = trial
        while end < trials and not covered[end]:
            end += 1
        gaps.append((trial, end))
        trial = end
    return gaps


def plan_chunks(
    config: SweepConfig,
    chunk_trials: int,
    done: dict[tuple[float, float], list[tuple[int, int]]] | None = None,
) -> list[Chunk]:
    """The tasks still to run: each setting's missing trials cut into chunks of at most
    ``chunk_trials``, setting by setting (so settings finish, and are journaled whole, early)."""
    _require(chunk_trials >= 1, f"--chunk must be at least 1 trial, got {chunk_trials}")
    chunks = []
    for pfp, pfn in config.settings():
        ranges = (done or {}).get((pfp, pfn), [])
        for start, stop in missing_ranges(config.trials, ranges):
            for first in range(start, stop, chunk_trials):
                chunks.append(Chunk(pfp, pfn, first, min(first + chunk_trials, stop)))
    return chunks


def result_rows(config: SweepConfig, results: Sequence[SettingResult]) -> list[dict[str, object]]:
    """Rows of ``results.csv`` in a stable order: rule, visibility, P_fp, P_fn, views."""
    rows = [row for result in results for row in result.rows()]
    order = {rule: i for i, rule in enumerate(config.fusion)}
    seen = {v: i for i, v in enumerate(VISIBILITIES)}
    return sorted(
        rows,
        key=lambda r: (order[r["fusion"]], seen[r["visibility"]], r["pfp"], r["pfn"], r["views"]),
    )


# -- running a sweep, resumably ----------------------------------------------------------------

JOURNAL_NAME = "settings.jsonl"


def _identity(config: SweepConfig) -> dict[str, object]:
    """The parameters that decide a setting's result, and the rules its rows of successes are."""
    identity: dict[str, object] = {
        "fusion": list(config.fusion),
        "trials": config.trials,
        "wedges": config.wedges,
        "fov": config.fov,
        "grid": config.grid,
        "supersample": config.supersample,
        "seed": config.seed,
        "min_observed": config.min_observed,
        "checkpoints": list(config.checkpoints),
    }
    # Only what departs from the paper's world, so a paper's sweep keeps its journal's identity.
    if config.occluders > 0.0:
        identity["occluders"] = config.occluders
    if config.scored:
        identity.update(
            scores=config.scores, score_on=list(config.score_on),
            score_off=list(config.score_off), thresholds=list(config.thresholds),
        )  # fmt: skip
    return identity


def _refuse_journal_without_rules(path: Path) -> None:
    """A journal written before sweeps ran only the named rules has no ``fusion`` in its
    identity; its rows cannot be matched to rules, so it is refused with the remedy."""
    try:
        with path.open(encoding="utf-8") as handle:
            recorded = json.loads(handle.readline())["sweep"]
    except (OSError, KeyError, TypeError, json.JSONDecodeError):
        return  # absent or not a sweep journal: JsonLinesJournal says so
    if isinstance(recorded, dict) and "fusion" not in recorded:
        raise InputError(
            f"{path.parent} holds a sweep journal from an older twin that did not record its "
            "rules; pass --fresh to run the sweep again, or choose another --out"
        )


DEFAULT_CHUNK_TRIALS = 250  # about 0.6 s of work per task at the default world: overhead < 1 %


class SweepJournal:
    """An append-only record of finished chunks of trials, so an interrupted sweep resumes.

    The first line holds the sweep's identity; each further line one finished chunk:
    ``{"pfp", "pfn", "trials": [start, stop], "successes": [[...], ...]}`` (a line without
    ``"trials"``, as older sweeps wrote, is the whole setting). A line torn by a crash is
    ignored (those trials simply run again). A resumed sweep runs exactly the trials no line
    covers, whatever chunk size either run used; sums of per-trial successes do not depend on
    how the trials were grouped, so the results equal an uninterrupted run's.
    """

    def __init__(self, path: Path | None, config: SweepConfig, fresh: bool = False) -> None:
        self.path = path  # None: kept in memory only
        self.config = config
        self.done: dict[tuple[float, float], SettingResult] = {}
        self.partial: dict[tuple[float, float], list[ChunkResult]] = {}
        self._journal: JsonLinesJournal | None = None
        if path is None:
            return
        if not fresh:
            _refuse_journal_without_rules(path)
        self._journal = JsonLinesJournal(path, "sweep", _identity(config), fresh)
        shape = (len(config.evaluations), len(config.checkpoints))
        for entry in self._journal.entries:
            try:
                start, stop = entry.get("trials", (0, config.trials))
                chunk = Chunk(float(entry["pfp"]), float(entry["pfn"]), int(start), int(stop))
                successes = np.asarray(entry["successes"], dtype=np.int64)
            except (AttributeError, KeyError, TypeError, ValueError):
                continue  # not a chunk: those trials run again
            if successes.shape == shape and 0 <= chunk.start < chunk.stop <= config.trials:
                self._add(ChunkResult(chunk, successes))

    def _add(self, result: ChunkResult) -> SettingResult | None:
        """Keep a chunk; return the setting's result if that chunk completed it.

        A chunk overlapping one already kept (two runs writing into one folder) is dropped,
        so every trial counts once.
        """
        setting, chunk = result.chunk.setting, result.chunk
        if setting in self.done:
            return None
        chunks = self.partial.setdefault(setting, [])
        if any(c.chunk.start < chunk.stop and chunk.start < c.chunk.stop for c in chunks):
            return None
        chunks.append(result)
        if sum(c.chunk.stop - c.chunk.start for c in chunks) < self.config.trials:
            return None
        total = np.sum([c.successes for c in chunks], axis=0, dtype=np.int64)
        del self.partial[setting]
        done = self.config.result(setting, total)
        self.done[setting] = done
        return done

    def ranges(self) -> dict[tuple[float, float], list[tuple[int, int]]]:
        """Trial ranges already run, per setting (whole settings as one range)."""
        out = {s: [(0, self.config.trials)] for s in self.done}
        for setting, chunks in self.partial.items():
            out[setting] = [(c.chunk.start, c.chunk.stop) for c in chunks]
        return out

    def record(self, result: ChunkResult) -> SettingResult | None:
        """Append one finished chunk (flushed to disk); return its setting's result if complete."""
        chunk = result.chunk
        entry = {
            "pfp": chunk.pfp,
            "pfn": chunk.pfn,
            "trials": [chunk.start, chunk.stop],
            "successes": result.successes.tolist(),
        }
        if self._journal is not None:
            self._journal.append(entry)
        return self._add(result)


def run_sweep(
    config: SweepConfig,
    executor: Executor,
    journal: SweepJournal | None = None,
    on_result: Callable[[SettingResult], None] | None = None,
    chunk_trials: int = DEFAULT_CHUNK_TRIALS,
    on_chunk: Callable[[ChunkResult], None] | None = None,
) -> list[SettingResult]:
    """Run every trial not already in ``journal``; return all results in setting order.

    Tasks are chunks of up to ``chunk_trials`` trials of one setting; each is journaled as it
    arrives (then ``on_chunk``), and ``on_result`` is called when a setting's last chunk arrives.
    The results do not depend on ``chunk_trials``, the executor or its number of workers.
    """
    journal = journal or SweepJournal(None, config)
    todo = plan_chunks(config, chunk_trials, journal.ranges())
    for _, result in executor.map_unordered(partial(run_chunk, config), todo):
        complete = journal.record(result)
        if on_chunk:
            on_chunk(result)
        if complete is not None and on_result:
            on_result(complete)
    return [journal.done[s] for s in config.settings()]


def write_results_csv(
    path: Path, rows: Sequence[dict[str, object]], columns: Sequence[str] = RESULT_COLUMNS
) -> Path:
    """``results.csv`` with exactly ``columns`` (``SweepConfig.result_columns``: by default
    the paper's), written atomically."""
    buffer = io.StringIO()
    writer = csv.DictWriter(buffer, fieldnames=columns, lineterminator="\n", extrasaction="ignore")
    writer.writeheader()
    writer.writerows(rows)
    return write_text_atomic(path, buffer.getvalue())
