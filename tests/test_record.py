"""The Rerun recording read back the way the viewer draws it.

A synthetic survey (no rendering, no detector: a column scores high when its wedge holds the
target) drives ``RerunRecorder``; the tests read the .rrd with ``rerun.chunk.RrdReader`` and
rebuild what a panel shows: an image's pixel (col, row) sits at (col + 0.5, row + 0.5) in its
entity's frame, row 0 at the top of a 2-D view (whose y points down), carried to the view's
origin by every ``Transform3D`` on the way (scale, then translation); a GridMap draws row 0 at
the top, its ``translation`` the lower-left corner. Positions are compared "as seen": in a 2-D
view, up on the screen is -y, so a point drawn at (u, v) is seen at (u, -v); a top-down 3-D view
sees (x, y). A map drawn the right way round shows every map point where the map says it is.
"""

from __future__ import annotations

import dataclasses
import math
import os
import signal
import subprocess
import sys
import textwrap
import time
import warnings
from collections import defaultdict
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np
import pytest

pytest.importorskip("rerun")

from twin.app.record import (
    Localization,
    RerunRecorder,
    SceneInfo,
    ViewRecord,
    clip_to_rect,
    colour_scale,
    wedge_polygons,
)
from twin.core.devices import View
from twin.core.fusion import Accumulate, LogOdds, Normalized
from twin.core.geometry import CameraModel, Footprint, Pose2D
from twin.core.grid import AccumulatorGrid, GridSpec

EXTENT = (0.0, 0.0, 4.5, 6.0)
TARGET = (1.5, 5.0)  # upper-left quarter: a map drawn upside down or mirrored misplaces it
STOPS = [(1.1, 1.2), (3.0, 2.0), (2.7, 4.4)]
NAME = "rice_box"
TESTS = Path(__file__).parent
CHANNEL_TYPES = {6: np.uint8, 8: np.uint16, 34: np.float32, 35: np.float64}


# -- a synthetic survey -----------------------------------------------------------------------


def make_grid(rule=None) -> AccumulatorGrid:
    return AccumulatorGrid([NAME], GridSpec(*EXTENT, 0.1), rule, supersample=2)


def make_scene() -> SceneInfo:
    sofa = Footprint("sofa", np.array([[0.2, 4.6], [1.0, 4.6], [1.0, 5.8], [0.2, 5.8]]), 0.8)
    return SceneInfo(EXTENT, (sofa,), {NAME: (*TARGET, 0.8)})


def patch_layout(width: int = 320, height: int = 240) -> tuple[np.ndarray, np.ndarray]:
    """RFCH's layout: 32 px patches every 16 px; (rows, cols, 4) boxes and (cols, 2) spans."""
    xs, ys = np.arange(0, width - 31, 16), np.arange(0, height - 31, 16)
    boxes = np.zeros((len(ys), len(xs), 4), dtype=np.int64)
    boxes[..., 0], boxes[..., 1] = xs[None, :], ys[:, None]
    boxes[..., 2], boxes[..., 3] = xs[None, :] + 32, ys[:, None] + 32
    return boxes, np.stack([xs, xs + 32], axis=1).astype(float)


def synthetic_views(grid: AccumulatorGrid, n_views: int):
    """Yield (record, layer after fusing it): 8 headings per stop, 45 degrees apart."""
    camera = CameraModel(320, 240, math.radians(45.0))
    boxes, spans = patch_layout()
    image = np.zeros((240, 320, 3), np.uint8)
    image[..., 0] = np.linspace(0, 255, 320, dtype=np.uint8)[None, :]
    for index in range(n_views):
        stop = index // 8
        x, y = STOPS[stop % len(STOPS)]
        pose = Pose2D(x, y, math.radians(45.0 * (index % 8)))
        wedges = camera.wedges(pose, 0.0, spans)
        bearing = math.atan2(TARGET[1] - y, TARGET[0] - x)
        offset = (bearing - wedges[:, 0]) % (2.0 * math.pi)
        # A typical match (TYPICAL_MATCH): the peak stays under the scale's top, unsaturated.
        values = np.where(offset <= wedges[:, 1] - wedges[:, 0], 0.25, 0.04)
        scores = values[None, :] * np.linspace(0.5, 1.0, boxes.shape[0])[:, None]
        grid.fuse_all((x, y), wedges, {NAME: scores.max(axis=0)})
        record = ViewRecord(
            index,
            stop,
            View(image, pose, 0.0, 0.0, 1000.0 + 2.0 * index),
            2.0 * index,
            camera,
            1.0,
            boxes,
            {NAME: scores},
            wedges,
            {NAME: scores.max(axis=0)},
            truth_pose=Pose2D(x + 0.02, y, pose.yaw),
        )
        yield record, grid.layer(NAME)


