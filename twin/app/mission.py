"""One mission run: the single place where a view happens.

A ``Mission`` owns what one run works with (the robot's devices, the detector, the grid, the
recorder, the checkpoint and the timings) and ``observe(target)`` does one view end to end:
move the base and the head, capture, score every patch, turn each patch column into a bearing
wedge from the pose the view was taken at, fuse the wedges into every object's layer, record,
checkpoint. The paper's fixed survey (``twin.app.survey``), the batch (``twin.app.batch``) and
later planners only choose targets; none of them repeats this body.

After every view the recording is flushed and then the grid and the mission's state are saved
atomically, in that order: what the grid checkpoint holds the recording holds, and the grid's
own view count is what a resumed mission trusts, so an interruption at any moment neither loses
nor double-counts a view. The robot's clock (``robot_time``) continues across a resume.
"""

from __future__ import annotations

import json
import math
import time
from collections.abc import Callable, Iterator, Mapping
from contextlib import contextmanager
from dataclasses import dataclass, field, replace
from pathlib import Path
from typing import Any, Protocol, runtime_checkable

import numpy as np

from twin.app.config import ConfidenceOptions
from twin.app.record import EstimatePoint, Localization, NullRecorder, Recorder, ViewRecord
from twin.app.view_log import LoggedView, ViewLog, fuse_view
from twin.core.devices import DeviceFaultError, Robot, View
from twin.core.errors import TwinError
from twin.core.geometry import CameraModel, Pose2D
from twin.core.grid import AccumulatorGrid, Peak, Peaks
from twin.core.height import HeightCheck, HeightEstimate, best_patch_elevations, height_fits
from twin.core.store import write_text_atomic
from twin.core.visibility import ColumnVisibility, SupportLevels

CHECKPOINT_GRID = "checkpoint/grid.npz"
CHECKPOINT_STATE = "checkpoint/state.json"
CHECKPOINT_VIEWS = "checkpoint/views.npz"
# Where a view's time goes: driving and panning (the physics, in the twin), taking the frame
# (rendering), scoring and projecting, fusing, recording, saving the checkpoint.
TIMING_KEYS = (
    "move", "capture", "detect", "visibility", "fuse", "record", "checkpoint", "total"
)  # fmt: skip


class PatchDetector(Protocol):
    """What a mission needs from a detector (``twin.rfch.Detector`` is one)."""

    @property
    def names(self) -> list[str]: ...

    def scores(self, image: np.ndarray) -> np.ndarray:
        """(objects, rows, cols) patch scores in [0, 1] of one H x W x 3 RGB frame."""
        ...

    def patch_boxes(self, shape: tuple[int, ...]) -> np.ndarray: ...

    def column_spans(self, width: int) -> np.ndarray: ...


class VisibilityModel(Protocol):
    """What the camera could have seen in a view (``twin.app.visibility_models``)."""

    def profiles(
        self, view: View, camera: CameraModel, column_spans: np.ndarray
    ) -> ColumnVisibility: ...


@runtime_checkable
class LocalizingBase(Protocol):
    """A base that localizes itself (``twin.app.localization``): what it saw is recorded."""

    def snapshot(self) -> Localization: ...


class ViewTarget(Protocol):
    """Where one view is taken from: the base's pose (map frame), the head's pan and tilt
    (radians, pan positive left), and the stop of a plan it belongs to (for progress). A target
    with an ``objects`` attribute (``PlannedView``'s floor sweep) is a view for those objects
    only; without one, or None, for all."""

    @property
    def stop(self) -> int: ...

    @property
    def base(self) -> Pose2D: ...

    @property
    def pan(self) -> float: ...

    @property
    def tilt(self) -> float: ...


class NotReachedError(DeviceFaultError):
    """A localizing base could not reach a view's place (no safe path, an obstacle in the way,
    a touch its recovery could not get round); it has stopped, backed off and localized again,
    so the mission may go on elsewhere."""


