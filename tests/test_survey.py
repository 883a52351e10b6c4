"""The survey: its plan, one view in the Mission, a reduced mission in the twin, resume, run
folders, signals."""

import json
import math
import os
import signal
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
import pytest

from twin.app.config import MissionConfig, load_config
from twin.app.mission import Checkpoint, Mission, MissionState, NotReachedError, PoseGate
from twin.app.record import Localization
from twin.app.survey import plan_views, run_survey
from twin.app.view_log import ViewLog
from twin.cli import main
from twin.core.devices import VCC4_LIMITS, Base, Camera, DeviceFaultError, Frame, PanTilt, Robot
from twin.core.errors import TwinError
from twin.core.geometry import CameraModel, Pose2D, wrap_angle
from twin.core.grid import AccumulatorGrid, GridSpec

REDUCED = "mission.stops=[[1.1, 1.2], [2.5, 3.3], [2.7, 4.4]]"  # 3 of the paper's 5 stops: 24 views


def survey_argv(out: Path, cache: Path, *sets: str, rerun: str = "off") -> list[str]:
    """``twin survey`` of the shipped config with the reduced mission and a shared model cache."""
    argv = ["survey", "--out", str(out), "--quiet", "--set", REDUCED]
    for setting in (f"run.cache={cache}", f"run.rerun={rerun}", *sets):
        argv += ["--set", setting]
    return argv


def read_result(out: Path) -> dict:
    return json.loads((out / "result.json").read_text())


# -- planning --------------------------------------------------------------------------------


def test_pan_mode_covers_every_heading_with_two_base_turns_per_stop():
    headings = tuple(math.radians(45 * i) for i in range(8))
    mission = MissionConfig((0.0, 0.0, 0.0), ((1.0, 1.0), (2.0, 2.0)), headings, "pan")
    plan = plan_views(mission, VCC4_LIMITS)
    assert len(plan) == 16
    for stop in (0, 1):
        views = [v for v in plan if v.stop == stop]
        assert len({round(v.base.yaw, 9) for v in views}) == 2
        seen = sorted(
            round(float(wrap_angle(v.base.yaw + v.pan)) % (2 * math.pi), 6) for v in views
        )
        assert seen == sorted(round(h % (2 * math.pi), 6) for h in headings)
        assert all(abs(v.pan) <= VCC4_LIMITS.pan_max for v in views)


def test_base_mode_faces_every_heading_with_the_head_straight():
    headings = tuple(math.radians(45 * i) for i in range(8))
    mission = MissionConfig((0.0, 0.0, 0.0), ((1.0, 1.0),), headings, "base", math.radians(10))
    plan = plan_views(mission, VCC4_LIMITS)
    assert [v.pan for v in plan] == [0.0] * 8
    assert {v.tilt for v in plan} == {math.radians(10)}
    assert sorted(round(v.base.yaw % (2 * math.pi), 6) for v in plan) == sorted(
        round(h % (2 * math.pi), 6) for h in headings
    )


# -- one view, on stand-in devices with exact poses ----------------------------------------------


class Switch:
    """connect/close for the stand-in devices: they only remember whether they are open."""

    _open = False

    def connect(self):
        self._open = True

    def close(self):
        self._open = False

    @property
    def is_connected(self):
        return self._open


class ExactBase(Switch, Base):
    name = "exact base"

    def __init__(self):
        self._pose = Pose2D(0.5, 0.5, 0.0)

    def pose(self):
        return self._pose

    def set_pose(self, pose):
        self._pose = pose

    def go_to(self, goal, *, timeout=60.0):
        self._pose = goal
        return goal

    def drive(self, speed, turn_rate, duration):
        return self._pose

    def stop(self):
        pass


class ExactHead(Switch, PanTilt):
    name = "exact head"

    def __init__(self):
        self.angles = (0.0, 0.0)

    @property
    def limits(self):
        return VCC4_LIMITS

    def move_to(self, pan, tilt=0.0, *, speed=None, timeout=10.0):
        self.angles = (pan, tilt)
        return self.angles

    def position(self):
        return self.angles

    def stop(self):
        pass


