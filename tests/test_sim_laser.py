"""The sim LMS200: ranges against geometry we can compute, the beam order, the scan rate in
simulated time, seeded noise with the data sheet's statistics, and the device contract."""

from __future__ import annotations

import math

import numpy as np
import pytest

import twin.sim  # noqa: F401  (must come first: it selects headless GL before mujoco loads)
from twin.core.devices import DeviceTimeoutError, LaserMount, NotConnectedError, Scan
from twin.core.errors import InputError
from twin.core.geometry import Pose2D
from twin.sim.laser import (
    LMS200_SIGMA,
    SCENE_GROUPS,
    LaserSpec,
    RayCaster,
    SimLaser,
    cast,
    laser_site,
)
from twin.sim.robot import SimRobot, make_sim_robot
from twin.sim.world import World

NOISELESS = LaserSpec(range_sigma=0.0, systematic=0.0, dropout=0.0, resolution=0.0)
FACING_LEFT_WALL = Pose2D(2.0, 3.0, math.pi)  # 1.85 m of free floor to the wall at x = 0


def _robot(start: Pose2D) -> SimRobot:
    return SimRobot(World("living_room"), start)


def _site(robot: SimRobot) -> tuple[np.ndarray, float]:
    """The laser's true position (x, y) and yaw in the map."""
    world = robot.world
    site = laser_site(world.model)
    rotation = world.data.site_xmat[site].reshape(3, 3)
    return world.data.site_xpos[site, :2].copy(), math.atan2(rotation[1, 0], rotation[0, 0])


def _to_map(robot: SimRobot, scan: Scan) -> np.ndarray:
    origin, yaw = _site(robot)
    c, s = math.cos(yaw), math.sin(yaw)
    return scan.points() @ np.array([[c, s], [-s, c]]) + origin


