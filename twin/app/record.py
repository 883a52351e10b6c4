"""What a survey shows in the Rerun viewer: the grid from above, the room, the robot's eyes.

The layout (sent with ``begin``, when the objects and the room are known):

* a large top-down panel per object (``top``; a Spatial2DView): the accumulator layer drawn with
  north (map +y) up, on a colour scale fixed for the whole run with its colour bar, the room
  and furniture outlines, metre ticks, the path so far, the robot, the estimate and (sim) the
  truth;
* the 3-D room (``world``): furniture boxes, the robot with its camera frustum, this view's
  wedges cut at the room's walls, the layer on the floor; the eye is framed on the room;
* the camera (``world/robot/camera``): the frame with the patch scores as a translucent heat
  overlay (one SegmentationImage per object; hovering a patch shows its score);
* time series per object: the best peak's value and the first/second peak ratio (``plots``).

Map frame as everywhere: x right, y up, metres. The 2-D panel draws its children of
``top/map`` through a transform that flips y, because a 2-D view draws +y downwards (image
rows); the layer is a DepthImage (row 0 = ``y_min``) placed by a transform of cell size and
corner, so its hover readout is the layer's value. The floor layer in the 3-D view is a GridMap,
which draws row 0 at the top: it gets the layer upside down.

Timelines: ``view`` (sequence) and ``robot_time`` (seconds on the robot's clock). Everything that
changes is logged per view (the path too: at view k it has k+1 points), so scrubbing back shows
the run as it was. Camera frames are JPEG-compressed and viewers get a memory limit.
"""

from __future__ import annotations

import math
import os
import sys
from collections.abc import Sequence
from dataclasses import dataclass, field, replace
from pathlib import Path
from typing import Any, Protocol

import numpy as np

from twin.app.rerun_server import VIEWER_MEMORY_LIMIT, RerunServer, has_display
from twin.core.devices import LaserMount, Scan, View
from twin.core.errors import TwinError
from twin.core.fusion import FusionRule
from twin.core.geometry import CameraModel, Footprint, Pose2D, is_wall
from twin.core.grid import AccumulatorGrid
from twin.core.visibility import ColumnVisibility
from twin.nav.maps import OccupancyMap

JPEG_QUALITY = 85
VIEWER_FLUSH_TIMEOUT = 10.0  # seconds a viewer may take to accept a view before it is left behind
STRONG_MATCH = 0.5  # an RFCH score that is a clear detection (rendered frames rarely pass it)
TYPICAL_MATCH = 0.25  # what the object's patches score in rendered frames (the ROC cut: 0.16)
COLUMNS_PER_CELL = 2  # RFCH's patches overlap by half: two patch columns cover each bearing
SCORE_LEVELS = 32  # steps of the camera's score overlay, from 0 to STRONG_MATCH
SCORE_ALPHA = 190  # overlay opacity (of 255) from STRONG_MATCH up; a patch scoring 0 is clear
VIEWS_PER_SWEEP = 8  # views in a full turn of a 45-degree camera; see colour_scale
ESTIMATE_SQUARE = 0.15  # metres: half the side of the estimate's square in the top-down panel
TRUTH_RING = 0.25  # metres: radius of the truth's ring in the top-down panel
MAP = "top/map"  # the top-down panel's map frame (y flipped for the 2-D view)


@dataclass(frozen=True)
class SceneInfo:
    """What a map of the room holds, for drawing: outline, furniture, and (sim) ground truth.

    ``peak_separation`` (metres) is the one the results use for their first/second peak ratio,
    so that the plotted ratio is the reported one.
    """

    extent: tuple[float, float, float, float]
    furniture: tuple[Footprint, ...] = ()
    truth: dict[str, tuple[float, float, float]] = field(default_factory=dict)
    peak_separation: float = 0.0
    occupancy: OccupancyMap | None = None  # the map the robot localizes against, if any
    planner: str | None = None  # a search's planner (twin search): the viewer says why it chose


@dataclass(frozen=True)
class ViewRecord:
    """Everything about one fused view that is worth showing (``Mission.observe`` returns it)."""

    index: int  # the view's number in the mission, from 0
    stop: int
    view: View  # the image, the pose its wedges were projected from, pan, tilt, timestamp
    robot_time: float  # seconds on the mission's robot clock; continues across resumes
    camera: CameraModel
    camera_height: float
    patch_boxes: np.ndarray  # (rows, cols, 4) pixel boxes x0, y0, x1, y1
    scores: dict[str, np.ndarray]  # object -> (rows, cols) in [0, 1]
    wedges: np.ndarray  # (cols, 2) bearing intervals, radians, map frame
    column_values: dict[str, np.ndarray]  # object -> (cols,)
    # (x, y, yaw) of every view so far, this one included (without it, it is added); empty:
    # the recorder draws the views it has seen itself
    path: tuple[tuple[float, float, float], ...] = ()
    truth_pose: Pose2D | None = None  # simulation only: where the base really stood
    refusal: str | None = None  # why the view was not fused (its pose too uncertain), if so
    localization: Localization | None = None  # the laser and the particles, with a localizer
    truth_path: tuple[tuple[float, float, float], ...] = ()  # simulation: the true poses so far
    visibility: ColumnVisibility | None = None  # what each column could have seen, if modelled
    confidence: dict[str, float] = field(default_factory=dict)  # object -> P(within radius)
    # object -> where the mission places it now (``Mission.located``); absent: the grid's
    # strongest peak, at an unknown height
    estimates: dict[str, EstimatePoint] = field(default_factory=dict)
    # the objects the view was taken for (the floor sweep's: the floor's), the only layers it
    # was fused into; None: all of them
    looked_for: tuple[str, ...] | None = None