@dataclass
class MissionState:
    """What a mission has done besides the grid: saved beside it after every view."""

    views_done: int = 0
    path: list[list[float]] = field(default_factory=list)  # [x, y, yaw] each view was taken from
    timings: dict[str, float] = field(default_factory=lambda: dict.fromkeys(TIMING_KEYS, 0.0))
    robot_time: float = 0.0  # seconds on the robot's clock at the last view, across resumes
    truth_path: list[list[float]] = field(default_factory=list)  # simulation: where it really was
    refused: list[dict[str, Any]] = field(default_factory=list)  # {"view", "reason"}: not fused

    def to_json(self) -> str:
        return json.dumps(
            {
                "views_done": self.views_done,
                "path": self.path,
                "timings_s": self.timings,
                "robot_time_s": self.robot_time,
                "truth_path": self.truth_path,
                "refused": self.refused,
            },
            indent=1,
        )

    @classmethod
    def read(cls, path: Path) -> MissionState:
        """The saved state, or a fresh one if there is none or it is unreadable: these are
        progress notes, the grid holds what counts."""
        if not path.is_file():
            return cls()
        try:
            data = json.loads(path.read_text(encoding="utf-8"))
            timings = {k: float(data["timings_s"].get(k, 0.0)) for k in TIMING_KEYS}
            robot_time = float(data.get("robot_time_s", 0.0))
            refused = [
                {"view": int(r["view"]), "reason": str(r["reason"])}
                for r in data.get("refused", [])
            ]
            return cls(
                int(data["views_done"]),
                list(data["path"]),
                timings,
                robot_time,
                list(data.get("truth_path", [])),
                refused,
            )
        except (ValueError, KeyError, TypeError, AttributeError):
            return cls()


@dataclass(frozen=True)
class PoseGate:
    """The largest pose uncertainty (one standard deviation) a view may be fused with. A wedge
    drawn from a pose this unsure blurs, offsets or duplicates the maxima (the paper's §4), so
    such a view is refused instead, and the refusal is reported."""

    max_sigma_m: float = 0.05  # along the worst direction of the position's covariance
    max_sigma_yaw: float = math.radians(2.0)

    def reason(self, covariance: np.ndarray | None) -> str | None:
        """Why a view with this pose covariance may not be fused, or ``None`` if it may."""
        if covariance is None:
            return None
        cov = np.asarray(covariance, dtype=float)
        if cov.shape != (3, 3) or not np.all(np.isfinite(cov)):
            return "the pose's covariance is not a finite 3 x 3 matrix"
        sigma_xy = math.sqrt(max(0.0, float(np.linalg.eigvalsh(cov[:2, :2]).max())))
        sigma_yaw = math.sqrt(max(0.0, float(cov[2, 2])))
        if sigma_xy > self.max_sigma_m:
            return (
                f"pose uncertain: {100 * sigma_xy:.1f} cm (1 sigma), more than the "
                f"{100 * self.max_sigma_m:g} cm allowed"
            )
        if sigma_yaw > self.max_sigma_yaw:
            return (
                f"pose uncertain: {math.degrees(sigma_yaw):.1f} deg (1 sigma), more than the "
                f"{math.degrees(self.max_sigma_yaw):g} deg allowed"
            )
        return None


