"""The real ARCOS driver against the emulator over a pseudo-terminal, with the emulator driving
the MuJoCo robot stepped in wall-clock time x 4: the sim's robot moves, and the driver's pose
follows the sim's wheel odometry."""

from __future__ import annotations

import math
import time
from collections.abc import Iterator

import pytest

from hardware.arcos import ArcosBase
from twin.core.geometry import Pose2D
from twin.serial_twins.arcos import serve_arcos
from twin.serial_twins.runner import WorldRunner
from twin.sim import SimRobot, make_sim_robot


@pytest.fixture(scope="module")
def rig() -> Iterator[tuple[SimRobot, ArcosBase]]:
    sim, _ = make_sim_robot("living_room")
    with WorldRunner(sim, time_scale=4.0):
        server = serve_arcos(sim)
        with sim.lock:
            start = sim.odometry_pose()
        base = ArcosBase.open(server.path, start=start)
        with base:
            yield sim, base
        server.stop()


def odometry(sim: SimRobot) -> Pose2D:
    with sim.lock:
        return sim.odometry_pose()


def truth(sim: SimRobot) -> Pose2D:
    with sim.lock:
        return sim.truth_pose()


def test_sips_arrive_at_10_hz(rig: tuple[SimRobot, ArcosBase]) -> None:
    _, base = rig
    count, t0 = base.sip_count, time.monotonic()
    time.sleep(1.0)
    rate = (base.sip_count - count) / (time.monotonic() - t0)
    assert 6.0 <= rate <= 12.0  # about 10 Hz; bench_arcos.py measures it exactly


def test_drive_moves_the_sim_and_the_pose_tracks_its_odometry(
    rig: tuple[SimRobot, ArcosBase],
) -> None:
    sim, base = rig
    before = truth(sim)
    pose = base.drive(0.1, math.radians(15), 1.0)
    moved = truth(sim)
    assert moved.distance_to(before) > 0.2  # ~0.1 m/s x 1 s x 4
    odo = odometry(sim)
    assert pose.distance_to(odo) < 0.01
    assert abs(pose.heading_error_to(odo)) < math.radians(0.5)


def test_go_to_brings_the_sim_robot_within_5_cm_and_3_degrees(
    rig: tuple[SimRobot, ArcosBase],
) -> None:
    sim, base = rig
    here = base.pose()
    for goal in (
        Pose2D(here.x + 0.4, here.y - 0.3, here.yaw - 1.2),
        Pose2D(here.x, here.y, here.yaw),
    ):
        pose = base.go_to(goal, timeout=30.0)
        for p in (pose, odometry(sim), truth(sim)):
            assert p.distance_to(goal) < 0.05
            assert abs(p.heading_error_to(goal)) < math.radians(3.0)
