"""Odometry as a real base has it: wheels that differ from what odometry assumes (made
physically true in the MuJoCo model) drift as the geometry predicts, slip noise grows with the
square root of the distance, and an ideal base still tracks the truth."""

from __future__ import annotations

import math

import numpy as np
import pytest

import twin.sim  # noqa: F401  (must come first: it selects headless GL before mujoco loads)
from twin.core.errors import InputError
from twin.core.geometry import Pose2D, wrap_angle
from twin.sim.drive import DiffDriveGeometry, Odometry, OdometryErrors
from twin.sim.robot import SimRobot, make_sim_robot
from twin.sim.world import World

# A free lane along y = 2.0 (sideboard behind, TV cabinet ahead, the chair 0.45 m to the left).
LANE_START = Pose2D(0.7, 2.0, 0.0)
LANE_GOAL = Pose2D(3.7, 2.0, 0.0)
OPEN_FLOOR = Pose2D(2.5, 3.3, 0.0)  # 0.8 m from anything: room to turn on the spot


class HeadingLog:
    """Unwrapped heading change (rad) of the truth and of the odometry, step by step."""

    def __init__(self, robot: SimRobot) -> None:
        self.truth = self.odometry = 0.0
        self._last = (robot.truth_pose().yaw, robot.odometry_pose().yaw)
        robot.listeners.append(self)

    def __call__(self, robot: SimRobot) -> None:
        truth, odometry = robot.truth_pose().yaw, robot.odometry_pose().yaw
        self.truth += float(wrap_angle(truth - self._last[0]))
        self.odometry += float(wrap_angle(odometry - self._last[1]))
        self._last = (truth, odometry)


def _full_turn(errors: OdometryErrors) -> HeadingLog:
    """Four quarter turns on the spot by go_to (closed on odometry): one full turn by odometry."""
    robot = SimRobot(World("living_room"), OPEN_FLOOR, odometry_errors=errors)
    log = HeadingLog(robot)
    for k in (1, 2, 3, 4):
        robot.go_to(Pose2D(OPEN_FLOOR.x, OPEN_FLOOR.y, OPEN_FLOOR.yaw + k * math.pi / 2))
    return log


def test_an_ideal_base_tracks_the_truth_as_before() -> None:
    robot = SimRobot(World("living_room"), LANE_START, odometry_errors=OdometryErrors())
    estimate = robot.go_to(LANE_GOAL)
    truth = robot.truth_pose()
    assert estimate.distance_to(truth) < 0.01
    assert abs(math.degrees(estimate.heading_error_to(truth))) < 0.1
    log = _full_turn(OdometryErrors())
    assert abs(math.degrees(log.truth - log.odometry)) < 0.5


def test_a_larger_right_wheel_bends_a_straight_drive_left_as_the_geometry_predicts() -> None:
    errors = OdometryErrors(wheel_radius_error=(0.0, 0.01))
    robot = SimRobot(World("living_room"), LANE_START, odometry_errors=errors)
    estimate = robot.go_to(LANE_GOAL)
    truth = robot.truth_pose()
    # odometry believes it drove 3 m straight; the truth turned (e_r - e_l) / track per metre
    assert estimate.distance_to(LANE_GOAL) < 0.02
    assert abs(math.degrees(estimate.yaw)) < 0.1
    expected = errors.straight_drift(robot.geometry) * LANE_START.distance_to(LANE_GOAL)
    assert math.degrees(expected) == pytest.approx(5.05, abs=0.01)  # 0.01 / 0.34 m * 3 m
    assert math.degrees(truth.yaw) == pytest.approx(math.degrees(expected), abs=0.2)
    # a constant-curvature arc: the lateral offset is half the distance times the final heading
    assert truth.y - LANE_GOAL.y == pytest.approx(3.0 * expected / 2.0, abs=0.01)


@pytest.mark.parametrize(
    "errors",
    [
        OdometryErrors(wheel_radius_error=(0.0, 0.01)),
        OdometryErrors(track_error=0.02),
        OdometryErrors(wheel_radius_error=(0.01, 0.01), track_error=-0.01),
    ],
    ids=["right wheel +1%", "track +2%", "both wheels +1%, track -1%"],
)
def test_a_full_turn_drifts_as_the_geometry_predicts(errors: OdometryErrors) -> None:
    """A pivot's true turn is the odometry's times (1 + mean wheel error) / (1 + track error);
    measured against an ideal base's turn, which already loses a fraction of a degree to the
    contacts' creep."""
    ideal = _full_turn(OdometryErrors())
    log = _full_turn(errors)
    assert math.degrees(log.odometry) == pytest.approx(360.0, abs=1.0)
    drift = (log.truth - log.odometry) - (ideal.truth - ideal.odometry)
    expected = log.odometry * (errors.turn_gain() - 1.0)
    assert abs(math.degrees(expected)) > 1.5  # a drift worth measuring
    assert math.degrees(drift) == pytest.approx(math.degrees(expected), abs=0.4)