class Checkpoint:
    """A mission's checkpoint in its run folder: the grid and the state, written atomically."""

    def __init__(self, folder: Path) -> None:
        self.grid_path = folder / CHECKPOINT_GRID
        self.state_path = folder / CHECKPOINT_STATE
        self.views_path = folder / CHECKPOINT_VIEWS

    def load(self, grid: AccumulatorGrid) -> tuple[AccumulatorGrid, MissionState] | None:
        """The saved grid and state, checked against a grid made from the run's config; ``None``
        if nothing was saved yet."""
        if not self.grid_path.is_file():
            return None
        saved = AccumulatorGrid.load(self.grid_path)
        if list(saved.objects) != list(grid.objects) or saved.spec != grid.spec:
            raise TwinError(
                f"{self.grid_path} does not match the run's config (objects or grid extent "
                "differ); start a new run"
            )
        state = MissionState.read(self.state_path)
        # The grid counts the fused views, the state the refused ones; the grid is saved first,
        # so a state one view behind it missed that (fused) view's notes only.
        done = saved.views(saved.objects[0]) + len(state.refused)
        state.views_done = done
        del state.path[done:]
        del state.truth_path[done:]
        return saved, state

    def load_views(self, state: MissionState) -> ViewLog | None:
        """The saved view log cut to the views the grid holds (it is saved first, so it may be
        one ahead), or ``None`` if there is none or it is unreadable or short: the log serves
        comparisons and the confidence, the grid holds what counts."""
        from twin.core.errors import FileFormatError

        try:
            log = ViewLog.load(self.views_path)
        except (FileFormatError, OSError):
            return None
        if len(log) < state.views_done:
            return None
        log.truncate(state.views_done)
        return log

    def save(
        self, grid: AccumulatorGrid, state: MissionState, views: ViewLog | None = None
    ) -> None:
        # Uncompressed: rewritten after every view, where compressing cost most of a view's
        # time on large floors (benchmarks/bench_scale.py); the run's final files are compressed.
        if views is not None:
            views.save(self.views_path, compress=False)
        grid.save(self.grid_path, compress=False)
        write_text_atomic(self.state_path, state.to_json())