@dataclass(frozen=True)
class EstimatePoint:
    """An object's estimate as the viewer draws it: plan position and height (m; ``z`` None
    while no view tells it), the peak's value and its ratio to the next peak."""

    x: float
    y: float
    z: float | None
    value: float
    ratio: float


@dataclass(frozen=True)
class Localization:
    """What a laser localizer saw at a view: its latest scan, where the scanner sits on the
    base, and the particles (n, 3: x, y, yaw in the map frame) its estimate came from."""

    scan: Scan | None
    mount: LaserMount
    particles: np.ndarray | None = None

    def scan_points(self, pose: Pose2D) -> np.ndarray:
        """(k, 2) map-frame points the scan's returns hit, seen from the base at ``pose``."""
        if self.scan is None:
            return np.zeros((0, 2))
        local = self.scan.points()
        c, s = math.cos(self.mount.yaw), math.sin(self.mount.yaw)
        x = self.mount.x + c * local[:, 0] - s * local[:, 1]
        y = self.mount.y + s * local[:, 0] + c * local[:, 1]
        c, s = math.cos(pose.yaw), math.sin(pose.yaw)
        return np.stack([pose.x + c * x - s * y, pose.y + s * x + c * y], axis=1)


class Recorder(Protocol):
    def begin(self, scene: SceneInfo, grid: AccumulatorGrid, planned_views: int) -> None:
        """Log what does not change (room, furniture, truth); ``planned_views`` is the mission's
        length, for scales fixed over the whole run."""
        ...

    def log_view(self, record: ViewRecord, grid: AccumulatorGrid) -> None: ...

    def log_choice(self, index: int, choice: Any, candidates: Any) -> None:
        """Before view ``index`` of a search: why the planner chose it (``ViewChoice``) among the
        ``Candidates``."""
        ...

    def explain(self, planner: str) -> None:
        """From now on ``planner`` chooses the views (a survey's follow-up, once its plan is
        flown): the layout gains its "why this view" log, if it has none yet."""
        ...

    def flush(self) -> None:
        """Put everything logged so far on disk (or on the wire) before the mission checkpoints,
        so that what the grid checkpoint holds, the recording holds."""
        ...

    def end(self) -> None:
        """Flush and close the recording (the mission is over, or was interrupted)."""
        ...

    def wait(self) -> None:
        """After the results are written: keep serving viewers if that is the mode."""
        ...


class NullRecorder:
    """Records nothing (``--rerun off``)."""

    def begin(self, scene: SceneInfo, grid: AccumulatorGrid, planned_views: int) -> None:
        pass

    def log_view(self, record: ViewRecord, grid: AccumulatorGrid) -> None:
        pass

    def log_choice(self, index: int, choice: Any, candidates: Any) -> None:
        pass

    def explain(self, planner: str) -> None:
        pass

    def flush(self) -> None:
        pass

    def end(self) -> None:
        pass

    def wait(self) -> None:
        pass


# -- pure helpers (tested without a viewer) ---------------------------------------------------


def heat_colors(values: np.ndarray, alpha: int | np.ndarray | None = None) -> np.ndarray:
    """RGB(A) uint8 colours of values in [0, 1] on a dark-blue→yellow ramp (like viridis);
    ``alpha`` (0..255) is one number or one per value."""
    stops = np.array([[68, 1, 84], [59, 82, 139], [33, 145, 140], [94, 201, 98], [253, 231, 37]])
    v = np.clip(np.asarray(values, dtype=float), 0.0, 1.0) * (len(stops) - 1)
    lo = np.floor(v).astype(int).clip(0, len(stops) - 2)
    t = (v - lo)[..., None]
    rgb = ((1 - t) * stops[lo] + t * stops[lo + 1]).round().astype(np.uint8)
    if alpha is None:
        return rgb
    a = np.broadcast_to(np.asarray(alpha), rgb.shape[:-1]).astype(np.uint8)[..., None]
    return np.concatenate([rgb, a], axis=-1)


def nice_ceil(value: float) -> float:
    """The smallest of 1, 1.5, 2, 2.5, 3, 4, 5, 6 or 8 times a power of ten that is >= ``value``
    (> 0): a scale's top that reads as a round number."""
    power = 10.0 ** math.floor(math.log10(value))
    for step in (1.0, 1.5, 2.0, 2.5, 3.0, 4.0, 5.0, 6.0, 8.0, 10.0):
        if step * power >= value * (1.0 - 1e-12):
            return step * power
    return 10.0 * power  # not reached: 10 * power >= value always


@dataclass(frozen=True)
class ColourScale:
    """A layer's colour scale, fixed for a run: ``lo``..``hi`` (layer units) span the colormap,
    values beyond saturate at its ends."""

    lo: float
    hi: float
    colormap: str  # a Rerun colormap name

    def unit(self, layer: np.ndarray) -> np.ndarray:
        """Values mapped to [0, 1] along the scale, saturated."""
        return np.clip((np.asarray(layer, dtype=float) - self.lo) / (self.hi - self.lo), 0.0, 1.0)

    def to_u8(self, layer: np.ndarray) -> np.ndarray:
        """Values as 0..255 along the scale (a GridMap's colormap spans 0..255 for u8 data)."""
        return np.rint(255.0 * self.unit(layer)).astype(np.uint8)

    def describe(self) -> str:
        return f"colour {self.lo:g} to {self.hi:g}, saturating beyond"


