"""Batches of randomized survey missions: many runs of the mission, one summary.

Run ``i`` of a batch with seed ``S`` draws each varied factor from its own generator,
``SeedSequence(S, spawn_key=(i, k))`` with k = 0 target, 1 lighting, 2 threshold, so a run's
draws depend only on (S, i) and on which factors vary, never on the executor, the number of
workers or which worker ran it. The factors:

* **target** — every object with a scene body is put on a random level furniture top
  (``twin.sim.placement.random_surface_pose``); otherwise it stays where the scene has it.
* **lighting** — the diffuse intensity of every scene light and the headlight's diffuse and
  ambient are scaled by one factor drawn uniformly from ``lighting`` (default 0.5 .. 1.5: from a
  dim evening room to one brighter than the scene's default; the detector was trained at 1.0).
* **threshold** — a detector threshold drawn uniformly from ``threshold`` (default 0 .. 0.25):
  every patch score below it reads 0 before fusion, so a column whose best patch is below it
  contributes nothing (the same cut as the logodds rule's ``threshold``, applied to any rule).
  Not varied, it is 0: the scores pass unchanged.

A worker keeps its MuJoCo world, renderer and trained detector between missions
(``_WORLDS``, one per batch in each worker process) and resets them before each mission: the
target back to the scene's pose, the lights to the drawn scale, the physics state to MuJoCo's
reset state (time 0, no warm-start), the robot placed at the mission's start. A mission in a
reused world is therefore the same as in a fresh one (a test checks it).

Results stream back to the caller, which appends each to ``DIR/runs.jsonl`` as it arrives: a
batch run again into the same folder runs only the missing runs (and may add runs).
"""

from __future__ import annotations

import csv
import hashlib
import io
import json
import math
import os
import socket
import tempfile
import time
import tomllib
from collections.abc import Callable, Sequence
from dataclasses import dataclass
from functools import partial
from pathlib import Path
from typing import Any

import numpy as np

from twin.app.executors import Executor
from twin.core.errors import InputError, TwinError
from twin.core.store import JsonLinesJournal, json_safe, write_text_atomic

VARY = ("target", "lighting", "threshold")
_FACTOR_KEY = {name: k for k, name in enumerate(VARY)}
DEFAULT_LIGHTING = (0.5, 1.5)  # scale of the scene's light intensities
# RFCH patch scores below this read 0. The rendered-frame ROC puts the best cut near 0.16
# (benchmarks/rfch_rendered.py); above ~0.35 the box's own columns are cut and a run says nothing.
DEFAULT_THRESHOLD = (0.0, 0.25)
SUCCESS_RADIUS_M = 0.3
JOURNAL_NAME = "runs.jsonl"
SUMMARY_COLUMNS = (
    "run", "success", "error_m", "truth_x", "truth_y", "estimate_x", "estimate_y", "surface",
    "lighting", "threshold", "peak", "peak_ratio", "views", "setup_s", "physics_s", "render_s",
    "detect_s", "fuse_s", "mission_s", "reused_world",
)  # fmt: skip


