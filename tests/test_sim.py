"""The twin robot: camera geometry measured from renders, driving, the pan-tilt's limits and
speeds, determinism, a golden frame, training views, and typed errors."""

from __future__ import annotations

import math
from pathlib import Path

import cv2
import numpy as np
import pytest

# isort: off
import twin.sim  # noqa: F401  (must come first: it selects headless GL before mujoco loads)
import mujoco

# isort: on
from twin.cli import main
from twin.core.devices import (
    BumpedError,
    DeviceFaultError,
    NotConnectedError,
    OutOfRangeError,
)
from twin.core.errors import InputError, TwinError
from twin.core.geometry import CameraModel, Pose2D
from twin.sim.drive import DiffDriveGeometry, Odometry, StallMonitor
from twin.sim.render import FrameRenderer
from twin.sim.robot import (
    CAMERA_NAME,
    STALL_DUTY,
    STALL_TIME,
    STALL_TORQUE,
    SimCamera,
    SimRobot,
    make_sim_robot,
)
from twin.sim.training import training_views
from twin.sim.world import World

DATA = Path(__file__).parent / "data"
# Regenerate (only after a deliberate change of the scene or robot) with:
#   twin sim snapshot --pose 2.5,3.3,134 --out tests/data/sim_golden_living_room.png
GOLDEN = DATA / "sim_golden_living_room.png"
GOLDEN_POSE = Pose2D(2.5, 3.3, math.radians(134.0))


def _box_corners(world: World, name: str) -> np.ndarray:
    geom = mujoco.mj_name2id(world.model, mujoco.mjtObj.mjOBJ_GEOM, name)
    half = world.model.geom_size[geom]
    signs = np.array([[sx, sy, sz] for sx in (-1, 1) for sy in (-1, 1) for sz in (-1, 1)])
    rot = world.data.geom_xmat[geom].reshape(3, 3)
    return world.data.geom_xpos[geom] + (signs * half) @ rot.T


@pytest.mark.parametrize(("pan_deg", "bearing_deg"), [(0.0, 12.0), (0.0, -15.0), (25.0, 35.0)])
def test_camera_height_and_fov_measured_from_a_render(pan_deg: float, bearing_deg: float) -> None:
    """The box's silhouette edges land where an ideal 45-degree camera 1.0 m up predicts."""
    camera = CameraModel()
    robot = SimRobot(World("living_room"), Pose2D(2.25, 0.9, math.pi / 2))
    robot.move_head(math.radians(pan_deg), 0.0)
    world = robot.world
    heading = robot.truth_pose().yaw + math.radians(bearing_deg)
    centre = robot.camera_position()[:2] + 2.6 * np.array([math.cos(heading), math.sin(heading)])
    world.place_static_body("rice_box", float(centre[0]), float(centre[1]), heading)
    with FrameRenderer(world.model, camera.width, camera.height, CAMERA_NAME) as renderer:
        ids = renderer.segment(world.data)
    geom = mujoco.mj_name2id(world.model, mujoco.mjtObj.mjOBJ_GEOM, "rice_box")
    rows, cols = np.nonzero(ids == geom)
    assert cols.size > 100

    # prediction: ideal pinhole at the camera's true x, y, at the nominal 1.0 m height
    cam_xy = robot.camera_position()[:2]
    axis = robot.truth_pose().yaw + robot.head()[0]
    corners = _box_corners(world, "rice_box")
    rel = corners[:, :2] - cam_xy
    forward = rel @ np.array([math.cos(axis), math.sin(axis)])
    left = rel @ np.array([-math.sin(axis), math.cos(axis)])
    u = camera.bearing_column(np.arctan2(left, forward))
    v_top = camera.height / 2 - camera.focal_px * (corners[:, 2].max() - 1.0) / forward
    assert cols.min() == pytest.approx(u.min(), abs=1.5)
    assert cols.max() + 1 == pytest.approx(u.max(), abs=1.5)
    assert rows.min() == pytest.approx(v_top.min(), abs=1.5)


@pytest.mark.parametrize(
    "goal",
    [
        Pose2D(2.3, 3.2, math.radians(45)),
        Pose2D(1.0, 1.4, math.radians(-90)),
        Pose2D(3.0, 1.9, math.radians(180)),
    ],
)
def test_driving_ends_within_5_cm_and_3_degrees(goal: Pose2D) -> None:
    robot = SimRobot(World("living_room"))
    estimate = robot.go_to(goal)
    truth = robot.truth_pose()
    assert truth.distance_to(goal) < 0.05
    assert abs(truth.heading_error_to(goal)) < math.radians(3.0)
    assert estimate.distance_to(truth) < 0.02  # odometry agrees with the truth
    assert robot.world.warnings() == {}