def test_the_laser_reads_a_wall_at_its_distance() -> None:
    robot = _robot(FACING_LEFT_WALL)
    spec = LaserSpec()
    origin, _ = _site(robot)
    assert origin[0] == pytest.approx(FACING_LEFT_WALL.x - 0.15, abs=0.005)  # 0.15 m forward
    true = cast(robot.world, spec)
    near = np.abs(spec.angles) <= math.radians(15.0)
    # the wall's face is x = 0: a beam at angle a travels x / cos(a)
    np.testing.assert_allclose(true[near], origin[0] / np.cos(spec.angles[near]), atol=1e-3)
    with SimLaser(robot, spec) as laser:
        scan = laser.scan()
    centre = scan.ranges[spec.beams // 2]
    assert scan.angles[spec.beams // 2] == 0.0
    assert abs(centre - origin[0]) < abs(laser.offset) + 4 * LMS200_SIGMA
    assert abs(laser.offset) <= 0.015


def test_a_table_leg_appears_where_it_is_and_the_table_top_does_not() -> None:
    """Facing the coffee table from 0.8 m: the two near legs (r = 2 cm) show where they stand;
    the beam between them passes under the top (0.41 m) and the rice box to the far wall."""
    robot = _robot(Pose2D(1.6, 3.3, math.pi / 2))
    world = robot.world
    origin, yaw = _site(robot)
    spec = NOISELESS
    caster = RayCaster(world.model, laser_site(world.model), spec.angles, spec.max_range)
    true = caster.cast(world.data)
    legs = {"coffee_table_leg2": 0, "coffee_table_leg3": 0}
    for name in legs:
        centre = world.data.geom_xpos[world.model.geom(name).id, :2]
        rel = centre - origin
        bearing = math.atan2(rel[1], rel[0]) - yaw
        beam = int(np.argmin(np.abs(spec.angles - bearing)))
        assert world.model.geom(int(caster.last_geoms[beam])).name == name
        # exact ray-circle intersection for that beam
        u = np.array([math.cos(yaw + spec.angles[beam]), math.sin(yaw + spec.angles[beam])])
        along, across = float(rel @ u), float(rel[0] * u[1] - rel[1] * u[0])
        assert true[beam] == pytest.approx(along - math.sqrt(0.02**2 - across**2), abs=1e-3)
        legs[name] = beam
    assert legs["coffee_table_leg2"] < spec.beams // 2 < legs["coffee_table_leg3"]  # right, left
    assert true[spec.beams // 2] == pytest.approx(6.0 - origin[1], abs=1e-3)
    with SimLaser(robot) as laser:
        points = _to_map(robot, laser.scan())
    for name in legs:
        centre = world.data.geom_xpos[world.model.geom(name).id, :2]
        nearest = np.min(np.linalg.norm(points - centre, axis=1))
        assert nearest == pytest.approx(0.02, abs=0.02)  # on the leg's surface, within noise


def test_the_robot_never_sees_itself() -> None:
    """All round, at the scan height: the laser's own housing and the column stand behind it.
    Casting at the robot's group too shows them; the laser's groups never do."""
    robot = _robot(FACING_LEFT_WALL)
    model = robot.world.model
    angles = np.linspace(-math.pi, math.pi, 720, endpoint=False)
    own = model.body_rootid[model.geom_bodyid] == model.body("base").id
    seen = RayCaster(model, laser_site(model), angles, 8.0)
    ranges = seen.cast(robot.world.data)
    hits = seen.last_geoms[seen.last_geoms >= 0]
    assert not own[hits].any()
    assert np.nanmin(ranges) > 0.5
    with_robot = RayCaster(
        model, laser_site(model), angles, 8.0, np.array([1, 1, 1, 0, 0, 0], np.uint8)
    )
    back = np.abs(np.abs(angles) - math.pi) < 0.2
    assert np.nanmax(with_robot.cast(robot.world.data)[back]) < 0.25
    assert own[with_robot.last_geoms[back]].all()
    assert SCENE_GROUPS[2] == 0 and SCENE_GROUPS[3] == 0


def test_nothing_beyond_the_maximum_range() -> None:
    robot = _robot(FACING_LEFT_WALL)
    spec = LaserSpec(max_range=2.0, dropout=0.0)
    true = cast(robot.world, LaserSpec(max_range=8.0))
    with SimLaser(robot, spec) as laser:
        ranges = laser.scan().ranges
    assert np.all(np.isfinite(true))  # a closed room: within 8 m every beam hits
    assert np.all(np.isnan(ranges[true > 2.05]))
    assert np.all(np.isfinite(ranges[true < 1.95]))
    assert np.nanmax(ranges) <= 2.0
    assert np.isnan(ranges).sum() > 20 and np.isfinite(ranges).sum() > 20


def test_left_is_positive() -> None:
    """Facing +y 0.8 m from the left wall: the +90 degree beam reads 0.8 m, the -90 degree one
    the 3.7 m to the right wall."""
    robot = _robot(Pose2D(0.8, 3.0, math.pi / 2))
    spec = LaserSpec()
    true = cast(robot.world, spec)
    assert spec.angles[0] == pytest.approx(-math.pi / 2) and np.all(np.diff(spec.angles) > 0)
    assert true[-1] == pytest.approx(0.8, abs=0.005)
    assert true[0] == pytest.approx(3.7, abs=0.005)


def test_scans_come_at_the_scan_rate_of_simulated_time() -> None:
    robot = _robot(Pose2D(1.5, 2.9, 0.0))
    step = robot.world.timestep
    with SimLaser(robot, LaserSpec(beams=361)) as laser:
        stamps = []
        for _ in range(5):
            called = robot.world.time
            scan = laser.scan()
            assert called < scan.timestamp <= called + 0.1 + step
            assert scan.ranges.shape == (361,)
            stamps.append(scan.timestamp)
        np.testing.assert_allclose(np.diff(stamps), 0.1, atol=step / 2)
        # while driving, the latest scan keeps up at the same rate
        seen: list[float] = []

        def watch(_: SimRobot) -> None:
            latest = laser.latest_scan()
            if latest is not None and (not seen or latest.timestamp != seen[-1]):
                seen.append(latest.timestamp)

        robot.listeners.append(watch)
        start = robot.world.time
        robot.go_to(Pose2D(2.8, 2.9, 0.0))
        took = robot.world.time - start
        assert len(seen) == pytest.approx(took * 10.0, abs=1.5)
        np.testing.assert_allclose(np.diff(seen), 0.1, atol=step / 2)
        with pytest.raises(DeviceTimeoutError, match="sim laser"):
            laser.scan(timeout=0.05)  # the next scan is 0.1 s after the last


def _scans(seed: int, count: int) -> list[np.ndarray]:
    robot = _robot(FACING_LEFT_WALL)
    with SimLaser(robot, LaserSpec(seed=seed, dropout=0.02)) as laser:
        return [laser.scan().ranges for _ in range(count)]


def test_the_noise_is_seeded() -> None:
    first, again, other = _scans(3, 3), _scans(3, 3), _scans(4, 3)
    for a, b in zip(first, again, strict=True):
        np.testing.assert_array_equal(a, b)  # NaNs in the same places too
    assert not np.array_equal(first[0], other[0], equal_nan=True)
    assert not np.array_equal(first[0], first[1], equal_nan=True)


def test_the_noise_statistics_match_the_settings() -> None:
    robot = _robot(FACING_LEFT_WALL)
    spec = LaserSpec(dropout=0.02, seed=5)
    with SimLaser(robot, spec) as laser:
        scans = np.array([laser.scan().ranges for _ in range(200)])
        offset = laser.offset
    true = cast(robot.world, spec)  # the robot stood still: one truth for every scan
    residual = scans - true
    finite = residual[np.isfinite(residual)]
    assert abs(offset) <= spec.systematic
    assert finite.mean() == pytest.approx(offset, abs=3e-4)
    assert finite.std() == pytest.approx(
        math.hypot(spec.range_sigma, 0.001 / math.sqrt(12)), rel=0.05
    )
    assert np.isnan(scans).mean() == pytest.approx(spec.dropout, rel=0.15)
    millimetres = scans[np.isfinite(scans)] * 1000.0
    np.testing.assert_allclose(millimetres, np.round(millimetres), atol=1e-6)


def test_ranges_at_any_bearing_for_a_wire_emulator() -> None:
    robot = _robot(FACING_LEFT_WALL)
    laser = SimLaser(robot, LaserSpec(seed=2, dropout=0.0))
    angles = np.array([0.0, 0.2, -0.2, math.pi / 2])
    ranges = laser.ranges_at(angles)
    caster = RayCaster(robot.world.model, laser.site, angles, 8.0)
    np.testing.assert_allclose(ranges, caster.cast(robot.world.data), atol=0.015 + 4 * 0.005)
    assert laser.ranges_at(np.zeros(0)).shape == (0,)


def test_the_sim_laser_is_a_device_of_the_robot() -> None:
    sim, robot = make_sim_robot(start=FACING_LEFT_WALL, laser=LaserSpec(beams=361))
    laser = robot.laser
    assert isinstance(laser, SimLaser)
    assert laser.mount == LaserMount(pytest.approx(0.15), 0.0, pytest.approx(0.30), 0.0)
    with pytest.raises(NotConnectedError, match="sim laser"):
        laser.scan()
    listeners = len(sim.listeners)
    with robot:
        scan = laser.scan()
        assert scan.timestamp == robot.camera.now()
        assert scan.max_range == 8.0 and scan.angles.shape == (361,)
        # a reset world restarts the clock: the old scans are gone, new ones come
        sim.world.reset()
        sim.place(FACING_LEFT_WALL)
        assert laser.latest_scan() is not None and laser.latest_scan().timestamp <= 0.3 + 1e-9
        assert laser.scan().timestamp > sim.world.time - 0.1
    assert len(sim.listeners) == listeners
    assert not laser.is_connected


@pytest.mark.parametrize(
    ("kwargs", "message"),
    [({"beams": 1}, "beams"), ({"max_range": 0.0}, "max_range"), ({"dropout": 1.0}, "dropout")],
)
def test_laser_settings_are_checked(kwargs: dict, message: str) -> None:
    with pytest.raises(InputError, match=message):
        LaserSpec(**kwargs)