def record_survey(path: Path, n_views: int = 24, rule=None) -> tuple[AccumulatorGrid, list]:
    """Save a synthetic survey to ``path``; returns the grid and every view's (record, layer)."""
    grid = make_grid(rule)
    recorder = RerunRecorder("save", path)
    recorder.begin(make_scene(), grid, n_views)
    seen = []
    for record, layer in synthetic_views(grid, n_views):
        recorder.log_view(record, grid)
        recorder.flush()
        seen.append((record, layer))
    recorder.end()
    return grid, seen


# -- reading a recording back ---------------------------------------------------------------


@dataclass
class Recording:
    """Every logged row: entity -> [(view or None when static, {component: value})]."""

    rows: dict[str, list[tuple[int | None, dict[str, Any]]]]
    blueprint: dict[str, dict[str, Any]]

    def latest(self, entity: str, component: str, view: int) -> Any:
        """What the viewer shows at ``view``: static data, else the newest row at or before."""
        found = None
        for at, values in self.rows.get(entity, []):
            if component not in values:
                continue
            if at is None:
                return values[component]
            if at <= view and (found is None or at >= found[0]):
                found = (at, values[component])
        return None if found is None else found[1]

    def views_of(self, entity: str, component: str) -> list[int]:
        return sorted(
            at for at, values in self.rows.get(entity, []) if at is not None and component in values
        )


def read_recording(path: Path) -> Recording:
    from rerun.chunk import RrdReader

    with warnings.catch_warnings():  # a killed writer leaves no footer: read it as a stream
        warnings.simplefilter("ignore")
        reader = RrdReader(path)
        stores = [(reader.stream(), False)]
        stores += [(reader.stream(store=store), True) for store in reader.blueprints()]
        rows: dict[str, list] = defaultdict(list)
        blueprint: dict[str, dict[str, Any]] = defaultdict(dict)
        for stream, is_blueprint in stores:
            for chunk in stream:
                batch = chunk.to_record_batch()
                names = [f.name for f in batch.schema if b"rerun:component" in (f.metadata or {})]
                views = (
                    batch.column("view").to_pylist()
                    if "view" in batch.schema.names
                    else [None] * batch.num_rows
                )
                for i in range(batch.num_rows):
                    values = {
                        n: batch.column(n)[i].as_py() for n in names if batch.column(n)[i].is_valid
                    }
                    if is_blueprint:
                        blueprint[chunk.entity_path].update(values)
                    else:
                        at = None if chunk.is_static else views[i]
                        rows[chunk.entity_path].append((at, values))
    return Recording(dict(rows), dict(blueprint))


def to_origin(
    rec: Recording, entity: str, origin: str, points: np.ndarray, view: int
) -> np.ndarray:
    """Points in ``entity``'s frame carried to ``origin``'s by the Transform3Ds between them."""
    out = np.asarray(points, dtype=float)
    path = entity
    while path not in (origin, "/"):
        for component in ("Transform3D:rotation_axis_angle", "Transform3D:quaternion"):
            assert rec.latest(path, component, view) is None, f"{path}: rotation not handled"
        scale = rec.latest(path, "Transform3D:scale", view)
        translation = rec.latest(path, "Transform3D:translation", view)
        if scale is not None:
            out = out * np.asarray(scale[0])[: out.shape[1]]
        if translation is not None:
            out = out + np.asarray(translation[0])[: out.shape[1]]
        path = path.rsplit("/", 1)[0] or "/"
    return out