class Mission:
    """One run of the robot: ``observe`` a target, as many times as a planner likes, then read
    ``result``. The robot must be connected while views are observed.

    ``truth`` (simulation only) maps objects to their true (x, y, z) in metres and
    ``truth_pose`` reads the base's true pose: both only annotate results and recordings, the
    estimate never sees them. ``state`` continues a resumed mission (``Checkpoint.load``), and
    ``views`` its view log (``Checkpoint.load_views``).

    ``visibility`` says per view what the camera could have seen; the grid weighs each wedge by
    it when ``fuse_visibility`` (the profiles are logged either way, for comparisons). ``belief``
    is a grid with the detector's calibrated rule (log-likelihood ratios), fused alongside
    ``grid`` (which may hold another rule, or be the same grid), always with the visibility
    when there is a model of it, for each object's ``confidence``, read with
    ``confidence_options``. ``height_check`` weighs each wedge by where its best patches'
    rows allow the object to stand (``twin.core.height.HeightCheck``). ``object_heights``
    gives each object's own height (m; the visibility model's one for the others): where its
    rows may put it above a surface, and how high it stands on the one it is found on.
    """

    def __init__(
        self,
        robot: Robot,
        detector: PatchDetector,
        grid: AccumulatorGrid,
        *,
        recorder: Recorder | None = None,
        checkpoint: Checkpoint | None = None,
        state: MissionState | None = None,
        max_range: float | None = None,
        camera_height: float = 1.0,
        truth: dict[str, tuple[float, float, float]] | None = None,
        truth_pose: Callable[[], Pose2D] | None = None,
        pose_gate: PoseGate | None = None,
        say: Callable[[str], None] = lambda _: None,
        visibility: VisibilityModel | None = None,
        fuse_visibility: bool = True,
        belief: AccumulatorGrid | None = None,
        confidence_options: ConfidenceOptions | None = None,
        views: ViewLog | None = None,
        height_check: HeightCheck | None = None,
        stands_on: Mapping[str, tuple[str, ...]] | None = None,
        object_heights: Mapping[str, float] | None = None,
    ) -> None:
        names = list(detector.names)
        if sorted(names) != sorted(grid.objects):
            raise TwinError(f"the detector finds {names} but the grid holds {list(grid.objects)}")
        self.robot, self.detector, self.grid = robot, detector, grid
        self.recorder = recorder or NullRecorder()
        self.checkpoint = checkpoint
        self.state = state or MissionState()
        fused = grid.views(grid.objects[0])
        if self.state.views_done != fused + len(self.state.refused):
            raise TwinError(
                f"the mission's state says {self.state.views_done} views "
                f"({len(self.state.refused)} refused) but its grid holds {fused}; resume from "
                "the run's own checkpoint"
            )
        self.max_range, self.camera_height = max_range, camera_height
        self.truth = dict(truth or {})
        self.truth_pose = truth_pose
        self.pose_gate, self.say = pose_gate, say
        self._names = names
        self.visibility, self.fuse_visibility = visibility, fuse_visibility
        # Where objects may stand, when the visibility model knows: a peak whose height fits
        # no surface there is passed over (``locate``).
        # An object known to stand on some kinds of surface only (``stands_on``: a crate on
        # the floor) may be only there.
        supports: SupportLevels | None = getattr(visibility, "supports", None)
        kinds = dict(stands_on or {})
        self.supports: dict[str, SupportLevels | None] = {
            name: supports
            if supports is None or not kinds.get(name)
            else supports.of_kinds(kinds[name])
            for name in names
        }
        # Each object's own height (m) where it is known, else the visibility model's one.
        default_height: float = getattr(visibility, "object_height", 0.2)
        self.object_heights: dict[str, float] = {
            name: float((object_heights or {}).get(name, default_height)) for name in names
        }
        self.confidence_options = confidence_options or ConfidenceOptions()
        self.views = views if views is not None else ViewLog(names, max_range)
        if len(self.views) != self.state.views_done:
            # An old checkpoint without a log: the log (and the belief) start from here.
            self.views = ViewLog(names, max_range)
        self.height_check: dict[str, HeightCheck] | None = None
        if height_check is not None:
            self.height_check = {
                name: replace(
                    height_check,
                    supports=self.supports[name] or height_check.supports,
                    object_height=self.object_heights[name],
                )
                for name in names
            }
        self.belief = belief
        if belief is not None and belief is not grid and belief.views(names[0]) == 0:
            self.views.fuse_into(belief, height_check=self.height_check)
        # Robot time continues across resumes: this session's clock starts where the last
        # session's last view left it.
        self._clock_origin = robot.camera.now() - self.state.robot_time

    @property
    def views_done(self) -> int:
        return self.state.views_done

    @contextmanager
    def _timed(self, key: str) -> Iterator[None]:
        tick = time.perf_counter()
        try:
            yield
        finally:
            self.state.timings[key] += time.perf_counter() - tick

    def observe(self, target: ViewTarget) -> ViewRecord:
        """Take one view from ``target`` and fuse it (unless its pose is too uncertain for the
        ``pose_gate``: then it is recorded, reported and not fused); returns what it was."""
        started = time.perf_counter()
        robot, state = self.robot, self.state
        with self._timed("move"):
            try:
                robot.base.go_to(target.base)
            except DeviceFaultError as fault:
                if not isinstance(robot.base, LocalizingBase):
                    raise  # it may still be touching what stopped it: nothing more to do
                raise NotReachedError(
                    fault.device, fault.asked, fault.seen, fault.remedy
                ) from fault
            robot.pantilt.move_to(target.pan, target.tilt)
        with self._timed("capture"):
            view = robot.capture()
            truth_pose = self.truth_pose() if self.truth_pose else None
        with self._timed("detect"):
            scores = self.detector.scores(view.image)
            values = scores.max(axis=1)  # a column's match: its best patch
            camera = robot.camera.model
            spans = self.detector.column_spans(view.image.shape[1])
            wedges = camera.wedges(view.pose, view.pan, spans, view.tilt)
            boxes = self.detector.patch_boxes(view.image.shape)
            elevations = best_patch_elevations(scores, boxes, camera, view.tilt)
        with self._timed("visibility"):
            seen = self.visibility.profiles(view, camera, spans) if self.visibility else None
        index = state.views_done
        per_object = {name: values[i] for i, name in enumerate(self._names)}
        # A view for some objects only (the floor sweep) says nothing about the others.
        wanted: tuple[str, ...] | None = getattr(target, "objects", None)
        unscored = np.full(len(wedges), np.nan)
        logged_values = {
            name: per_object[name] if wanted is None or name in wanted else unscored
            for name in self._names
        }
        refusal = self.pose_gate.reason(view.pose_covariance) if self.pose_gate else None
        origin = (view.pose.x, view.pose.y)
        logged = LoggedView(
            origin,
            wedges,
            logged_values,
            seen,
            refusal is None,
            {
                name: np.where(np.isfinite(logged_values[name]), elevations[i], np.nan)
                for i, name in enumerate(self._names)
            },
            self.camera_height,
        )
        self.views.append(logged)
        if refusal is None:
            with self._timed("fuse"):
                check = self.height_check
                fuse_view(
                    self.grid, logged, self.max_range,
                    visibility=self.fuse_visibility, height_check=check,
                )  # fmt: skip
                if self.belief is not None and self.belief is not self.grid:
                    fuse_view(self.belief, logged, self.max_range, height_check=check)
        else:
            state.refused.append({"view": index, "reason": refusal})
            self.say(f"view {index + 1} not fused: {refusal}")
        state.views_done += 1
        state.path.append([view.pose.x, view.pose.y, view.pose.yaw])
        if truth_pose is not None:
            state.truth_path.append([truth_pose.x, truth_pose.y, truth_pose.yaw])
        state.robot_time = view.timestamp - self._clock_origin
        located = self.located()
        record = ViewRecord(
            index,
            target.stop,
            view,
            state.robot_time,
            camera,
            self.camera_height,
            boxes,
            {name: scores[i] for i, name in enumerate(self._names)},
            wedges,
            per_object,
            tuple((x, y, yaw) for x, y, yaw in state.path),
            truth_pose,
            refusal,
            robot.base.snapshot() if isinstance(robot.base, LocalizingBase) else None,
            tuple((x, y, yaw) for x, y, yaw in state.truth_path),
            seen,
            {name: c for name, (c, _) in self.confidence_details(located).items()},
            {
                name: EstimatePoint(
                    at.peak.x,
                    at.peak.y,
                    None if at.height is None else at.height.z,
                    at.peak.value,
                    at.ratio,
                )
                for name, at in located.items()
            },
            None if wanted is None else tuple(wanted),
        )
        with self._timed("record"):
            self.recorder.log_view(record, self.grid)
            self.recorder.flush()
        if self.checkpoint is not None:
            with self._timed("checkpoint"):
                self.checkpoint.save(self.grid, state, self.views)
        state.timings["total"] += time.perf_counter() - started
        return record

    def result(self, peak_separation: float = 0.5) -> dict[str, Any]:
        """Per object the estimate (and, in the sim, the truth and the error), the views fused,
        the robot time and where the time went (seconds)."""
        # one choice of peak for the estimate and for its confidence
        located = self.located(peak_separation)
        objects = estimates(self.grid, self.truth, peak_separation, located=located)
        for name, (confidence, p_absent) in self.confidence_details(located).items():
            objects[name]["confidence"] = round(confidence, 4)
            objects[name]["p_absent"] = round(p_absent, 4)
        result: dict[str, Any] = {
            "objects": objects,
            "views": self.state.views_done,
            "views_refused": list(self.state.refused),
            "robot_time_s": round(self.state.robot_time, 3),
            "timings_s": {k: round(v, 3) for k, v in self.state.timings.items()},
        }
        error = pose_error(self.state)
        if error is not None:
            result["pose_error"] = error
        return result

    def confidence_details(
        self, located: dict[str, Located] | None = None
    ) -> dict[str, tuple[float, float]]:
        """Per object (confidence, p_absent): the posterior probability that it lies within the
        confidence radius of the grid's estimate, and that it is not in the mapped area at all;
        empty without a calibrated belief grid."""
        from twin.core.confidence import confidence_within, posterior

        if self.belief is None or self.belief.views(self._names[0]) == 0:
            return {}
        options, out = self.confidence_options, {}
        located = located or self.located()
        for name in self._names:
            best = located[name].peak
            cells, p_absent = posterior(
                self.belief.layer(name), options.temperature, options.p_absent
            )
            within = confidence_within(cells, self.belief.spec, (best.x, best.y), options.radius_m)
            out[name] = (float(within), float(p_absent))
        return out

    def skip(self, target: ViewTarget, reason: str) -> None:
        """Count ``target`` as a view not taken (its place could not be reached: ``reason``):
        refused in the results, an unfused entry in the view log, the robot's pose in the path;
        a fixed plan goes on with its next views, and a resumed run after it."""
        state, robot = self.state, self.robot
        index = state.views_done
        pose = robot.base.pose()
        camera = robot.camera.model
        spans = self.detector.column_spans(camera.width)
        zeros = np.zeros(len(spans))
        self.views.append(
            LoggedView(
                (pose.x, pose.y),
                camera.wedges(target.base, target.pan, spans, target.tilt),
                dict.fromkeys(self._names, zeros),
                None,
                False,
                dict.fromkeys(self._names, zeros),
                self.camera_height,
            )
        )
        state.refused.append({"view": index, "reason": f"not reached: {reason}"})
        state.views_done += 1
        state.path.append([pose.x, pose.y, pose.yaw])
        if self.truth_pose is not None:
            truth = self.truth_pose()
            state.truth_path.append([truth.x, truth.y, truth.yaw])
        if self.checkpoint is not None:
            with self._timed("checkpoint"):
                self.checkpoint.save(self.grid, state, self.views)

    def located(self, peak_separation: float = 0.5) -> dict[str, Located]:
        """Where each object is now: the grid's strongest peak whose height fits a surface
        there (``locate``, with the visibility model's supports when there is one)."""
        return {
            name: locate(
                self.grid,
                name,
                peak_separation,
                self.views,
                self.supports[name],
                self.object_heights[name],
            )
            for name in self._names
        }