def _random_drive(seed: int) -> np.ndarray:
    robot = SimRobot(World("living_room"))
    rng = np.random.default_rng(seed)
    poses = []
    for _ in range(10):
        robot.set_wheel_speeds(rng.uniform(-0.3, 0.3), rng.uniform(-1.0, 1.0))
        robot.advance(0.2)
        p = robot.truth_pose()
        poses.append((p.x, p.y, p.yaw))
    return np.array(poses)


def test_same_seed_same_trajectory_and_another_seed_differs() -> None:
    first, again, other = _random_drive(3), _random_drive(3), _random_drive(4)
    np.testing.assert_array_equal(first, again)
    assert np.abs(first - other).max() > 0.01


def test_pan_tilt_respects_speeds_and_reaches_its_targets() -> None:
    robot = SimRobot(World("living_room"))
    peak = [0.0, 0.0]

    def watch(r: SimRobot) -> None:
        pan_rate, tilt_rate = r.head_rates()
        peak[0], peak[1] = max(peak[0], abs(pan_rate)), max(peak[1], abs(tilt_rate))

    robot.listeners.append(watch)
    t0 = robot.world.time
    pan, tilt = robot.move_head(math.radians(-100.0), math.radians(90.0))
    took = robot.world.time - t0
    assert math.degrees(pan) == pytest.approx(-100.0, abs=0.2)
    assert math.degrees(tilt) == pytest.approx(90.0, abs=0.2)
    assert took >= 100.0 / 90.0  # no faster than the VC-C4's 90 deg/s pan
    assert took < 100.0 / 90.0 + 0.5
    assert math.degrees(peak[0]) <= 90.0 * 1.01
    assert math.degrees(peak[1]) <= 70.0 * 1.01
    assert math.degrees(peak[0]) > 85.0  # it did use the top speed
    t0 = robot.world.time
    robot.move_head(math.radians(-70.0), math.radians(90.0), speed=math.radians(10.0))
    assert robot.world.time - t0 >= 3.0  # 30 deg at 10 deg/s


@pytest.mark.parametrize(
    ("pan", "tilt", "speed"),
    [(101, 0, None), (-101, 0, None), (0, -31, None), (0, 91, None), (10, 0, 91), (10, 0, 0)],
)
def test_pan_tilt_rejects_what_the_vcc4_cannot_do(pan: float, tilt: float, speed) -> None:
    _, robot = make_sim_robot()
    with robot.pantilt as head, pytest.raises(OutOfRangeError, match="sim pan-tilt"):
        head.move_to(
            math.radians(pan),
            math.radians(tilt),
            speed=None if speed is None else math.radians(speed),
        )


def test_devices_need_connecting_and_capture_views_with_pose_and_pan() -> None:
    sim, robot = make_sim_robot(start=GOLDEN_POSE)
    with pytest.raises(NotConnectedError, match="sim camera"):
        robot.camera.grab()
    with pytest.raises(NotConnectedError, match="sim base"):
        robot.base.pose()
    with robot:
        robot.pantilt.move_to(math.radians(30.0))
        robot.base.go_to(Pose2D(2.5, 3.3, math.radians(100.0)))
        view = robot.capture()
    assert view.image.shape == (240, 320, 3) and view.image.dtype == np.uint8
    assert math.degrees(view.pan) == pytest.approx(30.0, abs=0.2)
    assert view.pose.distance_to(sim.truth_pose()) < 0.02
    assert view.timestamp == pytest.approx(sim.world.time)
    assert not robot.camera.is_connected


def test_base_reports_a_blocked_path_as_a_fault() -> None:
    sim, robot = make_sim_robot(start=Pose2D(1.3, 3.2, math.pi / 2))
    with robot.base as base, pytest.raises(DeviceFaultError, match="touched the sofa"):
        base.go_to(Pose2D(0.8, 5.6, 0.0))  # straight through the sofa's arm and the table
    assert sim.world.warnings() == {}


def _at_rest(sim: SimRobot) -> bool:
    return bool(np.abs(sim.world.data.qvel[:6]).max() < 0.01)


