"""The laser-localized base on stand-in devices: a base whose right wheel is 1 % larger than its
odometry believes, and a laser that ray-casts the true room (with noise)."""

import itertools
import math

import numpy as np
import pytest

from twin.app.localization import LaserLocalizedBase, LocalizerSettings
from twin.core.devices import Base, BumpedError, DeviceFaultError, Laser, LaserMount
from twin.core.geometry import Pose2D, wrap_angle
from twin.nav.maps import OccupancyMap
from twin.nav.raycast import simulate_scan

RES = 0.05
TRACK = 0.34  # m between the wheels
MOUNT = LaserMount(0.15, 0.0, 0.30, 0.0)


def room(extra_box: tuple[float, float, float, float] | None = None) -> OccupancyMap:
    """A 6 x 5 m room with walls, a sofa-like block and a table-like blob; ``extra_box`` (x0,
    y0, x1, y1) adds furniture the map the robot carries does not hold."""
    grid = np.zeros((100, 120))
    grid[:2, :] = grid[-2:, :] = grid[:, :2] = grid[:, -2:] = 1.0
    grid[70:90, 10:40] = 1.0  # a block in the upper left
    grid[30:36, 60:66] = 1.0  # a small blob mid-room
    grid[2:20, 104:108] = 1.0  # a short wall jutting from the bottom wall on the right
    grid[60:64, 104:118] = 1.0  # a shelf along the right wall
    if extra_box is not None:
        x0, y0, x1, y1 = (round(v / RES) for v in extra_box)
        grid[y0:y1, x0:x1] = 1.0
    return OccupancyMap(grid, RES)


class Switch:
    _open = False

    def connect(self):
        self._open = True

    def close(self):
        self._open = False

    @property
    def is_connected(self):
        return self._open


class MiscalibratedBase(Switch, Base):
    """Drives exactly where its odometry says in odometry terms; the truth differs because its
    right wheel is ``right_error`` larger than the odometry assumes."""

    name = "miscalibrated base"

    def __init__(self, start: Pose2D, right_error: float = 0.01, faults: int = 0) -> None:
        self.odometry = start
        self.truth = start
        self.right_error = right_error
        self.faults = faults  # go_to calls that end in a contact first

    def pose(self):
        return self.odometry

    def set_pose(self, pose):
        self.odometry = pose

    def _move(self, step: Pose2D) -> None:
        """``step`` in the odometry's terms (one turn-free straight or one turn in place)."""
        left = step.x - 0.5 * TRACK * step.yaw
        right = (step.x + 0.5 * TRACK * step.yaw) * (1.0 + self.right_error)
        travel, turn = 0.5 * (left + right), (right - left) / TRACK
        self.truth = self.truth.compose(
            Pose2D(travel * math.cos(0.5 * turn), travel * math.sin(0.5 * turn), turn)
        )
        self.odometry = self.odometry.compose(step)

    def go_to(self, goal, *, timeout=60.0):
        if self.faults:
            self.faults -= 1
            self._move(Pose2D(0.1, 0.0, 0.0))
            raise DeviceFaultError(self.name, "go to", "contact with a table leg", "back off")
        here = self.odometry
        dx, dy = goal.x - here.x, goal.y - here.y
        distance = math.hypot(dx, dy)
        if distance > 1e-6:
            self._move(Pose2D(0.0, 0.0, float(wrap_angle(math.atan2(dy, dx) - here.yaw))))
            self._move(Pose2D(distance, 0.0, 0.0))
        self._move(Pose2D(0.0, 0.0, float(wrap_angle(goal.yaw - self.odometry.yaw))))
        return self.odometry

    def drive(self, speed, turn_rate, duration):
        self._move(Pose2D(speed * duration, 0.0, 0.0))
        return self.odometry

    def stop(self):
        pass


class RoomLaser(Switch, Laser):
    """An LMS200 on ``MOUNT`` that sees ``world`` from the base's true pose (5 mm noise)."""

    name = "room laser"

    def __init__(self, base: MiscalibratedBase, world: OccupancyMap, seed: int = 1) -> None:
        self.base, self.world = base, world
        self.rng = np.random.default_rng(seed)
        self.t = 0.0

    @property
    def mount(self):
        return MOUNT

    def scan(self, timeout=2.0):
        self.t += 0.1
        return simulate_scan(
            self.world, self.base.truth, MOUNT, noise_m=0.005, rng=self.rng, timestamp=self.t
        )