@dataclass(frozen=True)
class BatchSpec:
    """What every run of a batch shares: the config (its text, so remote workers need no copy
    of the file), where its relative paths resolve, the seed and the varied factors."""

    config_text: str
    config_name: str
    config_folder: str  # relative scene/model paths resolve here, else in the shipped scenes
    working_dir: str  # run.cache (the trained detector) resolves here
    seed: int = 0
    vary: tuple[str, ...] = VARY
    lighting: tuple[float, float] = DEFAULT_LIGHTING
    threshold: tuple[float, float] = DEFAULT_THRESHOLD
    tolerance: float = SUCCESS_RADIUS_M

    def __post_init__(self) -> None:
        unknown = [v for v in self.vary if v not in VARY]
        if unknown:
            raise InputError(
                f"--vary: unknown factor {unknown[0]!r}; choose from {', '.join(VARY)}"
            )
        if self.seed < 0:
            raise InputError(f"--seed must be a non-negative integer, got {self.seed}")
        lo, hi = self.lighting
        if not (0.0 < lo <= hi) or not math.isfinite(hi):
            raise InputError(f"--lighting must be LOW,HIGH with 0 < LOW <= HIGH, got {lo},{hi}")
        lo, hi = self.threshold
        if not (0.0 <= lo <= hi <= 1.0):
            raise InputError(f"--threshold must be LOW,HIGH within [0, 1], got {lo},{hi}")
        if not self.tolerance > 0.0:
            raise InputError(
                f"--tolerance must be a positive distance in metres, got {self.tolerance}"
            )

    def identity(self) -> dict[str, Any]:
        """What decides a run's result (the tolerance only scores it, so it is not here)."""
        return {
            "config_sha256": hashlib.sha256(self.config_text.encode()).hexdigest(),
            "seed": self.seed,
            "vary": sorted(self.vary),
            "lighting": list(self.lighting),
            "threshold": list(self.threshold),
        }

    def load(self):
        """The parsed config (``twin.app.config.SurveyConfig``), on whichever machine runs this."""
        from twin.app.config import ConfigError, parse_config

        try:
            data = tomllib.loads(self.config_text)
        except tomllib.TOMLDecodeError as exc:
            raise ConfigError(f"{self.config_name}: not valid TOML ({exc}); fix the file") from None
        config = parse_config(
            data, self.config_name, Path(self.config_folder), Path(self.working_dir)
        )
        kinds = {d.type for d in config.devices.values()}
        if kinds != {"sim"}:
            raise InputError(
                f"{self.config_name}: batch-survey runs in the simulation only; "
                'give every robot device type = "sim"'
            )
        return config


@dataclass(frozen=True)
class MissionDraw:
    """A run's randomized factors (1.0 and 0.0 when not varied; target: seed of its draw)."""

    run: int
    lighting: float
    threshold: float
    place_target: bool


def factor_rng(seed: int, run: int, factor: str) -> np.random.Generator:
    return np.random.default_rng(np.random.SeedSequence(seed, spawn_key=(run, _FACTOR_KEY[factor])))


def draw_mission(spec: BatchSpec, run: int) -> MissionDraw:
    """Run ``run``'s factors: a function of (seed, run, factor) only."""
    lighting = 1.0
    threshold = 0.0
    if "lighting" in spec.vary:
        lighting = float(factor_rng(spec.seed, run, "lighting").uniform(*spec.lighting))
    if "threshold" in spec.vary:
        threshold = float(factor_rng(spec.seed, run, "threshold").uniform(*spec.threshold))
    return MissionDraw(run, lighting, threshold, "target" in spec.vary)


class ThresholdedDetector:
    """A detector whose patch scores below ``threshold`` read 0 (a ``PatchDetector``)."""

    def __init__(self, detector, threshold: float) -> None:
        self.detector = detector
        self.threshold = threshold

    @property
    def names(self) -> list[str]:
        return self.detector.names

    def scores(self, image: np.ndarray) -> np.ndarray:
        scores = self.detector.scores(image)
        if self.threshold <= 0.0:
            return scores
        return np.where(scores >= self.threshold, scores, 0.0).astype(scores.dtype, copy=False)

    def patch_boxes(self, shape: tuple[int, ...]) -> np.ndarray:
        return self.detector.patch_boxes(shape)

    def column_spans(self, width: int) -> np.ndarray:
        return self.detector.column_spans(width)


