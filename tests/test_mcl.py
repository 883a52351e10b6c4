"""Monte Carlo localization (twin.nav.mcl) and the distance transform under it (twin.nav.distance).

The world is geometry, not a grid: a room of walls, furniture boxes and a round pillar. Scans are
cast exactly against that geometry (plus the LMS200's 5 mm noise and dropouts), while the
localizer only knows the map rasterised from it at 5 cm, as a robot only knows its map.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
import pytest

from twin.core.devices import LaserMount, Scan
from twin.core.errors import InputError
from twin.core.geometry import Pose2D, wrap_angle
from twin.nav.distance import distance_transform, obstacle_distance, signed_surface_distance
from twin.nav.maps import UNKNOWN, OccupancyMap
from twin.nav.mcl import (
    MclConfig,
    MonteCarloLocalizer,
    kld_bound,
    log_likelihoods,
    low_variance_indices,
    sample_motion_odometry,
)

MOUNT = LaserMount(x=0.10, y=0.0, z=0.30, yaw=0.0)
RESOLUTION = 0.05
MAX_RANGE = 8.0


# -- the synthetic world ----------------------------------------------------------------------


@dataclass(frozen=True)
class World:
    """Axis-aligned boxes (x0, y0, x1, y1) and circles (cx, cy, r), metres; ``extent`` is the
    rasterised area (x0, y0, x1, y1)."""

    boxes: tuple[tuple[float, float, float, float], ...]
    circles: tuple[tuple[float, float, float], ...]
    extent: tuple[float, float, float, float]
    inside: tuple[float, float, float, float]  # the room's floor: free where nothing stands

    def contains(self, x: np.ndarray, y: np.ndarray) -> np.ndarray:
        hit = np.zeros(np.shape(x), dtype=bool)
        for x0, y0, x1, y1 in self.boxes:
            hit |= (x >= x0) & (x <= x1) & (y >= y0) & (y <= y1)
        for cx, cy, r in self.circles:
            hit |= np.hypot(x - cx, y - cy) <= r
        return hit

    def rasterise(self, resolution: float = RESOLUTION, sub: int = 4) -> OccupancyMap:
        """Occupied where any of a cell's sub x sub sample points lies in an obstacle; free on
        the room's floor; unknown outside it (beyond the walls)."""
        x0, y0, x1, y1 = self.extent
        nx, ny = round((x1 - x0) / resolution), round((y1 - y0) / resolution)
        offsets = (np.arange(sub) + 0.5) / sub * resolution
        xs = x0 + (np.arange(nx)[:, None] * resolution + offsets[None, :]).ravel()
        ys = y0 + (np.arange(ny)[:, None] * resolution + offsets[None, :]).ravel()
        gx, gy = np.meshgrid(xs, ys)
        occupied = self.contains(gx, gy).reshape(ny, sub, nx, sub).any(axis=(1, 3))
        cx = x0 + (np.arange(nx) + 0.5) * resolution
        cy = y0 + (np.arange(ny) + 0.5) * resolution
        fx0, fy0, fx1, fy1 = self.inside
        floor = ((cx >= fx0) & (cx <= fx1))[None, :] & ((cy >= fy0) & (cy <= fy1))[:, None]
        grid = np.where(floor, 0.0, UNKNOWN)
        grid[occupied] = 1.0
        return OccupancyMap(grid, resolution, origin=(x0, y0, 0.0))

    def cast(self, ox: float, oy: float, bearings: np.ndarray, max_range: float) -> np.ndarray:
        """Exact ranges (m) from (ox, oy) along map-frame bearings; inf where nothing is hit."""
        dx, dy = np.cos(bearings), np.sin(bearings)
        best = np.full(bearings.shape, np.inf)
        with np.errstate(divide="ignore", invalid="ignore"):
            for x0, y0, x1, y1 in self.boxes:
                tx0, tx1 = (x0 - ox) / dx, (x1 - ox) / dx
                ty0, ty1 = (y0 - oy) / dy, (y1 - oy) / dy
                t_near = np.maximum(np.minimum(tx0, tx1), np.minimum(ty0, ty1))
                t_far = np.minimum(np.maximum(tx0, tx1), np.maximum(ty0, ty1))
                ok = (t_near <= t_far) & (t_far > 0) & (t_near > 0)
                best = np.where(ok & (t_near < best), t_near, best)
            for cx, cy, r in self.circles:
                fx, fy = ox - cx, oy - cy
                b = fx * dx + fy * dy
                disc = b * b - (fx * fx + fy * fy - r * r)
                t = -b - np.sqrt(np.maximum(disc, 0.0))
                ok = (disc >= 0) & (t > 0)
                best = np.where(ok & (t < best), t, best)
        best[best > max_range] = np.inf
        return best