def test_driving_into_the_coffee_table_is_a_fault_naming_it() -> None:
    sim, robot = make_sim_robot(start=Pose2D(1.6, 3.55, math.pi / 2))
    with robot.base as base, pytest.raises(DeviceFaultError) as caught:
        base.go_to(Pose2D(1.6, 4.7, math.pi / 2))  # the column meets the table top's edge
    seen = caught.value.seen
    assert "coffee_table" in seen and "contact" in seen
    assert isinstance(caught.value, BumpedError)
    assert caught.value.bearing == pytest.approx(0.0)  # the front bumper: the table is ahead
    truth = sim.truth_pose()
    assert f"({truth.x:.2f}, {truth.y:.2f}) m" in seen  # where, in the truth
    assert 4.0 < truth.y < 4.3  # stopped at the table's edge (4.2 m), not under it
    assert _at_rest(sim)


def test_brushing_a_table_leg_is_a_fault_not_a_silent_turn() -> None:
    """The right tyre grazes a leg of the coffee table by 1.5 cm: the base is knocked round,
    and the drive stops at the touch instead of carrying on from a pose odometry never saw."""
    start = Pose2D(2.4, 4.05, math.pi)
    sim, robot = make_sim_robot(start=start)
    with robot.base as base, pytest.raises(DeviceFaultError, match="coffee_table_leg"):
        base.go_to(Pose2D(1.3, 4.05, math.pi))
    truth = sim.truth_pose()
    assert 1.9 < truth.x < 2.0  # where the tyre reaches the leg at x = 1.86 m
    assert abs(math.degrees(truth.heading_error_to(start))) < 10.0
    assert _at_rest(sim)


def test_driving_into_a_wall_names_the_wall() -> None:
    sim, robot = make_sim_robot(start=Pose2D(3.8, 3.9, 0.0))
    with robot.base as base, pytest.raises(BumpedError, match="wall_right") as caught:
        base.drive(0.3, 0.0, 5.0)
    assert caught.value.bearing == pytest.approx(0.0)
    assert sim.truth_pose().x == pytest.approx(4.5 - 0.2, abs=0.01)  # chassis front at the wall


def test_a_base_against_a_wall_backs_away_but_cannot_push_on() -> None:
    """As the firmware's bump stall: a base resting with its front against the wall cannot
    drive on into it, but can back straight away (one resting against a crate could otherwise
    never leave it: every later drive failed at its first step); a new touch, on the way back,
    is a fault again."""
    sim, robot = make_sim_robot(start=Pose2D(3.8, 3.9, 0.0))
    with robot.base as base:
        sim.place(Pose2D(4.305, 3.9, 0.0), settle=0.0)  # the chassis front 5 mm in
        assert sim.contacts()
        with pytest.raises(BumpedError, match="wall_right"):
            base.drive(0.1, 0.0, 1.0)
        sim.place(Pose2D(4.305, 3.9, 0.0), settle=0.0)
        base.drive(-0.2, 0.0, 1.0)
        assert sim.truth_pose().x < 4.2 and not sim.contacts()
        sim.place(Pose2D(3.8, 3.9, math.pi), settle=0.0)  # backing into the wall
        with pytest.raises(BumpedError, match="wall_right") as caught:
            base.drive(-0.3, 0.0, 5.0)
    assert abs(caught.value.bearing) == pytest.approx(math.pi)


def test_a_seized_wheel_stalls() -> None:
    """No contact at all, but the left motor strains against its jammed wheel."""
    sim, robot = make_sim_robot(start=Pose2D(2.5, 3.3, 0.0))
    model = sim.world.model
    model.dof_frictionloss[model.jnt_dofadr[model.joint("left_wheel").id]] = 100.0
    with robot.base as base, pytest.raises(DeviceFaultError, match="left wheel motor stalled"):
        base.drive(0.3, 0.0, 3.0)