START = Pose2D(1.0, 1.0, 0.0)
GOALS = [Pose2D(4.8, 1.2, math.pi / 2), Pose2D(4.5, 3.8, math.pi), Pose2D(1.0, 2.5, 0.0)]


def localized(world=None, carried=None, faults=0, start=START):
    base = MiscalibratedBase(START, faults=faults)
    laser = RoomLaser(base, world or room())
    wrapped = LaserLocalizedBase(base, laser, carried or room(), LocalizerSettings(seed=3), start)
    base.connect()
    laser.connect()
    return wrapped, base


def pose_error(a: Pose2D, b: Pose2D) -> tuple[float, float]:
    return math.hypot(a.x - b.x, a.y - b.y), abs(math.degrees(float(wrap_angle(a.yaw - b.yaw))))


def test_the_localized_pose_stays_on_the_truth_where_odometry_drifts():
    wrapped, base = localized()
    for goal in GOALS:
        reached = wrapped.go_to(goal)
        metres, degrees = pose_error(reached, base.truth)
        assert metres < 0.03 and degrees < 1.0, (goal, reached, base.truth)
        # it also got there: the truth within the contract's 5 cm and 3 degrees (plus the error)
        there, turned = pose_error(base.truth, goal)
        assert there < 0.05 + 0.03 and turned < 3.0 + 1.0
        assert wrapped.estimate().localized
    odometry_alone, _ = pose_error(base.odometry, base.truth)
    assert odometry_alone > 0.10  # what the views would have been projected from without it
    cov = wrapped.pose_covariance()
    assert math.sqrt(np.linalg.eigvalsh(cov[:2, :2]).max()) < 0.05


def test_legs_go_around_what_the_map_holds():
    wrapped, _ = localized()
    here = wrapped.pose()
    goal = Pose2D(5.0, 2.2, 0.0)  # the straight way passes through the blob mid-room
    assert not wrapped.planner.leg_is_clear((here.x, here.y), (goal.x, goal.y))
    legs = wrapped._legs(here, goal)
    assert len(legs) >= 2 and legs[-1] == goal
    points = [(here.x, here.y)] + [(p.x, p.y) for p in legs]
    for a, b in itertools.pairwise(points):
        assert wrapped.planner.leg_is_clear(a, b)
    for leg, after in itertools.pairwise(legs):  # each waypoint faces along its next leg
        assert abs(math.atan2(after.y - leg.y, after.x - leg.x) - leg.yaw) < 1e-9


def test_an_obstacle_the_map_does_not_hold_stops_the_leg_before_it_starts():
    world = room(extra_box=(2.4, 0.6, 2.8, 1.4))  # a box on the straight way to the first goal
    wrapped, base = localized(world=world)
    with pytest.raises(DeviceFaultError, match="the laser sees something the map does not hold"):
        wrapped.go_to(GOALS[0])
    assert base.truth.x < 2.4 - 0.3  # it did not drive into it


def test_a_contact_backs_off_relocalizes_and_replans_then_is_an_error():
    wrapped, base = localized(faults=1)
    reached = wrapped.go_to(GOALS[0])
    assert base.faults == 0  # it did touch something on the way
    assert pose_error(reached, GOALS[0])[0] < 0.05
    wrapped, _ = localized(faults=5)
    with pytest.raises(DeviceFaultError, match="contact with a table leg"):
        wrapped.go_to(GOALS[0])