def room_world() -> World:
    """A 6 x 4.5 m room (walls 0.1 m thick) with a sofa, a table, a bookcase and a pillar placed
    so that no turn or mirror of the room looks the same."""
    w, h, t = 6.0, 4.5, 0.1
    walls = ((-t, -t, w + t, 0.0), (-t, h, w + t, h + t), (-t, 0.0, 0.0, h), (w, 0.0, w + t, h))
    furniture = (
        (0.3, 3.6, 2.3, 4.5),  # sofa along the top wall, left
        (3.6, 1.2, 4.6, 2.0),  # table
        (5.6, 0.0, 6.0, 2.2),  # bookcase on the right wall, low
        (0.0, 0.0, 0.8, 0.5),  # cabinet in the lower-left corner
    )
    return World(
        boxes=walls + furniture,
        circles=((1.6, 1.8, 0.2),),
        extent=(-0.3, -0.3, w + 0.3, h + 0.3),
        inside=(0.0, 0.0, w, h),
    )


WORLD = room_world()
MAP = WORLD.rasterise()


def laser_angles(count: int = 181) -> np.ndarray:
    return np.linspace(-math.pi / 2, math.pi / 2, count)


def scan_from(
    pose: Pose2D,
    rng: np.random.Generator,
    count: int = 181,
    sigma: float = 0.005,
    dropout: float = 0.02,
    world: World = WORLD,
    timestamp: float = 0.0,
) -> Scan:
    """What the LMS200 on ``MOUNT`` sees from base pose ``pose``: exact ranges, Gaussian noise,
    a fraction of dropped beams (NaN), nothing beyond 8 m (NaN)."""
    c, s = math.cos(pose.yaw), math.sin(pose.yaw)
    ox = pose.x + c * MOUNT.x - s * MOUNT.y
    oy = pose.y + s * MOUNT.x + c * MOUNT.y
    angles = laser_angles(count)
    ranges = world.cast(ox, oy, pose.yaw + MOUNT.yaw + angles, MAX_RANGE)
    ranges = ranges + sigma * rng.standard_normal(count)
    ranges[rng.random(count) < dropout] = np.nan
    ranges[~np.isfinite(ranges) | (ranges >= MAX_RANGE)] = np.nan
    return Scan(angles, ranges, timestamp, MAX_RANGE)


# -- a drive with a biased odometry -----------------------------------------------------------

WHEEL_BASE = 0.38  # m


def drive(
    start: Pose2D,
    commands: list[tuple[float, float, float]],
    dt: float = 0.1,
    left_radius_error: float = 0.01,
) -> tuple[list[Pose2D], list[Pose2D]]:
    """Drive (v m/s, w rad/s, seconds) segments; returns the true poses and what odometry reads
    when the left wheel is ``left_radius_error`` larger than the odometry believes (one pose
    every ``dt``, the start first)."""
    truth, odometry = [start], [Pose2D(0.0, 0.0, 0.0)]
    for v, w, seconds in commands:
        for _ in range(round(seconds / dt)):
            right = (v + w * WHEEL_BASE / 2) * dt
            left = (v - w * WHEEL_BASE / 2) * dt
            truth.append(_advance(truth[-1], (right + left) / 2, (right - left) / WHEEL_BASE))
            left_read = left / (1.0 + left_radius_error)
            odometry.append(
                _advance(odometry[-1], (right + left_read) / 2, (right - left_read) / WHEEL_BASE)
            )
    return truth, odometry


def _advance(pose: Pose2D, distance: float, turn: float) -> Pose2D:
    heading = pose.yaw + turn / 2
    return Pose2D(
        pose.x + distance * math.cos(heading),
        pose.y + distance * math.sin(heading),
        float(wrap_angle(pose.yaw + turn)),
    )


