"""The real ARCOS driver against the emulator driving the MuJoCo robot, all on one
``ManualClock`` over a ``MemoryLink``: the world is stepped at exactly real-time pace in
virtual time, so the sim's robot moves as the firmware commands, the driver's pose follows the
sim's wheel odometry, and no figure depends on how fast or busy the machine is."""

from __future__ import annotations

import math
from collections.abc import Iterator

import pytest

from hardware.arcos import ArcosBase
from twin.core.clock import ManualClock
from twin.core.geometry import Pose2D
from twin.serial_twins.arcos import serve_arcos
from twin.serial_twins.memory import MemoryLink
from twin.serial_twins.runner import WorldRunner
from twin.sim import SimRobot, make_sim_robot


@pytest.fixture(scope="module")
def rig() -> Iterator[tuple[SimRobot, ArcosBase, ManualClock]]:
    clock = ManualClock()
    sim, _ = make_sim_robot("living_room")
    link = MemoryLink(clock, "arcos line")
    with WorldRunner(sim, clock=clock):
        server = serve_arcos(sim, link, clock=clock)
        with sim.lock:
            start = sim.odometry_pose()
        base = ArcosBase(lambda: link.transport("ARCOS base"), start=start, clock=clock)
        with base:
            yield sim, base, clock
        server.stop()


def odometry(sim: SimRobot) -> Pose2D:
    with sim.lock:
        return sim.odometry_pose()


def truth(sim: SimRobot) -> Pose2D:
    with sim.lock:
        return sim.truth_pose()


def test_sips_arrive_at_10_hz(rig: tuple[SimRobot, ArcosBase, ManualClock]) -> None:
    _, base, clock = rig
    count = base.sip_count
    clock.sleep(1.0)
    # one every 100 ms of the firmware's clock (the one due at the very end may be in flight)
    assert 9 <= base.sip_count - count <= 11


def test_drive_moves_the_sim_and_the_pose_tracks_its_odometry(
    rig: tuple[SimRobot, ArcosBase, ManualClock],
) -> None:
    sim, base, _ = rig
    before = truth(sim)
    pose = base.drive(0.1, math.radians(15), 2.0)
    moved = truth(sim)
    assert 0.15 < moved.distance_to(before) < 0.22  # an arc of ~0.1 m/s for 2 s, and the stop
    odo = odometry(sim)
    assert pose.distance_to(odo) < 0.01
    assert abs(pose.heading_error_to(odo)) < math.radians(0.5)


def test_go_to_brings_the_sim_robot_within_5_cm_and_3_degrees(
    rig: tuple[SimRobot, ArcosBase, ManualClock],
) -> None:
    sim, base, _ = rig
    here = base.pose()
    for goal in (
        Pose2D(here.x + 0.4, here.y - 0.3, here.yaw - 1.2),
        Pose2D(here.x, here.y, here.yaw),
    ):
        pose = base.go_to(goal, timeout=30.0)
        for p in (pose, odometry(sim), truth(sim)):
            assert p.distance_to(goal) < 0.05
            assert abs(p.heading_error_to(goal)) < math.radians(3.0)


def test_driving_into_furniture_presses_a_bumper_and_the_driver_stops() -> None:
    """The emulated firmware presses the bumper segment facing a contact in the MuJoCo world
    (and flags a stalled wheel), and the real driver turns either into a DeviceFaultError."""
    from twin.core.devices import DeviceFaultError

    clock = ManualClock()
    # just left of the coffee table, facing it: its nearest leg is about 0.3 m ahead
    sim, _ = make_sim_robot("living_room", start=Pose2D(1.2, 4.2, 0.0))
    link = MemoryLink(clock, "arcos line")
    with WorldRunner(sim, clock=clock):
        server = serve_arcos(sim, link, clock=clock)
        with sim.lock:
            start = sim.odometry_pose()
        base = ArcosBase(lambda: link.transport("ARCOS base"), start=start, clock=clock)
        try:
            with base, pytest.raises(DeviceFaultError, match=r"bumpers|stalled"):
                base.drive(0.3, 0.0, 4.0)
        finally:
            server.stop()
    assert truth(sim).x < 1.2 + 0.6  # stopped at the table, not driven through it
