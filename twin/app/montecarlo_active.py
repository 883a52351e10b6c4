"""Active views in the paper's abstract world: planners against Figure 3's random views.

The world is ``twin.app.montecarlo``'s (Figure 3): an n x n grid of unit cells, one object in a
random cell off the outer edge, a field of view split into equal wedges reaching to the map's
edge; a wedge that meets the object's cell fires with probability 1 - P_fn, any other with P_fp.
There every view is random. Here a **planner** chooses each view in turn, from what the grid
holds after the views before it:

* ``random``: Figure 3's views, drawn and fused by the existing sweep (a uniform point outside
  the object's cell, a uniform heading), so its curve is exactly ``twin montecarlo``'s.
* ``survey``: the paper's kind of plan (Section 2: 5 places, 8 views each): the quarter-points
  of the map and its centre, 8 headings at each, in a fixed order; 40 views.
* ``coverage``: greedy, where the grid has been seen least (``view_gain.unseen_coverage``).
* ``detection``: Ye & Tsotsos, the probability of detecting the object
  (``view_gain.detection_probability``) under the current posterior.
* ``information``: the expected information about the object's cell
  (``view_gain.information_gain``) under the current posterior.

The planned views are **candidates**: the robot stands on a lattice point (a cell corner
strictly inside the map, so never inside the object's cell) and faces one of 8 headings (45
degree steps). Their footprints (``view_gain.Footprints``: each wedge's share of every cell, by
``twin.core.coverage.add_coverage`` at the sweep's supersampling) are computed once per world
size and serve both the planners' scores and the grid's updates. A wedge's lift is
share x (1 - P_fn - P_fp) (0 for a detector no better than chance), its FPR is P_fp.

The posterior of ``detection`` and ``information`` is the detector model's exact belief: each
cell sums the log-likelihood ratio of every wedge that covered it (fired:
log((1 - P_fn) / P_fp), silent: log(P_fn / (1 - P_fp)), ``fusion.logodds_weights``) times the
wedge's share of the cell, read by ``confidence.posterior`` with no "absent" mass.

A greedy planner takes the candidate of the most gain per unit cost, gain / (1 + travel_cost x
the distance from the previous view's place, in cells), among the candidates it has not taken;
its first view is the best on the uniform prior (no travel yet). Ties (scores within 1e-9,
relative) go to the first candidate. The path length is the distance between successive views'
places, in cells.

Every trial is scored after each of its 1..V views, for each rule (by default ``accumulate``,
the paper's, and ``logodds`` with the true rates), exactly as the sweep scores it: success when
the rule's maximal cell (near-ties broken by the trial's tie draw for that view count) is the
object's cell or one of its 8 neighbours.

Randomness: trial t of setting (P_fp, P_fn) takes the sweep's draws for that trial
(``montecarlo.draw_trial`` with the sweep's generator for (seed, setting, t), views 1..V), so
every planner faces the same object cell, the same firing uniforms per view number and wedge,
and the same tie draws; a result depends only on the seed, the setting, V, the world and the
trial index, not on which other planners or settings run or on the workers.
"""

from __future__ import annotations

import csv
import io
import math
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field
from functools import lru_cache, partial
from pathlib import Path

import numpy as np
from numba import njit

from twin.app.executors import Executor
from twin.app.montecarlo import (
    _TIE_RTOL,
    BINARY_VALUES,
    SweepConfig,
    TrialDraws,
    _score,
    _span_meets_wedge,
    draw_trial,
    evidence_layers,
    run_trial,
    run_trials,
    sweep_rules,
    sweep_trial_rng,
)
from twin.core.confidence import posterior
from twin.core.coverage import NO_VISIBILITY, add_coverage
from twin.core.errors import InputError
from twin.core.fusion import logodds_weights
from twin.core.store import write_text_atomic
from twin.core.view_gain import (
    Footprints,
    detection_probability,
    information_gain,
    unseen_coverage,
)

