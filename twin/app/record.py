"""What a survey shows in the Rerun viewer: the room, the robot, its eyes, wedges and grids.

Entity layout (map frame, metres, z up):

* ``world/room`` — the room outline and furniture boxes (static);
* ``world/truth/<object>`` — where the objects really are (simulation only, static);
* ``world/robot`` — the base pose per view; ``world/path`` — the path so far;
* ``world/robot/camera`` — the camera at its pan and height: a Pinhole with the frame and the
  patch scores drawn over it as coloured boxes (``.../image/scores/<object>``);
* ``world/wedges/<object>`` — this view's wedges on the floor, coloured by column value;
* ``world/grid/<object>`` — the accumulator layer as a GridMap, updated every view;
* ``world/estimate/<object>`` — the current best peak; ``plots/peak/<object>`` — its value.

Timelines: ``view`` (sequence) and ``robot_time`` (seconds on the robot's clock). Camera frames
are JPEG-compressed and the viewer gets a memory limit, so long runs stay bounded.
"""

from __future__ import annotations

import math
import socket
import subprocess
import sys
import time
from dataclasses import dataclass, field
from pathlib import Path
from typing import Protocol

import numpy as np

from twin.core.devices import View
from twin.core.errors import TwinError
from twin.core.geometry import CameraModel, Footprint, Pose2D
from twin.core.grid import AccumulatorGrid

VIEWER_MEMORY_LIMIT = "1GiB"
JPEG_QUALITY = 85
WEDGE_DRAW_RANGE = 8.0  # metres; wedges are drawn to this length, then clipped by the eye


@dataclass(frozen=True)
class SceneInfo:
    """What a map of the room holds, for drawing: outline, furniture, and (sim) ground truth."""

    extent: tuple[float, float, float, float]
    furniture: tuple[Footprint, ...] = ()
    truth: dict[str, tuple[float, float, float]] = field(default_factory=dict)


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
    path: tuple[tuple[float, float, float], ...] = ()  # (x, y, yaw) of every view so far
    truth_pose: Pose2D | None = None  # simulation only: where the base really stood


class Recorder(Protocol):
    def begin(self, scene: SceneInfo, grid: AccumulatorGrid, planned_views: int) -> None:
        """Log what does not change (room, furniture, truth); ``planned_views`` is the mission's
        length, for scales fixed over the whole run."""
        ...

    def log_view(self, record: ViewRecord, grid: AccumulatorGrid) -> None: ...

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

    def flush(self) -> None:
        pass

    def end(self) -> None:
        pass

    def wait(self) -> None:
        pass


def heat_colors(values: np.ndarray, alpha: int | None = None) -> np.ndarray:
    """RGB(A) uint8 colours of values in [0, 1] on a dark-blue→yellow ramp (like viridis)."""
    stops = np.array([[68, 1, 84], [59, 82, 139], [33, 145, 140], [94, 201, 98], [253, 231, 37]])
    v = np.clip(np.asarray(values, dtype=float), 0.0, 1.0) * (len(stops) - 1)
    lo = np.floor(v).astype(int).clip(0, len(stops) - 2)
    t = (v - lo)[..., None]
    rgb = ((1 - t) * stops[lo] + t * stops[lo + 1]).round().astype(np.uint8)
    if alpha is None:
        return rgb
    return np.concatenate([rgb, np.full((*rgb.shape[:-1], 1), alpha, np.uint8)], axis=-1)


def _free_port() -> int:
    with socket.socket() as probe:
        probe.bind(("127.0.0.1", 0))
        return probe.getsockname()[1]


