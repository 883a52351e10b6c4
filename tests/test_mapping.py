"""Ray casting, occupancy grid mapping, correlative scan matching and building a map from a drive.

The synthetic world is a room drawn at 1 cm (walls and furniture at arbitrary positions, not on
the 5 cm grid maps are built at), scans are ray-cast in it with the LMS200's 181 beams and 1 cm
noise; the reference a built map is scored against is that world at 5 cm (a cell is occupied if
anything of the world is in it).
"""

import math

import numpy as np
import pytest

from twin.core.devices import LaserMount, Scan
from twin.core.errors import InputError
from twin.core.geometry import Pose2D
from twin.nav.distance import distance_transform
from twin.nav.mapping import (
    MapAgreement,
    MapBuilder,
    OccupancyGridMapper,
    map_agreement,
    wheel_odometry,
)
from twin.nav.maps import UNKNOWN, OccupancyMap
from twin.nav.raycast import (
    laser_pose,
    lms200_angles,
    raycast,
    scan_points_in_base,
    simulate_scan,
)
from twin.nav.scan_matching import CorrelativeScanMatcher, LikelihoodTable

MOUNT = LaserMount(x=0.1, y=0.0, z=0.30, yaw=0.0)
FINE = 0.01


def box(grid, x0, y0, x1, y1, origin=(-0.13, -0.11)):
    """Fill a box given in metres of the map frame on a FINE grid with that origin."""
    r0, r1 = (round((v - origin[1]) / FINE) for v in (y0, y1))
    c0, c1 = (round((v - origin[0]) / FINE) for v in (x0, x1))
    grid[r0:r1, c0:c1] = 1.0


def fine_room() -> OccupancyMap:
    """A 4.5 m x 6 m room at 1 cm: 12 cm walls, a sofa, a shelf, four 4 cm table legs."""
    grid = np.zeros((623, 473))
    box(grid, -0.13, -0.11, 4.6, 0.01)
    box(grid, -0.13, 6.0, 4.6, 6.12)
    box(grid, -0.13, -0.11, -0.01, 6.12)
    box(grid, 4.48, -0.11, 4.6, 6.12)
    box(grid, -0.01, 3.82, 0.84, 4.77)  # sofa
    box(grid, 1.9, 1.32, 3.28, 1.5)  # shelf
    for x, y in [(2.39, 2.8), (2.84, 2.8), (2.39, 3.32), (2.84, 3.32)]:
        box(grid, x - 0.02, y - 0.02, x + 0.02, y + 0.02)
    return OccupancyMap(grid, FINE, (-0.13, -0.11, 0.0))