class PoseCamera(Switch, Camera):
    """Renders nothing: its image is a deterministic function of where the robot looks."""

    name = "pose camera"

    def __init__(self, base, head):
        self.base, self.head = base, head

    @property
    def model(self):
        return CameraModel(64, 48)

    def grab(self):
        pose, (pan, _) = self.base.pose(), self.head.position()
        seed = int(1e6 * (pose.x + 3 * pose.y + 7 * (pose.yaw + pan)) % 2**32)
        image = np.random.default_rng(seed).integers(0, 256, (48, 64, 3), dtype=np.uint8)
        return Frame(image, 0.0)


class MeanDetector:
    """A stand-in detector: a patch's score is its mean red level."""

    names = ("thing",)

    def scores(self, image):
        red = image[..., 0].astype(float) / 255
        return red.reshape(3, 16, 8, 8).mean(axis=(1, 3))[None]

    def patch_boxes(self, shape):
        return np.array(
            [[[8 * c, 16 * r, 8 * c + 8, 16 * r + 16] for c in range(8)] for r in range(3)]
        )

    def column_spans(self, width):
        return np.array([[8 * c, 8 * c + 8] for c in range(8)], dtype=float)


class Clocked(PoseCamera):
    """A pose camera on a clock that starts at ``t0`` and runs 2 s per grab."""

    def __init__(self, base, head, t0):
        super().__init__(base, head)
        self.t = t0

    def now(self):
        return self.t

    def grab(self):
        self.t += 2.0
        return Frame(super().grab().image, self.t)


MISSION = MissionConfig(
    (0.5, 0.5, 0.0),
    ((1.0, 1.0), (3.0, 1.5), (2.0, 3.0)),
    tuple(math.radians(60 * i) for i in range(6)),
)
SPEC = GridSpec(0.0, 0.0, 4.0, 4.0, 0.1)


class Recording:
    """A recorder that remembers what it was given and when it was flushed."""

    def __init__(self):
        self.events = []

    def begin(self, scene, grid, planned_views):
        self.events.append(("begin", planned_views))

    def log_view(self, record, grid):
        self.events.append(("view", record.index, record.robot_time, len(record.path)))

    def flush(self):
        self.events.append(("flush",))

    def end(self):
        self.events.append(("end",))

    def wait(self):
        pass


def exact_mission(out: Path | None, grid=None, state=None, t0=100.0, recorder=None) -> Mission:
    base, head = ExactBase(), ExactHead()
    robot = Robot(Clocked(base, head, t0), head, base)
    return Mission(
        robot,
        MeanDetector(),
        grid or AccumulatorGrid(["thing"], SPEC),
        recorder=recorder,
        checkpoint=Checkpoint(out) if out else None,
        state=state,
    )


def test_a_view_is_fused_recorded_flushed_then_checkpointed(tmp_path):
    recorder = Recording()
    mission = exact_mission(tmp_path, recorder=recorder)
    plan = plan_views(MISSION, VCC4_LIMITS)
    with mission.robot:
        record = mission.observe(plan[0])
    assert record.index == 0 and record.view.pose == plan[0].base
    assert record.robot_time == pytest.approx(2.0)  # the robot's clock since the mission began
    assert recorder.events == [("view", 0, 2.0, 1), ("flush",)]
    saved = AccumulatorGrid.load(tmp_path / "checkpoint" / "grid.npz")
    np.testing.assert_array_equal(saved.layer("thing"), mission.grid.layer("thing"))
    assert MissionState.read(tmp_path / "checkpoint" / "state.json").views_done == 1
    assert mission.result()["views"] == 1


def test_resume_after_an_interruption_gives_the_same_grid_and_continues_the_clock(tmp_path):
    plan = plan_views(MISSION, VCC4_LIMITS)
    straight = exact_mission(None)
    with straight.robot:
        run_survey(straight, plan)

    interrupted = exact_mission(tmp_path)

    def stop_at_view_7(view):
        if view.index == 7:
            raise KeyboardInterrupt

    with pytest.raises(KeyboardInterrupt), interrupted.robot:
        run_survey(interrupted, plan, on_view=stop_at_view_7)
    grid, state = Checkpoint(tmp_path).load(AccumulatorGrid(["thing"], SPEC))
    assert grid.views("thing") == 7 and state.views_done == 7
    assert state.robot_time == pytest.approx(14.0)
    # A new session's clock starts anywhere (here at 5000 s): robot time continues from 14 s.
    resumed = exact_mission(tmp_path, grid, state, t0=5000.0)
    with resumed.robot:
        run_survey(resumed, plan)
    assert resumed.views_done == 18 and len(resumed.state.path) == 18
    assert resumed.state.robot_time == pytest.approx(36.0)
    np.testing.assert_array_equal(resumed.grid.layer("thing"), straight.grid.layer("thing"))
    np.testing.assert_array_equal(resumed.grid.observed("thing"), straight.grid.observed("thing"))