QUARTER = math.pi / 4  # rad/s: a quarter turn in 2 s
# A lap of the room from (1.0, 0.8) heading east: 13 m, 266 scans at 10 Hz.
LOOP = [
    (0.4, 0.0, 10.0),  # east along the bottom, under the table
    (0.0, QUARTER, 2.0),  # turn on the spot to face north
    (0.4, 0.0, 6.5),  # north between the table and the bookcase
    (0.0, QUARTER, 2.0),
    (0.4, 0.0, 5.0),  # west towards the sofa
    (0.3, math.pi / 6, 3.0),  # a quarter arc of 0.57 m radius, to face south
    (0.4, 0.0, 4.5),  # south past the pillar
    (0.0, QUARTER, 2.0),
]
START = Pose2D(1.0, 0.8, 0.0)


def error_of(estimate: Pose2D, truth: Pose2D) -> tuple[float, float]:
    return estimate.distance_to(truth), abs(truth.heading_error_to(estimate))


def localizer(seed: int = 7, **kwargs) -> MonteCarloLocalizer:
    kwargs.setdefault("initial_pose", START)
    kwargs.setdefault("initial_sigma", (0.1, 0.1, math.radians(5.0)))
    return MonteCarloLocalizer(MAP, MOUNT, rng=np.random.default_rng(seed), **kwargs)


# -- the distance transform -------------------------------------------------------------------


def brute_force_distance(mask: np.ndarray) -> np.ndarray:
    rows, cols = np.nonzero(mask)
    if rows.size == 0:
        return np.full(mask.shape, np.inf)
    r, c = np.indices(mask.shape)
    return np.sqrt(
        ((r[..., None] - rows) ** 2 + (c[..., None] - cols) ** 2).min(axis=-1).astype(float)
    )


@pytest.mark.parametrize("shape", [(1, 1), (1, 9), (7, 1), (13, 17), (40, 31)])
@pytest.mark.parametrize("density", [0.0, 0.02, 0.3, 1.0])
def test_the_distance_transform_is_exact(shape, density):
    rng = np.random.default_rng(shape[0] * 100 + shape[1])
    mask = rng.random(shape) < density
    expected = brute_force_distance(mask)
    np.testing.assert_allclose(distance_transform(mask), expected)
    np.testing.assert_allclose(distance_transform(mask, 0.05), expected * 0.05)


def test_the_distance_transform_refuses_what_is_not_a_grid():
    with pytest.raises(InputError, match="2-D"):
        distance_transform(np.zeros(5, dtype=bool))
    with pytest.raises(InputError, match="resolution"):
        distance_transform(np.zeros((2, 2), dtype=bool), 0.0)


def test_the_likelihood_field_crosses_zero_on_the_faces_of_obstacles():
    grid = np.zeros((5, 8))
    grid[:, 5:] = 1.0  # a wall whose face is at x = 0.5 m
    wall = OccupancyMap(grid, 0.1)
    field = signed_surface_distance(wall)
    np.testing.assert_allclose(field[2], [0.45, 0.35, 0.25, 0.15, 0.05, -0.05, -0.15, -0.25])
    np.testing.assert_allclose(field, signed_surface_distance(wall, obstacle_distance(wall)))


def test_the_likelihood_peaks_at_the_true_pose_not_half_a_cell_into_the_walls():
    mcl = localizer(config=MclConfig(beams=181))
    offsets = np.linspace(-0.04, 0.04, 33)  # 2.5 mm steps
    poses_seen = (START, Pose2D(3.0, 0.8, 0.0), Pose2D(5.0, 2.5, 1.57), Pose2D(2.0, 3.0, 3.0))
    for pose in poses_seen:
        scan = scan_from(pose, np.random.default_rng(0), sigma=0.0, dropout=0.0)
        hit = np.isfinite(scan.ranges)
        r, a = scan.ranges[hit], scan.angles[hit]
        beam_x, beam_y = MOUNT.x + r * np.cos(a), MOUNT.y + r * np.sin(a)
        for axis in (0, 1):
            poses = np.tile([pose.x, pose.y, pose.yaw], (len(offsets), 1)).astype(float)
            poses[:, axis] += offsets
            out = np.empty(len(poses))
            log_likelihoods(
                poses,
                beam_x,
                beam_y,
                mcl._surface,
                MAP.origin[0],
                MAP.origin[1],
                1.0 / MAP.resolution,
                mcl._lut(MAX_RANGE),
                1000.0,
                out,
            )
            assert abs(offsets[np.argmax(out)]) <= 0.005, (pose, axis)


