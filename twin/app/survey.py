"""The survey mission (paper, Section 2): stops, views, detection, fusion, estimates.

At every stop the robot looks in each of the mission's headings, by panning the head where its
range allows and turning the base for the rest; every frame's per-patch scores are reduced to
one value per patch column (the maximum over the column's rows), each column becomes a bearing
wedge from the camera's position, and the wedges are fused into the grid's object layers.

The loop knows the robot only through ``twin.core.devices`` (sim and hardware alike). After every
view the grid is saved atomically; the grid's own view count is what a resumed run trusts, so
an interruption at any moment neither loses nor double-counts a view.
"""

from __future__ import annotations

import json
import math
import time
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Protocol

import numpy as np

from twin.app.config import MissionConfig
from twin.app.record import NullRecorder, Recorder, ViewRecord
from twin.core.devices import PanTiltLimits, Robot
from twin.core.errors import TwinError
from twin.core.geometry import Pose2D, wrap_angle
from twin.core.grid import AccumulatorGrid
from twin.core.store import write_text_atomic

CHECKPOINT_GRID = "checkpoint/grid.npz"
CHECKPOINT_STATE = "checkpoint/state.json"
PAN_MARGIN = math.radians(5.0)  # stay clear of the head's end stops
TIMING_KEYS = ("physics", "render", "detect", "fuse", "record", "total")


class PatchDetector(Protocol):
    """What the mission needs from a detector (``twin.rfch.Detector`` is one)."""

    @property
    def names(self) -> list[str]: ...

    def scores(self, image: np.ndarray) -> np.ndarray: ...

    def patch_boxes(self, shape: tuple[int, ...]) -> np.ndarray: ...

    def column_spans(self, width: int) -> np.ndarray: ...


@dataclass(frozen=True)
class PlannedView:
    """One view of the plan: where the base stands and faces, and the head's pan (radians)."""

    index: int
    stop: int
    base: Pose2D
    pan: float


def plan_views(mission: MissionConfig, limits: PanTiltLimits) -> list[PlannedView]:
    """Every view of the mission, in the order the robot takes them.

    With ``turn = "pan"`` each stop's headings are covered by as few base orientations as the
    pan range allows (greedily, each orientation facing an uncovered heading and taking every
    heading within reach), ordered to turn the least; with ``"base"`` the base faces every
    heading with the head straight.
    """
    reach = min(limits.pan_max, -limits.pan_min) - PAN_MARGIN
    views: list[PlannedView] = []
    yaw = mission.start[2]
    for stop_index, (x, y) in enumerate(mission.stops):
        remaining = list(mission.headings)
        while remaining:
            if mission.turn == "base" or reach <= 0.0:
                base_yaw = _nearest(remaining, yaw)
                taken = [base_yaw]
            else:
                base_yaw, taken = _best_orientation(remaining, yaw, reach)
            for heading in sorted(taken, key=lambda h: wrap_angle(h - base_yaw)):
                pan = float(wrap_angle(heading - base_yaw))
                views.append(PlannedView(len(views), stop_index, Pose2D(x, y, base_yaw), pan))
                remaining.remove(heading)
            yaw = base_yaw
    return views


def _nearest(headings: Sequence[float], yaw: float) -> float:
    return min(headings, key=lambda h: abs(wrap_angle(h - yaw)))


def _best_orientation(
    headings: Sequence[float], yaw: float, reach: float
) -> tuple[float, list[float]]:
    """The base yaw (one of the headings) covering most headings; ties: least turning."""

    def covered(base: float) -> list[float]:
        return [h for h in headings if abs(wrap_angle(h - base)) <= reach + 1e-9]

    best = max(headings, key=lambda b: (len(covered(b)), -abs(wrap_angle(b - yaw))))
    return float(wrap_angle(best)), covered(best)


@dataclass
class SurveyState:
    """What a run has done so far, besides the grid: saved beside it after every view."""

    views_done: int = 0
    path: list[list[float]] = field(default_factory=list)  # [x, y, yaw] per view
    timings: dict[str, float] = field(default_factory=lambda: dict.fromkeys(TIMING_KEYS, 0.0))

    def to_json(self) -> str:
        return json.dumps(
            {"views_done": self.views_done, "path": self.path, "timings_s": self.timings}, indent=1
        )

    @classmethod
    def read(cls, path: Path) -> SurveyState:
        if not path.is_file():
            return cls()
        try:
            data = json.loads(path.read_text(encoding="utf-8"))
            timings = {k: float(data["timings_s"].get(k, 0.0)) for k in TIMING_KEYS}
            return cls(int(data["views_done"]), list(data["path"]), timings)
        except (ValueError, KeyError, TypeError, AttributeError):
            return cls()  # progress notes only: the grid holds what counts