def test_a_mission_refuses_a_state_that_is_not_its_grids(tmp_path):
    with pytest.raises(TwinError, match=r"state says 3 views \(0 refused\) but its grid holds 0"):
        exact_mission(None, state=MissionState(views_done=3))
    plan = plan_views(MISSION, VCC4_LIMITS)
    mission = exact_mission(None)
    with mission.robot:
        run_survey(mission, plan)
    with pytest.raises(TwinError, match="holds 18 views but its plan has 6"):
        run_survey(mission, plan[:6])


class UnsureBase(ExactBase):
    """An exact base that says it is unsure of its pose at the second stop (x = 3.0)."""

    def pose_covariance(self):
        sigma = 0.2 if self._pose.x == 3.0 else 0.01
        return np.diag([sigma**2, sigma**2, math.radians(0.5) ** 2])


def unsure_mission(out, grid=None, state=None, said=None):
    base, head = UnsureBase(), ExactHead()
    robot = Robot(Clocked(base, head, 0.0), head, base)
    offset = Pose2D(0.1, 0.0, math.radians(1.0))  # the truth lies 0.1 m and 1 degree away

    def truth():
        p = base.pose()
        return Pose2D(p.x + offset.x, p.y, p.yaw + offset.yaw)

    return Mission(
        robot, MeanDetector(), grid or AccumulatorGrid(["thing"], SPEC),
        checkpoint=Checkpoint(out), state=state, truth_pose=truth,
        pose_gate=PoseGate(max_sigma_m=0.05), say=said.append if said is not None else print,
    )  # fmt: skip


def test_a_view_whose_pose_is_too_uncertain_is_reported_and_not_fused(tmp_path):
    plan = plan_views(MISSION, VCC4_LIMITS)
    at_second_stop = [v.index for v in plan if v.stop == 1]
    said = []
    mission = unsure_mission(tmp_path, said=said)

    def stop_after_second_stop(view):
        if view.index == at_second_stop[-1] + 2:
            raise KeyboardInterrupt

    with pytest.raises(KeyboardInterrupt), mission.robot:
        run_survey(mission, plan, stop_after_second_stop)
    assert [r["view"] for r in mission.state.refused] == at_second_stop
    assert all("pose uncertain: 20.0 cm (1 sigma)" in r["reason"] for r in mission.state.refused)
    assert len(said) == len(at_second_stop) and said[0].startswith(f"view {at_second_stop[0] + 1}")
    # a resumed mission counts fused and refused views alike and takes no view twice
    grid, state = Checkpoint(tmp_path).load(AccumulatorGrid(["thing"], SPEC))
    assert grid.views("thing") == state.views_done - len(at_second_stop)
    resumed = unsure_mission(tmp_path, grid, state)
    with resumed.robot:
        run_survey(resumed, plan)
    assert resumed.views_done == len(plan)
    assert resumed.grid.views("thing") == len(plan) - len(at_second_stop)
    result = resumed.result()
    assert [r["view"] for r in result["views_refused"]] == at_second_stop
    assert result["pose_error"] == {"max_m": 0.1, "mean_m": 0.1, "max_deg": 1.0}


class BlockedStopBase(UnsureBase):
    """A base that cannot reach the second stop (x = 3.0): something stands there that its
    map does not hold."""

    def __init__(self):
        super().__init__()
        self.tries = 0

    def pose_covariance(self):
        return np.diag([1e-4, 1e-4, 1e-4])

    def go_to(self, goal, *, timeout=60.0):
        if goal.x == 3.0:
            self.tries += 1
            raise DeviceFaultError(self.name, "go to", "no safe path: a crate", "clear it")
        return super().go_to(goal, timeout=timeout)