PLANNERS: tuple[str, ...] = ("random", "survey", "coverage", "detection", "information")
GAIN_PLANNERS: tuple[str, ...] = ("coverage", "detection", "information")
DEFAULT_FUSION: tuple[str, ...] = ("accumulate", "logodds")
DEFAULT_SETTINGS: tuple[tuple[float, float], ...] = ((0.1, 0.1),)
DEFAULT_VIEWS = 40
DEFAULT_TRAVEL_COST = 0.1  # per cell travelled: a view 10 cells away must gain twice as much
HEADINGS = 8  # candidate headings, 45 degrees apart
SURVEY_STOPS = 5
SURVEY_VIEWS = SURVEY_STOPS * HEADINGS  # the paper's 40 planned views
DEFAULT_CHUNK_TRIALS = 25  # trials per task: a few seconds of a greedy planner's work
ACTIVE_COLUMNS: tuple[str, ...] = (
    "planner",
    "fusion",
    "pfp",
    "pfn",
    "views",
    "trials",
    "successes",
    "success_rate",
    "path_length",
)
# A wedge meets a cell only when their bearings overlap by more than this (radians): lattice
# views put wedge edges exactly on cell corners' bearings, where rounding must not decide.
_ANGLE_EPS = 1e-9


def _require(condition: bool, message: str) -> None:
    if not condition:
        raise InputError(message)


@dataclass(frozen=True)
class ActiveConfig:
    """An active-mode comparison: planners x detector settings, V views per trial, the world.

    ``settings`` are (P_fp, P_fn) pairs; ``views`` is V (every count 1..V is scored; the survey
    has at most its 40); ``travel_cost`` weighs a greedy planner's distance (per cell). The
    world (``grid``, ``wedges``, ``fov`` in radians, ``supersample``), ``fusion`` and ``seed``
    are the sweep's (``montecarlo.SweepConfig``), validated by it, as is ``min_observed``
    (the ``normalized`` rule's, in full-cell views).
    """

    planners: tuple[str, ...] = PLANNERS
    settings: tuple[tuple[float, float], ...] = DEFAULT_SETTINGS
    views: int = DEFAULT_VIEWS
    trials: int = 100
    grid: int = 20
    wedges: int = 8
    fov: float = math.radians(45.0)
    supersample: int = 10
    fusion: tuple[str, ...] = DEFAULT_FUSION
    travel_cost: float = DEFAULT_TRAVEL_COST
    seed: int = 0
    min_observed: float = 1.0

    def __post_init__(self) -> None:
        unknown = [p for p in self.planners if p not in PLANNERS]
        _require(
            bool(self.planners) and not unknown,
            f"--active: unknown planner(s) {', '.join(unknown) or '(none given)'}; choose from "
            f"{', '.join(PLANNERS)}",
        )
        _require(
            len(set(self.planners)) == len(self.planners),
            f"--active names a planner twice: {', '.join(self.planners)}",
        )
        _require(bool(self.settings), "give at least one detector setting (--pfp, --pfn)")
        _require(
            len(set(self.settings)) == len(self.settings),
            f"a detector setting is given twice: {self.settings!r}",
        )
        _require(
            isinstance(self.views, int) and self.views >= 1,
            f"--views: the active mode needs at least 1 view per trial, got {self.views!r}",
        )
        _require(
            math.isfinite(self.travel_cost) and self.travel_cost >= 0.0,
            f"--travel-cost must be a number >= 0 (per cell travelled), got {self.travel_cost!r}",
        )
        for setting in self.settings:
            _require(
                len(setting) == 2,
                f"a detector setting is a (P_fp, P_fn) pair, got {setting!r}",
            )
            self.sweep(setting)  # the sweep validates rates, world, rules and seed

    def sweep(self, setting: tuple[float, float]) -> SweepConfig:
        """The ``twin montecarlo`` sweep whose trials this setting's trials are: views 1..V."""
        pfp, pfn = setting
        return SweepConfig(
            pfp=(pfp,), pfn=(pfn,), views=tuple(range(1, self.views + 1)), trials=self.trials,
            wedges=self.wedges, fov=self.fov, grid=self.grid, supersample=self.supersample,
            fusion=self.fusion, seed=self.seed, min_observed=self.min_observed,
        )  # fmt: skip

    def views_of(self, planner: str) -> int:
        """How many views a planner's trial takes: V, or at most the survey's 40."""
        return min(self.views, SURVEY_VIEWS) if planner == "survey" else self.views


