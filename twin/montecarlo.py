"""The paper's Section 3 evaluation: Monte Carlo over detector false-positive/negative rates.

An abstract world (Figure 3): an n x n grid of unit cells, one object in a random cell off the
outer edge. Every view puts the robot at a uniformly random point anywhere but in the object's
cell, with a uniformly random heading; its field of view is split into equal-angle wedges that
reach to the map's edge. A wedge whose angular span meets the object's cell (exactly, from the
cell's corners) fires with probability 1 - P_fn, any other wedge with probability P_fp; a fired
wedge has value 1. All fusion rules update their own grids from the same views and firings.

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
import io
import json
import math
import os
from collections.abc import Callable, Iterable, Sequence
from dataclasses import dataclass, field
from functools import partial
from pathlib import Path

import numpy as np
from numba import njit

from twin.coverage import add_coverage
from twin.errors import InputError
from twin.executors import Executor
from twin.fusion import RULES, logodds_weights
from twin.store import write_text_atomic

DEFAULT_RATES: tuple[float, ...] = tuple(round(0.1 * i, 1) for i in range(11))
# Indices of the rules inside the trial kernel's state; the order is fixed.
KERNEL_RULES: tuple[str, ...] = ("accumulate", "normalized", "logodds")
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
    fusion: tuple[str, ...] = KERNEL_RULES
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

    @property
    def checkpoints(self) -> tuple[int, ...]:
        return tuple(sorted(set(self.views)))

    def settings(self) -> list[tuple[float, float]]:
        return [(pfp, pfn) for pfp in self.pfp for pfn in self.pfn]


@dataclass(frozen=True)
class SettingResult:
    """Successes of every kernel rule at every checkpoint, for one (P_fp, P_fn) setting."""

    pfp: float
    pfn: float
    trials: int
    checkpoints: tuple[int, ...]
    successes: np.ndarray = field(repr=False)  # (len(KERNEL_RULES), len(checkpoints)) ints

    def rows(self, fusion: Iterable[str]) -> list[dict[str, object]]:
        out = []
        for rule in fusion:
            r = KERNEL_RULES.index(rule)
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
def _wedge_meets_cell(px, py, a0, a1, col, row) -> bool:
    """Whether the wedge [a0, a1] from (px, py) meets the unit cell (col, row), exactly.

    The robot is outside the cell, so the cell's corners span less than pi as seen from it;
    the wedge meets the cell iff that span overlaps the wedge's span (modulo 2 pi).
    """
    centre = math.atan2(row + 0.5 - py, col + 0.5 - px)
    lo = math.inf
    hi = -math.inf
    for cx in (col + 0.0, col + 1.0):
        for cy in (row + 0.0, row + 1.0):
            d = (math.atan2(cy - py, cx - px) - centre + math.pi) % (2.0 * math.pi) - math.pi
            lo = min(lo, d)
            hi = max(hi, d)
    start = (a0 - centre + math.pi) % (2.0 * math.pi) - math.pi
    width = a1 - a0
    for shift in (-2.0 * math.pi, 0.0, 2.0 * math.pi):
        if start + shift < hi and start + shift + width > lo:
            return True
    return False


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
def _run_trial(
    n, supersample, fov, n_wedges, object_row, object_col, xs, ys, yaws, fire_u, tie_u,
    checkpoints, pfp, pfn, fired_weight, silent_weight, min_observed,
):  # fmt: skip
    """Run one trial for all three rules; returns successes (3, len(checkpoints)) as bools."""
    # state[0]: evidence of accumulate and normalized (same sums), [1]: observed, [2]: logodds
    state = np.zeros((3, n, n))
    a0 = np.empty(n_wedges)
    a1 = np.empty(n_wedges)
    weights = np.empty((3, n_wedges))
    wedge = fov / n_wedges
    success = np.zeros((3, checkpoints.shape[0]), dtype=np.bool_)
    normalized = np.zeros((n, n))
    c = 0
    for v in range(xs.shape[0]):
        for w in range(n_wedges):
            a1[w] = yaws[v] + 0.5 * fov - w * wedge
            a0[w] = a1[w] - wedge
            hit = _wedge_meets_cell(xs[v], ys[v], a0[w], a1[w], object_col, object_row)
            fired = fire_u[v, w] < ((1.0 - pfn) if hit else pfp)
            weights[0, w] = 1.0 if fired else 0.0
            weights[1, w] = 1.0
            weights[2, w] = fired_weight if fired else silent_weight
        add_coverage(state, xs[v], ys[v], a0, a1, weights, 0.0, 0.0, 1.0, supersample, 0.0)
        if v + 1 == checkpoints[c]:
            for r in range(n):
                for q in range(n):
                    seen = state[1, r, q]
                    ok = seen > 0.0 and seen >= min_observed
                    normalized[r, q] = state[0, r, q] / seen if ok else 0.0
            success[0, c] = _argmax_hits(state[0], tie_u[c], object_row, object_col)
            success[1, c] = _argmax_hits(normalized, tie_u[c], object_row, object_col)
            success[2, c] = _argmax_hits(state[2], tie_u[c], object_row, object_col)
            c += 1
            if c == checkpoints.shape[0]:
                break
    return success


def run_trial(config: SweepConfig, pfp: float, pfn: float, trial: int) -> np.ndarray:
    """Successes (len(KERNEL_RULES), len(checkpoints)) of one trial, as booleans."""
    draws = draw_trial(config, trial_rng(config.seed, pfp, pfn, trial))
    fired_weight, silent_weight = logodds_weights(pfp, pfn)
    return _run_trial(
        config.grid, config.supersample, config.fov, config.wedges, draws.object_row,
        draws.object_col, draws.x, draws.y, draws.yaw, draws.fire, draws.tie,
        np.asarray(config.checkpoints, dtype=np.int64), pfp, pfn, fired_weight, silent_weight,
        config.min_observed,
    )  # fmt: skip


def run_setting(config: SweepConfig, setting: tuple[float, float]) -> SettingResult:
    """All trials of one (P_fp, P_fn) setting."""
    pfp, pfn = setting
    successes = np.zeros((len(KERNEL_RULES), len(config.checkpoints)), dtype=np.int64)
    for trial in range(config.trials):
        successes += run_trial(config, pfp, pfn, trial)
    return SettingResult(pfp, pfn, config.trials, config.checkpoints, successes)


def result_rows(config: SweepConfig, results: Sequence[SettingResult]) -> list[dict[str, object]]:
    """Rows of ``results.csv`` in a stable order: rule, P_fp, P_fn, views."""
    rows = [row for result in results for row in result.rows(config.fusion)]
    order = {rule: i for i, rule in enumerate(config.fusion)}
    return sorted(rows, key=lambda r: (order[r["fusion"]], r["pfp"], r["pfn"], r["views"]))


# -- running a sweep, resumably ----------------------------------------------------------------

JOURNAL_NAME = "settings.jsonl"


def _identity(config: SweepConfig) -> dict[str, object]:
    """The parameters that decide a setting's result (the rules reported do not: all run)."""
    return {
        "trials": config.trials,
        "wedges": config.wedges,
        "fov": config.fov,
        "grid": config.grid,
        "supersample": config.supersample,
        "seed": config.seed,
        "min_observed": config.min_observed,
        "checkpoints": list(config.checkpoints),
    }


