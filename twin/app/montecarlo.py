"""The paper's Section 3 evaluation: Monte Carlo over detector false-positive/negative rates.

An abstract world (Figure 3): an n x n grid of unit cells, one object in a random cell off the
outer edge. Every view puts the robot at a uniformly random point anywhere but in the object's
cell, with a uniformly random heading; its field of view is split into equal-angle wedges that
reach to the map's edge. A wedge whose angular span meets the object's cell (exactly, from the
cell's corners) fires with probability 1 - P_fn, any other wedge with probability P_fp; a fired
wedge has value 1.

The rules are ``twin.core.fusion``'s, named by ``--fusion`` (any registered rule, with the
parameters this sweep can supply: the setting's true P_fp and P_fn, and --min-observed). Each
rule's weights for a silent and a fired wedge (``column_weights([0, 1])``) name an evidence
layer; rules with the same weights share one, and all share the ``observed`` layer, so one
coverage pass per view updates every rule. The layers are copied at each checkpoint, and each
rule's element-wise ``read`` turns a whole batch of trials x checkpoints into confidence maps.

After each checkpoint (by default 10, 25, 75 and 150 views of one trial: nested, so one trial
yields all view counts) the trial succeeds for a rule when that rule's maximal cell is the
object's cell or one of its 8 neighbours. Cells within 1e-9 (relative) of the maximum are tied;
ties are broken uniformly at random with one draw per checkpoint shared by all rules, so a flat
grid scores chance (about 9 / n^2), not a bias toward a corner.

Randomness: trial t of setting (P_fp, P_fn) draws everything from
``SeedSequence(seed, spawn_key=(P_fp in 1e-9, P_fn in 1e-9, t))``, so a result depends only on
the seed, the setting and the trial index: not on the number of workers, the order in which
settings run, or which other settings are in the sweep.
"""

from __future__ import annotations

import csv
import inspect
import io
import json
import math
from collections.abc import Callable, Iterable, Sequence
from dataclasses import dataclass, field
from functools import partial
from pathlib import Path

import numpy as np
from numba import njit

from twin.app.executors import Executor
from twin.core.coverage import add_coverage
from twin.core.errors import InputError, TwinError
from twin.core.fusion import RULES, FusionRule, make_rule
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
_TIE_RTOL = 1e-9
_RATE_KEY_SCALE = 1e9
# Checkpoint copies of the layers (and confidence maps) of one batch of trials stay below this.
_BATCH_BYTES = 32 * 1024 * 1024


@dataclass(frozen=True)
class SweepConfig:
    """One Monte Carlo sweep: settings, view counts, the abstract world and the rules."""

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
        _require(
            bool(self.fusion) and not unknown,
            f"--fusion: unknown rule(s) {unknown or self.fusion!r}; choose from {', '.join(RULES)}",
        )
        _require(
            len(set(self.fusion)) == len(self.fusion),
            f"--fusion names a rule twice: {', '.join(self.fusion)}",
        )
        _require(
            math.isfinite(self.min_observed) and self.min_observed >= 0.0,
            f"--min-observed must be a number >= 0 of full-cell views, got {self.min_observed!r}",
        )
        for pfp, pfn in self.settings():
            sweep_rules(self, pfp, pfn)  # a rule this sweep cannot parametrize fails here

    @property
    def checkpoints(self) -> tuple[int, ...]:
        return tuple(sorted(set(self.views)))

    def settings(self) -> list[tuple[float, float]]:
        return [(pfp, pfn) for pfp in self.pfp for pfn in self.pfn]


@dataclass(frozen=True)
class SettingResult:
    """Successes of every rule at every checkpoint, for one (P_fp, P_fn) setting."""

    pfp: float
    pfn: float
    trials: int
    checkpoints: tuple[int, ...]
    fusion: tuple[str, ...]
    successes: np.ndarray = field(repr=False)  # (len(fusion), len(checkpoints)) ints

    def rows(self) -> list[dict[str, object]]:
        out = []
        for r, rule in enumerate(self.fusion):
            for c, views in enumerate(self.checkpoints):
                hits = int(self.successes[r, c])
                out.append(
                    {
                        "fusion": rule,
                        "pfp": self.pfp,
                        "pfn": self.pfn,
                        "views": views,
                        "trials": self.trials,
                        "successes": hits,
                        "success_rate": hits / self.trials,
                    }
                )
        return out