# -- the candidate views ------------------------------------------------------------------------


@dataclass(frozen=True)
class Candidates:
    """The views a planner may take: ``places`` (P, 2) lattice points (x, y in cells) x
    ``headings`` directions; view v stands at place v // headings facing
    (v % headings) x 2 pi / headings radians. ``footprints`` holds each view's ``wedges`` rows
    (wedge order: from the field of view's counter-clockwise edge) with the wedge's share of each
    cell (lift = share: a perfect detector; ``lifted`` gives a setting's). ``distance`` (P, P)
    is the straight distance between places, in cells."""

    places: np.ndarray = field(repr=False)
    headings: int
    wedges: int
    fov: float
    footprints: Footprints = field(repr=False)
    distance: np.ndarray = field(repr=False)

    @property
    def n_views(self) -> int:
        return self.footprints.n_views

    @property
    def place_of(self) -> np.ndarray:
        """(n_views,) each view's place index."""
        return np.arange(self.n_views) // self.headings

    def yaw(self, view: int) -> float:
        """View ``view``'s heading, radians."""
        return (view % self.headings) * (2.0 * math.pi / self.headings)

    def lifted(self, pfp: float, pfn: float) -> Footprints:
        """The footprints for a detector of rates (P_fp, P_fn): lift = share x (1 - P_fn - P_fp),
        clipped at 0 (a detector no better than chance tells nothing)."""
        f = self.footprints
        contrast = max(0.0, 1.0 - pfn - pfp)
        return Footprints(f.indptr, f.cells, f.share, f.share * contrast, f.row_view, f.n_views,
                          f.n_cells)  # fmt: skip


def lattice_view(grid: int, x: int, y: int, heading: int) -> int:
    """The candidate index of the view at lattice point (x, y) (cells, 1 .. grid - 1) facing
    heading index ``heading`` (0 .. 7: 45 degree steps counter-clockwise from +x)."""
    _require(
        1 <= x < grid and 1 <= y < grid and 0 <= heading < HEADINGS,
        f"no lattice view at ({x}, {y}) heading {heading} in a {grid} x {grid} world",
    )
    return ((y - 1) * (grid - 1) + (x - 1)) * HEADINGS + heading


def _wedge_edges(yaw: float, fov: float, n_wedges: int) -> tuple[np.ndarray, np.ndarray]:
    """(a0, a1) of a view's wedges, radians, as the sweep splits its field of view."""
    wedge = fov / n_wedges
    a1 = yaw + 0.5 * fov - np.arange(n_wedges) * wedge
    return a1 - wedge, a1


@lru_cache(maxsize=4)
def candidate_views(grid: int, wedges: int, fov: float, supersample: int) -> Candidates:
    """Every lattice view of an n x n world (``grid`` cells a side) and its footprint: (n - 1)^2
    interior cell corners x 8 headings, each wedge's coverage of every cell by ``add_coverage``
    (x0 = y0 = 0, unit cells, unlimited range). Computed once per world size and process."""
    n = grid
    coords = np.arange(1, n, dtype=float)
    xs, ys = np.meshgrid(coords, coords)  # row-major: x fastest
    places = np.column_stack([xs.ravel(), ys.ravel()])
    eye = np.eye(wedges)
    dense = np.zeros((wedges, n, n))
    indptr, cells, shares = [np.zeros(1, dtype=np.int64)], [], []
    total = 0
    for x, y in places:
        for h in range(HEADINGS):
            a0, a1 = _wedge_edges(h * (2.0 * math.pi / HEADINGS), fov, wedges)
            dense[:] = 0.0
            # The optional arguments are given so numba's on-disk cache recognizes the call.
            add_coverage(dense, float(x), float(y), a0, a1, eye, 0.0, 0.0, 1.0, supersample,
                         0.0, NO_VISIBILITY, 1.0)  # fmt: skip
            flat = dense.reshape(wedges, -1)
            rows, cols = np.nonzero(flat > 0.0)  # row-major: wedge by wedge, cells ascending
            counts = np.bincount(rows, minlength=wedges)
            indptr.append(total + np.cumsum(counts))
            total += len(cols)
            cells.append(cols)
            shares.append(flat[rows, cols])
    n_views = len(places) * HEADINGS
    share = np.clip(np.concatenate(shares), 0.0, 1.0)
    footprints = Footprints(
        np.concatenate(indptr), np.concatenate(cells), share, share,
        np.repeat(np.arange(n_views), wedges), n_views, n * n,
    )  # fmt: skip
    distance = np.hypot(*(places[:, None, :] - places[None, :, :]).transpose(2, 0, 1))
    for array in (places, distance):
        array.flags.writeable = False
    return Candidates(places, HEADINGS, wedges, fov, footprints, distance)


