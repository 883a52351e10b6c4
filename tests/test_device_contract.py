"""One contract, every implementation: what twin.core.devices promises, checked on each device.

Gymnasium-style: the same tests run against the MuJoCo sim devices, the OpenCV camera on a real
capture backend (a video file: no camera is attached here), and the serial hardware drivers
talking to their emulators (the serial twins, on lines in memory, all on one ``ManualClock``:
the drivers' timeouts and the world's pace are virtual seconds, so no result depends on the
machine's speed; tests/test_vcc4_pty.py and test_arcos_driver.py keep the real-pty runs). A new
device type joins by adding a factory (a laser's yields a ``LaserUnderTest``: the device with its
clock and field of view). The clocks the drivers wait on have their contract too.
"""

from __future__ import annotations

import contextlib
import math
import threading
import time
from collections.abc import Callable, Iterator
from dataclasses import dataclass

import cv2
import numpy as np
import pytest

from twin.core.clock import Clock, ClockStalledError, ManualClock, SystemClock
from twin.core.devices import (
    Base,
    Camera,
    Laser,
    LaserMount,
    NotConnectedError,
    OutOfRangeError,
    PanTilt,
)
from twin.core.geometry import Pose2D

DeviceFactory = Callable[[object], contextlib.AbstractContextManager]


# -- factories: each yields an unconnected device, and cleans up what it started -------------------


@contextlib.contextmanager
def sim_devices() -> Iterator:
    from twin.sim import make_sim_robot

    _sim, robot = make_sim_robot("living_room", start=Pose2D(2.5, 3.3, 0.0))
    yield robot


@contextlib.contextmanager
def sim_camera(tmp_path) -> Iterator[Camera]:
    with sim_devices() as robot:
        yield robot.camera


@contextlib.contextmanager
def sim_pantilt(tmp_path) -> Iterator[PanTilt]:
    with sim_devices() as robot:
        yield robot.pantilt


@contextlib.contextmanager
def sim_base(tmp_path) -> Iterator[Base]:
    with sim_devices() as robot:
        yield robot.base


@contextlib.contextmanager
def opencv_camera(tmp_path) -> Iterator[Camera]:
    from hardware.opencv_camera import OpenCVCamera

    video = tmp_path / "camera.avi"
    writer = cv2.VideoWriter(str(video), cv2.VideoWriter_fourcc(*"MJPG"), 15, (640, 480))
    for i in range(30):
        writer.write(np.full((480, 640, 3), 8 * i, np.uint8))
    writer.release()
    yield OpenCVCamera(str(video), reconnect_delay=0.01)


@contextlib.contextmanager
def serial_twins(wiring: str = "direct") -> Iterator:
    from twin.serial_twins.session import SerialTwins
    from twin.sim import make_sim_robot

    clock = ManualClock()
    sim, _ = make_sim_robot("living_room", start=Pose2D(2.5, 3.3, 0.0))
    with SerialTwins(sim, vcc4_wiring=wiring, clock=clock, lines="memory") as twins:
        yield sim, twins, clock


def plug(link: object, name: str):
    """A driver's transport on a serial twin's memory line."""
    from twin.serial_twins.memory import MemoryLink

    assert isinstance(link, MemoryLink)
    return link.transport(name)


@contextlib.contextmanager
def vcc4_on_its_line(tmp_path) -> Iterator[PanTilt]:
    from hardware.vcc4 import VCC4

    with serial_twins() as (_, twins, clock):
        yield VCC4(opener=lambda: plug(twins.vcc4_link, "VC-C4"), clock=clock)


@contextlib.contextmanager
def vcc4_on_the_aux_port(tmp_path) -> Iterator[PanTilt]:
    from hardware.arcos import ArcosBase
    from hardware.vcc4 import VCC4

    with (
        serial_twins("aux") as (_, twins, clock),
        ArcosBase(lambda: plug(twins.arcos_link, "ARCOS base"), clock=clock) as base,
    ):
        yield VCC4(base.aux_transport(1), answer_timeout=1.0, clock=clock)


