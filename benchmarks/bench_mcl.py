"""Time Monte Carlo localization on a 10 x 8 m map of 5 cm cells, and say how well it localizes.

    python benchmarks/bench_mcl.py

Prints the distance transform of the map, one filter update (500 particles x 181 beams, the
goal being at most 5 ms; 1000 x 361; the default 500 x 60), global initialisation, the accuracy
of tracking and global localization along a 24 m drive with a 1 % wheel-radius error in the
odometry, and how soon a kidnapped robot is found again. Scans are ray-cast through the map
(``twin.nav.raycast``) with the LMS200's 5 mm noise and 2 % dropouts. Times are medians (and
95th percentiles) of wall time per call.
"""

from __future__ import annotations

import math
import time

import numpy as np

from twin.core.devices import LaserMount, Scan
from twin.core.geometry import Pose2D, wrap_angle
from twin.nav.distance import distance_transform
from twin.nav.maps import OccupancyMap
from twin.nav.mcl import MclConfig, MonteCarloLocalizer
from twin.nav.raycast import lms200_angles, simulate_scan

RES = 0.05
MOUNT = LaserMount(x=0.10, y=0.0, z=0.30, yaw=0.0)
WHEEL_BASE = 0.38


def office_map() -> OccupancyMap:
    """10 x 8 m: outer walls, a half wall with a door, desks, shelves and two pillars."""
    nx, ny = round(10.0 / RES), round(8.0 / RES)
    x = (np.arange(nx) + 0.5) * RES
    y = (np.arange(ny) + 0.5) * RES
    gx, gy = np.meshgrid(x, y)
    solid = (gx < 0.1) | (gx > 9.9) | (gy < 0.1) | (gy > 7.9)
    boxes = [
        (6.0, 0.1, 6.1, 3.0),  # half wall, the door above it to y = 4.0
        (6.0, 4.0, 6.1, 7.9),
        (1.0, 5.5, 3.0, 6.3),  # desk
        (7.0, 6.5, 9.9, 7.9),  # shelves
        (3.5, 1.0, 4.5, 1.6),  # table
        (8.0, 1.0, 9.0, 2.5),  # cabinet
    ]
    for x0, y0, x1, y1 in boxes:
        solid |= (gx >= x0) & (gx <= x1) & (gy >= y0) & (gy <= y1)
    for cx, cy, r in ((2.0, 3.0, 0.25), (8.0, 4.5, 0.2)):
        solid |= np.hypot(gx - cx, gy - cy) <= r
    return OccupancyMap(solid.astype(float), RES)


def drive(start: Pose2D, commands: list[tuple[float, float, float]], dt: float = 0.1):
    """True poses and odometry (left wheel 1 % larger than the odometry assumes), every dt."""
    truth, odometry = [start], [Pose2D(0.0, 0.0, 0.0)]
    for v, w, seconds in commands:
        for _ in range(round(seconds / dt)):
            right = (v + w * WHEEL_BASE / 2) * dt
            left = (v - w * WHEEL_BASE / 2) * dt
            for poses, l_read in ((truth, left), (odometry, left / 1.01)):
                d, turn = (right + l_read) / 2, (right - l_read) / WHEEL_BASE
                p = poses[-1]
                heading = p.yaw + turn / 2
                poses.append(
                    Pose2D(
                        p.x + d * math.cos(heading),
                        p.y + d * math.sin(heading),
                        float(wrap_angle(p.yaw + turn)),
                    )
                )
    return truth, odometry


QUARTER = math.pi / 4
# from (1, 0.8) east under the table, north, east through the door, back, south and west home:
# 24 m at 0.4 m/s
COMMANDS = [
    (0.4, 0.0, 10.0),
    (0.0, QUARTER, 2.0),
    (0.4, 0.0, 6.5),
    (0.0, -QUARTER, 2.0),
    (0.4, 0.0, 6.25),
    (0.0, QUARTER, 4.0),
    (0.4, 0.0, 6.25),
    (0.0, QUARTER, 2.0),
    (0.4, 0.0, 6.5),
    (0.0, -QUARTER, 2.0),
    (0.4, 0.0, 10.0),
]
START = Pose2D(1.0, 0.8, 0.0)


def scans_along(occupancy: OccupancyMap, truth: list[Pose2D], beams: int, seed: int) -> list[Scan]:
    rng = np.random.default_rng(seed)
    scans = []
    for k, pose in enumerate(truth):
        scan = simulate_scan(
            occupancy,
            pose,
            MOUNT,
            lms200_angles(beams),
            noise_m=0.005,
            rng=rng,
            timestamp=0.1 * k,
        )
        ranges = scan.ranges.copy()
        ranges[rng.random(beams) < 0.02] = np.nan
        scans.append(Scan(scan.angles, ranges, scan.timestamp, scan.max_range))
    return scans


def median_ms(times: list[float]) -> str:
    return f"{1e3 * np.median(times):7.2f} ms (p95 {1e3 * np.percentile(times, 95):6.2f})"