# -- the pieces of the filter -----------------------------------------------------------------


def relative(a: Pose2D, b: Pose2D) -> tuple[float, float, float]:
    """b in a's frame."""
    c, s = math.cos(a.yaw), math.sin(a.yaw)
    dx, dy = b.x - a.x, b.y - a.y
    return c * dx + s * dy, -s * dx + c * dy, float(wrap_angle(b.yaw - a.yaw))


@pytest.mark.parametrize(
    "step",
    [
        Pose2D(0.3, 0.1, 0.4),  # forward, curving left
        Pose2D(-0.2, 0.0, 0.0),  # straight back
        Pose2D(0.0, 0.0, -1.2),  # turn on the spot
        Pose2D(0.004, 0.0, 0.1),  # a step shorter than 1 cm: no rot1
    ],
)
def test_the_motion_model_without_noise_moves_particles_by_the_odometry_increment(step):
    start_odometry = Pose2D(4.0, -1.0, 2.0)
    c, s = math.cos(start_odometry.yaw), math.sin(start_odometry.yaw)
    end_odometry = Pose2D(
        start_odometry.x + c * step.x - s * step.y,
        start_odometry.y + s * step.x + c * step.y,
        start_odometry.yaw + step.yaw,
    )
    config = MclConfig(alphas=(0.0, 0.0, 0.0, 0.0), jitter_xy=0.0, jitter_yaw=0.0)
    particles = np.array([[1.0, 2.0, 0.5], [3.0, 1.0, -2.5]])
    mcl = localizer(config=config)
    mcl.init_particles(particles)
    mcl.predict(start_odometry)
    mcl.predict(end_odometry)
    for before, after in zip(particles, mcl.particles, strict=True):
        moved = relative(Pose2D(*before), Pose2D(*after))
        np.testing.assert_allclose(moved, (step.x, step.y, step.yaw), atol=1e-12)


def test_the_motion_model_spreads_a_straight_metre_as_the_textbook_says():
    n = 20000
    poses = np.zeros((n, 3))
    noise = np.random.default_rng(3).standard_normal((n, 6))
    alphas = np.array([0.0, 0.0, 0.04, 0.0])  # sd of trans = 0.2 * trans
    sample_motion_odometry(poses, 0.0, 1.0, 0.0, alphas, 0.0, 0.0, noise)
    assert np.mean(poses[:, 0]) == pytest.approx(1.0, abs=0.01)
    assert np.std(poses[:, 0]) == pytest.approx(0.2, rel=0.03)
    assert np.all(poses[:, 1:] == 0.0)
    poses = np.zeros((n, 3))
    alphas = np.array([0.0, 0.01, 0.0, 0.0])  # sd of rot1 and rot2 = 0.1 rad per metre
    sample_motion_odometry(poses, 0.0, 1.0, 0.0, alphas, 0.0, 0.0, noise)
    assert np.std(poses[:, 2]) == pytest.approx(0.1 * math.sqrt(2), rel=0.03)


def test_low_variance_resampling_draws_each_particle_in_proportion_to_its_weight():
    weights = np.array([0.5, 0.25, 0.125, 0.125, 0.0])
    for start in (0.0, 0.3, 0.999):
        counts = np.bincount(low_variance_indices(weights, 8, start), minlength=5)
        np.testing.assert_array_equal(counts, [4, 2, 1, 1, 0])
    weights = np.random.default_rng(0).random(50)
    weights /= weights.sum()
    counts = np.bincount(low_variance_indices(weights, 1000, 0.5), minlength=50)
    assert np.all(np.abs(counts - 1000 * weights) <= 1.0 + 1e-9)


def test_the_kld_bound_follows_the_chi_square_quantile():
    stats = pytest.importorskip("scipy.stats")
    for bins in (2, 10, 100, 1000):
        exact = stats.chi2.ppf(0.99, bins - 1) / (2 * 0.05)
        assert kld_bound(bins, 0.05, 2.326) == pytest.approx(exact, rel=0.03)
    assert kld_bound(1, 0.05, 2.326) == 1


# -- the filter on the room -------------------------------------------------------------------