@contextlib.contextmanager
def arcos_base(tmp_path) -> Iterator[Base]:
    from hardware.arcos import ArcosBase

    with serial_twins() as (sim, twins, clock):
        yield ArcosBase(
            lambda: plug(twins.arcos_link, "ARCOS base"), start=sim.truth_pose(), clock=clock
        )


@dataclass(frozen=True)
class LaserUnderTest:
    """A laser for the contract, not yet connected, with what the contract cannot ask it: the
    clock its scans are timestamped on (``now``, seconds) and the field of view its beams span
    (rad, centred on the zero beam)."""

    device: Laser
    now: Callable[[], float]
    fov: float


@contextlib.contextmanager
def lms2xx_on_its_emulator(tmp_path) -> Iterator[LaserUnderTest]:
    """The LMS2xx driver on the emulated LMS200 in the spec's 4 m square room, on a memory line
    that knows the driver's baud rate, in virtual time."""
    from hardware.lms2xx import LMS2xx
    from twin.serial_twins.lms2xx import BaudMemoryLink, serve_lms2xx, square_room

    clock = ManualClock()
    link = BaudMemoryLink(clock, "lms2xx line")
    with serve_lms2xx(square_room(), link, clock=clock):
        laser = LMS2xx(lambda: link.transport("SICK LMS2xx"), clock=clock)
        yield LaserUnderTest(laser, clock.now, math.pi)


@contextlib.contextmanager
def sim_laser(tmp_path) -> Iterator[LaserUnderTest]:
    """The MuJoCo laser on the Peoplebot in the living room, on simulated time."""
    from twin.sim import make_sim_robot
    from twin.sim.laser import LaserSpec, SimLaser

    sim, _ = make_sim_robot("living_room", start=Pose2D(2.5, 3.3, 0.0))
    yield LaserUnderTest(SimLaser(sim, LaserSpec()), lambda: sim.world.time, math.pi)


CAMERAS = {"sim": sim_camera, "opencv": opencv_camera}
PANTILTS = {"sim": sim_pantilt, "vcc4": vcc4_on_its_line, "vcc4-aux": vcc4_on_the_aux_port}
BASES = {"sim": sim_base, "arcos": arcos_base}
LASERS = {"lms2xx": lms2xx_on_its_emulator, "sim": sim_laser}


@pytest.fixture(params=sorted(CAMERAS))
def camera(request, tmp_path):
    with CAMERAS[request.param](tmp_path) as device:
        yield device
        device.close()


@pytest.fixture(params=sorted(PANTILTS))
def pantilt(request, tmp_path):
    with PANTILTS[request.param](tmp_path) as device:
        yield device
        device.close()


@pytest.fixture(params=sorted(BASES))
def base(request, tmp_path):
    with BASES[request.param](tmp_path) as device:
        yield device
        device.close()


@pytest.fixture(params=sorted(LASERS))
def laser(request, tmp_path) -> Iterator[LaserUnderTest]:
    with LASERS[request.param](tmp_path) as under_test:
        yield under_test
        under_test.device.close()


# -- every device ----------------------------------------------------------------------------------


def check_connect_lifecycle(device, use) -> None:
    """Work is refused before connect and after close; connect is idempotent; close too."""
    with pytest.raises(NotConnectedError, match=device.name):
        use(device)
    with device:
        device.connect()
        assert device.is_connected
        use(device)
    assert not device.is_connected
    device.close()
    with pytest.raises(NotConnectedError):
        use(device)


def test_a_camera_is_used_only_while_connected(camera):
    check_connect_lifecycle(camera, lambda d: d.grab())


def test_a_head_is_used_only_while_connected(pantilt):
    check_connect_lifecycle(pantilt, lambda d: d.position())


def test_a_base_is_used_only_while_connected(base):
    check_connect_lifecycle(base, lambda d: d.pose())


def test_a_laser_is_used_only_while_connected(laser):
    check_connect_lifecycle(laser.device, lambda d: d.scan())