def run(occupancy, truth, odometry, scans, particles, beams, initial=START):
    mcl = MonteCarloLocalizer(
        occupancy,
        MOUNT,
        rng=np.random.default_rng(1),
        particles=particles,
        config=MclConfig(beams=beams),
        initial_pose=initial,
        initial_sigma=(0.1, 0.1, math.radians(5.0)),
    )
    times, errors, found = [], [], None
    for k, (pose, odo, scan) in enumerate(zip(truth, odometry, scans, strict=True)):
        t = time.perf_counter()
        estimate = mcl.update(odo, scan)
        times.append(time.perf_counter() - t)
        error = (estimate.pose.distance_to(pose), abs(pose.heading_error_to(estimate.pose)))
        errors.append(error)
        if found is None and estimate.localized and error[0] < 0.05:
            found = k
    return times, np.array(errors), found


def main() -> None:
    occupancy = office_map()
    ny, nx = occupancy.shape
    print(f"map 10 x 8 m at {RES} m: {nx} x {ny} cells")
    times = []
    for _ in range(30):
        t = time.perf_counter()
        distance_transform(occupancy.occupied, RES)
        times.append(time.perf_counter() - t)
    print(f"  exact distance transform:          {median_ms(times)}")
    times = []
    for _ in range(10):
        t = time.perf_counter()
        MonteCarloLocalizer(occupancy, MOUNT, rng=np.random.default_rng(0), initial_pose=START)
        times.append(time.perf_counter() - t)
    print(f"  localizer set-up (fields, tables): {median_ms(times)}")
    mcl = MonteCarloLocalizer(occupancy, MOUNT, rng=np.random.default_rng(0), initial_pose=START)
    times = []
    for _ in range(30):
        t = time.perf_counter()
        mcl.init_global()
        times.append(time.perf_counter() - t)
    print(f"  init_global (5000 particles):      {median_ms(times)}")

    truth, odometry = drive(START, COMMANDS)
    print(f"\none update along a {len(truth)}-scan drive (1 % wheel error), tracking from 0.1 m:")
    for particles, beams in ((500, 181), (1000, 361), (500, 60)):
        scans = scans_along(occupancy, truth, beams, seed=2)
        run(occupancy, truth[:3], odometry[:3], scans[:3], particles, beams)  # compile/warm
        times, errors, _ = run(occupancy, truth, odometry, scans, particles, beams)
        settled = errors[10:]
        print(
            f"  {particles:5d} particles x {beams:3d} beams: {median_ms(times)}; error after "
            f"1 s: mean {100 * settled[:, 0].mean():.1f} cm, max {100 * settled[:, 0].max():.1f}"
            f" cm, max {math.degrees(settled[:, 1].max()):.2f} deg"
        )
    print(
        "\nglobal localization (no start pose: 50 000 poses weigh the first scan, 5000 are kept,"
        " falling to 500 as it converges), 60 beams:"
    )
    scans = scans_along(occupancy, truth, 181, seed=3)
    for seed in range(8):
        mcl = MonteCarloLocalizer(occupancy, MOUNT, rng=np.random.default_rng(10 + seed))
        found, times = None, []
        for k, (pose, odo, scan) in enumerate(zip(truth, odometry, scans, strict=True)):
            t = time.perf_counter()
            estimate = mcl.update(odo, scan)
            times.append(time.perf_counter() - t)
            if found is None and estimate.localized and estimate.pose.distance_to(pose) < 0.05:
                found = k
        error = estimate.pose.distance_to(truth[-1])
        print(
            f"  seed {seed}: within 5 cm and localized after {found} updates; first update "
            f"{1e3 * times[0]:.1f} ms; final error {100 * error:.1f} cm"
        )

    print("\nkidnapping: tracked for 10 s, then carried off while the odometry stands still:")
    for target in (Pose2D(3.0, 4.0, 0.5), Pose2D(4.5, 6.8, -2.5), Pose2D(7.5, 3.5, 3.0)):
        found_after, slowest = [], 0.0
        for seed in range(4):
            rng = np.random.default_rng(40 + seed)
            mcl = MonteCarloLocalizer(
                occupancy, MOUNT, rng=np.random.default_rng(seed), initial_pose=START
            )
            for k in range(100):
                mcl.update(odometry[k], scans[k])
            found = None
            for j in range(300):
                scan = simulate_scan(occupancy, target, MOUNT, noise_m=0.005, rng=rng)
                t = time.perf_counter()
                estimate = mcl.update(odometry[99], scan)
                slowest = max(slowest, time.perf_counter() - t)
                if estimate.localized and estimate.pose.distance_to(target) < 0.05:
                    found = j
                    break
            found_after.append(found)
        print(
            f"  to ({target.x}, {target.y}, {target.yaw} rad): within 5 cm and localized after "
            f"{found_after} updates (4 seeds); slowest update {1e3 * slowest:.1f} ms"
        )


if __name__ == "__main__":
    main()