def test_a_wheel_pushing_a_wall_stalls_through_its_stick_slip() -> None:
    """Pushed against a wall, the wheels grip and slip in turn: the torque drops under the stall
    threshold several times a second. The stall still fires, within a second of the touch; a
    rule needing an unbroken strain never did (and odometry ran on by a metre)."""
    sim = SimRobot(World("living_room"), Pose2D(3.8, 3.9, 0.0))
    monitor = StallMonitor(STALL_TORQUE, STALL_TIME, STALL_DUTY)
    wheels = [sim.world.model.actuator(n).id for n in ("left_wheel", "right_wheel")]
    sim.set_wheel_speeds(0.5, 0.0)
    touched, stalled, strained_since, longest = None, None, None, 0.0
    for _ in range(round(3.0 / sim.world.timestep)):  # step() alone: no guard stops it
        sim.step()
        now = sim.world.time
        torque = sim.world.data.actuator_force[wheels]
        left, right = monitor.update(now, float(torque[0]), float(torque[1]))
        if touched is None and sim.contacts():
            touched = now
        if stalled is None and left and right:
            stalled = now
        if touched is not None:
            if abs(float(torque[0])) >= STALL_TORQUE:
                strained_since = now if strained_since is None else strained_since
                longest = max(longest, now - strained_since)
            else:
                strained_since = None
    assert touched is not None and stalled is not None
    assert 0.0 < stalled - touched < 1.0
    assert longest < STALL_TIME  # never strained for STALL_TIME on end: stick-slip
    assert sim.odometry_pose().x - sim.truth_pose().x > 0.3  # the wheels spun on


def test_the_stall_monitor_needs_a_full_window_and_forgets_old_strain() -> None:
    monitor = StallMonitor(threshold=3.0, window=0.5, duty=0.5)
    times = np.arange(0.0, 2.0, 0.004)
    flags = []
    for t in times:
        # strained only between 0.5 s and 0.8 s: 0.3 s of strain
        torque = 10.0 if 0.5 <= t < 0.8 else 1.0
        flags.append(monitor.update(float(t), torque, 0.0))
    stalled = np.array([left for left, _ in flags])
    assert not np.array([right for _, right in flags]).any()
    assert stalled.any()
    first, last = times[stalled][0], times[stalled][-1]
    assert first == pytest.approx(0.75, abs=0.01)  # half the window strained
    assert last == pytest.approx(1.05, abs=0.01)  # and the strain has left the window
    monitor.reset()
    assert monitor.update(3.0, 10.0, 10.0) == (False, False)


def test_base_rejects_out_of_range_drive_commands() -> None:
    _, robot = make_sim_robot()
    with robot.base as base, pytest.raises(OutOfRangeError, match="sim base"):
        base.drive(5.0, 0.0, 1.0)


def test_golden_frame() -> None:
    _, robot = make_sim_robot(start=GOLDEN_POSE)
    with robot:
        image = robot.capture().image
    golden = cv2.cvtColor(cv2.imread(str(GOLDEN)), cv2.COLOR_BGR2RGB)
    diff = np.abs(image.astype(float) - golden.astype(float))
    # Mesa versions shift edges and shading slightly; a wrong scene or pose moves far more
    assert diff.mean() < 3.0
    assert np.percentile(diff, 99) < 60.0
    moved = SimRobot(World("living_room"), Pose2D(2.5, 3.3, math.radians(124.0)))
    with moved.devices() as devices:
        other = devices.capture().image
    assert np.abs(other.astype(float) - golden.astype(float)).mean() > 3.0


def test_sim_camera_refuses_a_camera_model_that_does_not_match_the_mjcf() -> None:
    sim = SimRobot(World("living_room"))
    with pytest.raises(OutOfRangeError, match="fovy"):
        SimCamera(sim, CameraModel(hfov=math.radians(60.0)))


def test_footprints_and_placing_the_target() -> None:
    world = World("living_room")
    prints = world.footprints()
    assert set(prints) >= {"sofa", "chair", "bookcase", "rice_box"}
    x0, y0, x1, y1 = prints["sofa"].aabb
    assert (x0, y0, x1, y1) == pytest.approx((0.05, 3.7, 0.95, 5.7), abs=0.01)
    chair = prints["chair"].polygon
    assert chair.shape[1] == 2 and len(chair) >= 4
    pose = world.place_static_body("rice_box", 3.5, 5.0, 0.3)
    assert (pose.x, pose.y, pose.yaw) == pytest.approx((3.5, 5.0, 0.3))
    assert world.body_position("rice_box")[2] == pytest.approx(0.755 + 0.15, abs=1e-6)
    with pytest.raises(InputError, match="inside the sofa"):
        world.check_free(0.5, 4.5, 0.3, "stop")
    with pytest.raises(InputError, match="outside the room"):
        world.place_static_body("rice_box", 5.0, 1.0, 0.0)