class LocalizedBlockedStopBase(BlockedStopBase):
    """The same, localizing (it has a ``snapshot``): it has backed off and found itself."""

    def snapshot(self):
        return Localization(None, None)


def test_a_stop_the_base_cannot_reach_is_skipped_reported_and_the_survey_goes_on(tmp_path):
    plan = plan_views(MISSION, VCC4_LIMITS)
    at_second_stop = [v.index for v in plan if v.stop == 1]
    base, head, said = LocalizedBlockedStopBase(), ExactHead(), []
    robot = Robot(Clocked(base, head, 0.0), head, base)
    grid = AccumulatorGrid(["thing"], SPEC)
    mission = Mission(
        robot, MeanDetector(), grid, checkpoint=Checkpoint(tmp_path), truth_pose=base.pose,
        say=said.append,
    )  # fmt: skip
    with mission.robot:
        run_survey(mission, plan)
    assert base.tries == 1  # one try, then the stop's other views are skipped without driving
    assert mission.views_done == len(plan)
    assert mission.grid.views("thing") == len(plan) - len(at_second_stop)
    refused = mission.result()["views_refused"]
    assert [r["view"] for r in refused] == at_second_stop
    assert all(
        r["reason"].startswith("not reached: exact base: go to: no safe path") for r in refused
    )
    assert said == [f"stop 2 not reached, its views skipped: {refused[0]['reason'][13:]}"]
    # the checkpoint holds it all: a resumed run takes no view twice
    grid, state = Checkpoint(tmp_path).load(AccumulatorGrid(["thing"], SPEC))
    assert state.views_done == len(plan) and len(Checkpoint(tmp_path).load_views(state)) == len(
        plan
    )


def test_an_unreachable_place_still_stops_a_base_that_does_not_localize(tmp_path):
    """Without a localizer nothing backed the base off what stopped it: the fault ends the run."""
    plan = plan_views(MISSION, VCC4_LIMITS)
    base, head = BlockedStopBase(), ExactHead()
    robot = Robot(Clocked(base, head, 0.0), head, base)
    mission = Mission(robot, MeanDetector(), AccumulatorGrid(["thing"], SPEC))
    with mission.robot, pytest.raises(DeviceFaultError, match="no safe path") as caught:
        run_survey(mission, plan)
    assert not isinstance(caught.value, NotReachedError)


# -- the mission in the twin ------------------------------------------------------------------


@pytest.fixture(scope="module")
def reduced_run(tmp_path_factory, model_cache):
    out = tmp_path_factory.mktemp("reduced") / "run"
    assert main(survey_argv(out, model_cache, rerun="save")) == 0
    return out


def test_a_reduced_mission_finds_the_rice_box(reduced_run):
    result = read_result(reduced_run)
    box = result["objects"]["rice_box"]
    assert result["status"] == "complete"
    assert result["views"] == result["views_planned"] == 24
    assert box["error_m"] < 0.2
    # 3-D: the height from the rows its best patches were in, the truth from the twin
    assert len(box["estimate_m"]) == len(box["truth_m"]) == 3
    assert box["height_views"] >= 2 and box["height_error_m"] < 0.1
    assert box["height_error_m"] == pytest.approx(
        abs(box["estimate_m"][2] - box["truth_m"][2]), abs=2e-4
    )
    assert box["peak_ratio"] is None or box["peak_ratio"] > 1.1
    assert set(result["timings_s"]) >= {"move", "capture", "detect", "fuse", "record", "total"}
    assert result["robot_time_s"] > 0
    assert (reduced_run / "grid_rice_box.png").read_bytes()[:4] == b"\x89PNG"
    assert AccumulatorGrid.load(reduced_run / "grid.npz").views("rice_box") == 24


def test_the_run_keeps_the_config_it_really_ran_with(reduced_run, model_cache):
    config = load_config(reduced_run / "config.toml")
    assert config.mission.stops == ((1.1, 1.2), (2.5, 3.3), (2.7, 4.4))
    assert config.cache == model_cache
    text = (reduced_run / "config.toml").read_text()
    assert text.startswith("# The config this run used:") and "# with --set mission.stops" in text
    options = json.loads((reduced_run / "run.json").read_text())
    assert options["kind"] == "twin-survey-run" and REDUCED in options["overrides"]


