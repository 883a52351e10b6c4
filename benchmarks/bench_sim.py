"""How fast is the twin? Frames rendered per second, physics real-time factor, drive accuracy.

    python benchmarks/bench_sim.py [--frames 300] [--seconds 60] [--goals 12] [--seed 1]

Goals (issue 4): >= 20 frames/s at 320x240 with software rendering, and a physics real-time
factor >= 20x without rendering. Figures depend on the CPU and on what else runs on it.
"""

from __future__ import annotations

import argparse
import math
import os
import time

import numpy as np

from twin.core.geometry import Pose2D
from twin.sim.robot import SimRobot  # twin.sim selects headless EGL unless MUJOCO_GL is set
from twin.sim.sheet import LIVING_ROOM_STOPS
from twin.sim.world import World


def bench_render(frames: int) -> float:
    """Frames per second of the head camera while the head pans (a new view every frame)."""
    robot = SimRobot(World("living_room"), Pose2D(2.5, 3.3, math.radians(134.0)))
    with robot.devices() as devices:
        devices.capture()  # warm up: first frame uploads textures
        start = time.perf_counter()
        for k in range(frames):
            # a new view every frame: place the head directly (rendering, not control, is timed)
            robot.place(robot.truth_pose(), pan=math.radians(-90 + 180 * k / frames), settle=0.0)
            devices.camera.grab()
        return frames / (time.perf_counter() - start)


def bench_physics(seconds: float) -> tuple[float, float]:
    """Real-time factors: bare mj_step while driving a circle, and the go-to controller loop."""
    robot = SimRobot(World("living_room"))
    robot.set_wheel_speeds(0.3, 0.3)
    robot.step()  # writes the wheel controls; then bare stepping keeps them
    world = robot.world
    n = round(seconds / world.timestep)
    start = time.perf_counter()
    world.step(n)
    bare = seconds / (time.perf_counter() - start)

    robot = SimRobot(World("living_room"))
    simulated, wall = 0.0, 0.0
    while simulated < seconds:
        for x, y in LIVING_ROOM_STOPS:
            t0, w0 = robot.world.time, time.perf_counter()
            robot.go_to(Pose2D(x, y, 0.0))
            for k in range(1, 8):  # the survey's 45-degree base turns
                robot.go_to(Pose2D(x, y, math.radians(45.0 * k)))
            wall += time.perf_counter() - w0
            simulated += robot.world.time - t0
    return bare, simulated / wall


def bench_accuracy(goals: int, seed: int) -> tuple[float, float, float]:
    """Worst final error against ground truth over random reachable goals: (m, deg), and the
    worst odometry-vs-truth gap (m)."""
    rng = np.random.default_rng(seed)
    robot = SimRobot(World("living_room"))
    worst_xy = worst_yaw = worst_odo = 0.0
    done = 0
    while done < goals:  # random goals near the survey stops, whose straight path is clear
        x, y = LIVING_ROOM_STOPS[int(rng.integers(len(LIVING_ROOM_STOPS)))]
        goal = Pose2D(
            x + rng.uniform(-0.2, 0.2), y + rng.uniform(-0.2, 0.2), rng.uniform(-math.pi, math.pi)
        )
        here = robot.truth_pose()
        if robot.world.path_clearance((here.x, here.y), (goal.x, goal.y)) < 0.35:
            continue
        done += 1
        estimate = robot.go_to(goal)
        truth = robot.truth_pose()
        worst_xy = max(worst_xy, truth.distance_to(goal))
        worst_yaw = max(worst_yaw, abs(math.degrees(truth.heading_error_to(goal))))
        worst_odo = max(worst_odo, estimate.distance_to(truth))
    return worst_xy, worst_yaw, worst_odo


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--frames", type=int, default=300)
    parser.add_argument("--seconds", type=float, default=60.0)
    parser.add_argument("--goals", type=int, default=12)
    parser.add_argument("--seed", type=int, default=1)
    args = parser.parse_args()
    print(f"MUJOCO_GL={os.environ['MUJOCO_GL']}, {os.cpu_count()} CPUs")
    fps = bench_render(args.frames)
    print(f"render  320x240 living room: {fps:7.1f} frames/s   (goal >= 20)")
    bare, controlled = bench_physics(args.seconds)
    print(f"physics real-time factor, bare mj_step:        {bare:7.1f}x  (goal >= 20)")
    print(f"physics real-time factor, go-to controller:    {controlled:7.1f}x")
    xy, yaw, odo = bench_accuracy(args.goals, args.seed)
    print(
        f"drive accuracy over {args.goals} goals: worst {100 * xy:.1f} cm, {yaw:.2f} deg "
        f"(promise 5 cm, 3 deg); odometry vs truth worst {100 * odo:.1f} cm"
    )


if __name__ == "__main__":
    main()