# -- cameras ---------------------------------------------------------------------------------------


def test_a_camera_delivers_rgb_frames_of_its_model_with_rising_timestamps(camera):
    with camera:
        frames = [camera.grab() for _ in range(3)]
    model = camera.model
    for frame in frames:
        assert frame.image.shape == (model.height, model.width, 3)
        assert frame.image.dtype == np.uint8
        assert math.isfinite(frame.timestamp)
    assert frames[0].timestamp <= frames[1].timestamp <= frames[2].timestamp
    assert 0 < model.hfov < math.pi


# -- pan-tilt heads --------------------------------------------------------------------------------


def test_a_head_reaches_angles_with_pan_positive_to_the_left(pantilt):
    with pantilt:
        for pan, tilt in [
            (math.radians(30), 0.0),
            (math.radians(-60), math.radians(10)),
            (0.0, 0.0),
        ]:
            reached = pantilt.move_to(pan, tilt)
            position = pantilt.position()
            for got in (reached, position):
                assert got[0] == pytest.approx(pan, abs=math.radians(1.0))
                assert got[1] == pytest.approx(tilt, abs=math.radians(1.0))
        pantilt.stop()


def test_a_head_refuses_angles_beyond_its_limits_and_stays_put(pantilt):
    with pantilt:
        pantilt.move_to(math.radians(20), 0.0)
        limits = pantilt.limits
        with pytest.raises(OutOfRangeError, match=pantilt.name):
            pantilt.move_to(limits.pan_max + math.radians(5), 0.0)
        with pytest.raises(OutOfRangeError):
            pantilt.move_to(0.0, limits.tilt_min - math.radians(5))
        assert pantilt.position()[0] == pytest.approx(math.radians(20), abs=math.radians(1.0))
    assert limits.pan_min <= -math.radians(90) and limits.pan_max >= math.radians(90)


# -- bases -----------------------------------------------------------------------------------------


def test_a_base_reports_the_pose_it_was_anchored_to(base):
    with base:
        base.set_pose(Pose2D(2.5, 3.3, 0.0))
        pose = base.pose()
    assert pose.x == pytest.approx(2.5, abs=0.02) and pose.y == pytest.approx(3.3, abs=0.02)
    assert abs(pose.heading_error_to(Pose2D(0, 0, 0.0))) < math.radians(1.0)


def test_a_base_drives_forward_along_its_heading_and_turns_left_for_positive_rates(base):
    with base:
        base.set_pose(Pose2D(2.5, 3.3, 0.0))
        moved = base.drive(0.2, 0.0, 1.0)
        assert moved.x - 2.5 == pytest.approx(0.2, rel=0.25)
        assert abs(moved.y - 3.3) < 0.03
        turned = base.drive(0.0, math.radians(30), 1.0)
        assert turned.heading_error_to(moved) == pytest.approx(-math.radians(30), rel=0.25)
        base.stop()


def test_a_base_goes_to_a_pose_within_5_cm_and_3_degrees(base):
    goal = Pose2D(2.0, 3.6, math.radians(120))
    with base:
        base.set_pose(Pose2D(2.5, 3.3, 0.0))
        final = base.go_to(goal)
        pose = base.pose()
    for got in (final, pose):
        assert got.distance_to(goal) < 0.05
        assert abs(got.heading_error_to(goal)) < math.radians(3.0)


# -- lasers ----------------------------------------------------------------------------------------


def test_a_laser_scan_is_fresh_and_the_next_one_newer(laser):
    with laser.device as device:
        stamps = []
        for _ in range(3):
            called = laser.now()
            scan = device.scan()
            assert called < scan.timestamp <= laser.now()  # taken after the call, not buffered
            stamps.append(scan.timestamp)
    assert stamps[0] < stamps[1] < stamps[2]