class RerunRecorder:
    """Logs a survey to Rerun: ``save`` to an .rrd file, ``spawn`` a viewer, or ``serve`` gRPC.

    ``serve`` starts the ``rerun`` server bound to ``bind`` (localhost unless told otherwise;
    the SDK's own server would listen on every interface) and prints the URL to connect to.
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

        self._rr = rr
        self.mode = mode
        self.url: str | None = None
        self._server: subprocess.Popen[bytes] | None = None
        self.stream = rr.RecordingStream(application_id, recording_id=recording_id)
        blueprint = self._blueprint()
        if mode == "save":
            if path is None:
                raise TwinError("Rerun 'save' mode needs a file path")
            path.parent.mkdir(parents=True, exist_ok=True)
            self.stream.save(path, default_blueprint=blueprint)
        elif mode == "spawn":
            self.stream.spawn(memory_limit=VIEWER_MEMORY_LIMIT, default_blueprint=blueprint)
        elif mode == "serve":
            self.url = self._start_server(bind, port or _free_port())
            self.stream.connect_grpc(self.url, default_blueprint=blueprint)
        else:
            raise TwinError(f"unknown Rerun mode {mode!r}; use save, spawn, serve or off")
        self._path: list[tuple[float, float]] = []

    def _start_server(self, bind: str, port: int) -> str:
        # The viewer binary ships in rerun-sdk: run it with this interpreter, so an
        # unactivated virtual environment works too.
        command = [
            sys.executable,
            "-m",
            "rerun",
            "--serve-grpc",
            "--bind",
            bind,
            "--port",
            str(port),
            "--server-memory-limit",
            VIEWER_MEMORY_LIMIT,
        ]
        self._server = subprocess.Popen(command, stdout=subprocess.DEVNULL, stderr=subprocess.PIPE)
        host = "127.0.0.1" if bind in ("0.0.0.0", "::", "127.0.0.1") else bind
        deadline = time.monotonic() + 10.0
        while time.monotonic() < deadline:
            if self._server.poll() is not None:
                raise TwinError(f"the Rerun server on {bind}:{port} exited; is the port taken?")
            try:
                with socket.create_connection((host, port), timeout=0.2):
                    return f"rerun+http://{host}:{port}/proxy"
            except OSError:
                time.sleep(0.1)
        self._server.terminate()
        raise TwinError(f"the Rerun server on {bind}:{port} did not start within 10 s")

    def _blueprint(self):
        import rerun.blueprint as rrb

        return rrb.Blueprint(
            rrb.Horizontal(
                rrb.Spatial3DView(name="room", origin="world"),
                rrb.Vertical(
                    rrb.Spatial2DView(name="camera", origin="world/robot/camera"),
                    rrb.TimeSeriesView(name="peak value", origin="plots"),
                    row_shares=[2, 1],
                ),
                column_shares=[3, 2],
            ),
            collapse_panels=True,
        )

    # -- the Recorder protocol ---------------------------------------------------------------

    def begin(self, scene: SceneInfo, grid: AccumulatorGrid, planned_views: int) -> None:
        rr, log = self._rr, self.stream.log
        log("world", rr.ViewCoordinates.RIGHT_HAND_Z_UP, static=True)
        x0, y0, x1, y1 = scene.extent
        outline = [[x0, y0, 0], [x1, y0, 0], [x1, y1, 0], [x0, y1, 0], [x0, y0, 0]]
        log("world/room/outline", rr.LineStrips3D([outline], colors=[200, 200, 200]), static=True)
        for item in scene.furniture:
            lo, hi = item.polygon.min(axis=0), item.polygon.max(axis=0)
            log(
                f"world/room/furniture/{item.name}",
                rr.Boxes3D(
                    centers=[[*(0.5 * (lo + hi)), 0.5 * item.top]],
                    half_sizes=[[*(0.5 * (hi - lo)), 0.5 * item.top]],
                    colors=[150, 130, 110],
                    labels=[item.name],
                ),
                static=True,
            )
        for name, position in scene.truth.items():
            log(
                f"world/truth/{name}",
                rr.Points3D(
                    [position], radii=0.06, colors=[255, 60, 60], labels=[f"{name} (truth)"]
                ),
                static=True,
            )
        for name in grid.objects:
            log(f"plots/peak/{name}", rr.SeriesLines(names=name), static=True)

    def log_view(self, record: ViewRecord, grid: AccumulatorGrid) -> None:
        rr, log = self._rr, self.stream.log
        view = record.view
        self.stream.set_time("view", sequence=record.index)
        self.stream.set_time("robot_time", duration=record.robot_time)
        pose = view.pose
        log(
            "world/robot",
            rr.Transform3D(
                translation=[pose.x, pose.y, 0.0],
                rotation_axis_angle=rr.RotationAxisAngle(axis=[0, 0, 1], radians=pose.yaw),
            ),
        )
        log(
            "world/robot/body",
            rr.Boxes3D(centers=[[0, 0, 0.6]], half_sizes=[[0.25, 0.2, 0.6]], colors=[90, 90, 200]),
        )
        self._path.append((pose.x, pose.y))
        # Static: only the newest path is kept, so a long run's memory grows linearly.
        log(
            "world/path",
            rr.LineStrips3D([[[x, y, 0.01] for x, y in self._path]], colors=[90, 90, 200]),
            static=True,
        )
        self._log_camera(record)
        for name, values in record.column_values.items():
            self._log_wedges(name, view, record.wedges, values)
            self._log_grid(name, grid)

    def flush(self) -> None:
        self.stream.flush()

    def end(self) -> None:
        self.stream.flush()
        self.stream.disconnect()

    def wait(self) -> None:
        """In ``serve`` mode the server holds the recording for viewers until Ctrl-C."""
        if self._server is None:
            return
        print(f"Rerun server serving the recording at {self.url}; stop it with Ctrl-C", flush=True)
        try:
            self._server.wait()
        except KeyboardInterrupt:
            pass
        finally:
            self._server.terminate()
            self._server.wait(timeout=5)

    # -- pieces --------------------------------------------------------------------------------

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
        log(
            "world/robot/camera/image",
            rr.Image(record.view.image, color_model="RGB").compress(jpeg_quality=JPEG_QUALITY),
        )
        boxes = record.patch_boxes.reshape(-1, 4)
        for name, scores in record.scores.items():
            log(
                f"world/robot/camera/image/scores/{name}",
                rr.Boxes2D(
                    array=boxes,
                    array_format=rr.Box2DFormat.XYXY,
                    colors=heat_colors(scores.reshape(-1), alpha=110),
                    radii=0.5,
                    draw_order=10.0,
                ),
            )

    def _log_wedges(self, name: str, view: View, wedges: np.ndarray, values: np.ndarray) -> None:
        rr = self._rr
        ox, oy = view.pose.x, view.pose.y
        vertices, colors = [], []
        for (a0, a1), value in zip(wedges, values, strict=True):
            vertices += [
                [ox, oy, 0.02],
                [ox + WEDGE_DRAW_RANGE * math.cos(a0), oy + WEDGE_DRAW_RANGE * math.sin(a0), 0.02],
                [ox + WEDGE_DRAW_RANGE * math.cos(a1), oy + WEDGE_DRAW_RANGE * math.sin(a1), 0.02],
            ]
            colors += [heat_colors(np.array([value]), alpha=int(40 + 150 * value))[0]] * 3
        self.stream.log(
            f"world/wedges/{name}", rr.Mesh3D(vertex_positions=vertices, vertex_colors=colors)
        )

    def _log_grid(self, name: str, grid: AccumulatorGrid) -> None:
        rr = self._rr
        layer = grid.layer(name)
        top = float(layer.max())
        low = float(layer.min())
        scaled = (layer - low) / (top - low) if top > low else np.zeros_like(layer)
        data = (255 * scaled).astype(np.uint8)
        spec = grid.spec
        self.stream.log(
            f"world/grid/{name}",
            rr.GridMap(
                data=data.tobytes(),
                format=rr.components.ImageFormat(
                    width=spec.nx, height=spec.ny, color_model="L", channel_datatype="U8"
                ),
                cell_size=spec.cell_size,
                translation=[spec.x_min, spec.y_min, 0.005],
                colormap=rr.components.Colormap.Viridis,
                opacity=0.8,
            ),
        )
        best = grid.peaks(name, k=2)
        peak = best.best
        self.stream.log(
            f"world/estimate/{name}",
            rr.Points3D(
                [[peak.x, peak.y, 0.05]],
                radii=0.08,
                colors=[255, 255, 255],
                labels=[f"{name} estimate"],
            ),
        )
        self.stream.log(f"plots/peak/{name}", rr.Scalars(peak.value))