class MissionWorld:
    """One worker's MuJoCo world, connected robot and trained detector, reused between runs."""

    def __init__(self, spec: BatchSpec) -> None:
        from twin.app.detection import prepare_detector
        from twin.app.factory import build_robot

        self.config = config = spec.load()
        self.robot, context = build_robot(config)
        self.sim = context.sim
        self.start = context.start
        self.world = world = self.sim.world
        model = world.model
        self.targets = {o.name: o.body for o in config.objects if o.body is not None}
        self._body_pose = {
            body: (model.body_pos[world.body_id(body)].copy(),
                   model.body_quat[world.body_id(body)].copy())
            for body in self.targets.values()
        }  # fmt: skip
        self._light = model.light_diffuse.copy()
        self._head_diffuse = model.vis.headlight.diffuse.copy()
        self._head_ambient = model.vis.headlight.ambient.copy()
        quiet = lambda _: None  # noqa: E731 - the detector is trained before workers start
        self.detector = prepare_detector(config.objects, config.detector, config.cache, quiet)
        self.robot.connect()
        self.missions = 0

    def reset(self, spec: BatchSpec, draw: MissionDraw) -> dict[str, str]:
        """Put the world in run ``draw``'s state; returns the furniture each target stands on."""
        import mujoco

        from twin.sim.placement import random_surface_pose

        world, model = self.world, self.world.model
        model.light_diffuse[:] = self._light * draw.lighting
        model.vis.headlight.diffuse[:] = self._head_diffuse * draw.lighting
        model.vis.headlight.ambient[:] = self._head_ambient * draw.lighting
        for body, (pos, quat) in self._body_pose.items():
            model.body_pos[world.body_id(body)] = pos
            model.body_quat[world.body_id(body)] = quat
        mujoco.mj_resetData(model, world.data)
        world.forward()
        if draw.place_target:
            rng = factor_rng(spec.seed, draw.run, "target")
            for body in self.targets.values():
                random_surface_pose(world, body, rng)
        self.sim.place(self.start)
        return {name: self._surface(body) for name, body in self.targets.items()}

    def _surface(self, body: str) -> str:
        x, y = (float(v) for v in self.world.body_position(body)[:2])
        for name, footprint in self.world.footprints().items():
            if name == body:
                continue
            xmin, ymin, xmax, ymax = footprint.aabb
            if xmin <= x <= xmax and ymin <= y <= ymax and name in self.world.furniture():
                return name
        return "floor"

    def close(self) -> None:
        self.robot.close()


_WORLDS: dict[str, MissionWorld] = {}  # per worker process: the batch's world, kept alive


def _world_for(spec: BatchSpec) -> tuple[MissionWorld, bool]:
    key = json.dumps(spec.identity(), sort_keys=True) + spec.config_folder + spec.working_dir
    if key in _WORLDS:
        return _WORLDS[key], True
    for old in _WORLDS.values():  # one world per worker: a new batch replaces the last
        old.close()
    _WORLDS.clear()
    _WORLDS[key] = MissionWorld(spec)
    return _WORLDS[key], False


def run_mission(spec: BatchSpec, run: int) -> dict[str, Any]:
    """One randomized mission (the task a worker runs); returns its JSON-ready result."""
    from twin.app.record import NullRecorder
    from twin.app.survey import SurveyContext, estimates, run_survey
    from twin.core.grid import AccumulatorGrid

    started = time.perf_counter()
    mission_world, reused = _world_for(spec)
    config = mission_world.config
    draw = draw_mission(spec, run)
    surfaces = mission_world.reset(spec, draw)
    grid = AccumulatorGrid(
        [o.name for o in config.objects], config.grid.spec, config.grid.rule,
        config.grid.supersample,
    )  # fmt: skip
    detector = ThresholdedDetector(mission_world.detector, draw.threshold)
    setup = time.perf_counter() - started
    with tempfile.TemporaryDirectory(prefix="twin-batch-") as scratch:  # checkpoints: unused
        context = SurveyContext(
            mission_world.robot, detector, grid, config.mission, Path(scratch),
            config.grid.max_range, NullRecorder(),
        )  # fmt: skip
        state = run_survey(context)
    world = mission_world.world
    truth = {
        name: tuple(float(v) for v in world.body_position(body)[:2])
        for name, body in mission_world.targets.items()
    }
    objects = estimates(grid, truth, config.grid.peak_separation)
    for name, surface in surfaces.items():
        objects[name]["surface"] = surface
    mission_world.missions += 1
    return {
        "run": run,
        "lighting": draw.lighting,
        "threshold": draw.threshold,
        "objects": json_safe(objects),
        "views": state.views_done,
        "timings_s": {
            "setup": round(setup, 3),
            **{k: round(v, 3) for k, v in state.timings.items()},
            "mission": round(time.perf_counter() - started, 3),
        },
        "reused_world": reused,
        "worker": f"{socket.gethostname()}:{os.getpid()}",
    }


# -- the batch, resumably ----------------------------------------------------------------------