def test_a_laser_scan_spans_its_field_of_view_counter_clockwise(laser):
    with laser.device as device:
        scan = device.scan()
        assert isinstance(device.mount, LaserMount)
    angles = scan.angles
    assert angles.ndim == 1 and len(angles) >= 2 and scan.ranges.shape == angles.shape
    steps = np.diff(angles)
    assert np.all(steps > 0) and np.allclose(steps, steps[0], rtol=1e-6)
    assert angles[-1] - angles[0] == pytest.approx(laser.fov)
    assert angles[0] + angles[-1] == pytest.approx(0.0, abs=1e-9)  # -fov/2 right .. +fov/2 left


def test_a_laser_reports_metres_within_its_range_or_nan(laser):
    with laser.device as device:
        scan = device.scan()
    ranges = scan.ranges
    assert ranges.dtype.kind == "f" and not np.isinf(ranges).any()
    hits = ranges[np.isfinite(ranges)]
    assert hits.size > 0 and np.all(hits >= 0.0) and np.all(hits <= scan.max_range)
    assert 0.0 < scan.max_range < 100.0  # metres, not millimetres
    assert scan.points().shape == (hits.size, 2)


# -- clocks ----------------------------------------------------------------------------------------

CLOCKS = {"system": SystemClock, "manual": ManualClock}
# The system clock's timed waits may end a timer tick early; a manual clock's end exactly.
EARLY = {"system": 0.005, "manual": 0.0}


@pytest.fixture(params=sorted(CLOCKS))
def clock(request) -> Iterator[tuple[Clock, float]]:
    yield CLOCKS[request.param](), EARLY[request.param]


def test_a_clock_sleeps_forward_and_never_back(clock):
    clock, early = clock
    start = clock.now()
    clock.sleep(0.02)
    after = clock.now()
    assert after - start >= 0.02 - early
    clock.sleep(0.0)
    clock.sleep(-1.0)  # nothing to wait for
    assert clock.now() >= after


def test_a_clock_condition_times_out_or_is_notified_and_its_threads_join(clock):
    clock, early = clock
    cond = clock.condition()
    with cond:
        start = clock.now()
        assert cond.wait(0.05) is False
        assert clock.now() - start >= 0.05 - early
    box: list[float] = []

    def notify_later() -> None:
        clock.sleep(0.02)
        with cond:
            box.append(clock.now())
            cond.notify_all()

    thread = clock.start_thread(notify_later, "notifier")
    with cond:
        assert cond.wait_for(lambda: bool(box), 5.0)
    assert clock.join(thread, 5.0) and not thread.is_alive()
    with pytest.raises(RuntimeError):
        cond.notify_all()  # only while holding its lock, as threading.Condition


def test_manual_time_stands_still_while_a_thread_of_it_runs() -> None:
    """A reader thread that the machine starves (here: 20 ms of real work per tick) still gets
    every tick before the caller's wait ends: no timeout can fire because a thread was slow."""
    clock = ManualClock()
    cond = clock.condition()
    ticks: list[float] = []

    def starved_reader() -> None:
        for _ in range(5):
            clock.sleep(0.1)
            time.sleep(0.02)
            with cond:
                ticks.append(clock.now())
                cond.notify_all()

    thread = clock.start_thread(starved_reader, "reader")
    clock.sleep(0.25)
    assert ticks == pytest.approx([0.1, 0.2])
    with cond:  # the fifth tick is due at 0.5, within this wait's 0.3 s
        assert cond.wait_for(lambda: len(ticks) == 5, 0.3)
        assert clock.now() == pytest.approx(0.5)
    assert clock.join(thread, 1.0) and clock.now() == pytest.approx(0.5)


def test_manual_clock_names_a_thread_that_blocks_outside_it() -> None:
    clock = ManualClock(stall_timeout=0.2)
    gate = threading.Event()
    thread = clock.start_thread(lambda: gate.wait(10.0), "stuck-in-a-real-wait")
    try:
        with pytest.raises(ClockStalledError, match="stuck-in-a-real-wait"):
            clock.sleep(1.0)
    finally:
        gate.set()
    assert clock.join(thread, 1.0)