def _require(condition: bool, message: str) -> None:
    if not condition:
        raise InputError(message)


def _rule_for(name: str, offered: dict[str, float]) -> FusionRule:
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
    detector's true rates (``p_fp``, ``p_fn``) and ``min_observed`` (full-cell views)."""
    offered = {"p_fp": pfp, "p_fn": pfn, "min_observed": config.min_observed}
    return tuple(_rule_for(name, offered) for name in config.fusion)


def evidence_layers(rules: Sequence[FusionRule]) -> tuple[np.ndarray, tuple[int, ...]]:
    """The distinct (silent, fired) weight pairs of ``rules`` as a (layers, 2) array, and the
    layer of each rule: rules that weight the binary detector alike share one evidence sum."""
    pairs: list[tuple[float, float]] = []
    layer_of = []
    for rule in rules:
        weights = np.asarray(rule.column_weights(BINARY_VALUES), dtype=float)
        if weights.shape != BINARY_VALUES.shape:
            raise TwinError(
                f"fusion rule {rule.name!r}: column_weights gave shape {weights.shape} for "
                f"{BINARY_VALUES.size} values; it must give one weight per column"
            )
        pair = (float(weights[0]), float(weights[1]))
        if pair not in pairs:
            pairs.append(pair)
        layer_of.append(pairs.index(pair))
    return np.array(pairs, dtype=float).reshape(-1, 2), tuple(layer_of)


def trial_rng(seed: int, pfp: float, pfn: float, trial: int) -> np.random.Generator:
    """The generator of one trial: a function of (seed, setting, trial) only."""
    key = (round(pfp * _RATE_KEY_SCALE), round(pfn * _RATE_KEY_SCALE), trial)
    return np.random.default_rng(np.random.SeedSequence(seed, spawn_key=key))


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


def draw_trial(config: SweepConfig, rng: np.random.Generator) -> TrialDraws:
    n = config.grid
    n_views = config.checkpoints[-1]
    object_row, object_col = (int(v) for v in rng.integers(1, n - 1, size=2))
    # Uniform over the area outside the object's cell: a uniform other cell, then a point in it.
    cell = rng.integers(0, n * n - 1, size=n_views)
    cell += cell >= object_row * n + object_col
    offset = rng.random((n_views, 2))
    return TrialDraws(
        object_row,
        object_col,
        x=cell % n + offset[:, 0],
        y=cell // n + offset[:, 1],
        yaw=rng.uniform(-math.pi, math.pi, size=n_views),
        fire=rng.random((n_views, config.wedges)),
        tie=rng.random(len(config.checkpoints)),
    )


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
def _run_trial(
    n, supersample, fov, n_wedges, object_row, object_col, xs, ys, yaws, fire_u, checkpoints,
    pfp, pfn, layer_weights, out,
):  # fmt: skip
    """Fuse one trial's views; out[k, c] gets layer k at checkpoint c.

    Layers are one evidence sum per row of ``layer_weights`` ((silent, fired) weights), then the
    observed sum (weight 1), all (n, n) over cells.
    """
    n_layers = layer_weights.shape[0]
    state = np.zeros((n_layers + 1, n, n))
    a0 = np.empty(n_wedges)
    a1 = np.empty(n_wedges)
    weights = np.ones((n_layers + 1, n_wedges))
    wedge = fov / n_wedges
    c = 0
    for v in range(xs.shape[0]):
        centre, lo, hi = _cell_span(xs[v], ys[v], object_col, object_row)
        for w in range(n_wedges):
            a1[w] = yaws[v] + 0.5 * fov - w * wedge
            a0[w] = a1[w] - wedge
            hit = _span_meets_wedge(centre, lo, hi, a0[w], a1[w])
            fired = 1 if fire_u[v, w] < ((1.0 - pfn) if hit else pfp) else 0
            for k in range(n_layers):
                weights[k, w] = layer_weights[k, fired]
        add_coverage(state, xs[v], ys[v], a0, a1, weights, 0.0, 0.0, 1.0, supersample, 0.0)
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
    layer_weights: np.ndarray,
    layer_of: Sequence[int],
) -> np.ndarray:
    """Successes (len(rules), len(trials), len(checkpoints)) of some trials, as booleans."""
    n, checkpoints = config.grid, np.asarray(config.checkpoints, dtype=np.int64)
    n_layers = len(layer_weights)
    # Layer first, so each rule reads contiguous (trials, checkpoints, n, n) blocks.
    layers = np.zeros((n_layers + 1, len(trials), len(checkpoints), n, n))
    ties = np.empty((len(trials), len(checkpoints)))
    object_rows = np.empty(len(trials), dtype=np.int64)
    object_cols = np.empty(len(trials), dtype=np.int64)
    for t, trial in enumerate(trials):
        draws = draw_trial(config, trial_rng(config.seed, pfp, pfn, trial))
        ties[t], object_rows[t], object_cols[t] = draws.tie, draws.object_row, draws.object_col
        _run_trial(
            n, config.supersample, config.fov, config.wedges, draws.object_row, draws.object_col,
            draws.x, draws.y, draws.yaw, draws.fire, checkpoints, pfp, pfn, layer_weights,
            layers[:, t],
        )  # fmt: skip
    layers.flags.writeable = False  # shared by the rules' reads: none may change it
    observed = layers[-1]
    hits = np.empty((len(rules), len(trials), len(checkpoints)), dtype=np.bool_)
    for r, rule in enumerate(rules):
        confidence = np.asarray(rule.read(layers[layer_of[r]], observed), dtype=float)
        if confidence.shape != observed.shape:
            raise TwinError(
                f"fusion rule {rule.name!r}: read gave shape {confidence.shape} for layers of "
                f"shape {observed.shape}; it must be element-wise"
            )
        _score(np.ascontiguousarray(confidence), ties, object_rows, object_cols, hits[r])
    return hits