def test_the_recording_holds_the_expected_entities(reduced_run):
    from rerun.chunk import RrdReader

    store = RrdReader(reduced_run / "recording.rrd").store()
    entities = set(store.schema().entity_paths())
    assert {"/world/robot", "/world/robot/camera/image"} <= entities
    archetypes = {str(a) for a in store.schema().archetypes()}
    assert any("GridMap" in a for a in archetypes) and any("Pinhole" in a for a in archetypes)


def test_the_grid_as_the_viewer_draws_it_is_brightest_at_the_estimate(reduced_run):
    """Read the real survey's recording the way Rerun draws it (a GridMap's row 0 at the top, a
    2-D view's y down) and find the brightest cell: it must sit on the estimate, in every
    picture of the grid, not mirrored to the other end of the room."""
    from test_record import brightest, drawn_grids, read_recording

    estimate = read_result(reduced_run)["objects"]["rice_box"]["estimate_m"][:2]
    pictures = drawn_grids(read_recording(reduced_run / "recording.rrd"), view=23)
    assert {p.kind for p in pictures} == {"DepthImage", "GridMap"}
    for picture in pictures:
        assert math.dist(brightest(picture), estimate) < 0.15, picture.entity


def test_the_viewer_shows_the_estimate_at_its_height(reduced_run):
    """In the 3-D view the estimate is drawn where the result says the object is, at its
    height, not on the floor."""
    from test_record import read_recording

    box = read_result(reduced_run)["objects"]["rice_box"]
    rec = read_recording(reduced_run / "recording.rrd")
    drawn = rec.latest("/world/estimate/rice_box", "Points3D:positions", 23)
    assert drawn is not None
    assert np.allclose(np.asarray(drawn[0], dtype=float), box["estimate_m"], atol=2e-3)


def test_ctrl_c_while_serving_the_results_stops_the_server_and_exits_130(tmp_path, model_cache):
    out = tmp_path / "run"
    sets = ("mission.stops=[[2.5, 3.3]]", "mission.views_per_stop=2")
    argv = survey_argv(out, model_cache, *sets, rerun="serve")
    process = subprocess.Popen(
        [sys.executable, "-m", "twin.cli", *argv],
        stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True, start_new_session=True,
        env={**os.environ, "MUJOCO_GL": "egl"},
    )  # fmt: skip
    assert "serving the recording" in process.stdout.readline()
    # The survey's own server: a session led by one of its children (other tests, in other
    # workers, may be serving recordings of their own).
    table = [
        line.split(None, 3)
        for line in subprocess.run(
            ["ps", "-ww", "-o", "pid=,ppid=,pgid=,args=", "-A"], capture_output=True, text=True
        ).stdout.splitlines()
    ]
    children = {int(pid) for pid, ppid, *_ in table if int(ppid) == process.pid}
    server_groups = {
        int(pgid) for _, _, pgid, args in table if "serve-grpc" in args and int(pgid) in children
    }
    assert server_groups, "the survey serves its recording from a server of its own"
    from test_record import group_alive

    os.killpg(process.pid, signal.SIGINT)  # what a terminal's Ctrl-C sends to the job
    _, err = process.communicate(timeout=60)
    assert process.returncode == 130, err
    assert "Traceback" not in err and err.strip().endswith("interrupted")
    assert read_result(out)["status"] == "complete"
    deadline = time.monotonic() + 15
    while any(group_alive(g) for g in server_groups):
        assert time.monotonic() < deadline, "the Rerun server outlived the survey"
        time.sleep(0.1)