@dataclass
class DrawnGrid:
    entity: str
    kind: str  # "DepthImage" in the top-down 2-D panel, "GridMap" on the 3-D floor
    seen: np.ndarray  # (n, 2) where each cell's centre is seen, metres (x right, y up)
    brightness: np.ndarray  # (n,) along the colormap


def drawn_grids(rec: Recording, view: int) -> list[DrawnGrid]:
    """Every picture of NAME's layer in the recording, as the viewer places it."""
    found = []
    for entity in rec.rows:
        parts = entity.strip("/").split("/")
        if "grid" not in parts or NAME not in parts:
            continue
        image = rec.latest(entity, "DepthImage:buffer", view)
        if image is not None:
            fmt = rec.latest(entity, "DepthImage:format", view)[0]
            values = np.frombuffer(bytes(image[0]), CHANNEL_TYPES[fmt["channel_datatype"]])
            values = values.reshape(fmt["height"], fmt["width"])
            rows, cols = np.indices(values.shape)
            local = np.stack([cols.ravel() + 0.5, rows.ravel() + 0.5], axis=1)
            drawn = to_origin(rec, "/" + "/".join(parts), "/" + parts[0], local, view)
            seen = np.stack([drawn[:, 0], -drawn[:, 1]], axis=1)  # a 2-D view's y points down
            found.append(DrawnGrid(entity, "DepthImage", seen, values.ravel().astype(float)))
        data = rec.latest(entity, "GridMap:data", view)
        if data is not None:
            fmt = rec.latest(entity, "GridMap:format", view)[0]
            cell = rec.latest(entity, "GridMap:cell_size", view)[0]
            corner = rec.latest(entity, "GridMap:translation", view)
            corner = np.asarray(corner[0][:2]) if corner is not None else np.zeros(2)
            values = np.frombuffer(bytes(data[0]), CHANNEL_TYPES[fmt["channel_datatype"]])
            height, width = fmt["height"], fmt["width"]
            rows, cols = np.indices((height, width))
            # Row 0 at the top: row r spans y from corner + (height - r - 1) cells upwards.
            local = np.stack(
                [
                    corner[0] + (cols.ravel() + 0.5) * cell,
                    corner[1] + (height - rows.ravel() - 0.5) * cell,
                ],
                axis=1,
            )
            seen = to_origin(rec, entity, "/world", local, view)
            found.append(DrawnGrid(entity, "GridMap", seen, values.astype(float)))
    return found


def brightest(drawn: DrawnGrid) -> np.ndarray:
    """Where the brightest cells are seen (their mean if several saturate alike)."""
    top = drawn.brightness.max()
    return drawn.seen[drawn.brightness >= top].mean(axis=0)


def seen_2d(rec: Recording, entity: str, view: int, component: str) -> list[np.ndarray]:
    """A 2-D entity's strips or points as seen in the view whose origin is ``/top``."""
    value = rec.latest(entity, component, view)
    assert value is not None, f"nothing logged at {entity} ({component}) by view {view}"
    items = value if component.endswith("strips") else [value]
    out = []
    for item in items:
        drawn = to_origin(rec, entity, "/top", np.asarray(item, dtype=float), view)
        out.append(np.stack([drawn[:, 0], -drawn[:, 1]], axis=1))
    return out


@pytest.fixture(scope="module")
def survey(tmp_path_factory) -> tuple[Recording, AccumulatorGrid, list]:
    path = tmp_path_factory.mktemp("rec") / "recording.rrd"
    grid, seen = record_survey(path)
    return read_recording(path), grid, seen


# -- what the user sees ------------------------------------------------------------------------