def test_tracking_stays_within_centimetres_and_a_degree_despite_a_biased_odometry():
    truth, odometry = drive(START, LOOP)
    # what the 1 % wheel does to dead reckoning over the lap: 35 cm
    dead_reckoning = relative(odometry[0], odometry[-1])
    true_motion = relative(truth[0], truth[-1])
    assert math.hypot(dead_reckoning[0] - true_motion[0], dead_reckoning[1] - true_motion[1]) > 0.3
    mcl = localizer(initial_pose=Pose2D(START.x + 0.08, START.y - 0.06, math.radians(3.0)))
    scans = np.random.default_rng(11)
    errors = []
    for k, (pose, odo) in enumerate(zip(truth, odometry, strict=True)):
        estimate = mcl.update(odo, scan_from(pose, scans, timestamp=0.1 * k))
        errors.append(error_of(estimate.pose, pose))
        assert estimate.timestamp == pytest.approx(0.1 * k)
    errors = np.array(errors[10:])  # converged after a second
    assert errors[:, 0].max() < 0.03
    assert math.degrees(errors[:, 1].max()) < 1.0
    assert estimate.localized and estimate.unimodal and estimate.scan_fit > 0.9


def test_global_localization_finds_the_robot_in_the_asymmetric_room():
    truth, odometry = drive(START, LOOP)
    mcl = MonteCarloLocalizer(MAP, MOUNT, rng=np.random.default_rng(5))  # no start pose
    first = mcl.estimate()
    assert first.particles == MclConfig().max_particles
    assert not first.localized and not first.unimodal and first.std_xy > 1.0
    scans = np.random.default_rng(12)
    found = None
    for k, (pose, odo) in enumerate(zip(truth, odometry, strict=True)):
        estimate = mcl.update(odo, scan_from(pose, scans))
        distance, heading = error_of(estimate.pose, pose)
        if found is None and estimate.localized and distance < 0.03:
            found = k
        if found is not None:  # once found, it stays found
            assert distance < 0.03 and heading < math.radians(1.0), (k, distance, heading)
    assert found is not None and found < 20
    assert estimate.particles == 500  # KLD sampling let go of the global cloud


def test_a_kidnapped_robot_is_found_again():
    truth, odometry = drive(START, LOOP)
    mcl = localizer()
    scans = np.random.default_rng(13)
    for pose, odo in zip(truth[:60], odometry[:60], strict=True):
        estimate = mcl.update(odo, scan_from(pose, scans))
    assert estimate.localized and error_of(estimate.pose, truth[59])[0] < 0.03
    carried_to = Pose2D(2.2, 2.8, -2.0)  # odometry says it never moved
    estimates = [mcl.update(odometry[59], scan_from(carried_to, scans)) for _ in range(120)]
    assert not estimates[0].localized and estimates[0].scan_fit < 0.5  # it knows it is lost
    assert sum(e.injected for e in estimates) > 0  # augmented MCL threw in random particles
    found = next(
        k for k, e in enumerate(estimates) if e.localized and error_of(e.pose, carried_to)[0] < 0.03
    )
    assert found < 40
    for e in estimates[found + 10 :]:  # a second to settle, then it stays
        assert error_of(e.pose, carried_to)[0] < 0.03
    assert estimates[-1].injected == 0


def test_resampling_happens_only_when_the_effective_sample_size_is_low():
    truth, odometry = drive(START, LOOP)
    mcl = localizer(initial_sigma=(0.05, 0.05, 0.03))
    scans = np.random.default_rng(14)
    seen = []
    for pose, odo in zip(truth[:80], odometry[:80], strict=True):
        estimate = mcl.update(odo, scan_from(pose, scans))
        assert estimate.resampled == (estimate.ess < 0.5 * estimate.particles)
        seen.append(estimate.resampled)
    assert any(seen) and not all(seen)
    # a scan without a single return says nothing: the weights stay, nothing is resampled
    weights = mcl.weights
    blind = Scan(laser_angles(), np.full(181, np.nan), 0.0, MAX_RANGE)
    estimate = mcl.update(odometry[79], blind)
    assert estimate.beams == 0 and not estimate.resampled
    np.testing.assert_array_equal(mcl.weights, weights)
    # with the threshold at 0 the weights only ever multiply up
    never = localizer(config=MclConfig(resample_threshold=0.0))
    for pose, odo in zip(truth[:20], odometry[:20], strict=True):
        assert not never.update(odo, scan_from(pose, scans)).resampled
    assert never.estimate().ess < 5