class ToyOnTheFloorBase(MiscalibratedBase):
    """A base with a toy of ``radius`` at ``toy`` on the floor, below the laser's plane: a
    straight leg that would pass within the robot's radius of it stops where the bumper meets
    it and raises ``BumpedError`` with the bumper's side."""

    def __init__(self, start: Pose2D, toy: tuple[float, float], radius: float = 0.15) -> None:
        super().__init__(start)
        self.toy, self.toy_radius, self.bumps = toy, radius, 0

    def go_to(self, goal, *, timeout=60.0):
        here = self.truth
        dx, dy = goal.x - here.x, goal.y - here.y
        length = math.hypot(dx, dy)
        if length > 1e-6:
            ux, uy = dx / length, dy / length
            tx, ty = self.toy[0] - here.x, self.toy[1] - here.y
            along, across = tx * ux + ty * uy, abs(-tx * uy + ty * ux)
            touch = 0.30 + self.toy_radius
            if across < touch and 0.0 < along < length + touch:
                stop = max(0.0, along - math.sqrt(touch**2 - across**2))
                self._move(Pose2D(0.0, 0.0, float(wrap_angle(math.atan2(dy, dx) - here.yaw))))
                self._move(Pose2D(stop, 0.0, 0.0))
                self.bumps += 1
                at = self.truth
                bearing = math.atan2(self.toy[1] - at.y, self.toy[0] - at.x) - at.yaw
                raise BumpedError(self.name, "go to", "front bumper", "back off", bearing)
        return super().go_to(goal, timeout=timeout)


def test_what_the_bumper_felt_is_planned_around():
    """A toy below the laser's plane on the straight way to the goal: the base bumps it once,
    backs away, plans around it and arrives; a new mission forgets it."""
    toy = (2.6, 1.1)
    base = ToyOnTheFloorBase(START, toy)
    laser = RoomLaser(base, room())
    wrapped = LaserLocalizedBase(base, laser, room(), LocalizerSettings(seed=3), START)
    base.connect()
    laser.connect()
    reached = wrapped.go_to(GOALS[0])
    assert base.bumps == 1
    assert pose_error(reached, GOALS[0])[0] < 0.05
    assert pose_error(base.truth, GOALS[0])[0] < 0.08
    [(x, y, radius)] = wrapped.planner.added
    assert math.hypot(x - toy[0], y - toy[1]) < 0.15 and radius > 0
    assert not wrapped.planner.leg_is_clear((1.0, 1.1), (4.0, 1.1))
    wrapped.restart(START)
    assert wrapped.planner.added == [] and wrapped.planner.leg_is_clear((1.0, 1.1), (4.0, 1.1))


def test_a_global_start_finds_the_robot_without_being_told_where_it_is():
    wrapped, base = localized(start=None)
    metres, degrees = pose_error(wrapped.pose(), base.truth)
    assert metres < 0.05 and degrees < 2.0


def test_a_kidnapped_robot_is_found_again():
    """Carried 1.5 m and turned while its odometry saw nothing: the next scans disagree with
    the map, the filter injects random particles and finds the robot again."""
    wrapped, base = localized()
    wrapped.go_to(GOALS[0])
    base.truth = Pose2D(2.0, 3.0, -math.pi / 2)  # kidnapped: odometry unchanged
    estimate = wrapped._settle()  # what a leg's end does: scans at rest until sure
    metres, degrees = pose_error(estimate.pose, base.truth)
    assert estimate.localized and metres < 0.05 and degrees < 2.0
    reached = wrapped.go_to(GOALS[1])
    assert pose_error(reached, base.truth)[0] < 0.03


def test_after_a_bump_the_base_plans_again_to_its_goal_not_to_the_legs_end():
    """A toy on the first leg's end (a corner of the path: in a home, a door's middle): the
    disc the base marks for what it felt covers that waypoint, so it plans again to the goal
    itself, round the toy, and arrives."""
    goal = Pose2D(5.0, 2.3, 0.0)  # behind the blob mid-room, seen from the start
    probe = LaserLocalizedBase(
        MiscalibratedBase(START), RoomLaser(MiscalibratedBase(START), room()), room(),
        LocalizerSettings(seed=3), START,
    )  # fmt: skip
    legs = probe._legs(START, goal)
    assert len(legs) >= 2  # the path bends: its first leg ends short of the goal
    corner = (legs[0].x, legs[0].y)
    base = ToyOnTheFloorBase(START, corner, radius=0.08)  # a toy car
    laser = RoomLaser(base, room())
    wrapped = LaserLocalizedBase(base, laser, room(), LocalizerSettings(seed=3), START)
    base.connect()
    laser.connect()
    reached = wrapped.go_to(goal)
    assert base.bumps >= 1
    assert pose_error(reached, goal)[0] < 0.05
    assert not wrapped.planner.leg_is_clear(corner, corner)
