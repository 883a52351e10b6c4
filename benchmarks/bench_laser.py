"""How fast is the sim laser? One simulated scan (361 and 181 beams), and the physics real-time
factor with the laser streaming at 10 scans per simulated second.

    python benchmarks/bench_laser.py [--scans 2000] [--seconds 60]

Goal: one 361-beam scan (a single mj_multiRay plus the data sheet's noise) in <= 1 ms, so
streaming at 10 Hz costs the physics little. Times are medians over poses around the living
room's survey stops; figures depend on the CPU and on what else runs on it.
"""

from __future__ import annotations

import argparse
import math
import os
import statistics
import time

from twin.core.geometry import Pose2D
from twin.sim.laser import LaserSpec, RayCaster, SimLaser, laser_site
from twin.sim.robot import SimRobot  # twin.sim selects headless EGL unless MUJOCO_GL is set
from twin.sim.sheet import LIVING_ROOM_STOPS
from twin.sim.world import World


def bench_scan(beams: int, scans: int) -> tuple[float, float]:
    """Median milliseconds of one bare cast (mj_multiRay and the fan's rotation) and of one
    SimLaser scan (the cast plus offset, noise, rounding, range limit and dropouts)."""
    bare, full = [], []
    per_stop = max(1, scans // len(LIVING_ROOM_STOPS))
    for x, y in LIVING_ROOM_STOPS:
        robot = SimRobot(World("living_room"), Pose2D(x, y, math.radians(30.0)))
        spec = LaserSpec(beams=beams)
        caster = RayCaster(robot.world.model, laser_site(robot.world.model), spec.angles, 8.0)
        laser = SimLaser(robot, spec)
        data = robot.world.data
        caster.cast(data)  # warm up
        for _ in range(per_stop):
            t0 = time.perf_counter()
            caster.cast(data)
            t1 = time.perf_counter()
            laser._cast_scan()  # what the step listener does at each scan instant
            t2 = time.perf_counter()
            bare.append(t1 - t0)
            full.append(t2 - t1)
    return 1e3 * statistics.median(bare), 1e3 * statistics.median(full)


def _drive_survey(robot: SimRobot, seconds: float) -> tuple[float, float]:
    """Drive the survey's stops and base turns until ``seconds`` of simulated time have passed;
    returns (simulated, wall) seconds."""
    simulated, wall = 0.0, 0.0
    while simulated < seconds:
        for x, y in LIVING_ROOM_STOPS:
            t0, w0 = robot.world.time, time.perf_counter()
            robot.go_to(Pose2D(x, y, 0.0))
            for k in range(1, 8):  # the survey's 45-degree base turns
                robot.go_to(Pose2D(x, y, math.radians(45.0 * k)))
            wall += time.perf_counter() - w0
            simulated += robot.world.time - t0
    return simulated, wall


def bench_streaming(seconds: float, beams: int) -> tuple[float, float, int, float]:
    """Real-time factors of the go-to controller loop without and with a connected laser
    casting at 10 Hz, and the scans cast in the simulated seconds of the second run."""
    plain = SimRobot(World("living_room"))
    simulated, wall = _drive_survey(plain, seconds)
    without = simulated / wall

    robot = SimRobot(World("living_room"))
    count = [0]
    with SimLaser(robot, LaserSpec(beams=beams, rate=10.0)) as laser:
        last = [None]

        def watch(_: SimRobot) -> None:
            scan = laser.latest_scan()
            if scan is not None and scan is not last[0]:
                last[0] = scan
                count[0] += 1

        robot.listeners.append(watch)
        simulated, wall = _drive_survey(robot, seconds)
    return without, simulated / wall, count[0], simulated


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--scans", type=int, default=2000)
    parser.add_argument("--seconds", type=float, default=60.0)
    args = parser.parse_args()
    print(f"MUJOCO_GL={os.environ['MUJOCO_GL']}, {os.cpu_count()} CPUs")
    for beams in (361, 181):
        bare, full = bench_scan(beams, args.scans)
        print(
            f"one {beams}-beam scan: {full:.3f} ms (goal <= 1 ms for 361); "
            f"the mj_multiRay cast alone {bare:.3f} ms"
        )
    without, with_laser, scans, simulated = bench_streaming(args.seconds, 361)
    print(f"physics real-time factor, go-to controller, no laser:            {without:7.1f}x")
    print(
        f"physics real-time factor, go-to controller, 361 beams at 10 Hz:  {with_laser:7.1f}x "
        f"({scans} scans in {simulated:.1f} s simulated)"
    )


if __name__ == "__main__":
    main()