class BatchJournal:
    """``DIR/runs.jsonl``: the batch's identity, then one finished run per line, appended as
    each arrives. A torn last line is ignored (that run runs again)."""

    def __init__(self, path: Path, spec: BatchSpec, fresh: bool = False) -> None:
        self.path = path
        self._journal = JsonLinesJournal(path, "batch", spec.identity(), fresh)
        self.done: dict[int, dict[str, Any]] = {}
        for entry in self._journal.entries:
            try:
                self.done[int(entry["run"])] = entry
            except (KeyError, TypeError, ValueError):
                continue

    def record(self, result: dict[str, Any]) -> None:
        self._journal.append(result)
        self.done[int(result["run"])] = result


def prepare(spec: BatchSpec, say: Callable[[str], None] = print) -> None:
    """Check the config and train (or load) the detector once here, before workers start, so
    local workers find it cached instead of each training it."""
    from twin.app.detection import prepare_detector

    config = spec.load()
    if not any(o.body is not None for o in config.objects):
        raise InputError(
            f"{spec.config_name}: objects: batch-survey scores estimates against a scene body; "
            "give each object a body"
        )
    prepare_detector(config.objects, config.detector, config.cache, say)


def run_batch(
    spec: BatchSpec,
    runs: int,
    executor: Executor,
    journal: BatchJournal | None = None,
    on_result: Callable[[dict[str, Any]], None] | None = None,
) -> list[dict[str, Any]]:
    """Run every run of 0..runs-1 not in ``journal``; return all results in run order."""
    if runs < 1:
        raise InputError(f"--runs must be at least 1, got {runs}")
    done = dict(journal.done) if journal else {}
    todo = [i for i in range(runs) if i not in done]
    for _, result in executor.map_unordered(partial(run_mission, spec), todo):
        if journal:
            journal.record(result)
        done[int(result["run"])] = result
        if on_result:
            on_result(result)
    return [done[i] for i in range(runs)]


# -- the summary -------------------------------------------------------------------------------


def target_name(results: Sequence[dict[str, Any]]) -> str:
    """The object scored in the summary: the first with ground truth."""
    for name, entry in results[0]["objects"].items():
        if "error_m" in entry:
            return name
    raise TwinError("no object of the batch has ground truth; give each object a scene body")


def summary_rows(results: Sequence[dict[str, Any]], tolerance: float) -> list[dict[str, Any]]:
    name = target_name(results)
    rows = []
    for r in results:
        entry, t = r["objects"][name], r["timings_s"]
        rows.append({
            "run": r["run"],
            "success": int(entry["error_m"] <= tolerance),
            "error_m": entry["error_m"],
            "truth_x": entry["truth_m"][0], "truth_y": entry["truth_m"][1],
            "estimate_x": entry["estimate_m"][0], "estimate_y": entry["estimate_m"][1],
            "surface": entry.get("surface", ""),
            "lighting": round(r["lighting"], 4), "threshold": round(r["threshold"], 4),
            "peak": entry["peak"], "peak_ratio": entry["peak_ratio"], "views": r["views"],
            "setup_s": t["setup"], "physics_s": t["physics"], "render_s": t["render"],
            "detect_s": t["detect"], "fuse_s": t["fuse"], "mission_s": t["mission"],
            "reused_world": int(r["reused_world"]),
        })  # fmt: skip
    return rows


def summarize(
    spec: BatchSpec, results: Sequence[dict[str, Any]], wall_s: float | None = None
) -> dict[str, Any]:
    """Success rate within the tolerance, the error distribution and the timings."""
    rows = summary_rows(results, spec.tolerance)
    errors = np.array([r["error_m"] for r in rows])
    hits = int(sum(r["success"] for r in rows))
    timing_keys = ("setup_s", "physics_s", "render_s", "detect_s", "fuse_s", "mission_s")
    summary: dict[str, Any] = {
        "target": target_name(results),
        "runs": len(rows),
        "seed": spec.seed,
        "vary": list(spec.vary),
        "lighting_range": list(spec.lighting),
        "threshold_range": list(spec.threshold),
        "tolerance_m": spec.tolerance,
        "successes": hits,
        "success_rate": hits / len(rows),
        "error_m": {
            "mean": float(errors.mean()),
            "median": float(np.median(errors)),
            "p90": float(np.percentile(errors, 90)),
            "min": float(errors.min()),
            "max": float(errors.max()),
        },
        "timings_s": {
            k[:-2]: {
                "mean": float(np.mean([r[k] for r in rows])),
                "total": float(np.sum([r[k] for r in rows])),
            }
            for k in timing_keys
        },
        "worlds_reused": int(sum(r["reused_world"] for r in rows)),
    }
    if wall_s is not None:
        summary["wall_s"] = round(wall_s, 3)
    return summary