class SweepJournal:
    """An append-only record of finished settings, so an interrupted sweep resumes.

    The first line holds the sweep's identity; each further line one finished setting. A line
    torn by a crash is ignored (that setting simply runs again).
    """

    def __init__(self, path: Path, config: SweepConfig, fresh: bool = False) -> None:
        self.path = path
        self.config = config
        self.done: dict[tuple[float, float], SettingResult] = {}
        identity = _identity(config)
        if path.exists() and not fresh:
            self._read(identity)
        else:
            path.parent.mkdir(parents=True, exist_ok=True)
            with path.open("w", encoding="utf-8") as handle:
                handle.write(json.dumps({"sweep": identity}) + "\n")

    def _read(self, identity: dict[str, object]) -> None:
        lines = self.path.read_text(encoding="utf-8").splitlines()
        try:
            recorded = json.loads(lines[0])["sweep"]
        except (IndexError, KeyError, TypeError, json.JSONDecodeError):
            raise InputError(
                f"{self.path} is not a sweep journal; choose another --out or pass --fresh"
            ) from None
        if recorded != identity:
            changed = sorted(k for k in identity if recorded.get(k) != identity[k])
            raise InputError(
                f"{self.path.parent} holds a sweep with other parameters ({', '.join(changed)}); "
                "choose another --out, or pass --fresh to discard it"
            )
        for line in lines[1:]:
            try:
                entry = json.loads(line)
                result = SettingResult(
                    float(entry["pfp"]),
                    float(entry["pfn"]),
                    self.config.trials,
                    self.config.checkpoints,
                    np.asarray(entry["successes"], dtype=np.int64),
                )
            except (KeyError, TypeError, ValueError):
                continue  # a torn last line: that setting runs again
            if result.successes.shape == (len(KERNEL_RULES), len(self.config.checkpoints)):
                self.done[(result.pfp, result.pfn)] = result

    def record(self, result: SettingResult) -> None:
        entry = {"pfp": result.pfp, "pfn": result.pfn, "successes": result.successes.tolist()}
        with self.path.open("a", encoding="utf-8") as handle:
            handle.write(json.dumps(entry) + "\n")
            handle.flush()
            os.fsync(handle.fileno())
        self.done[(result.pfp, result.pfn)] = result


def run_sweep(
    config: SweepConfig,
    executor: Executor,
    journal: SweepJournal | None = None,
    on_result: Callable[[SettingResult], None] | None = None,
) -> list[SettingResult]:
    """Run every setting not already in ``journal``; return all results in setting order."""
    done = dict(journal.done) if journal else {}
    todo = [s for s in config.settings() if s not in done]
    for _, result in executor.map_unordered(partial(run_setting, config), todo):
        if journal:
            journal.record(result)
        done[(result.pfp, result.pfn)] = result
        if on_result:
            on_result(result)
    return [done[s] for s in config.settings()]


def write_results_csv(path: Path, rows: Sequence[dict[str, object]]) -> Path:
    """``results.csv`` with exactly ``RESULT_COLUMNS``, written atomically."""
    buffer = io.StringIO()
    writer = csv.DictWriter(buffer, fieldnames=RESULT_COLUMNS, lineterminator="\n")
    writer.writeheader()
    writer.writerows(rows)
    return write_text_atomic(path, buffer.getvalue())