def colour_scale(rule: FusionRule, planned_views: int, baseline: float = 0.0) -> ColourScale:
    """The fixed colour scale of a layer fused by ``rule`` over ``planned_views`` views.

    A camera with a 45-degree field of view sees a given cell in about one of the
    ``VIEWS_PER_SWEEP`` views of a full turn, so a mission holds ``planned_views / 8`` looks at
    the object, and in each look ``COLUMNS_PER_CELL`` patch columns cover its cell. The top of
    the scale is what the object's cell gathers over the mission: ``accumulate``, a typical
    match (``TYPICAL_MATCH``) per column and look; ``logodds`` (symmetric about 0), the expected
    weight of a detector with the rule's miss rate; ``calibrated`` (symmetric), half the
    strongest log-likelihood ratio per column and look; ``normalized`` is a mean match, 0 to a
    strong one (``STRONG_MATCH``). Tops are rounded up by ``nice_ceil``; a clear peak saturates.
    ``baseline`` is the room's usual gain per column and look where the grid takes one off
    (``AccumulatorGrid(baseline=...)``): an additive rule's object then gains only the rest.
    """
    looks = max(1.0, planned_views / VIEWS_PER_SWEEP) * COLUMNS_PER_CELL
    if rule.name == "normalized":
        return ColourScale(0.0, STRONG_MATCH, "viridis")
    if rule.name == "logodds":
        fired = float(getattr(rule, "fired_weight", 1.0))
        silent = float(getattr(rule, "silent_weight", 0.0))
        missed = float(getattr(rule, "p_fn", 0.0))
        top = nice_ceil(max(1.0, looks * ((1.0 - missed) * fired + missed * silent)))
        return ColourScale(-top, top, "cyantoyellow")
    if rule.name == "calibrated":
        # Half the strongest log-likelihood ratio per look: the object's cell, seen with some
        # columns strong and some weak, gathers about that.
        strongest = max(float(v) for v in getattr(rule, "llr", (1.0,)))
        top = nice_ceil(max(1.0, looks * 0.5 * strongest))
        return ColourScale(-top, top, "cyantoyellow")
    return ColourScale(0.0, nice_ceil(max(TYPICAL_MATCH - baseline, 0.05) * looks), "viridis")


def clip_to_rect(polygon: np.ndarray, extent: tuple[float, float, float, float]) -> np.ndarray:
    """The part of a convex polygon ((n, 2) metres) inside the rectangle ``extent``
    (x0, y0, x1, y1), as an (m, 2) array (m = 0 when they do not meet); Sutherland-Hodgman."""
    x0, y0, x1, y1 = extent
    points = [tuple(p) for p in np.asarray(polygon, dtype=float)]
    for axis, bound, sign in ((0, x0, 1.0), (0, x1, -1.0), (1, y0, 1.0), (1, y1, -1.0)):
        kept: list[tuple[float, float]] = []
        for i, current in enumerate(points):
            previous = points[i - 1]
            inside_now = sign * (current[axis] - bound) >= 0.0
            inside_before = sign * (previous[axis] - bound) >= 0.0
            if inside_now != inside_before:
                t = (bound - previous[axis]) / (current[axis] - previous[axis])
                kept.append(
                    (
                        previous[0] + t * (current[0] - previous[0]),
                        previous[1] + t * (current[1] - previous[1]),
                    )
                )
            if inside_now:
                kept.append(current)
        points = kept
        if not points:
            break
    return np.array(points, dtype=float).reshape(-1, 2)


def wedge_polygons(
    origin: tuple[float, float], wedges: np.ndarray, extent: tuple[float, float, float, float]
) -> list[np.ndarray]:
    """Each bearing interval [a0, a1] (radians) from ``origin`` cut at the room's walls, as a
    convex polygon in metres (empty where the wedge misses the room). Wedges wider than 120
    degrees are split so that the triangle's far edge stays beyond the walls."""
    x0, y0, x1, y1 = extent
    ox, oy = origin
    reach = 2.0 * math.hypot(x1 - x0, y1 - y0) + math.hypot(
        max(x0 - ox, ox - x1, 0.0), max(y0 - oy, oy - y1, 0.0)
    )
    out = []
    for a0, a1 in np.asarray(wedges, dtype=float):
        pieces = max(1, math.ceil((a1 - a0) / math.radians(120.0)))
        angles = np.linspace(a0, a1, pieces + 1)
        rim = [(ox + reach * math.cos(a), oy + reach * math.sin(a)) for a in angles]
        out.append(clip_to_rect(np.array([(ox, oy), *rim]), extent))
    return out