def pose_error(state: MissionState) -> dict[str, float] | None:
    """How far the poses the fused views were projected from lay from the truth (simulation
    only): max and mean position error (m), max heading error (degrees); ``None`` without truth."""
    refused = {r["view"] for r in state.refused}
    pairs = [
        (used, true)
        for i, (used, true) in enumerate(zip(state.path, state.truth_path, strict=False))
        if i not in refused
    ]
    if not pairs or len(state.truth_path) < len(state.path):
        return None
    used, true = np.array([p[0] for p in pairs]), np.array([p[1] for p in pairs])
    distance = np.hypot(*(used[:, :2] - true[:, :2]).T)
    heading = np.abs((used[:, 2] - true[:, 2] + math.pi) % (2 * math.pi) - math.pi)
    return {
        "max_m": round(float(distance.max()), 4),
        "mean_m": round(float(distance.mean()), 4),
        "max_deg": round(math.degrees(float(heading.max())), 3),
    }


@dataclass(frozen=True)
class Located:
    """Where an object is: the chosen peak of its layer and its height there (None: no view
    tells it), the layer's strongest peaks, and the stronger ones passed over because their
    height fits no surface under them (with those heights)."""

    peak: Peak
    height: HeightEstimate | None
    peaks: Peaks
    passed_over: tuple[tuple[Peak, float], ...] = ()

    @property
    def ratio(self) -> float:
        """The chosen peak's value over the next peak's (``Peaks.ratio`` for the first)."""
        later = [p for p in self.peaks.peaks if p.value < self.peak.value]
        return Peaks((self.peak, *later[:1])).ratio