def test_training_views_have_exact_masks_on_a_neutral_stage() -> None:
    images, masks = training_views(distances=(1.0, 2.5), angles=(0.0, math.pi / 2))
    assert images.shape == (4, 240, 320, 3) and masks.shape == (4, 240, 320)
    area = masks.reshape(4, -1).sum(axis=1)
    assert np.all(area > 100)
    assert area[0] > 4 * area[2]  # 2.5x farther: ~6x smaller
    assert area[1] < area[0]  # the 7 cm side is narrower than the 20 cm front
    hsv = cv2.cvtColor(images[0], cv2.COLOR_RGB2HSV)
    saturation = hsv[..., 1].astype(float)
    assert saturation[masks[0]].mean() > 3 * saturation[~masks[0]].mean()
    with pytest.raises(InputError, match="distance"):
        training_views(distances=(0.0,))


@pytest.mark.parametrize(
    ("argv", "message"),
    [
        (["sim", "snapshot", "--pose", "1,2", "--out", "x.png"], "--pose '1,2'"),
        (["sim", "snapshot", "--pose", "2,2,0", "--pan", "abc", "--out", "x.png"], "--pan"),
        (["sim", "snapshot", "--pose", "2,2,0", "--pan", "150", "--out", "x.png"], "pan outside"),
        (["sim", "drive", "--to", "9,9,0"], "inside the room"),
        (["sim", "drive", "--to", "2,2,0", "--scene", "attic"], "scene 'attic'"),
    ],
)
def test_cli_bad_input_is_one_line(
    argv: list[str], message: str, capsys, tmp_path, monkeypatch
) -> None:
    monkeypatch.chdir(tmp_path)
    assert main(argv) == 2
    err = capsys.readouterr().err
    assert message in err and err.count("\n") == 1


def test_cli_snapshot_and_drive(capsys, tmp_path) -> None:
    out = tmp_path / "frame.png"
    assert main(["sim", "snapshot", "--pose", "2.5,3.3,134", "--pan", "5", "--out", str(out)]) == 0
    image = cv2.imread(str(out))
    assert image.shape == (240, 320, 3)
    assert main(["sim", "drive", "--to", "2.3,3.2,45"]) == 0
    text = capsys.readouterr().out
    assert "odometry vs truth" in text and "real time" in text


def test_a_missing_gl_context_is_a_one_line_error_with_the_remedy(monkeypatch) -> None:
    def no_context(*args, **kwargs):
        raise RuntimeError("Cannot initialize a EGL device display.\nmore detail")

    monkeypatch.setattr(mujoco, "Renderer", no_context)
    _, robot = make_sim_robot()
    with pytest.raises(TwinError) as caught, robot:
        pass
    message = str(caught.value)
    assert "\n" not in message and "libegl1" in message and "MUJOCO_GL=osmesa" in message
    assert not robot.base.is_connected  # the devices opened before the camera were closed


def test_odometry_integrates_an_arc_exactly() -> None:
    geometry = DiffDriveGeometry(wheel_radius=0.1, track=0.4)
    odometry = Odometry(geometry, Pose2D(1.0, 2.0, 0.0), 0.0, 0.0)
    radius, quarter = 1.5, math.pi / 2  # a left quarter circle about (1.0, 3.5)
    left = (radius - 0.2) * quarter / 0.1
    right = (radius + 0.2) * quarter / 0.1
    odometry.update(left, right)  # one update: the chord formula must still be exact
    assert (odometry.x, odometry.y, odometry.yaw) == pytest.approx((2.5, 3.5, quarter))


def test_turning_on_the_spot_stays_on_the_spot() -> None:
    robot = SimRobot(World("living_room"), Pose2D(2.5, 3.3, 0.0))
    for k in range(1, 8):
        robot.go_to(Pose2D(2.5, 3.3, math.radians(45.0 * k)))
        truth = robot.truth_pose()
        assert truth.distance_to(Pose2D(2.5, 3.3, 0.0)) < 0.01
        assert abs(math.degrees(truth.heading_error_to(Pose2D(0, 0, math.radians(45.0 * k))))) < 3


def test_the_base_can_report_truth_instead_of_odometry() -> None:
    sim, robot = make_sim_robot(start=Pose2D(2.5, 3.3, 0.0), pose_source="truth")
    with robot.base as base:
        base.set_pose(Pose2D(0.0, 0.0, 0.0))  # re-anchors odometry only
        assert base.pose() == sim.truth_pose()
    assert sim.odometry_pose().distance_to(sim.truth_pose()) > 1.0
    with pytest.raises(InputError, match="pose source"):
        make_sim_robot(pose_source="slam")