def test_brightest_cell_is_drawn_where_the_peak_is(survey) -> None:
    rec, grid, seen = survey
    last = len(seen) - 1
    best = grid.peaks(NAME, k=1).best
    assert math.dist((best.x, best.y), TARGET) < 0.15  # the synthetic survey finds its target
    pictures = drawn_grids(rec, last)
    assert pictures, "no picture of the grid in the recording"
    for picture in pictures:
        at = brightest(picture)
        assert math.dist(at, (best.x, best.y)) < 0.06, (
            f"{picture.entity} ({picture.kind}) shows its brightest cell at "
            f"({at[0]:.2f}, {at[1]:.2f}) m; the grid's peak is at ({best.x:.2f}, {best.y:.2f}) m"
        )
    # The large top-down panel exists, is a 2-D view of /top, and shows this object's grid.
    assert {p.kind for p in pictures} == {"DepthImage", "GridMap"}
    views = [v for v in rec.blueprint.values() if v.get("ViewBlueprint:space_origin") == ["top"]]
    assert [v["ViewBlueprint:class_identifier"] for v in views] == [["2D"]]


def test_top_down_panel_is_north_up_with_room_truth_and_estimate(survey) -> None:
    rec, grid, seen = survey
    last = len(seen) - 1
    (room,) = seen_2d(rec, "/top/map/room", last, "LineStrips2D:strips")
    assert np.allclose(room.min(axis=0), EXTENT[:2]) and np.allclose(room.max(axis=0), EXTENT[2:])
    (ring,) = seen_2d(rec, f"/top/map/objects/{NAME}/truth", last, "LineStrips2D:strips")
    assert np.allclose(ring.mean(axis=0), TARGET, atol=0.02)
    (square,) = seen_2d(rec, f"/top/map/objects/{NAME}/estimate", last, "LineStrips2D:strips")
    best = grid.peaks(NAME, k=1).best
    assert np.allclose(0.5 * (square.min(axis=0) + square.max(axis=0)), (best.x, best.y))