def run_trial(config: SweepConfig, pfp: float, pfn: float, trial: int) -> np.ndarray:
    """Successes (len(config.fusion), len(checkpoints)) of one trial, as booleans."""
    rules = sweep_rules(config, pfp, pfn)
    layer_weights, layer_of = evidence_layers(rules)
    batch = _run_batch(config, pfp, pfn, range(trial, trial + 1), rules, layer_weights, layer_of)
    return batch[:, 0]


def run_trials(config: SweepConfig, pfp: float, pfn: float, start: int, stop: int) -> np.ndarray:
    """Summed successes (len(config.fusion), len(checkpoints)) of trials start..stop-1."""
    rules = sweep_rules(config, pfp, pfn)
    layer_weights, layer_of = evidence_layers(rules)
    successes = np.zeros((len(rules), len(config.checkpoints)), dtype=np.int64)
    size = _batch_size(config, len(layer_weights))
    for first in range(start, stop, size):
        trials = range(first, min(first + size, stop))
        hits = _run_batch(config, pfp, pfn, trials, rules, layer_weights, layer_of)
        successes += hits.sum(axis=1)
    return successes


def run_setting(config: SweepConfig, setting: tuple[float, float]) -> SettingResult:
    """All trials of one (P_fp, P_fn) setting."""
    pfp, pfn = setting
    successes = run_trials(config, pfp, pfn, 0, config.trials)
    return SettingResult(pfp, pfn, config.trials, config.checkpoints, config.fusion, successes)


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
    successes: np.ndarray = field(repr=False)  # (len(fusion), len(checkpoints)) ints


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
    """Rows of ``results.csv`` in a stable order: rule, P_fp, P_fn, views."""
    rows = [row for result in results for row in result.rows()]
    order = {rule: i for i, rule in enumerate(config.fusion)}
    return sorted(rows, key=lambda r: (order[r["fusion"]], r["pfp"], r["pfn"], r["views"]))


# -- running a sweep, resumably ----------------------------------------------------------------

JOURNAL_NAME = "settings.jsonl"


def _identity(config: SweepConfig) -> dict[str, object]:
    """The parameters that decide a setting's result, and the rules its rows of successes are."""
    return {
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
        shape = (len(config.fusion), len(config.checkpoints))
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
        config = self.config
        done = SettingResult(*setting, config.trials, config.checkpoints, config.fusion, total)
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


def write_results_csv(path: Path, rows: Sequence[dict[str, object]]) -> Path:
    """``results.csv`` with exactly ``RESULT_COLUMNS``, written atomically."""
    buffer = io.StringIO()
    writer = csv.DictWriter(buffer, fieldnames=RESULT_COLUMNS, lineterminator="\n")
    writer.writeheader()
    writer.writerows(rows)
    return write_text_atomic(path, buffer.getvalue())