def coarse(world: OccupancyMap, factor: int = 5) -> OccupancyMap:
    """``world`` at ``factor`` times its cell size: a cell is occupied if any fine cell is."""
    ny, nx = (n // factor for n in world.shape)
    blocks = world.occupancy[: ny * factor, : nx * factor].reshape(ny, factor, nx, factor)
    return OccupancyMap(blocks.max(axis=(1, 3)), world.resolution * factor, world.origin)


def drive(waypoints, step=0.05, turn=0.087) -> list[Pose2D]:
    """Poses every ``step`` metres along straight legs between waypoints, turning on the spot
    by at most ``turn`` radians per pose; the first waypoint is (x, y, yaw)."""
    x, y, yaw = waypoints[0]
    poses = [Pose2D(x, y, yaw)]
    for wx, wy in waypoints[1:]:
        change = math.remainder(math.atan2(wy - y, wx - x) - yaw, 2 * math.pi)
        n = max(1, math.ceil(abs(change) / turn))
        poses += [Pose2D(x, y, yaw + change * k / n) for k in range(1, n + 1)]
        yaw += change
        n = max(1, math.ceil(math.hypot(wx - x, wy - y) / step))
        poses += [Pose2D(x + (wx - x) * k / n, y + (wy - y) * k / n, yaw) for k in range(1, n + 1)]
        x, y = wx, wy
    return poses


LOOP = [(1.0, 1.0, 0.0), (3.5, 1.0), (3.5, 5.0), (1.5, 5.0), (1.5, 2.2), (2.2, 2.4)]


@pytest.fixture(scope="module")
def world():
    return fine_room()


@pytest.fixture(scope="module")
def loop_scans(world):
    rng = np.random.default_rng(0)
    truth = drive(LOOP)
    return truth, [simulate_scan(world, p, MOUNT, noise_m=0.01, rng=rng) for p in truth]


# -- ray casting ----------------------------------------------------------------------------------


def walled(nx=60, ny=40, res=0.05, origin=(0.0, 0.0)):
    grid = np.zeros((ny, nx))
    grid[0, :] = grid[-1, :] = grid[:, 0] = grid[:, -1] = 1.0
    return OccupancyMap(grid, res, (*origin, 0.0))


def test_raycast_reads_the_distance_to_the_first_occupied_cell():
    room = walled()  # inner faces at x = 0.05, 2.95 and y = 0.05, 1.95
    angles = np.array([0.0, math.pi / 2, math.pi, -math.pi / 2, math.atan2(0.95, 1.95)])
    ranges = raycast(room, Pose2D(1.0, 1.0, 0.0), angles, 8.0)
    np.testing.assert_allclose(ranges, [1.95, 0.95, 0.95, 0.95, math.hypot(1.95, 0.95)])
    # the sensor's yaw turns every beam
    turned = raycast(room, Pose2D(1.0, 1.0, math.pi / 2), angles[:4], 8.0)
    np.testing.assert_allclose(turned, [0.95, 0.95, 0.95, 1.95])


def test_raycast_no_return_beyond_max_range_or_off_the_map_and_zero_inside_a_wall():
    room = walled()
    assert np.isnan(raycast(room, Pose2D(1.0, 1.0, 0.0), np.array([0.0]), 1.9)[0])
    open_room = OccupancyMap(np.zeros((10, 10)), 0.1)
    assert np.isnan(raycast(open_room, Pose2D(0.5, 0.5, 0.0), np.array([0.3]), 8.0)[0])
    assert raycast(room, Pose2D(0.01, 1.0, 0.0), np.array([0.0, 1.0]), 8.0).tolist() == [0, 0]
    # a sensor outside the map sees the map's outer face
    outside = raycast(room, Pose2D(-1.0, 1.0, 0.0), np.array([0.0, math.pi]), 8.0)
    assert outside[0] == pytest.approx(1.0) and np.isnan(outside[1])


def test_raycast_passes_unknown_cells_unless_told_to_stop():
    grid = np.zeros((10, 30))
    grid[:, 20] = UNKNOWN
    grid[:, 25] = 1.0
    strip = OccupancyMap(grid, 0.1)
    pose, beam = Pose2D(0.05, 0.55, 0.0), np.array([0.0])
    assert raycast(strip, pose, beam, 8.0)[0] == pytest.approx(2.45)
    assert raycast(strip, pose, beam, 8.0, block_unknown=True)[0] == pytest.approx(1.95)


def test_the_laser_pose_and_points_follow_the_mount():
    mount = LaserMount(x=0.2, y=0.1, z=0.3, yaw=math.pi / 2)
    sensor = laser_pose(Pose2D(1.0, 2.0, math.pi / 2), mount)
    assert (sensor.x, sensor.y, sensor.yaw) == pytest.approx((0.9, 2.2, -math.pi))
    scan = Scan(np.array([0.0, 0.5]), np.array([1.0, np.nan]), 0.0, 8.0)
    # the zero beam of a scanner turned left by 90 degrees points along the base's +y
    np.testing.assert_allclose(scan_points_in_base(scan, mount), [[0.2, 1.1]])


def test_simulated_scans_carry_the_noise_asked_for():
    room = walled(nx=200, ny=200)
    angles = np.zeros(4000)
    clean = simulate_scan(room, Pose2D(5.0, 5.0, 0.0), LaserMount(), angles)
    noisy = simulate_scan(
        room, Pose2D(5.0, 5.0, 0.0), LaserMount(), angles, noise_m=0.01,
        rng=np.random.default_rng(1),
    )  # fmt: skip
    assert clean.max_range == 8.0 and np.all(clean.ranges == pytest.approx(4.95))
    assert np.std(noisy.ranges - clean.ranges) == pytest.approx(0.01, rel=0.05)
    with pytest.raises(InputError, match="Generator"):
        simulate_scan(room, Pose2D(5.0, 5.0, 0.0), noise_m=0.01)
    assert lms200_angles(361)[1] - lms200_angles(361)[0] == pytest.approx(math.radians(0.5))


# -- occupancy grid mapping -------------------------------------------------------------------


def one_beam_scan(range_m, angle=0.0):
    return Scan(np.array([angle]), np.array([range_m]), 0.0, 8.0)


def test_a_beam_clears_the_cells_it_crosses_and_marks_its_return():
    mapper = OccupancyGridMapper((0.0, 0.0, 2.0, 1.0), 0.1, mount=LaserMount())
    mapper.integrate(Pose2D(0.05, 0.55, 0.0), one_beam_scan(1.0))  # return at x = 1.05
    occupancy = mapper.to_map().occupancy
    row = occupancy[5]
    assert row[10] == pytest.approx(0.7)  # the return's cell: p_hit
    np.testing.assert_allclose(row[:10], 0.4)  # every crossed cell once: p_miss
    assert np.all(row[11:] == UNKNOWN) and np.all(np.delete(occupancy, 5, axis=0) == UNKNOWN)
    for _ in range(30):  # evidence is clamped so the map can still change
        mapper.integrate(Pose2D(0.05, 0.55, 0.0), one_beam_scan(1.0))
    row = mapper.to_map().occupancy[5]
    assert row[10] == pytest.approx(0.97) and row[0] == pytest.approx(0.12)
    assert mapper.scans == 31


def test_a_beam_without_return_clears_only_up_to_the_free_distance():
    mapper = OccupancyGridMapper((0.0, 0.0, 5.0, 1.0), 0.1, no_return_free_m=2.0)
    mapper.integrate(Pose2D(0.05, 0.55, 0.0), one_beam_scan(np.nan))
    row = mapper.to_map().occupancy[5]
    assert np.all(row[:20] == pytest.approx(0.4)) and np.all(row[21:] == UNKNOWN)
    assert not mapper.to_map().occupied.any()


def test_the_mapper_keeps_where_in_its_cell_each_surface_was_seen():
    mapper = OccupancyGridMapper((0.0, 0.0, 2.0, 1.0), 0.1)
    mapper.integrate(Pose2D(0.05, 0.55, 0.0), one_beam_scan(1.02))
    mapper.integrate(Pose2D(0.05, 0.57, 0.0), one_beam_scan(1.04))
    points = mapper.surface_points()
    np.testing.assert_allclose(points[5, 10], [1.08, 0.56])  # the mean of the two returns
    assert np.isnan(points[5, :10]).all() and np.isnan(points[4]).all()
    # the matcher's table takes them as the surface's points in its occupied cells
    table = LikelihoodTable(mapper.to_map(), surface_points=points)
    np.testing.assert_allclose(table.anchors[5, 10], [1.08, 0.56])
    assert table.fine[5, 10] == pytest.approx(-(0.03**2 + 0.01**2) / (2 * 0.05**2))
    with pytest.raises(InputError, match="surface_points"):
        LikelihoodTable(mapper.to_map(), surface_points=points[:, :5])


def test_in_one_scan_a_cell_is_updated_once_and_a_hit_is_not_cleared_by_a_grazing_beam():
    mapper = OccupancyGridMapper((0.0, 0.0, 2.0, 1.0), 0.1)
    # two beams along the same row: the short one hits cell 5, the long one crosses it
    scan = Scan(np.array([0.0, 0.0]), np.array([0.5, 1.0]), 0.0, 8.0)
    mapper.integrate(Pose2D(0.05, 0.55, 0.0), scan)
    row = mapper.to_map().occupancy[5]
    assert row[5] == pytest.approx(0.7) and row[10] == pytest.approx(0.7)
    np.testing.assert_allclose(row[:5], 0.4)  # crossed twice in one scan, updated once


def test_mapping_at_the_true_poses_reproduces_the_room(world, loop_scans):
    truth, scans = loop_scans
    reference = coarse(world)
    mapper = OccupancyGridMapper(reference.extent, 0.05, mount=MOUNT)
    for pose, scan in zip(truth, scans, strict=True):
        mapper.integrate(pose, scan)
    built = mapper.to_map()
    assert built.shape == reference.shape and built.origin == reference.origin
    exact = map_agreement(built, reference, tolerance_m=0.0)
    assert exact.precision > 0.98 and exact.recall > 0.95
    # what is missed is where an obstacle fills a sliver of a cell seen at a glancing angle
    # (the sofa's side): beams cross its free part more often than one ends in it
    within_a_cell = map_agreement(built, reference, tolerance_m=0.05)
    assert within_a_cell.precision == 1.0 and within_a_cell.recall > 0.97
    # inside the room, the free floor is seen as free (all but cells hidden behind things)
    inside = np.zeros(built.shape, dtype=bool)
    inside[3:-3, 3:-3] = True
    floor = inside & ~near(reference, 2)
    assert np.mean(built.free[floor]) > 0.97
    # 7 cm behind the left and bottom walls' faces (7 sigma of the noise) nothing is known
    assert built.unknown[:, 0].all() and built.unknown[0, :].all()


def near(occupancy_map, cells):
    """Cells within ``cells`` cells of an occupied one."""
    return distance_transform(occupancy_map.occupied) <= cells


# -- scan matching --------------------------------------------------------------------------------


def test_the_coarse_table_bounds_every_fine_cell_of_its_block(world):
    table = LikelihoodTable(coarse(world), sigma_m=0.05, coarse_cells=4)
    fine, d = table.fine, 4
    padded = np.full((fine.shape[0] + 2 * d, fine.shape[1] + 2 * d), table.floor)
    padded[d:-d, d:-d] = fine
    # coarse[a, b] is the maximum of fine[a-3 .. a, b-3 .. b]
    for a, b in [(0, 0), (3, 3), (50, 40), (table.coarse.shape[0] - 1, 7)]:
        block = padded[a + 1 : a + 1 + d, b + 1 : b + 1 + d]
        assert table.coarse[a, b] == block.max()
    assert table.fine.max() == 0.0 and table.fine.min() == table.floor == -4.5


def test_without_known_points_the_surface_is_anywhere_in_its_cell():
    table = LikelihoodTable(walled(), sigma_m=0.05)  # the wall: column 0, faces at x = 0.05
    # inside the wall cell 0, then (half a cell, 1.5 cells) from its square: -d² / (2 sigma²)
    np.testing.assert_allclose(table.fine[20, :4], [0.0, -0.125, -1.125, -3.125])
    assert table.surface[20, 0] and not table.surface[20, 1]
    # a thick wall scores by its outline: deep inside it is as bad as far from it
    thick = np.zeros((40, 60))
    thick[:, :10] = 1.0
    inside = LikelihoodTable(OccupancyMap(thick, 0.05)).fine[20]
    assert inside[9] == 0.0 and inside[5] == inside[15] == -4.5


@pytest.mark.parametrize(
    ("truth", "offset"),
    [
        (Pose2D(1.2, 1.0, 0.3), (0.17, -0.12, math.radians(7.0))),
        (Pose2D(3.3, 4.6, 2.5), (-0.25, 0.21, math.radians(-13.0))),
        (Pose2D(2.0, 2.3, -1.2), (0.04, 0.28, math.radians(11.0))),
    ],
)
def test_the_matcher_recovers_a_known_offset(world, truth, offset):
    reference = coarse(world)
    scan = simulate_scan(world, truth, MOUNT, noise_m=0.01, rng=np.random.default_rng(4))
    prior = Pose2D(truth.x + offset[0], truth.y + offset[1], truth.yaw + offset[2])
    matcher = CorrelativeScanMatcher(mount=MOUNT)
    result = matcher.match(LikelihoodTable(reference), scan, prior)
    # within the 5 cm cells' quantisation of where the obstacles' faces are
    assert result.pose.distance_to(truth) < 0.04
    assert abs(result.pose.heading_error_to(truth)) < math.radians(0.7)
    assert result.points == 181 and result.evaluated < result.candidates / 4
    # the multi-resolution search finds what scoring every pose finds
    exhaustive = CorrelativeScanMatcher(mount=MOUNT, covariance_margin=1e9, refine=False)
    full = exhaustive.match(LikelihoodTable(reference), scan, prior)
    lattice = CorrelativeScanMatcher(mount=MOUNT, refine=False)
    fast = lattice.match(LikelihoodTable(reference), scan, prior)
    assert full.evaluated == full.candidates == 13 * 13 * 31
    assert fast.score == full.score and fast.pose == full.pose
    np.testing.assert_allclose(fast.covariance, full.covariance, rtol=1e-3, atol=1e-9)


def test_the_covariance_is_long_along_a_corridor_and_short_across_it():
    grid = np.zeros((40, 400))
    grid[8:10, :] = grid[30:32, :] = 1.0  # two long walls along x, 1 m apart
    corridor = OccupancyMap(grid, 0.05)
    truth = Pose2D(10.0, 1.0, 0.0)
    angles = np.linspace(-1.2, 1.2, 181)  # no beam reaches the corridor's ends
    scan = simulate_scan(corridor, truth, MOUNT, angles, max_range=4.0)
    result = CorrelativeScanMatcher(mount=MOUNT).match(LikelihoodTable(corridor), scan, truth)
    sx, sy = np.sqrt(np.diag(result.covariance)[:2])
    assert sx > 0.1 > 0.03 > sy  # x is not observable, y is
    assert abs(result.pose.y - truth.y) < 0.03
    # in the room, the same matcher is sure of both, to about the size of a cell
    room = walled(nx=80, ny=80)
    scan = simulate_scan(room, Pose2D(2.0, 2.0, 0.3), MOUNT)
    boxed = CorrelativeScanMatcher(mount=MOUNT).match(
        LikelihoodTable(room), scan, Pose2D(2.0, 2.0, 0.3)
    )
    assert np.sqrt(np.diag(boxed.covariance)[:2]).max() < 0.03


def test_a_prior_holds_the_pose_where_the_scan_cannot():
    grid = np.zeros((40, 400))
    grid[8:10, :] = grid[30:32, :] = 1.0
    corridor = OccupancyMap(grid, 0.05)
    truth = Pose2D(10.0, 1.0, 0.0)
    scan = simulate_scan(corridor, truth, MOUNT, np.linspace(-1.2, 1.2, 181), max_range=4.0)
    prior = Pose2D(10.1, 1.1, 0.05)
    held = CorrelativeScanMatcher(mount=MOUNT, prior_sigma=(0.05, 0.1))
    result = held.match(LikelihoodTable(corridor), scan, prior)
    assert abs(result.pose.x - prior.x) < 0.03  # along the corridor: the prior
    assert abs(result.pose.y - truth.y) < 0.03  # across it: the scan


def test_matching_a_scan_without_returns_is_refused(world):
    empty = Scan(lms200_angles(), np.full(181, np.nan), 0.0, 8.0)
    with pytest.raises(InputError, match="no returns"):
        CorrelativeScanMatcher().match(LikelihoodTable(coarse(world)), empty, Pose2D(1, 1, 0))


# -- building a map from a drive ------------------------------------------------------------------


def test_map_agreement_counts_obstacle_cells_within_the_tolerance():
    grid = np.zeros((40, 60))
    grid[10, 10:30] = grid[30, 20:50] = 1.0
    reference = OccupancyMap(grid, 0.05)
    assert map_agreement(reference, reference, 0.0).f1 == 1.0
    shifted = OccupancyMap(np.roll(grid, 2, axis=0), 0.05)  # 10 cm up
    assert map_agreement(shifted, reference, 0.05) == MapAgreement(0.0, 0.0, 0.0, 50, 50)
    assert map_agreement(shifted, reference, 0.1).f1 == 1.0
    # reference cells the built map never observed do not count against it
    half = grid.copy()
    half[:, 30:] = UNKNOWN
    score = map_agreement(OccupancyMap(half, 0.05), reference, 0.0)
    assert (score.precision, score.recall) == (1.0, 1.0)
    assert score.reference_observed == 30 and score.built_occupied == 30
    # a built map on another grid is read where its cells are
    offset = OccupancyMap(grid, 0.05, (0.02, -0.01, 0.0))
    assert map_agreement(offset, reference, 0.05).f1 == 1.0


def test_wheel_odometry_drifts_as_a_larger_right_wheel_turns_left():
    truth = drive([(0.0, 0.0, 0.0), (5.0, 0.0)])
    assert wheel_odometry(truth, right_scale=1.0)[-1].distance_to(truth[-1]) < 1e-9
    odometry = wheel_odometry(truth, right_scale=1.01)
    # a straight 5 m at 0.01 * 5 / 0.34 rad of accumulated heading error
    assert odometry[-1].yaw == pytest.approx(0.01 * 5.0 / 0.34 / 2.0 * 2.0, rel=0.05)
    assert odometry[-1].y > 0.15


def test_the_builder_corrects_odometry_drift_and_maps_the_room(world, loop_scans):
    truth, scans = loop_scans
    odometry = wheel_odometry(truth, right_scale=1.01)  # a 1 % wheel error
    odometry_error = max(o.distance_to(t) for o, t in zip(odometry, truth, strict=True))
    builder = MapBuilder((-0.5, -0.5, 5.0, 6.5), 0.05, mount=MOUNT)
    for pose, scan in zip(odometry, scans, strict=True):
        builder.add(pose, scan)
    errors = [c.distance_to(t) for c, t in zip(builder.trajectory, truth, strict=True)]
    yaw_errors = [
        abs(c.heading_error_to(t)) for c, t in zip(builder.trajectory, truth, strict=True)
    ]
    assert odometry_error > 0.4
    assert max(errors) < 0.04 and float(np.sqrt(np.mean(np.square(errors)))) < 0.025
    assert max(yaw_errors) < math.radians(1.0)
    assert builder.odometry == odometry and builder.matches[0] is None
    assert all(m is not None for m in builder.matches[1:])
    score = map_agreement(builder.to_map(), coarse(world), tolerance_m=0.05)
    assert score.precision > 0.95 and score.recall > 0.95
    # odometry alone smears the same scans into a worse map
    smeared = OccupancyGridMapper((-0.5, -0.5, 5.0, 6.5), 0.05, mount=MOUNT)
    for pose, scan in zip(odometry, scans, strict=True):
        smeared.integrate(pose, scan)
    assert map_agreement(smeared.to_map(), coarse(world), tolerance_m=0.05).f1 < 0.8


def test_bad_mapper_arguments_are_refused():
    with pytest.raises(InputError, match="extent"):
        OccupancyGridMapper((1.0, 0.0, 0.0, 1.0))
    with pytest.raises(InputError, match="sensor model"):
        OccupancyGridMapper((0.0, 0.0, 1.0, 1.0), p_hit=0.4)
    with pytest.raises(InputError, match="yaw_step"):
        CorrelativeScanMatcher(yaw_step=0.0)
    with pytest.raises(InputError, match="mount"):
        MapBuilder((0.0, 0.0, 1.0, 1.0), mount=MOUNT, matcher=CorrelativeScanMatcher())
    assert MapBuilder((0.0, 0.0, 1.0, 1.0), mount=MOUNT).mapper.mount == MOUNT