def test_the_physical_wheels_change_and_repeating_the_errors_does_not_compound() -> None:
    world = World("living_room")
    nominal = world.loaded_geom(world.model.geom("right_wheel").id)[0][0]
    errors = OdometryErrors(wheel_radius_error=(-0.005, 0.01), track_error=0.03)
    robot = SimRobot(world, OPEN_FLOOR, odometry_errors=errors)
    robot.set_odometry_errors(errors)  # twice
    model = world.model
    left, right = (model.geom(n).id for n in ("left_wheel", "right_wheel"))
    assert model.geom_size[right, 0] == pytest.approx(nominal * 1.01)
    assert model.geom_size[left, 0] == pytest.approx(nominal * 0.995)
    spacing = world.data.geom_xpos[left] - world.data.geom_xpos[right]
    assert np.linalg.norm(spacing) == pytest.approx(robot.geometry.track * 1.03, abs=1e-6)
    # odometry keeps assuming the file's wheels
    assert robot.geometry == DiffDriveGeometry(nominal, pytest.approx(0.34))
    robot.set_odometry_errors(OdometryErrors())
    assert model.geom_size[right, 0] == nominal


def _straight_runs(
    slip: float, distances: tuple[float, ...], seeds: int, step: float
) -> dict[float, np.ndarray]:
    """(seeds, 2) odometry errors (distance from the start minus the distance rolled, m;
    heading, rad) after each distance of a straight roll in increments of ``step`` metres."""
    geometry = DiffDriveGeometry(0.1, 0.34)
    found = {d: np.zeros((seeds, 2)) for d in distances}
    for seed in range(seeds):
        odometry = Odometry(geometry, Pose2D(0, 0, 0), 0.0, 0.0, slip, np.random.default_rng(seed))
        rolled = 0.0
        for distance in distances:
            while rolled < distance - 1e-9:
                rolled += step
                odometry.update(rolled / 0.1, rolled / 0.1)
            found[distance][seed] = (math.hypot(odometry.x, odometry.y) - rolled, odometry.yaw)
    return found


def test_slip_noise_grows_with_the_square_root_of_the_distance() -> None:
    # small enough that the heading's wander barely shortens the distance from the start
    slip, track = 0.002, 0.34
    runs = _straight_runs(slip, (1.0, 4.0), seeds=500, step=0.01)
    for distance, errors in runs.items():
        along, heading = errors.std(axis=0)
        # per wheel sigma = slip * sqrt(d); the mean of two wheels, their difference over track
        assert along == pytest.approx(slip * math.sqrt(distance / 2.0), rel=0.1)
        assert heading == pytest.approx(slip * math.sqrt(2.0 * distance) / track, rel=0.1)
        assert abs(errors[:, 1].mean()) < 3 * heading / math.sqrt(500)  # zero mean
    ratio = runs[4.0].std(axis=0) / runs[1.0].std(axis=0)
    np.testing.assert_allclose(ratio, [2.0, 2.0], rtol=0.12)  # sqrt(4), not 4
    # the same noise however finely the wheels are read
    coarse = _straight_runs(slip, (1.0,), seeds=500, step=0.05)[1.0].std(axis=0)
    np.testing.assert_allclose(coarse, runs[1.0].std(axis=0), rtol=0.15)


def test_slip_noise_in_the_sim_is_seeded_and_restarts_with_each_placing() -> None:
    def run(seed: int, robot: SimRobot | None = None) -> tuple[Pose2D, Pose2D]:
        errors = OdometryErrors(slip_noise=0.01, seed=seed)
        if robot is None:
            robot = SimRobot(World("living_room"), LANE_START, odometry_errors=errors)
        else:
            robot.world.reset()
            robot.place(LANE_START)
        robot.go_to(LANE_GOAL)
        return robot.odometry_pose(), robot.truth_pose()

    first = run(1)
    robot = SimRobot(
        World("living_room"), LANE_START, odometry_errors=OdometryErrors(slip_noise=0.01, seed=1)
    )
    robot.go_to(Pose2D(2.0, 2.0, 1.0))  # use the noise up, then start a new run in this world
    assert run(1, robot) == first
    other = run(2)
    assert other[1].distance_to(first[1]) > 1e-3  # closed on another noisy odometry
    for odometry, truth in (first, other):
        assert 1e-4 < odometry.distance_to(truth) < 0.2


def test_make_sim_robot_takes_the_errors() -> None:
    errors = OdometryErrors(wheel_radius_error=(0.0, 0.005))
    sim, _ = make_sim_robot(start=OPEN_FLOOR, odometry_errors=errors)
    assert sim.odometry_errors == errors
    assert sim.world.model.geom_size[sim.world.model.geom("right_wheel").id, 0] == pytest.approx(
        sim.geometry.wheel_radius * 1.005
    )


@pytest.mark.parametrize(
    ("kwargs", "message"),
    [
        ({"wheel_radius_error": (0.0, 0.5)}, "wheel_radius_error"),
        ({"wheel_radius_error": (0.0,)}, "two numbers"),
        ({"track_error": math.nan}, "track_error"),
        ({"slip_noise": -0.01}, "slip_noise"),
    ],
)
def test_odometry_errors_are_checked(kwargs: dict, message: str) -> None:
    with pytest.raises(InputError, match=message):
        OdometryErrors(**kwargs)
    assert OdometryErrors(wheel_radius_error=[0, 0.01]).wheel_radius_error == (0.0, 0.01)