def test_an_interrupted_survey_writes_its_results_and_resumes(
    tmp_path, model_cache, monkeypatch, reduced_run
):
    out = tmp_path / "run"
    real = Mission.observe

    def observe(self, target):
        if self.views_done == 10:
            raise KeyboardInterrupt
        return real(self, target)

    monkeypatch.setattr(Mission, "observe", observe)
    assert main(survey_argv(out, model_cache, rerun="save")) == 130
    stopped = read_result(out)
    assert stopped["status"] == "interrupted" and stopped["views"] == 10
    assert stopped["views_planned"] == 24
    assert AccumulatorGrid.load(out / "grid.npz").views("rice_box") == 10
    monkeypatch.setattr(Mission, "observe", real)
    assert main(["survey", "--resume", str(out), "--quiet"]) == 0
    result = read_result(out)
    assert result["status"] == "complete" and result["views"] == 24
    assert result["robot_time_s"] > stopped["robot_time_s"]  # the clock went on, not from 0
    assert (out / "recording-resumed-1.rrd").is_file()
    # The view log went on too: all 24 views, and the confidence counts every one of them.
    assert len(ViewLog.load(out / "views.npz")) == 24
    assert 0.0 <= result["objects"]["rice_box"]["confidence"] <= 1.0
    resumed = AccumulatorGrid.load(out / "grid.npz").layer("rice_box")
    straight = AccumulatorGrid.load(reduced_run / "grid.npz").layer("rice_box")
    # The resumed robot reaches each stop by another path and localizes there anew, so its
    # poses differ from the straight run's by the localization's centimetre or two. (With the
    # room's baseline taken off, most cells sit near 0, where such shifts weigh most: 0.96
    # measured, 0.97+ for the paper's rule alone.)
    assert np.corrcoef(resumed.ravel(), straight.ravel())[0, 1] > 0.94
    assert (
        math.dist(
            result["objects"]["rice_box"]["estimate_m"][:2],
            read_result(reduced_run)["objects"]["rice_box"]["estimate_m"][:2],
        )
        <= 0.1 + 1e-9
    )


def test_the_run_logs_its_views_and_they_fuse_again_into_its_grid(reduced_run):
    grid = AccumulatorGrid.load(reduced_run / "grid.npz")
    log = ViewLog.load(reduced_run / "views.npz")
    assert len(log) == 24
    again = AccumulatorGrid(
        grid.objects, grid.spec, grid.rules, grid.supersample,
        direction_bins=grid.direction_bins, baseline=grid.baselines,
    )  # fmt: skip
    log.fuse_into(again, visibility=load_config(reduced_run / "config.toml").grid.visibility)
    np.testing.assert_array_equal(again.evidence("rice_box"), grid.evidence("rice_box"))
    # The twin's depth hid something in some columns and showed the open room in others.
    profiles = np.concatenate([v.visibility.profiles.ravel() for v in log.views])
    assert (profiles == 0).mean() > 0.05 and (profiles == 1).mean() > 0.02
    assert ((profiles > 0) & (profiles < 1)).any()  # and parts of objects: partly hidden


def test_the_result_says_how_sure_it_is_from_the_calibrated_belief(reduced_run):
    from twin.app.config import load_config
    from twin.app.detection import mission_detector
    from twin.app.run import make_grids
    from twin.core.confidence import confidence_within, posterior

    box = read_result(reduced_run)["objects"]["rice_box"]
    config = load_config(reduced_run / "config.toml")
    detector, rooms = mission_detector(config, lambda _: None)  # cached by the run: no retraining
    assert set(rooms) == {"rice_box"}  # the twin measured the room's look with the calibration
    _, belief = make_grids(config, detector, rooms)
    assert belief.rule.name == "calibrated" and set(belief.baselines) == {"rice_box"}
    ViewLog.load(reduced_run / "views.npz").fuse_into(belief)
    options = config.confidence
    cells, p_absent = posterior(belief.layer("rice_box"), options.temperature, options.p_absent)
    # The grid's own peak, unrounded: a cell 0.2 m from it is in or out by a hair.
    peak = AccumulatorGrid.load(reduced_run / "grid.npz").peaks("rice_box", k=1).best
    assert math.dist((peak.x, peak.y), box["estimate_m"][:2]) < 1e-3
    within = confidence_within(cells, config.grid.spec, (peak.x, peak.y), options.radius_m)
    assert box["confidence"] == pytest.approx(within, abs=1e-4)
    assert box["p_absent"] == pytest.approx(p_absent, abs=1e-4)
    assert box["confidence"] > 0.5  # a reduced survey that finds the box is fairly sure of it


def test_resuming_a_finished_run_changes_nothing(reduced_run, capsys):
    before = {p: p.stat().st_mtime_ns for p in reduced_run.rglob("*")}
    assert main(["survey", "--resume", str(reduced_run)]) == 0
    assert "is a finished run (24 views); nothing to resume" in capsys.readouterr().out
    assert {p: p.stat().st_mtime_ns for p in reduced_run.rglob("*")} == before