def locate(
    grid: AccumulatorGrid,
    name: str,
    min_separation: float = 0.5,
    views: ViewLog | None = None,
    supports: SupportLevels | None = None,
    object_height: float = 0.2,
    k: int = 3,
) -> Located:
    """The strongest of ``name``'s ``k`` peaks whose height (from ``views``) fits a surface of
    ``supports`` within a cell of it (``twin.core.height.height_fits``); the strongest peak when
    none fits, or without views or supports. Bearings from a few stops also cross in front of
    a look-alike, on bare floor, and the patch rows then put the object in mid-air. When the
    supports are the room's real surfaces, the chosen peak's object stands on the one its rows
    fit best (``HeightEstimate.on_surface``)."""
    peaks = grid.peaks(name, k=k, min_separation=min_separation)

    def height_at(peak: Peak) -> HeightEstimate | None:
        return views.height(name, (peak.x, peak.y)) if views is not None else None

    first = height_at(peaks.best)
    if supports is None or views is None:
        return Located(peaks.best, first, peaks)
    offsets = np.array([-1.0, 0.0, 1.0]) * grid.spec.cell_size
    passed: list[tuple[Peak, float]] = []
    for index, peak in enumerate(peaks.peaks):
        height = first if index == 0 else height_at(peak)
        if height is None:
            return Located(peak, height, peaks, tuple(passed))
        x, y = np.meshgrid(peak.x + offsets, peak.y + offsets)
        levels = supports.sample(x, y)
        if height_fits(height.z, levels, object_height):
            if supports.surfaces:
                height = height.on_surface(levels, object_height)
            return Located(peak, height, peaks, tuple(passed))
        passed.append((peak, height.z))
    return Located(peaks.best, first, peaks)