def test_equal_seeds_give_equal_runs():
    truth, odometry = drive(START, LOOP[:2])

    def run(seed: int) -> tuple[np.ndarray, list[Pose2D]]:
        mcl = MonteCarloLocalizer(MAP, MOUNT, rng=np.random.default_rng(seed))
        scans = np.random.default_rng(99)
        poses = [
            mcl.update(o, scan_from(p, scans)).pose for p, o in zip(truth, odometry, strict=True)
        ]
        return mcl.particles, poses

    first, again, other = run(1), run(1), run(2)
    np.testing.assert_array_equal(first[0], again[0])
    assert first[1] == again[1]
    assert first[0].shape != other[0].shape or not np.array_equal(first[0], other[0])


def test_the_covariance_shrinks_as_the_filter_converges():
    mcl = localizer(initial_pose=START, initial_sigma=(0.3, 0.3, 0.3))
    scans = np.random.default_rng(15)
    start = mcl.estimate()
    assert not start.localized
    assert start.std_xy == pytest.approx(0.3, rel=0.15)
    assert start.std_yaw == pytest.approx(0.3, rel=0.15)
    traces = [np.trace(start.covariance)]
    for _ in range(10):
        estimate = mcl.update(START, scan_from(START, scans))
        traces.append(np.trace(estimate.covariance))
    assert traces[-1] < traces[0] / 100
    assert estimate.localized and error_of(estimate.pose, START)[0] < 0.03


def test_two_equal_modes_are_not_unimodal():
    rng = np.random.default_rng(4)
    cloud = rng.normal(0.0, 0.02, (200, 3))
    mcl = localizer()
    one = mcl.init_particles(cloud + np.array([2.0, 2.0, 0.0]))
    assert one.unimodal and one.localized and one.mode_mass == pytest.approx(1.0)
    two = mcl.init_particles(
        np.concatenate([cloud + np.array([2.0, 2.0, 0.0]), cloud + np.array([4.0, 2.0, 0.0])])
    )
    assert not two.unimodal and not two.localized and two.mode_mass < 0.1
    assert two.pose.x == pytest.approx(3.0, abs=0.01)  # the mean lies between the modes
    assert two.std_xy == pytest.approx(1.0, abs=0.01)
    weighted = mcl.init_particles(
        np.concatenate([cloud + np.array([2.0, 2.0, 0.0]), cloud + np.array([4.0, 2.0, 0.0])]),
        np.r_[np.ones(200), np.full(200, 1e-6)],
    )
    assert weighted.unimodal and weighted.pose.x == pytest.approx(2.0, abs=0.01)


def test_the_yaw_estimate_is_a_circular_mean():
    mcl = localizer()
    yaws = np.array([math.pi - 0.05, -math.pi + 0.05, math.pi - 0.02, -math.pi + 0.02])
    estimate = mcl.init_particles(np.c_[np.full(4, 2.0), np.full(4, 2.0), yaws])
    assert abs(wrap_angle(estimate.pose.yaw - math.pi)) < 1e-9
    assert estimate.std_yaw == pytest.approx(math.sqrt((0.05**2 + 0.02**2) / 2))


def test_bad_arguments_are_one_line_errors():
    with pytest.raises(InputError, match="Generator"):
        MonteCarloLocalizer(MAP, MOUNT, rng=7)  # type: ignore[arg-type]
    with pytest.raises(InputError, match="particles"):
        localizer(particles=0)
    with pytest.raises(InputError, match="sigma_hit"):
        MclConfig(sigma_hit=0.0)
    with pytest.raises(InputError, match="alpha_slow"):
        MclConfig(alpha_slow=0.5, alpha_fast=0.1)
    with pytest.raises(InputError, match="distance field shape"):
        localizer(distance=np.zeros((3, 3)))
    with pytest.raises(InputError, match="sigma"):
        localizer().init_pose(START, (0.1, 0.1))  # type: ignore[arg-type]
    walled = OccupancyMap(np.ones((10, 10)), 0.05)
    with pytest.raises(InputError, match="no free cell"):
        MonteCarloLocalizer(walled, MOUNT, rng=np.random.default_rng(0))
    mcl = localizer()
    with pytest.raises(InputError, match="equal 1-D"):
        mcl.update(START, Scan(laser_angles(), np.ones(5), 0.0, MAX_RANGE))