def test_random_target_placement_moves_the_truth(tmp_path, model_cache):
    out = tmp_path / "run"
    argv = survey_argv(out, model_cache, "mission.stops=[[2.5, 3.3]]", "mission.views_per_stop=2")
    assert main([*argv, "--place-target", "random", "--seed", "3"]) == 0
    truth = read_result(out)["objects"]["rice_box"]["truth_m"]
    assert math.dist(truth[:2], (1.5, 5.0)) > 0.3


# -- run folders --------------------------------------------------------------------------------


def one_line_error(capsys, argv: list[str]) -> str:
    code = main(argv)
    err = capsys.readouterr().err.strip()
    assert code == 2, err
    assert len(err.splitlines()) == 1, err
    return err


def test_an_unusable_out_is_one_line_and_creates_nothing(tmp_path, capsys):
    a_file = tmp_path / "a_file"
    a_file.write_text("mine")
    cases = {
        a_file: "is a file, not a folder",
        a_file / "inside": "lies inside",
        Path("/proc/no/such/run"): "cannot create the folder",
    }
    for out, message in cases.items():
        assert message in one_line_error(capsys, ["survey", "--out", str(out), "--quiet"])
    assert a_file.read_text() == "mine"
    assert sorted(p.name for p in tmp_path.iterdir()) == ["a_file"]


def test_a_folder_that_is_not_a_run_is_refused_never_overwritten(tmp_path, capsys):
    theirs = tmp_path / "theirs"
    theirs.mkdir()
    (theirs / "result.json").write_text("someone else's")
    err = one_line_error(capsys, ["survey", "--out", str(theirs), "--quiet"])
    assert "holds files that are not a twin survey run (e.g. result.json)" in err
    assert [p.name for p in theirs.iterdir()] == ["result.json"]


def test_a_run_folder_is_never_restarted_and_resume_needs_a_run(tmp_path, reduced_run, capsys):
    assert "--resume" in one_line_error(capsys, ["survey", "--out", str(reduced_run), "--quiet"])
    assert "holds no survey to resume" in one_line_error(
        capsys, ["survey", "--resume", str(tmp_path)]
    )
    (tmp_path / "f").write_text("x")
    assert "is a file" in one_line_error(capsys, ["survey", "--resume", str(tmp_path / "f")])
    for content in ('{"kind": "twin-survey-run"}', "[1, 2]", "{torn"):
        (tmp_path / "run.json").write_text(content)
        err = one_line_error(capsys, ["survey", "--resume", str(tmp_path)])
        assert "run.json" in err and "start a new run" in err


def test_a_false_start_leaves_no_folder_behind(tmp_path, capsys, model_cache):
    out = tmp_path / "new" / "run"
    argv = survey_argv(out, model_cache, "scene.file=no_such_room.xml")
    assert "scene.file: no scene file" in one_line_error(capsys, argv)
    assert not (tmp_path / "new").exists()


# -- signals ------------------------------------------------------------------------------------


def wait_for(path: Path, timeout: float = 120.0) -> None:
    deadline = time.monotonic() + timeout
    while not path.exists():
        assert time.monotonic() < deadline, f"{path} never appeared"
        time.sleep(0.05)


@pytest.mark.parametrize(("signum", "code", "status"), [
    (signal.SIGTERM, 143, "terminated"), (signal.SIGINT, 130, "interrupted"),
])  # fmt: skip
def test_a_signal_mid_run_writes_the_results_so_far_and_exits_cleanly(
    tmp_path, model_cache, reduced_run, signum, code, status
):
    out = tmp_path / "run"
    argv = survey_argv(out, model_cache)
    process = subprocess.Popen(
        [sys.executable, "-m", "twin.cli", *argv], stderr=subprocess.PIPE, text=True,
        env={**os.environ, "MUJOCO_GL": "egl"},
    )  # fmt: skip
    wait_for(out / "checkpoint" / "grid.npz")
    process.send_signal(signum)
    _, err = process.communicate(timeout=120)
    assert process.returncode == code, err
    assert "Traceback" not in err and err.strip().splitlines()[-1].endswith(status)
    result = read_result(out)
    assert result["status"] == status and 1 <= result["views"] < 24
    assert AccumulatorGrid.load(out / "grid.npz").views("rice_box") == result["views"]