def score_levels(
    boxes: np.ndarray, scores: np.ndarray, shape: tuple[int, int]
) -> tuple[np.ndarray, int]:
    """Every pixel's highest patch score (patches overlap when the stride is smaller than the
    patch) as uint8 class ids 0..SCORE_LEVELS, in steps of STRONG_MATCH / SCORE_LEVELS and
    saturating at STRONG_MATCH; and the block size in pixels the map is given in.

    The map is constant over blocks of the largest size that divides every box edge and the
    frame (16 px for RFCH's 32/16 patches), so it is returned one value per block: 256 times
    smaller than per pixel, drawn scaled back up by the block size."""
    height, width = shape
    edges = np.asarray(boxes, dtype=np.int64).reshape(-1, 4)
    block = math.gcd(height, width, *(int(v) for v in np.unique(edges)))
    unit = np.clip(np.asarray(scores, float) / STRONG_MATCH, 0.0, 1.0)
    levels = np.rint(unit * SCORE_LEVELS).astype(np.uint8)
    out = np.zeros((height // block, width // block), np.uint8)
    for (bx0, by0, bx1, by1), level in zip(edges // block, levels.reshape(-1), strict=True):
        region = out[max(by0, 0) : max(by1, 0), max(bx0, 0) : max(bx1, 0)]
        np.maximum(region, level, out=region)
    return out, block


def path_points(record: ViewRecord, seen: list[tuple[float, float]]) -> list[tuple[float, float]]:
    """The (x, y) of every view up to and including ``record``'s: the record's path when it
    carries one (with this view added if it lacks it), else ``seen``, the views this recorder
    logged, which gets this view appended."""
    pose = record.view.pose
    if not record.path:
        seen.append((pose.x, pose.y))
        return list(seen)
    points = [(float(p[0]), float(p[1])) for p in record.path]
    if len(points) == record.index:
        points.append((pose.x, pose.y))
    return points


def _score_label(level: int) -> str:
    score = level * STRONG_MATCH / SCORE_LEVELS
    return f"score >= {score:.2f}" if level == SCORE_LEVELS else f"score {score:.2f}"


def _ring(x: float, y: float, radius: float) -> np.ndarray:
    angles = np.linspace(0.0, 2.0 * math.pi, 33)
    return np.stack([x + radius * np.cos(angles), y + radius * np.sin(angles)], axis=1)


def _fsync(path: Path) -> None:
    """Push a file's written bytes from the page cache to the disk."""
    try:
        fd = os.open(path, os.O_RDONLY)
    except FileNotFoundError:
        return
    try:
        os.fsync(fd)
    except OSError as exc:
        raise TwinError(f"could not write the recording {path}: {exc.strerror}") from None
    finally:
        os.close(fd)


# -- the recorder ---------------------------------------------------------------------------------


class RerunRecorder:
    """Logs a survey to Rerun: ``save`` to an .rrd file, ``spawn`` a viewer, or ``serve`` gRPC.

    ``serve`` starts the bundled ``rerun`` server bound to ``bind`` (localhost unless told
    otherwise), in its own process group so that a Ctrl-C meant for the survey does not reach
    it, and prints the URL to connect to; ``wait`` serves until Ctrl-C, ``end`` stops it when the
    mission did not finish (``wait`` will not come), and on Linux it dies with this process.
    ``spawn`` without a display (Linux: no DISPLAY or WAYLAND_DISPLAY) saves to ``path`` instead
    and says so in one line.
    """

    def __init__(
        self,
        mode: str,
        path: Path | None = None,
        bind: str = "127.0.0.1",
        port: int | None = None,
        application_id: str = "bearing_twin",
        recording_id: str | None = None,
    ) -> None:
        import rerun as rr

        if mode not in ("save", "spawn", "serve"):
            raise TwinError(f"unknown Rerun mode {mode!r}; use save, spawn, serve or off")
        if mode == "spawn" and not has_display():
            if path is None:
                raise TwinError(
                    "no display for a Rerun viewer (DISPLAY and WAYLAND_DISPLAY are unset); "
                    "use --rerun save or serve"
                )
            print(f"no display for a Rerun viewer: saving the recording to {path}", flush=True)
            mode = "save"
        self._rr = rr
        self.mode = mode
        self.url: str | None = None
        self.file: Path | None = None
        self._server: RerunServer | None = None
        self._viewer_lagging = False
        self._seen: list[tuple[float, float]] = []
        self._scales: dict[str, ColourScale] = {}
        self._peak_separation = 0.0
        self._planned = 0  # views the mission plans (from begin) and the last one logged
        self._last_view = -1
        self._scene: SceneInfo | None = None
        self._grid: AccumulatorGrid | None = None
        self.stream = rr.RecordingStream(application_id, recording_id=recording_id)
        if mode == "save":
            if path is None:
                raise TwinError("Rerun 'save' mode needs a file path")
            path.parent.mkdir(parents=True, exist_ok=True)
            self.file = path
            self.stream.save(path)
        elif mode == "spawn":
            self.stream.spawn(memory_limit=VIEWER_MEMORY_LIMIT)
        else:
            self._server = RerunServer(bind, port)
            self.url = self._server.url
            self.stream.connect_grpc(self.url)

    # -- the Recorder protocol ---------------------------------------------------------------

    def begin(self, scene: SceneInfo, grid: AccumulatorGrid, planned_views: int) -> None:
        rr, log = self._rr, self.stream.log
        self._extent = tuple(float(v) for v in scene.extent)
        self._peak_separation = scene.peak_separation
        self._planned = planned_views
        baselines = grid.baselines
        self._scales = {
            name: colour_scale(
                grid.rules[name],
                planned_views,
                # the room's usual where the room has seen the object's kind of thing at all
                float(np.median(b[b > 0])) if (b := baselines.get(name)) is not None else 0.0,
            )
            for name in grid.objects
        }
        self._scene, self._grid = scene, grid  # for a layout sent again (``explain``)
        self.stream.send_blueprint(self._blueprint(scene, grid), make_active=True)
        log("world", rr.ViewCoordinates.RIGHT_HAND_Z_UP, static=True)
        log(MAP, rr.Transform3D(scale=[1.0, -1.0, 1.0]), static=True)  # north up in 2-D
        self._log_room(scene)
        if scene.occupancy is not None:
            self._log_occupancy(scene.occupancy)
        log(
            "world/robot/body",
            rr.Boxes3D(centers=[[0, 0, 0.6]], half_sizes=[[0.25, 0.2, 0.6]], colors=[90, 90, 200]),
            static=True,
        )
        log(
            "world/robot/camera/image/scores",
            rr.AnnotationContext(
                [
                    (level, _score_label(level), tuple(int(c) for c in rgba))
                    for level, rgba in enumerate(self._score_colours())
                ]
            ),
            static=True,
        )
        spec = grid.spec
        for name in grid.objects:
            # Layer cells (row, col) to metres: the DepthImage pixel grid scaled and placed.
            log(
                f"{MAP}/objects/{name}/grid",
                rr.Transform3D(
                    translation=[spec.x_min, spec.y_min, 0.0],
                    scale=[spec.cell_size, spec.cell_size, 1.0],
                ),
                static=True,
            )
            self._log_legend(name, spec.cell_size)
            for metric in ("peak", "peak_ratio", "confidence"):
                log(f"plots/{metric}/{name}", rr.SeriesLines(names=name), static=True)
            if name in scene.truth:
                self._log_truth(name, scene.truth[name])

    def log_view(self, record: ViewRecord, grid: AccumulatorGrid) -> None:
        rr, log = self._rr, self.stream.log
        self._last_view = record.index
        self.stream.set_time("view", sequence=record.index)
        self.stream.set_time("robot_time", duration=record.robot_time)
        pose = record.view.pose
        log(
            "world/robot",
            rr.Transform3D(
                translation=[pose.x, pose.y, 0.0],
                rotation_axis_angle=rr.RotationAxisAngle(axis=[0, 0, 1], radians=pose.yaw),
            ),
        )
        path = path_points(record, self._seen)
        log("world/path", rr.LineStrips3D([[[x, y, 0.01] for x, y in path]], colors=[90, 90, 200]))
        log(
            f"{MAP}/path",
            rr.LineStrips2D([path], colors=[110, 170, 255], radii=0.025, draw_order=20.0),
        )
        heading = pose.yaw + record.view.pan
        self._log_facing(f"{MAP}/robot", pose, heading, 0.45, 0.04, [110, 170, 255], "robot", 30.0)
        if record.truth_pose is not None:
            truth = record.truth_pose
            log(
                f"{MAP}/robot_truth",
                rr.Points2D(
                    [[truth.x, truth.y]],
                    radii=0.06,
                    colors=[255, 160, 60],
                    labels=["robot (truth)"],
                    show_labels=False,
                    draw_order=29.0,
                ),
            )
        if record.truth_path:
            log(
                f"{MAP}/truth_path",
                rr.LineStrips2D(
                    [[(p[0], p[1]) for p in record.truth_path]],
                    colors=[255, 160, 60],
                    radii=0.015,
                    draw_order=19.0,
                ),
            )
        if record.localization is not None:
            self._log_localization(record.localization, pose)
        self._log_camera(record)
        for name, values in record.column_values.items():
            if record.looked_for is not None and name not in record.looked_for:
                # not fused into that layer: no wedges drawn as though it were
                log(f"world/wedges/{name}", rr.Clear(recursive=False))
                continue
            self._log_wedges(name, (pose.x, pose.y), record.wedges, values)
        for name in grid.objects:
            self._log_grid(name, grid, record.estimates.get(name))
        for name, confidence in record.confidence.items():
            log(f"plots/confidence/{name}", rr.Scalars(confidence))

    def log_choice(self, index: int, choice: Any, candidates: Any) -> None:
        """Why view ``index`` was chosen: the planner's words in the "why this view" log, every
        place's best score (heat colours, brighter: worth more per second) and the chosen view
        as an arrow, in the top-down panel at the view's time."""
        rr, log = self._rr, self.stream.log
        self.stream.set_time("view", sequence=index)
        log("plan/why", rr.TextLog(f"view {index + 1}: {choice.why}", level="INFO"))
        if choice.scores is not None:
            per_place = np.asarray(choice.scores, float).reshape(len(candidates.places), -1)
            best = np.nanmax(np.where(np.isnan(per_place), -np.inf, per_place), axis=1)
            shown = np.isfinite(best)
            top = float(best[shown].max()) if shown.any() else 0.0
            unit = np.clip(best[shown] / top, 0.0, 1.0) if top > 0 else np.zeros(shown.sum())
            log(
                f"{MAP}/plan/options",
                rr.Points2D(
                    candidates.places[shown],
                    radii=0.05,
                    colors=heat_colors(unit, alpha=200),
                    draw_order=25.0,
                ),
            )
        heading = choice.base.yaw + choice.pan
        white = [255, 255, 255]
        self._log_facing(f"{MAP}/plan/next", choice.base, heading, 0.6, 0.035, white, "next view",
                         31.0)  # fmt: skip

    def explain(self, planner: str) -> None:
        """Send the layout again with the "why this view" log under the map: a survey sends
        its layout before it flies, when whether a follow-up will choose any view is not
        known, and an empty log in every recording would say nothing."""
        if self._scene is None or self._grid is None or self._scene.planner == planner:
            return
        self._scene = replace(self._scene, planner=planner)
        self.stream.send_blueprint(self._blueprint(self._scene, self._grid), make_active=True)

    def _log_facing(self, path: str, at: Pose2D, heading: float, length: float, radius: float,
                    colour: list[int], label: str, order: float) -> None:  # fmt: skip
        """An arrow in the top-down panel: where a camera stands and which way it looks."""
        self.stream.log(
            path,
            self._rr.Arrows2D(
                origins=[[at.x, at.y]],
                vectors=[[length * math.cos(heading), length * math.sin(heading)]],
                radii=radius,
                colors=colour,
                labels=[label],
                show_labels=False,
                draw_order=order,
            ),
        )

    def flush(self) -> None:
        """Block until every view logged so far is in the file (and fsync'd), or sent to the
        viewer; a viewer that takes nothing for ``VIEWER_FLUSH_TIMEOUT`` is left behind with one
        printed line rather than stalling the mission."""
        if self.file is not None:
            self.stream.flush()  # the file writer has written every message when this returns
            _fsync(self.file)
            return
        if self._viewer_lagging:
            self.stream.flush(timeout_sec=0.0)
            return
        try:
            self.stream.flush(timeout_sec=VIEWER_FLUSH_TIMEOUT)
        except RuntimeError:  # the SDK's flush timed out (the viewer was closed, or hangs)
            self._viewer_lagging = True
            where = self.url or "the spawned viewer"
            print(f"Rerun: {where} takes no data; the survey goes on without it", flush=True)

    def end(self) -> None:
        """Flush and close the recording (a .rrd gets its footer). When the mission did not
        finish (an exception is on its way, or fewer views were logged than planned) it also
        stops a ``serve`` server: ``wait`` is for finished runs only."""
        finished = self._last_view >= 0 and self._last_view + 1 >= self._planned
        interrupted = sys.exc_info()[0] is not None or not finished
        try:
            self.flush()
            self.stream.disconnect()
            if self.file is not None:
                _fsync(self.file)
        finally:
            if interrupted and self._server is not None:
                self._server.stop()

    def wait(self) -> None:
        """In ``serve`` mode the server holds the recording for viewers until Ctrl-C or SIGTERM,
        which stop it (its whole process group) and propagate, so the command exits 130 / 143
        like any interrupted one; the results were written before."""
        if self._server is None:
            return
        try:
            print(
                f"Rerun server serving the recording at {self.url}; stop it with Ctrl-C", flush=True
            )
            self._server.wait()
        finally:
            print("Rerun server stopped", flush=True)

    @property
    def server_pid(self) -> int | None:
        """The ``serve`` server's process id (its process group's too), while it runs."""
        return self._server.pid if self._server is not None else None

    # -- layout ----------------------------------------------------------------------------------

    def _blueprint(self, scene: SceneInfo, grid: AccumulatorGrid) -> Any:
        import rerun.blueprint as rrb

        x0, y0, x1, y1 = self._extent
        cx, cy = 0.5 * (x0 + x1), 0.5 * (y0 + y1)
        size = max(x1 - x0, y1 - y0)
        less = " less the room's usual look"
        fused = {
            name: grid.rules[name].name + (less if name in grid.baselines else "")
            for name in grid.objects
        }
        maps = [
            rrb.Spatial2DView(
                name=f"{name}: grid from above, {fused[name]}, {self._scales[name].describe()}",
                origin="top",
                contents=["+ /top/**", "- /top/map/objects/**", f"+ /top/map/objects/{name}/**"],
                # The view's y is the map's -y (the flip at top/map); room for ticks and legend.
                visual_bounds=rrb.VisualBounds2D(
                    x_range=[x0 - 0.7, x1 + 1.5], y_range=[-(y1 + 0.6), -(y0 - 0.6)]
                ),
            )
            for name in grid.objects
        ]
        room = rrb.Spatial3DView(
            name="room",
            origin="world",
            eye_controls=rrb.EyeControls3D(
                position=[cx, y0 - 0.3 * size, 0.85 * size],
                look_target=[cx, cy, 0.0],
                eye_up=[0.0, 0.0, 1.0],
            ),
        )
        camera = rrb.Tabs(
            rrb.Spatial2DView(name="camera and patch scores", origin="world/robot/camera"),
            rrb.Spatial2DView(name="depth (visibility)", origin="depth"),
        )
        series = [
            rrb.TimeSeriesView(name="peak value", origin="plots/peak"),
            rrb.TimeSeriesView(name="first / second peak", origin="plots/peak_ratio"),
            rrb.TimeSeriesView(
                name="confidence: P(within 0.2 m)",
                origin="plots/confidence",
                axis_y=rrb.ScalarAxis(range=(0.0, 1.0)),
            ),
        ]
        plots = rrb.Horizontal(*series)
        left = maps[0] if len(maps) == 1 else rrb.Tabs(*maps)
        if scene.planner is not None:  # a search says why it chose each view, under the map:
            # the lines are long, and the map's column is the wide one
            why = rrb.TextLogView(name=f"why this view ({scene.planner})", origin="plan")
            left = rrb.Vertical(left, why, row_shares=[4, 1])
        return rrb.Blueprint(
            rrb.Horizontal(
                left,
                rrb.Vertical(room, camera, plots, row_shares=[4, 3, 2]),
                column_shares=[5, 4],
            ),
            collapse_panels=True,
        )

    # -- pieces --------------------------------------------------------------------------------

    def _log_room(self, scene: SceneInfo) -> None:
        rr, log = self._rr, self.stream.log
        x0, y0, x1, y1 = self._extent
        outline = [[x0, y0], [x1, y0], [x1, y1], [x0, y1], [x0, y0]]
        log(
            "world/room/outline",
            rr.LineStrips3D([[[x, y, 0.0] for x, y in outline]], colors=[200, 200, 200]),
            static=True,
        )
        log(
            f"{MAP}/room",
            rr.LineStrips2D([outline], colors=[220, 220, 220], radii=0.03, draw_order=10.0),
            static=True,
        )
        for item in scene.furniture:
            lo, hi = item.polygon.min(axis=0), item.polygon.max(axis=0)
            log(
                f"world/room/furniture/{item.name}",
                rr.Boxes3D(
                    centers=[[*(0.5 * (lo + hi)), 0.5 * item.top]],
                    half_sizes=[[*(0.5 * (hi - lo)), 0.5 * item.top]],
                    colors=[150, 130, 110],
                    labels=None if is_wall(item.name) else [item.name],
                ),
                static=True,
            )
        if scene.furniture:
            log(
                f"{MAP}/furniture",
                rr.LineStrips2D(
                    [np.vstack([f.polygon, f.polygon[:1]]) for f in scene.furniture],
                    colors=[205, 170, 125],
                    radii=0.02,
                    labels=["" if is_wall(f.name) else f.name for f in scene.furniture],
                    draw_order=11.0,
                ),
                static=True,
            )
        # Metre ticks along the bottom and left walls, and which way is north.
        xs = range(math.ceil(x0), math.floor(x1) + 1)
        ys = range(math.ceil(y0), math.floor(y1) + 1)
        log(
            f"{MAP}/ticks",
            rr.LineStrips2D(
                [[[x, y0], [x, y0 - 0.1]] for x in xs] + [[[x0, y], [x0 - 0.1, y]] for y in ys],
                colors=[120, 120, 120],
                radii=0.015,
                draw_order=10.0,
            ),
            static=True,
        )
        log(
            f"{MAP}/ticks/labels",
            rr.Points2D(
                [[x, y0 - 0.28] for x in xs]
                + [[x0 - 0.35, y] for y in ys]
                + [[x0 - 0.35, y1 + 0.35]],
                radii=0.001,
                colors=[120, 120, 120],
                labels=[f"{x} m" for x in xs] + [f"{y} m" for y in ys] + ["N ↑"],
                draw_order=10.0,
            ),
            static=True,
        )

    def _log_occupancy(self, occupancy: OccupancyMap) -> None:
        """The map's occupied cells: dark squares in the top-down panel, and a slice at the
        laser's height in the 3-D room (what the robot localizes against)."""
        rr, log = self._rr, self.stream.log
        rows, cols = np.nonzero(occupancy.occupied)
        xs, ys = occupancy.center_of(rows, cols)
        half = 0.5 * occupancy.resolution
        log(  # filled dots: a Boxes2D is only an outline, too thin to see at a room's scale
            f"{MAP}/occupancy",
            rr.Points2D(
                np.stack([xs, ys], axis=1), radii=half, colors=[40, 40, 40, 200], draw_order=12.0
            ),
            static=True,
        )
        log(
            "world/room/occupancy",
            rr.Points3D(
                np.stack([xs, ys, np.full_like(xs, 0.3)], axis=1), radii=half, colors=[60, 60, 60]
            ),
            static=True,
        )

    def _log_localization(self, localization: Localization, pose: Pose2D) -> None:
        """This view's laser returns (at the pose the view was taken from) and particles."""
        rr, log = self._rr, self.stream.log
        hits = localization.scan_points(pose)
        log(
            f"{MAP}/scan",
            rr.Points2D(hits, radii=0.02, colors=[230, 60, 60], draw_order=25.0),
        )
        log(
            "world/scan",
            rr.Points3D(
                np.column_stack([hits, np.full(len(hits), localization.mount.z)]),
                radii=0.015,
                colors=[230, 60, 60],
            ),
        )
        if localization.particles is not None:
            log(
                f"{MAP}/particles",
                rr.Points2D(
                    np.asarray(localization.particles)[:, :2],
                    radii=0.01,
                    colors=[40, 200, 200],
                    draw_order=24.0,
                ),
            )

    def _log_truth(self, name: str, position: tuple[float, float, float]) -> None:
        rr, log = self._rr, self.stream.log
        log(
            f"world/truth/{name}",
            rr.Points3D([position], radii=0.06, colors=[255, 60, 60], labels=[f"{name} (truth)"]),
            static=True,
        )
        log(
            f"{MAP}/objects/{name}/truth",
            rr.LineStrips2D(
                [_ring(position[0], position[1], TRUTH_RING)],
                colors=[255, 70, 70],
                radii=0.03,
                labels=["truth"],
                show_labels=False,
                draw_order=40.0,
            ),
            static=True,
        )

    def _log_legend(self, name: str, cell_size: float) -> None:
        """Beside the room: a colour bar on the layer's scale with its ends and middle named,
        and under it a key to the marks drawn on the map."""
        rr, log = self._rr, self.stream.log
        scale = self._scales[name]
        _, y0, x1, y1 = self._extent
        bottom = y0 + 0.4 * (y1 - y0)  # the bar's lower end; the key goes below
        steps = 64
        values = scale.lo + (np.arange(steps) + 0.5) / steps * (scale.hi - scale.lo)
        bar = f"{MAP}/objects/{name}/legend"
        log(
            bar,
            rr.Transform3D(
                translation=[x1 + 0.35, bottom, 0.0], scale=[0.25, (y1 - bottom) / steps, 1.0]
            ),
            static=True,
        )
        log(
            bar,
            rr.DepthImage(
                values.astype(np.float32)[:, None],
                meter=1.0,
                colormap=scale.colormap,
                depth_range=[scale.lo, scale.hi],
                draw_order=0.0,
            ),
            static=True,
        )
        label_x = x1 + 0.95
        log(
            f"{MAP}/objects/{name}/legend_labels",
            rr.Points2D(
                [
                    [label_x, bottom],
                    [label_x, 0.5 * (bottom + y1)],
                    [label_x, y1],
                    [x1 + 0.5, y1 + 0.3],
                ],
                radii=0.001,
                colors=[120, 120, 120],
                labels=[
                    f"<= {scale.lo:g}" if scale.lo < 0 else f"{scale.lo:g}",
                    f"{0.5 * (scale.lo + scale.hi):g}",
                    f">= {scale.hi:g}",
                    f"{name}, {cell_size:g} m cells",
                ],
                draw_order=10.0,
            ),
            static=True,
        )
        key_x, step = x1 + 0.75, 0.45
        keys = [
            ("truth (ring)", [255, 70, 70]),
            ("estimate (white square)", [150, 150, 150]),
            ("robot, path", [110, 170, 255]),
            ("furniture", [205, 170, 125]),
        ]
        log(
            f"{MAP}/objects/{name}/key",
            rr.Points2D(
                [[key_x, bottom - 0.45 - step * k] for k in range(len(keys))],
                radii=0.07,
                colors=[colour for _, colour in keys],
                labels=[text for text, _ in keys],
                draw_order=10.0,
            ),
            static=True,
        )

    def _score_colours(self) -> np.ndarray:
        # Opacity grows like the square root of the score: weak responses stay visible as a
        # tint, strong ones cover the patch; the colour is the grid's (yellow = strong).
        levels = np.arange(SCORE_LEVELS + 1) / SCORE_LEVELS
        return heat_colors(levels, alpha=np.rint(SCORE_ALPHA * np.sqrt(levels)).astype(int))

    def _log_camera(self, record: ViewRecord) -> None:
        rr, log = self._rr, self.stream.log
        camera = record.camera
        # The camera frame: x right, y down, z forward (RDF), panned about the base's z axis.
        log(
            "world/robot/camera",
            rr.Transform3D(
                translation=[0.0, 0.0, record.camera_height],
                rotation_axis_angle=rr.RotationAxisAngle(axis=[0, 0, 1], radians=record.view.pan),
            ),
        )
        log(
            "world/robot/camera",
            rr.Pinhole(
                focal_length=camera.focal_px,
                width=camera.width,
                height=camera.height,
                camera_xyz=rr.ViewCoordinates.FLU,
                image_plane_distance=0.5,
            ),
        )
        image = record.view.image
        log(
            "world/robot/camera/image",
            rr.Image(image, color_model="RGB").compress(jpeg_quality=JPEG_QUALITY),
        )
        if record.view.depth is not None:
            # What the visibility model saw: the depth at half resolution, in millimetres (a
            # few tens of kB a view), beside the frame in the camera panel.
            depth = np.nan_to_num(record.view.depth[::2, ::2], nan=0.0, posinf=0.0)
            millimetres = np.clip(depth * 1000.0, 0, 65535).astype(np.uint16)
            log("depth", rr.DepthImage(millimetres, meter=1000.0, colormap="turbo"))
        for name, scores in record.scores.items():
            levels, block = score_levels(record.patch_boxes, scores, image.shape[:2])
            overlay = f"world/robot/camera/image/scores/{name}"
            log(overlay, rr.Transform3D(scale=[block, block, 1.0]))
            log(overlay, rr.SegmentationImage(levels, opacity=1.0, draw_order=10.0))

    def _log_wedges(
        self, name: str, origin: tuple[float, float], wedges: np.ndarray, values: np.ndarray
    ) -> None:
        rr = self._rr
        vertices: list[Sequence[float]] = []
        colors: list[np.ndarray] = []
        triangles: list[tuple[int, int, int]] = []
        for polygon, value in zip(
            wedge_polygons(origin, wedges, self._extent), values, strict=True
        ):
            if len(polygon) < 3:
                continue
            first = len(vertices)
            colour = heat_colors(np.array([value]), alpha=int(40 + 150 * value))[0]
            vertices += [[x, y, 0.02] for x, y in polygon]
            colors += [colour] * len(polygon)
            triangles += [(first, first + k, first + k + 1) for k in range(1, len(polygon) - 1)]
        path = f"world/wedges/{name}"
        if not triangles:
            self.stream.log(path, rr.Clear(recursive=False))
            return
        self.stream.log(
            path,
            rr.Mesh3D(vertex_positions=vertices, vertex_colors=colors, triangle_indices=triangles),
        )

    def _log_grid(
        self, name: str, grid: AccumulatorGrid, estimate: EstimatePoint | None = None
    ) -> None:
        rr, log = self._rr, self.stream.log
        layer = grid.layer(name)
        scale = self._scales[name]
        spec = grid.spec
        # 3-D floor: a GridMap draws row 0 at the top (its translation is the lower-left corner).
        log(
            f"world/grid/{name}",
            rr.GridMap(
                data=np.ascontiguousarray(np.flipud(scale.to_u8(layer))).tobytes(),
                format=rr.components.ImageFormat(
                    width=spec.nx, height=spec.ny, color_model="L", channel_datatype="U8"
                ),
                cell_size=spec.cell_size,
                translation=[spec.x_min, spec.y_min, 0.005],
                colormap=scale.colormap,
                opacity=0.8,
            ),
        )
        # Top-down panel: the layer itself (row 0 = y_min) in cells, placed and flipped by the
        # transforms; the viewer colours it on the fixed scale and shows the value on hover.
        log(
            f"{MAP}/objects/{name}/grid",
            rr.DepthImage(
                layer.astype(np.float32),
                meter=1.0,
                colormap=scale.colormap,
                depth_range=[scale.lo, scale.hi],
                draw_order=0.0,
            ),
        )
        if estimate is None:
            peaks = grid.peaks(name, k=2, min_separation=self._peak_separation)
            estimate = EstimatePoint(
                peaks.best.x, peaks.best.y, None, peaks.best.value, peaks.ratio
            )
        best, height = estimate, estimate.z
        # In 3-D the estimate stands at its height (twin.core.height), on a stalk from the
        # floor so that its place on the plan reads too; on the floor while it is unknown.
        z = 0.05 if height is None else height
        log(
            f"world/estimate/{name}",
            rr.Points3D(
                [[best.x, best.y, z]],
                radii=0.08,
                colors=[255, 255, 255],
                labels=["estimate" if height is None else f"estimate, {height:.2f} m up"],
            ),
        )
        log(
            f"world/estimate/{name}/stalk",
            rr.LineStrips3D([[[best.x, best.y, 0.0], [best.x, best.y, z]]], radii=0.01),
        )
        # A hollow square around the estimate's cell, so that the cell itself stays visible.
        half = ESTIMATE_SQUARE
        corners = [(-1, -1), (1, -1), (1, 1), (-1, 1), (-1, -1)]
        log(
            f"{MAP}/objects/{name}/estimate",
            rr.LineStrips2D(
                [[[best.x + half * dx, best.y + half * dy] for dx, dy in corners]],
                radii=0.02,
                colors=[255, 255, 255],
                labels=["estimate"],
                show_labels=False,
                draw_order=41.0,
            ),
        )
        log(f"plots/peak/{name}", rr.Scalars(best.value))
        if math.isfinite(best.ratio):
            log(f"plots/peak_ratio/{name}", rr.Scalars(best.ratio))