@dataclass(frozen=True)
class SurveyContext:
    """Everything a survey runs with, built by the caller from the config."""

    robot: Robot
    detector: PatchDetector
    grid: AccumulatorGrid
    mission: MissionConfig
    out: Path
    max_range: float | None = None
    recorder: Recorder = field(default_factory=NullRecorder)
    camera_height: float = 1.0


def column_values(scores: np.ndarray) -> np.ndarray:
    """Per-column match: the maximum over each column's patch rows, (objects, cols)."""
    return scores.max(axis=1)


def run_survey(
    context: SurveyContext,
    on_view: Callable[[PlannedView], None] | None = None,
    resume: bool = False,
) -> SurveyState:
    """Run (or, with ``resume``, continue) the mission; return its state when all is fused.

    The robot must be connected. With ``resume`` the grid is read from the checkpoint and the
    views it already holds are skipped; without it the checkpoint starts empty.
    """
    robot, grid, out = context.robot, context.grid, context.out
    plan = plan_views(context.mission, robot.pantilt.limits)
    grid_path, state_path = out / CHECKPOINT_GRID, out / CHECKPOINT_STATE
    state = SurveyState.read(state_path) if resume else SurveyState()
    done = grid.views(grid.objects[0])
    if done > len(plan):
        raise TwinError(
            f"{grid_path} holds {done} views but the mission has {len(plan)}; "
            "resume with the config the run started with"
        )
    state.views_done = done
    del state.path[done:]
    names = context.detector.names
    if sorted(names) != sorted(grid.objects):
        raise TwinError(f"the detector finds {names} but the grid holds {list(grid.objects)}")
    timings = state.timings
    for planned in plan[done:]:
        started = time.perf_counter()
        if on_view:
            on_view(planned)
        tick = time.perf_counter()
        robot.base.go_to(planned.base)
        robot.pantilt.move_to(planned.pan, context.mission.tilt)
        timings["physics"] += time.perf_counter() - tick

        tick = time.perf_counter()
        view = robot.capture()
        timings["render"] += time.perf_counter() - tick

        tick = time.perf_counter()
        scores = context.detector.scores(view.image)
        values = column_values(scores)
        spans = context.detector.column_spans(view.image.shape[1])
        camera = robot.camera.model
        wedges = camera.wedges(view.pose, view.pan, spans)
        timings["detect"] += time.perf_counter() - tick

        tick = time.perf_counter()
        per_object = {name: values[i] for i, name in enumerate(names)}
        grid.fuse_all((view.pose.x, view.pose.y), wedges, per_object, context.max_range)
        grid.save(grid_path)
        state.views_done = planned.index + 1
        state.path.append([view.pose.x, view.pose.y, view.pose.yaw])
        timings["fuse"] += time.perf_counter() - tick

        tick = time.perf_counter()
        context.recorder.log_view(
            ViewRecord(
                planned.index,
                planned.stop,
                view,
                view.timestamp,
                camera,
                context.camera_height,
                context.detector.patch_boxes(view.image.shape),
                {name: scores[i] for i, name in enumerate(names)},
                wedges,
                per_object,
            ),
            grid,
        )
        timings["record"] += time.perf_counter() - tick
        timings["total"] += time.perf_counter() - started
        write_text_atomic(state_path, state.to_json())
    return state


def estimates(
    grid: AccumulatorGrid,
    truth: dict[str, tuple[float, float]] | None = None,
    min_separation: float = 0.5,
) -> dict[str, dict[str, Any]]:
    """Per object: the best peak in metres, its value, the first/second peak ratio, and, when
    the truth is known (simulation), the truth and the estimate's error in metres."""
    out: dict[str, dict[str, Any]] = {}
    for name in grid.objects:
        peaks = grid.peaks(name, k=3, min_separation=min_separation)
        best = peaks.best
        entry: dict[str, Any] = {
            "estimate_m": [round(best.x, 4), round(best.y, 4)],
            "peak": best.value,
            "peak_ratio": peaks.ratio if math.isfinite(peaks.ratio) else None,
            "peaks": [
                {"xy_m": [round(p.x, 4), round(p.y, 4)], "value": p.value} for p in peaks.peaks
            ],
        }
        if truth and name in truth:
            tx, ty = truth[name]
            entry["truth_m"] = [round(tx, 4), round(ty, 4)]
            entry["error_m"] = round(math.hypot(best.x - tx, best.y - ty), 4)
        out[name] = entry
    return out