def test_colour_scale_is_fixed_for_the_run(survey) -> None:
    rec, _, seen = survey
    scale = colour_scale(Accumulate(), len(seen))
    entity = f"/top/map/objects/{NAME}/grid"
    ranges = {tuple(rec.latest(entity, "DepthImage:depth_range", k)[0]) for k in range(len(seen))}
    assert ranges == {(scale.lo, scale.hi)}
    legend = rec.latest(f"/top/map/objects/{NAME}/legend", "DepthImage:depth_range", 0)
    assert tuple(legend[0]) == (scale.lo, scale.hi)
    # The floor's u8 GridMap maps a value to the same byte early and late in the run.
    for k in (3, len(seen) // 2, len(seen) - 1):
        layer = seen[k][1]
        data = rec.latest(f"/world/grid/{NAME}", "GridMap:data", k)[0]
        shown = np.flipud(np.frombuffer(bytes(data), np.uint8).reshape(layer.shape))
        expected = np.clip(layer / scale.hi, 0.0, 1.0) * 255.0
        assert np.abs(shown - expected).max() <= 0.5 + 1e-9
    assert layer.max() > 2.0 * seen[3][1].max()  # the layer grew, the scale did not


def test_scales_follow_the_rule_and_the_plan() -> None:
    assert (colour_scale(Accumulate(), 40).lo, colour_scale(Accumulate(), 40).hi) == (0.0, 2.5)
    assert colour_scale(Accumulate(), 160).hi == 10.0
    # With the room's usual look taken off (0.12 a column), the object gains only the rest.
    assert colour_scale(Accumulate(), 40, baseline=0.12).hi == 1.5
    assert colour_scale(Normalized(), 40).hi == 0.5
    logodds = colour_scale(LogOdds(p_fp=0.1, p_fn=0.05, threshold=0.162), 40)
    assert (logodds.lo, logodds.hi) == (-20.0, 20.0)  # 10 looks at ~2 log-odds each


def test_wedges_stay_inside_the_room(survey) -> None:
    rec, _, seen = survey
    x0, y0, x1, y1 = EXTENT
    for k in range(len(seen)):
        vertices = np.asarray(rec.latest(f"/world/wedges/{NAME}", "Mesh3D:vertex_positions", k))
        assert len(vertices) >= 3
        assert vertices[:, 0].min() >= x0 - 1e-6 and vertices[:, 0].max() <= x1 + 1e-6
        assert vertices[:, 1].min() >= y0 - 1e-6 and vertices[:, 1].max() <= y1 + 1e-6
        on_wall = np.isclose(vertices[:, 0], x0) | np.isclose(vertices[:, 0], x1)
        on_wall |= np.isclose(vertices[:, 1], y0) | np.isclose(vertices[:, 1], y1)
        assert on_wall.any()  # cut at the walls, not shortened


def test_clip_to_rect_cuts_a_wedge_at_the_walls() -> None:
    (polygon,) = wedge_polygons((1.0, 1.0), np.array([[0.0, math.pi / 4]]), EXTENT)
    assert np.allclose(
        sorted(map(tuple, np.round(polygon, 9))), [(1.0, 1.0), (4.5, 1.0), (4.5, 4.5)]
    )
    assert len(clip_to_rect(np.array([[5.0, 5.0], [6.0, 5.0], [6.0, 7.0]]), EXTENT)) == 0


def test_path_grows_one_point_per_view_and_is_not_static(survey) -> None:
    rec, _, seen = survey
    for entity, component in (
        ("/top/map/path", "LineStrips2D:strips"),
        ("/world/path", "LineStrips3D:strips"),
    ):
        assert all(at is not None for at, _ in rec.rows[entity])
        for k, (record, _) in enumerate(seen):
            (strip,) = rec.latest(entity, component, k)
            assert len(strip) == k + 1
            assert np.allclose(strip[-1][:2], (record.view.pose.x, record.view.pose.y))


def test_timelines_and_peak_series(survey) -> None:
    rec, grid, seen = survey
    entity = f"/top/map/objects/{NAME}/grid"
    assert rec.views_of(entity, "DepthImage:buffer") == list(range(len(seen)))
    peaks = rec.rows[f"/plots/peak/{NAME}"]
    assert len([at for at, _ in peaks if at is not None]) == len(seen)
    ratio = rec.latest(f"/plots/peak_ratio/{NAME}", "Scalars:scalars", len(seen) - 1)
    assert ratio == pytest.approx([grid.peaks(NAME, k=2).ratio])


def test_patch_scores_are_a_translucent_overlay(survey) -> None:
    rec, _, seen = survey
    record = seen[0][0]
    entity = f"/world/robot/camera/image/scores/{NAME}"
    image = rec.latest(entity, "SegmentationImage:buffer", 0)
    fmt = rec.latest(entity, "SegmentationImage:format", 0)[0]
    corner = [[fmt["width"], fmt["height"]]]  # the far corner of the overlay's pixels
    drawn = to_origin(rec, entity, "/world/robot/camera/image", np.array(corner, float), 0)
    assert np.allclose(drawn[0], record.view.image.shape[1::-1])  # it covers the frame
    classes = rec.latest("/world/robot/camera/image/scores", "AnnotationContext:context", 0)
    alpha = {c["class_id"]: c["class_description"]["info"]["color"] & 0xFF for c in classes[0]}
    assert alpha[0] == 0 and 0 < max(alpha.values()) < 255
    assert len(np.unique(np.frombuffer(bytes(image[0]), np.uint8))) > 1
    logged = {c for rows in rec.rows.values() for _, values in rows for c in values}
    assert not any(c.startswith("Boxes2D:") for c in logged)  # no outlines over the frame


# -- modes and processes ----------------------------------------------------------------------

CHILD = """
import os, sys, time
sys.path.insert(0, {tests!r})
from test_record import RerunRecorder, make_grid, make_scene, synthetic_views
from pathlib import Path
mode, planned, logged = sys.argv[1], int(sys.argv[2]), int(sys.argv[3])
grid = make_grid()
recorder = RerunRecorder(mode, Path(sys.argv[4]))
recorder.begin(make_scene(), grid, planned)
for record, _ in synthetic_views(grid, logged):
    recorder.log_view(record, grid)
    recorder.flush()
    print("flushed", record.index, flush=True)
{after}
"""


def start_child(tmp_path: Path, after: str, *args: str) -> subprocess.Popen[str]:
    script = tmp_path / "child.py"
    script.write_text(CHILD.format(tests=str(TESTS), after=textwrap.dedent(after)))
    return subprocess.Popen(
        [sys.executable, str(script), *args],
        stdout=subprocess.PIPE,
        stderr=subprocess.PIPE,
        text=True,
        start_new_session=True,  # the child leads a group, as a terminal's foreground job does
    )


def read_until(child: subprocess.Popen[str], prefix: str) -> str:
    assert child.stdout is not None
    for line in child.stdout:
        if line.startswith(prefix):
            return line.strip()
    raise AssertionError(f"the child ended before printing {prefix!r}: {child.stderr.read()}")


def group_alive(pgid: int) -> bool:
    try:
        os.killpg(pgid, 0)
    except ProcessLookupError:
        return False
    return True


def wait_gone(pgid: int, seconds: float = 15.0) -> bool:
    deadline = time.monotonic() + seconds
    while time.monotonic() < deadline:
        if not group_alive(pgid):
            return True
        time.sleep(0.05)
    return False


def test_views_flushed_before_a_sigkill_are_in_the_file(tmp_path) -> None:
    path = tmp_path / "killed.rrd"
    child = start_child(
        tmp_path, 'print("ready", flush=True)\ntime.sleep(120)', "save", "40", "6", str(path)
    )
    try:
        read_until(child, "ready")
    finally:
        child.kill()
        child.wait()
    rec = read_recording(path)
    assert rec.views_of(f"/top/map/objects/{NAME}/grid", "DepthImage:buffer") == list(range(6))
    assert rec.views_of(f"/world/wedges/{NAME}", "Mesh3D:vertex_positions") == list(range(6))


def test_spawn_without_a_display_saves_instead(tmp_path, monkeypatch, capsys) -> None:
    monkeypatch.delenv("DISPLAY", raising=False)
    monkeypatch.delenv("WAYLAND_DISPLAY", raising=False)
    monkeypatch.setattr(sys, "platform", "linux")
    path = tmp_path / "spawned.rrd"
    recorder = RerunRecorder("spawn", path)
    if recorder.mode != "save":
        pytest.fail(f"spawn without a display went to mode {recorder.mode!r}")
    printed = capsys.readouterr().out.strip().splitlines()
    assert len(printed) == 1 and "no display" in printed[0] and str(path) in printed[0]
    grid = make_grid()
    recorder.begin(make_scene(), grid, 2)
    for record, _ in synthetic_views(grid, 2):
        recorder.log_view(record, grid)
    recorder.end()
    recorder.wait()  # returns at once: nothing to serve
    assert read_recording(path).views_of(f"/world/wedges/{NAME}", "Mesh3D:vertex_positions") == [
        0,
        1,
    ]


def test_serve_stops_its_server_group_when_the_mission_ends_early(tmp_path) -> None:
    grid = make_grid()
    recorder = RerunRecorder("serve", tmp_path / "unused.rrd")
    pgid = recorder.server_pid
    assert pgid is not None and group_alive(pgid)
    assert os.getpgid(pgid) == pgid != os.getpgid(0)  # its own group: Ctrl-C does not reach it
    recorder.begin(make_scene(), grid, 8)
    for record, _ in synthetic_views(grid, 2):  # 2 of 8 views: the mission was interrupted
        recorder.log_view(record, grid)
    recorder.end()
    assert wait_gone(pgid)


def test_ctrl_c_while_serving_stops_the_server_and_propagates(tmp_path) -> None:
    child = start_child(
        tmp_path,
        """
        recorder.end()
        print("server", recorder.server_pid, flush=True)
        try:
            recorder.wait()
        except KeyboardInterrupt:  # the command line turns it into exit 130
            print("done", flush=True)
        """,
        "serve",
        "2",
        "2",
        str(tmp_path / "unused.rrd"),
    )
    try:
        pgid = int(read_until(child, "server").split()[1])
        assert group_alive(pgid)  # a finished mission keeps serving until Ctrl-C
        read_until(child, "Rerun server serving")
        os.killpg(child.pid, signal.SIGINT)  # what Ctrl-C sends to the foreground job
        out, err = child.communicate(timeout=30)
    finally:
        child.kill()
    assert child.returncode == 0, err
    assert "Traceback" not in err and "done" in out
    assert wait_gone(pgid)


def test_sigterm_leaves_no_server_behind(tmp_path) -> None:
    if not sys.platform.startswith("linux"):
        pytest.skip("the server dies with its parent through a Linux prctl")
    child = start_child(
        tmp_path,
        """
        recorder.end()
        print("server", recorder.server_pid, flush=True)
        recorder.wait()
        """,
        "serve",
        "1",
        "1",
        str(tmp_path / "unused.rrd"),
    )
    try:
        pgid = int(read_until(child, "server").split()[1])
        read_until(child, "Rerun server serving")
        os.kill(child.pid, signal.SIGTERM)
        child.wait(timeout=30)
    finally:
        child.kill()
    assert wait_gone(pgid), "the Rerun server outlived the survey"


def test_localization_draws_the_map_the_scan_at_the_pose_and_the_particles(tmp_path) -> None:
    """A laser localizer's view: the map's occupied cells, the scan's returns where they hit
    (laser mounted ahead of the base's centre), the particles, and the true path."""
    from dataclasses import replace

    from twin.core.devices import LaserMount, Scan
    from twin.nav.maps import OccupancyMap

    occupancy = np.zeros((120, 90))
    occupancy[100:102, 20:30] = 1.0  # a wall segment 1.0..1.5 m in x at y = 5.0..5.1 m
    scene = replace(make_scene(), occupancy=OccupancyMap(occupancy, 0.05))
    grid = make_grid()
    mount = LaserMount(x=0.2, y=0.0, z=0.3, yaw=0.0)
    # two beams: straight ahead 1 m, and 90 degrees left 0.5 m; a third saw nothing
    scan = Scan(np.array([0.0, math.pi / 2, -math.pi / 2]), np.array([1.0, 0.5, np.nan]), 0.0, 8.0)
    particles = np.array([[1.1, 1.2, 0.0], [1.12, 1.18, 0.01], [1.09, 1.21, -0.01]])
    path = tmp_path / "localized.rrd"
    recorder = RerunRecorder("save", path)
    recorder.begin(scene, grid, 1)
    record, _ = next(synthetic_views(grid, 1))  # at (1.1, 1.2) facing +x
    record = replace(
        record,
        localization=Localization(scan, mount, particles),
        truth_path=((1.12, 1.2, 0.0),),
    )
    recorder.log_view(record, grid)
    recorder.end()
    rec = read_recording(path)
    (hits,) = seen_2d(rec, "/top/map/scan", 0, "Points2D:positions")
    np.testing.assert_allclose(hits, [[1.1 + 0.2 + 1.0, 1.2], [1.1 + 0.2, 1.2 + 0.5]], atol=1e-6)
    (dots,) = seen_2d(rec, "/top/map/particles", 0, "Points2D:positions")
    np.testing.assert_allclose(dots, particles[:, :2], atol=1e-6)
    (cells,) = seen_2d(rec, "/top/map/occupancy", 0, "Points2D:positions")
    assert len(cells) == 20 and np.allclose(cells.mean(axis=0), (1.25, 5.05), atol=1e-6)


def test_a_view_not_taken_for_an_object_draws_no_wedges_for_it(tmp_path) -> None:
    """The floor sweep's views are fused into the floor's objects only: the viewer draws no
    wedges for the others at those views, as though they had counted (it clears them)."""
    path = tmp_path / "sweep.rrd"
    grid = make_grid()
    recorder = RerunRecorder("save", path)
    recorder.begin(make_scene(), grid, 3)
    for record, _ in synthetic_views(grid, 3):
        looked_for = ("toy_crate",) if record.index == 1 else None
        recorder.log_view(dataclasses.replace(record, looked_for=looked_for), grid)
    recorder.end()
    rec = read_recording(path)
    assert rec.views_of(f"/world/wedges/{NAME}", "Mesh3D:vertex_positions") == [0, 2]
    assert rec.views_of(f"/world/wedges/{NAME}", "Clear:is_recursive") == [1]  # cleared there