def survey_plan(grid: int) -> np.ndarray:
    """The survey's 40 views (candidate indices): 5 stops, the map's quarter-points and its
    centre on lattice points, visited bottom-left, bottom-right, centre, top-left, top-right
    (a short tour), 8 headings each from 0 degrees counter-clockwise."""
    n = grid
    q = max(1, n // 4)
    stops = ((q, q), (n - q, q), (n // 2, n // 2), (q, n - q), (n - q, n - q))
    return np.array(
        [lattice_view(n, x, y, h) for x, y in stops for h in range(HEADINGS)], dtype=np.int64
    )


# -- the world's answer to a lattice view -------------------------------------------------------


@njit(cache=True)
def _meets_cell(px, py, a0, a1, col, row) -> bool:
    """Whether the wedge [a0, a1] from (px, py) meets the unit cell (col, row) by more than
    ``_ANGLE_EPS``. A lattice view may stand on one of the cell's corners: that corner has no
    bearing, and the two corners next to it bound the cell's quarter of the view."""
    centre = math.atan2(row + 0.5 - py, col + 0.5 - px)
    lo = math.inf
    hi = -math.inf
    for cx in (col + 0.0, col + 1.0):
        for cy in (row + 0.0, row + 1.0):
            if cx == px and cy == py:
                continue
            d = (math.atan2(cy - py, cx - px) - centre + math.pi) % (2.0 * math.pi) - math.pi
            lo = min(lo, d)
            hi = max(hi, d)
    return _span_meets_wedge(centre, lo + _ANGLE_EPS, hi - _ANGLE_EPS, a0, a1)


@njit(cache=True)
def _lattice_values(px, py, yaw, fov, n_wedges, object_row, object_col, fire_u, pfp, pfn, out):
    """out[w] = 1 if wedge w of the view fires, else 0: with 1 - P_fn when it meets the
    object's cell, else P_fp, decided by the uniform ``fire_u[w]`` (the sweep's rule)."""
    wedge = fov / n_wedges
    for w in range(n_wedges):
        a1 = yaw + 0.5 * fov - w * wedge
        a0 = a1 - wedge
        hit = _meets_cell(px, py, a0, a1, object_col, object_row)
        out[w] = 1 if fire_u[w] < ((1.0 - pfn) if hit else pfp) else 0


@njit(cache=True)
def _add_view(state, weights, indptr, cells, share, first_row):
    """state[q, cell] += weights[q, w] x share for every entry of the view's wedge rows
    first_row .. first_row + weights.shape[1] - 1."""
    for w in range(weights.shape[1]):
        r = first_row + w
        for k in range(indptr[r], indptr[r + 1]):
            c = cells[k]
            s = share[k]
            for q in range(state.shape[0]):
                state[q, c] += weights[q, w] * s


# -- one trial --------------------------------------------------------------------------------


@dataclass(frozen=True)
class ActiveTrial:
    """One trial of one planner: ``hits`` (rules, views) whether each rule had found the object
    after 1, 2, ... views; ``path`` (views,) the distance travelled so far (cells); ``views``
    the candidate views taken (-1: the random planner's off-lattice views); ``object_cell``
    the object's (row, col)."""

    hits: np.ndarray
    path: np.ndarray
    views: np.ndarray
    object_cell: tuple[int, int]


class _Setting:
    """What every trial of one (config, setting) shares: candidates, rules, weight tables."""

    def __init__(self, config: ActiveConfig, setting: tuple[float, float]) -> None:
        self.config, self.setting = config, setting
        self.pfp, self.pfn = setting
        self.sweep = config.sweep(setting)
        self.rules = sweep_rules(self.sweep, *setting)
        self.candidates = candidate_views(config.grid, config.wedges, config.fov,
                                          config.supersample)  # fmt: skip
        self.footprints = self.candidates.lifted(*setting)
        self.contrast = max(0.0, 1.0 - self.pfn - self.pfp)
        # Weights of a silent (0) and a fired (1) wedge per state row: the rules' distinct
        # evidence layers, then observed (1 per unit of coverage), then the posterior's LLR.
        layer_weights, self.layer_of = evidence_layers(self.rules, BINARY_VALUES)
        fired, silent = logodds_weights(self.pfp, self.pfn)
        self.table = np.vstack([layer_weights, [1.0, 1.0], [silent, fired]])
        self.n_evidence = layer_weights.shape[0]
        self.place_of = self.candidates.place_of
        self._first: dict[str, int] = {}

    def draws(self, trial: int) -> TrialDraws:
        """Trial ``trial``'s draws: the sweep's, so every planner faces the same world."""
        return draw_trial(self.sweep, sweep_trial_rng(self.sweep, self.pfp, self.pfn, trial))

    def gains(self, planner: str, state: np.ndarray) -> np.ndarray:
        """(n_views,) every candidate's gain under the trial's grid ``state``."""
        n = self.config.grid
        if planner == "coverage":
            return unseen_coverage(self.footprints, state[self.n_evidence])
        if self.contrast <= 0.0:  # a detector no better than chance: no view tells anything
            return np.zeros(self.footprints.n_views)
        probs, _ = posterior(state[self.n_evidence + 1].reshape(n, n), 1.0, 0.0)
        if planner == "detection":
            return detection_probability(self.footprints, probs, self.contrast)
        return information_gain(self.footprints, probs, self.pfp)

    def first(self, planner: str) -> int:
        """The first view of a greedy planner: its best on the uniform prior (no travel)."""
        if planner not in self._first:
            state = np.zeros((len(self.table), self.config.grid**2))
            self._first[planner] = _best(self.gains(planner, state))
        return self._first[planner]

    def choose(self, planner: str, state: np.ndarray, taken: np.ndarray, here: int) -> int:
        """The untaken candidate of the most gain per unit cost from place ``here``."""
        cost = 1.0 + self.config.travel_cost * self.candidates.distance[here][self.place_of]
        scores = self.gains(planner, state) / cost
        scores[taken] = -np.inf
        return _best(scores)


def _best(scores: np.ndarray) -> int:
    """The first index whose score is within ``_TIE_RTOL`` (relative) of the best."""
    top = float(np.max(scores))
    return int(np.argmax(scores >= top - _TIE_RTOL * max(1.0, abs(top))))


def _planned_trial(context: _Setting, planner: str, trial: int) -> ActiveTrial:
    """One trial of ``survey`` or a greedy planner, views chosen one after another."""
    config, cands = context.config, context.candidates
    n, n_views = config.grid, config.views_of(planner)
    draws = context.draws(trial)
    f = cands.footprints
    n_layers = context.n_evidence + 1  # the evidence layers and observed: what rules read
    state = np.zeros((len(context.table), n * n))
    history = np.empty((n_layers, n_views, n * n))
    taken = np.zeros(cands.n_views, dtype=np.bool_)
    views = np.empty(n_views, dtype=np.int64)
    path = np.empty(n_views)
    plan = survey_plan(n) if planner == "survey" else None
    values = np.empty(config.wedges, dtype=np.int64)
    here, walked = -1, 0.0
    for k in range(n_views):
        if plan is not None:
            view = int(plan[k])
        elif k == 0:
            view = context.first(planner)
        else:
            view = context.choose(planner, state, taken, here)
        place = int(context.place_of[view])
        if here >= 0:
            walked += float(cands.distance[here, place])
        x, y = cands.places[place]
        _lattice_values(float(x), float(y), cands.yaw(view), config.fov, config.wedges,
                        draws.object_row, draws.object_col, draws.fire[k], context.pfp,
                        context.pfn, values)  # fmt: skip
        weights = np.ascontiguousarray(context.table[:, values])
        _add_view(state, weights, f.indptr, f.cells, f.share, view * config.wedges)
        history[:, k] = state[:n_layers]
        taken[view] = True
        here = place
        views[k] = view
        path[k] = walked
    hits = np.empty((len(context.rules), n_views), dtype=np.bool_)
    observed = history[context.n_evidence].reshape(n_views, n, n)
    rows = np.array([draws.object_row], dtype=np.int64)
    cols = np.array([draws.object_col], dtype=np.int64)
    for r, rule in enumerate(context.rules):
        evidence = history[context.layer_of[r]].reshape(n_views, n, n)
        confidence = np.asarray(rule.read(evidence, observed), dtype=float)
        _score(np.ascontiguousarray(confidence[None]), draws.tie[None, :n_views], rows, cols,
               hits[r : r + 1])  # fmt: skip
    return ActiveTrial(hits, path, views, (draws.object_row, draws.object_col))


def _random_path(draws: TrialDraws) -> np.ndarray:
    """(V,) the distance (cells) walked by a trial's random views after each view."""
    steps = np.hypot(np.diff(draws.x), np.diff(draws.y))
    return np.concatenate([[0.0], np.cumsum(steps)])


def run_active_trial(
    config: ActiveConfig, setting: tuple[float, float], planner: str, trial: int
) -> ActiveTrial:
    """Trial ``trial`` (>= 0) of ``planner`` at the (P_fp, P_fn) ``setting`` in ``config``'s
    world (any setting: a trial depends only on the seed, the setting and its index)."""
    _require(planner in PLANNERS, f"unknown planner {planner!r}; choose from {', '.join(PLANNERS)}")
    _require(trial >= 0, f"a trial index is a non-negative integer, got {trial!r}")
    context = _Setting(config, setting)
    if planner == "random":
        hits = run_trial(context.sweep, *setting, trial)
        views = np.full(config.views, -1, dtype=np.int64)
        draws = context.draws(trial)
        cell = (draws.object_row, draws.object_col)
        return ActiveTrial(hits, _random_path(draws), views, cell)
    return _planned_trial(context, planner, trial)


# -- many trials --------------------------------------------------------------------------------


@dataclass(frozen=True)
class ActiveChunk:
    """A task: trials ``start`` .. ``stop - 1`` of one planner at one setting."""

    pfp: float
    pfn: float
    planner: str
    start: int
    stop: int

    @property
    def setting(self) -> tuple[float, float]:
        return (self.pfp, self.pfn)


@dataclass(frozen=True)
class ActiveResult:
    """Summed over trials of one planner at one setting: ``successes`` (rules, views) and
    ``path`` (views,) the distance travelled after each view, in cells."""

    pfp: float
    pfn: float
    planner: str
    trials: int
    fusion: tuple[str, ...]
    successes: np.ndarray = field(repr=False)
    path: np.ndarray = field(repr=False)

    @property
    def setting(self) -> tuple[float, float]:
        return (self.pfp, self.pfn)

    def success_rate(self, rule: str, views: int) -> float:
        """Share of trials in which ``rule`` had found the object after ``views`` views."""
        return float(self.successes[self.fusion.index(rule), views - 1]) / self.trials

    def mean_path(self, views: int) -> float:
        """Mean distance travelled (cells) over the first ``views`` views."""
        return float(self.path[views - 1]) / self.trials

    def rows(self) -> list[dict[str, object]]:
        out = []
        for r, rule in enumerate(self.fusion):
            for c in range(self.successes.shape[1]):
                hits = int(self.successes[r, c])
                out.append(
                    {
                        "planner": self.planner, "fusion": rule, "pfp": self.pfp,
                        "pfn": self.pfn, "views": c + 1, "trials": self.trials,
                        "successes": hits, "success_rate": hits / self.trials,
                        "path_length": float(self.path[c]) / self.trials,
                    }
                )  # fmt: skip
        return out


@dataclass(frozen=True)
class ActiveChunkResult:
    """A task's trials: ``successes`` (rules, views) summed, ``paths`` (trials, views) each
    trial's distance travelled (kept apart, so the float sums do not depend on the chunks)."""

    chunk: ActiveChunk
    successes: np.ndarray = field(repr=False)
    paths: np.ndarray = field(repr=False)


def run_active_chunk(config: ActiveConfig, chunk: ActiveChunk) -> ActiveChunkResult:
    """One task (module level, so local and Ray workers can import it)."""
    context = _Setting(config, chunk.setting)
    trials = range(chunk.start, chunk.stop)
    if chunk.planner == "random":
        successes = run_trials(context.sweep, *chunk.setting, chunk.start, chunk.stop)
        paths = np.array([_random_path(context.draws(t)) for t in trials])
    else:
        outcomes = [_planned_trial(context, chunk.planner, t) for t in trials]
        successes = np.sum([o.hits for o in outcomes], axis=0, dtype=np.int64)
        paths = np.array([o.path for o in outcomes])
    return ActiveChunkResult(chunk, np.asarray(successes, dtype=np.int64), paths)


def plan_active_chunks(config: ActiveConfig, chunk_trials: int) -> list[ActiveChunk]:
    """Every setting x planner's trials cut into tasks of at most ``chunk_trials``, slowest
    planners first (so no worker is left with one long task at the end)."""
    _require(chunk_trials >= 1, f"--chunk must be at least 1 trial, got {chunk_trials}")
    slow_first = sorted(config.planners, key=lambda p: p not in GAIN_PLANNERS)
    return [
        ActiveChunk(pfp, pfn, planner, first, min(first + chunk_trials, config.trials))
        for planner in slow_first
        for pfp, pfn in config.settings
        for first in range(0, config.trials, chunk_trials)
    ]


def run_active(
    config: ActiveConfig,
    executor: Executor,
    chunk_trials: int = DEFAULT_CHUNK_TRIALS,
    on_chunk: Callable[[ActiveChunk], None] | None = None,
) -> list[ActiveResult]:
    """Every planner at every setting; results in setting order, planners in config order.
    They do not depend on ``chunk_trials``, the executor or its number of workers."""
    parts: dict[tuple[tuple[float, float], str], list[ActiveChunkResult]] = {}
    chunks = plan_active_chunks(config, chunk_trials)
    for chunk, result in executor.map_unordered(partial(run_active_chunk, config), chunks):
        parts.setdefault((chunk.setting, chunk.planner), []).append(result)
        if on_chunk:
            on_chunk(chunk)
    out = []
    for setting in config.settings:
        for planner in config.planners:
            done = sorted(parts[(setting, planner)], key=lambda p: p.chunk.start)
            paths = np.concatenate([p.paths for p in done])  # in trial order, however cut
            out.append(
                ActiveResult(
                    *setting, planner, len(paths), config.fusion,
                    np.sum([p.successes for p in done], axis=0, dtype=np.int64),
                    paths.sum(axis=0),
                )
            )  # fmt: skip
    return out


def active_rows(results: Sequence[ActiveResult]) -> list[dict[str, object]]:
    """The CSV's rows: planner, rule, setting, views in the results' order."""
    return [row for result in results for row in result.rows()]


def write_active_csv(path: Path, rows: Sequence[dict[str, object]]) -> Path:
    """``active.csv``: success per planner x rule x setting x views, with the mean path length
    (cells) so far; written atomically."""
    buffer = io.StringIO()
    writer = csv.DictWriter(buffer, fieldnames=ACTIVE_COLUMNS, lineterminator="\n")
    writer.writeheader()
    writer.writerows(rows)
    return write_text_atomic(path, buffer.getvalue())


# -- the figure --------------------------------------------------------------------------------

_PLANNER_LABEL = {
    "random": "random (Figure 3)",
    "survey": "survey (40 views)",
    "coverage": "coverage",
    "detection": "detection",
    "information": "information",
}
_PLANNER_STYLE = {
    "random": {"color": "0.45", "linestyle": "--"},
    "survey": {"color": "tab:brown", "linestyle": "-"},
    "coverage": {"color": "tab:green", "linestyle": "-"},
    "detection": {"color": "tab:orange", "linestyle": "-"},
    "information": {"color": "tab:blue", "linestyle": "-"},
}


def draw_active_figure(results: Sequence[ActiveResult], title: str = ""):
    """Success (%) over the number of views, one line per planner; a panel per rule (rows) and
    detector setting (columns). The survey's line ends in a marker at its 40th view."""
    from twin.app.plots import _pyplot

    plt = _pyplot()
    settings = list(dict.fromkeys(r.setting for r in results))
    fusion = results[0].fusion
    fig, axes = plt.subplots(len(fusion), len(settings), figsize=(4.2 * len(settings),
                             3.4 * len(fusion)), squeeze=False, sharex=True, sharey=True,
                             layout="constrained")  # fmt: skip
    for i, rule in enumerate(fusion):
        for j, setting in enumerate(settings):
            ax = axes[i, j]
            for result in (r for r in results if r.setting == setting):
                r = result.fusion.index(rule)
                counts = np.arange(1, result.successes.shape[1] + 1)
                rate = 100.0 * result.successes[r] / result.trials
                style = _PLANNER_STYLE[result.planner]
                ax.plot(counts, rate, label=_PLANNER_LABEL[result.planner], linewidth=1.6,
                        **style)  # fmt: skip
                if result.planner == "survey":
                    ax.plot(counts[-1], rate[-1], marker="o", color=style["color"])
            ax.set_ylim(0, 100)
            ax.set_xlim(0.5, max(r.successes.shape[1] for r in results) + 0.8)
            ax.grid(alpha=0.3)
            ax.set_title(f"{rule}: P_fp = {setting[0]:g}, P_fn = {setting[1]:g}", fontsize=10)
            if i == len(fusion) - 1:
                ax.set_xlabel("views")
            if j == 0:
                ax.set_ylabel("success (%)")
    handles, labels = axes[0, 0].get_legend_handles_labels()
    fig.legend(handles, labels, loc="outside lower center", ncols=len(labels), fontsize=9)
    trials = sorted({r.trials for r in results})
    note = f"{trials[0]} trials per planner and setting" if len(trials) == 1 else ""
    fig.suptitle(title or f"Localization success vs views, abstract world; {note}")
    return fig


def active_figure(path: Path, results: Sequence[ActiveResult], title: str = "") -> Path:
    """Write ``draw_active_figure`` as a PNG."""
    from twin.app.plots import save_figure

    return save_figure(draw_active_figure(results, title), path, tight=False)


def active_table(results: Sequence[ActiveResult], counts: Sequence[int]) -> str:
    """A markdown table: per setting, planner and rule, success (%) after each of ``counts``
    views ("-" past a planner's last view) and the mean path length (cells) of its trials."""
    counts = sorted(set(counts))
    head = ["P_fp, P_fn", "planner", "rule", *(f"{c} views" for c in counts), "path, cells"]
    lines = ["| " + " | ".join(head) + " |", "|" + "---|" * len(head)]
    for result in results:
        last = result.successes.shape[1]
        for rule in result.fusion:
            cells = [
                f"{100 * result.success_rate(rule, c):.0f}%" if c <= last else "-" for c in counts
            ]
            setting = f"{result.pfp:g}, {result.pfn:g}"
            path = f"{result.mean_path(last):.0f}"
            lines.append("| " + " | ".join([setting, result.planner, rule, *cells, path]) + " |")
    return "\n".join(lines)