def estimates(
    grid: AccumulatorGrid,
    truth: dict[str, tuple[float, ...]] | None = None,
    min_separation: float = 0.5,
    views: ViewLog | None = None,
    supports: SupportLevels | None = None,
    object_height: float = 0.2,
    located: Mapping[str, Located] | None = None,
) -> dict[str, dict[str, Any]]:
    """Per object: the best peak in metres (``locate``: with ``views`` and ``supports``, the
    strongest whose height fits a surface there), its value, its ratio to the next peak, and,
    when the truth is known (simulation), the truth and the estimate's error in metres.

    With the mission's ``views``, the estimate is [x, y, z]: z is the object's height from the
    rows its best patches were found in (``ViewLog.height``; None when no view with rows looks
    toward the estimate), with ``height_views`` and ``height_spread_m``; an object placed on a
    surface of the room adds the surface's height ``stands_on_m`` and the rows' own height
    ``height_measured_m`` (``HeightEstimate.on_surface``); a truth with z adds
    ``height_error_m``. ``error_m`` stays the error in the plan. Peaks passed over are listed
    in ``passed_over`` with the height their views gave. ``located`` hands in ``locate``'s
    answers already made (``Mission.located``)."""
    out: dict[str, dict[str, Any]] = {}
    for name in grid.objects:
        if located is not None:
            found = located[name]
        else:
            found = locate(grid, name, min_separation, views, supports, object_height)
        best, height, ratio = found.peak, found.height, found.ratio
        entry: dict[str, Any] = {
            "estimate_m": [round(best.x, 4), round(best.y, 4)],
            "peak": best.value,
            "peak_ratio": ratio if math.isfinite(ratio) else None,
            "peaks": [
                {"xy_m": [round(p.x, 4), round(p.y, 4)], "value": p.value}
                for p in found.peaks.peaks
            ],
        }
        if found.passed_over:
            entry["passed_over"] = [
                {"xy_m": [round(p.x, 4), round(p.y, 4)], "value": p.value, "z_m": round(z, 4)}
                for p, z in found.passed_over
            ]
        if views is not None or located is not None:
            entry["estimate_m"].append(None if height is None else round(height.z, 4))
            entry["height_views"] = 0 if height is None else height.views
            entry["height_spread_m"] = None if height is None else round(height.spread, 4)
            if height is not None and height.surface is not None:
                entry["stands_on_m"] = round(height.surface, 4)
                entry["height_measured_m"] = round(float(height.measured), 4)
        if truth and name in truth:
            tx, ty = truth[name][:2]
            entry["truth_m"] = [round(float(v), 4) for v in truth[name]]
            entry["error_m"] = round(math.hypot(best.x - tx, best.y - ty), 4)
            if height is not None and len(truth[name]) > 2:
                entry["height_error_m"] = round(abs(height.z - float(truth[name][2])), 4)
        out[name] = entry
    return out