def write_summary(
    out: Path, spec: BatchSpec, results: Sequence[dict[str, Any]], wall_s: float | None = None
) -> tuple[dict[str, Any], list[Path]]:
    """``summary.csv`` (one row per run), ``summary.json`` and the plots; returns the summary."""
    rows = summary_rows(results, spec.tolerance)
    buffer = io.StringIO()
    writer = csv.DictWriter(buffer, fieldnames=SUMMARY_COLUMNS, lineterminator="\n")
    writer.writeheader()
    writer.writerows(rows)
    paths = [write_text_atomic(out / "summary.csv", buffer.getvalue())]
    summary = summarize(spec, results, wall_s)
    paths.append(write_text_atomic(out / "summary.json", json.dumps(summary, indent=1)))
    paths.append(_error_histogram(out / "errors.png", rows, spec.tolerance))
    factors = {"target": "surface", "lighting": "lighting", "threshold": "threshold"}
    for factor in spec.vary:
        paths.append(_success_vs(out / f"success_vs_{factor}.png", rows, factors[factor]))
    return summary, paths


def _pyplot():
    import matplotlib

    matplotlib.use("Agg", force=True)
    import matplotlib.pyplot as plt

    return plt


def _error_histogram(path: Path, rows: list[dict[str, Any]], tolerance: float) -> Path:
    from twin.app.plots import save_figure

    plt = _pyplot()
    fig, ax = plt.subplots(figsize=(5.5, 3.5))
    errors = [r["error_m"] for r in rows]
    ax.hist(errors, bins=min(30, max(5, len(errors) // 3)), color="#4477aa")
    ax.axvline(tolerance, color="#cc3311", linestyle="--", label=f"success radius {tolerance} m")
    ax.set_xlabel("estimate error (m)")
    ax.set_ylabel("runs")
    ax.set_title(f"{len(rows)} runs: {100 * np.mean([r['success'] for r in rows]):.0f} % success")
    ax.legend()
    return save_figure(fig, path)


def _success_vs(path: Path, rows: list[dict[str, Any]], key: str) -> Path:
    """Success rate per furniture top, or per bin (about 5) of a numeric factor."""
    from twin.app.plots import save_figure

    plt = _pyplot()
    fig, ax = plt.subplots(figsize=(5.5, 3.5))
    if key == "surface":
        labels = sorted({r[key] for r in rows})
        groups = [[r["success"] for r in rows if r[key] == label] for label in labels]
        ax.set_xlabel("furniture the target stands on")
    else:
        values = np.array([r[key] for r in rows])
        edges = np.linspace(values.min(), values.max() + 1e-9, min(5, len(rows)) + 1)
        which = np.clip(np.digitize(values, edges) - 1, 0, len(edges) - 2)
        labels = [f"{edges[i]:.2f}-{edges[i + 1]:.2f}" for i in range(len(edges) - 1)]
        groups = [[r["success"] for r, w in zip(rows, which, strict=True) if w == i]
                  for i in range(len(labels))]  # fmt: skip
        ax.set_xlabel("light scale" if key == "lighting" else "detector threshold")
    rates = [100 * np.mean(g) if g else 0.0 for g in groups]
    bars = ax.bar(range(len(labels)), rates, color="#228833")
    for bar, group in zip(bars, groups, strict=True):
        ax.annotate(f"n={len(group)}", (bar.get_x() + bar.get_width() / 2, bar.get_height()),
                    ha="center", va="bottom", fontsize=8)  # fmt: skip
    ax.set_xticks(range(len(labels)), labels, rotation=30, ha="right", fontsize=8)
    ax.set_ylabel("success (%)")
    ax.set_ylim(0, 110)
    return save_figure(fig, path)
