"""The SICK LMS2xx driver against the emulated scanner: start-up, scans, units, variants, NAKs,
silence, junk, a restarted scanner and a lost line; the serial twins' laser; the CLI.

Most tests run on a ``BaudMemoryLink`` in virtual time (``ManualClock``): the driver's reader
thread and the emulator's line share one clock that moves only when both wait, so every byte's
time on the line, every reply timeout and every probe of a baud rate is exact, whatever the
machine's load. The last ones run end to end over a real pseudo-terminal in real time, where
the emulator reads the port's rate from the terminal settings.
"""

from __future__ import annotations

import json
import math
from collections.abc import Iterator
from pathlib import Path

import numpy as np
import pytest

from hardware.lms2xx import LMS2xx
from hardware.lms2xx_codec import Command, Mode, Units, Variant
from twin.core.clock import ManualClock
from twin.core.devices import (
    ConnectionLostError,
    DeviceFaultError,
    DeviceTimeoutError,
    NotConnectedError,
    ProtocolError,
)
from twin.core.errors import InputError
from twin.serial_twins import lms2xx as emulated
from twin.serial_twins.bytedevice import LineServer
from twin.serial_twins.lms2xx import BaudMemoryLink, serve_lms2xx, square_room
from twin.serial_twins.pty import PtyLink

ROOM = square_room()


def serve(clock: ManualClock | None = None, **options: object) -> LineServer:
    clock = clock or ManualClock()
    return serve_lms2xx(ROOM, BaudMemoryLink(clock, "lms2xx line"), clock=clock, **options)


@pytest.fixture
def server() -> Iterator[LineServer]:
    srv = serve()
    yield srv
    srv.stop()


def laser_on(server: LineServer, **options: object) -> LMS2xx:
    """A driver on the server's line and clock."""
    link = server.link
    assert isinstance(link, BaudMemoryLink)
    return LMS2xx(lambda: link.transport("SICK LMS2xx"), clock=server.clock, **options)  # type: ignore[arg-type]


def commands(server: LineServer) -> list[str]:
    return [c.hex(" ").upper() for c in server.emulator.commands()]


def check_room(scan, variant: Variant, unit: float) -> None:
    assert len(scan.angles) == variant.count and len(scan.ranges) == variant.count
    assert scan.angles[0] == pytest.approx(-math.radians(variant.angle / 2))
    assert scan.angles[-1] == pytest.approx(math.radians(variant.angle / 2))
    np.testing.assert_allclose(scan.ranges, ROOM(scan.angles), atol=unit / 2 + 1e-9)


# -- start-up, scans, close -----------------------------------------------------------------------


def test_start_up_follows_section_13_and_close_leaves_the_scanner_at_9600(server):
    with laser_on(server) as laser:
        assert commands(server) == [
            "20 25",  # stop a stream, found at 9600 (power-on)
            "20 40",  # 38400: the port switched after A0 00
            "3A",
            "31",
            "3B B4 00 64 00",  # 180 deg at 1 deg: the scanner powers on at 0.5 deg
            "74",  # units and mode already mm / 00: no installation mode, no 77
            "20 24",
        ]
        emu = server.emulator
        assert (emu.baud, emu.mode, emu.variant) == (38400, Mode.CONTINUOUS, Variant(180, 100))
        assert laser.info.type == "LMS200;30106;V02.30" and laser.info.found_baud == 9600
        assert laser.info.status.variant == Variant(180, 50)
        assert laser.max_range == pytest.approx(8.182)
    assert commands(server)[-2:] == ["20 25", "20 42"]
    assert (emu.baud, emu.mode) == (9600, Mode.ON_REQUEST)
    assert not laser.is_connected


def test_scans_are_fresh_metres_counter_clockwise_from_the_right(server):
    clock = server.clock
    with laser_on(server) as laser:
        stamps = []
        for _ in range(5):
            called = clock.now()
            scan = laser.scan()
            # the sweep began after the call: one mirror turn (13.3 ms) before its timestamp
            assert scan.timestamp - 1 / 75 > called
            assert scan.timestamp < clock.now()
            check_room(scan, Variant(180, 100), 0.001)
            stamps.append(scan.timestamp)
        assert np.all(np.diff(stamps) > 0)
        assert scan.max_range == pytest.approx(8.182)
        assert not scan.ranges.flags.writeable  # the same arrays may be shared
        assert laser.protocol_errors == 0


def test_the_half_degree_variant_and_an_emulator_already_at_it(server):
    with laser_on(server, resolution=0.5) as laser:
        assert "3B B4 00 32 00" not in commands(server)  # the power-on variant: no switch
        check_room(laser.scan(), Variant(180, 50), 0.001)


def test_centimetres_go_through_installation_mode_and_77(server):
    with laser_on(server, units="cm") as laser:
        sent = commands(server)
        assert sent[5:8] == ["74", "20 00 53 49 43 4B 5F 4C 4D 53", sent[7]]
        assert sent[7].startswith("77 00 00 00 00 00 00 00 00 00 02 02")  # units byte 6: cm
        assert len(server.emulator.config.raw) == 32  # the block as long as the scanner's
        assert server.emulator.config.units == Units.CM
        check_room(laser.scan(), Variant(180, 100), 0.01)
        assert laser.max_range == pytest.approx(81.82)
    with laser_on(server) as laser:  # and back to mm: 77 only because it differs
        assert server.emulator.config.units == Units.MM
        check_room(laser.scan(), Variant(180, 100), 0.001)


def test_an_lms291s_34_byte_block_is_written_back_at_its_own_length():
    srv = serve(model="LMS291")
    try:
        with laser_on(srv, units="cm") as laser:
            [written] = [c for c in srv.emulator.commands() if c[0] == Command.WRITE_CONFIG]
            assert len(written) == 1 + 34 and written[1 + 32 :] == bytes([2, 0])
            assert laser.info.type.startswith("LMS291;") and len(laser.info.config.raw) == 34
            check_room(laser.scan(), Variant(180, 100), 0.01)
    finally:
        srv.stop()


def test_a_scanner_left_streaming_at_38400_is_found_there():
    clock = ManualClock()
    srv = serve(clock, baud=38400, mode=Mode.CONTINUOUS)
    try:
        began = clock.now()
        with laser_on(srv) as laser:
            assert laser.info.found_baud == 38400
            # 9600 was tried twice (1 s each, nothing heard at the wrong rate), then 38400
            assert clock.now() - began > 2.0
            assert commands(srv)[:2] == ["20 25", "3A"]  # no baud change: already there
            check_room(laser.scan(), Variant(180, 100), 0.001)
    finally:
        srv.stop()


def test_constructor_options_are_checked():
    for options in ({"resolution": 0.25}, {"units": "inch"}, {"baud": 57600},
                    {"measuring_mode": 0x3F}):  # fmt: skip
        with pytest.raises(InputError, match="SICK LMS2xx"):
            LMS2xx(lambda: None, **options)  # type: ignore[arg-type, return-value]


def test_use_before_connect_is_a_typed_error(server):
    with pytest.raises(NotConnectedError, match="SICK LMS2xx: read a scan"):
        laser_on(server).scan()


# -- faults ---------------------------------------------------------------------------------------


def test_naks_are_answered_by_resending_at_most_three_times(server):
    server.emulator.faults.nak_count = 3
    with laser_on(server) as laser:
        assert laser.naks == 3
        assert commands(server)[:4] == ["20 25"] * 4
        laser.scan()
    server.emulator.faults.nak_count = 4
    laser = laser_on(server)
    with pytest.raises(ProtocolError, match="answered NAK 4 times"):
        laser.connect()
    assert not laser.is_connected


def test_a_silent_scanner_is_a_timeout_naming_every_rate_tried(server):
    server.emulator.faults.silent = True
    clock = server.clock
    began = clock.now()
    with pytest.raises(DeviceTimeoutError) as caught:
        laser_on(server).connect()
    assert str(caught.value) == (
        "SICK LMS2xx: find the scanner's baud rate: no answer to 20 25 at 9600, 38400, 19200, "
        "500000 baud (nothing came back); check the scanner's power and cable and that this is "
        "its port ('twin hw probe' says what answers where)"
    )
    assert clock.now() - began == pytest.approx(4 * 2 * 1.0)  # 4 rates x 2 tries x 1 s


class Loopback:
    """A port whose cable is looped back on itself: every byte sent comes back (a wrong port
    with an echoing device on it)."""

    name = "loopback"

    def __init__(self, clock: ManualClock) -> None:
        self.clock, self.buf = clock, bytearray()

    def write(self, data: bytes) -> None:
        self.buf += data

    def read(self, size: int, timeout: float) -> bytes:
        if not self.buf:
            self.clock.sleep(timeout)
        out = bytes(self.buf[:size])
        del self.buf[:size]
        return out

    def reset_input(self) -> None:
        self.buf.clear()

    def set_baudrate(self, baudrate: int) -> None:
        pass

    def close(self) -> None:
        pass


def test_a_port_where_bytes_come_but_no_lms_telegram_is_named_as_such():
    clock = ManualClock()
    laser = LMS2xx(lambda: Loopback(clock), clock=clock, probe_rates=(9600,), probe_tries=1)
    with pytest.raises(DeviceTimeoutError, match=r"at 9600, 38400 baud \(16 bytes came, none"):
        laser.connect()  # its own 20 25 (8 bytes, addressed to a scanner) back at both rates


def test_a_stream_that_falls_silent_times_out_and_the_next_call_configures_again(server):
    clock = server.clock
    with laser_on(server) as laser:
        laser.scan()
        server.emulator.faults.silent = True
        called = clock.now()
        with pytest.raises(DeviceTimeoutError, match=r"read a scan: no scan within 0\.5 s"):
            laser.scan(timeout=0.5)
        assert clock.now() - called == pytest.approx(0.5)
        server.emulator.faults.silent = False
        check_room(laser.scan(), Variant(180, 100), 0.001)
        assert laser.reconnects == 1


def test_junk_and_broken_scans_are_skipped(server):
    faults = server.emulator.faults
    faults.junk_count = 6  # before the start-up replies and the first scans
    with laser_on(server) as laser:
        faults.corrupt_scans = 3
        faults.junk_count = 3
        for _ in range(8):
            check_room(laser.scan(), Variant(180, 100), 0.001)
        assert laser.protocol_errors >= 3
        assert str(laser.last_protocol_error).startswith("SICK LMS2xx: read a telegram: ")


def test_a_scanner_reporting_an_error_in_its_status_byte_is_a_fault(server):
    with laser_on(server) as laser:
        server.emulator.faults.scan_status = 0x13
        with pytest.raises(DeviceFaultError, match=r"an error \(status byte 13\)"):
            laser.scan()
        server.emulator.faults.scan_status = 0x90  # pollution: reported, the ranges still come
        check_room(laser.scan(), Variant(180, 100), 0.001)
        assert laser.last_status == 0x90


def test_a_request_the_scanner_does_not_know_is_a_protocol_error(server, monkeypatch):
    monkeypatch.setitem(
        emulated._HANDLERS, Command.VARIANT, lambda emu, data, now: emu._incorrect(now)
    )
    with pytest.raises(ProtocolError, match=r"switch the variant .* answered 92"):
        laser_on(server).connect()
    assert server.emulator.mode == Mode.ON_REQUEST  # not left streaming


def test_a_power_cycled_scanner_is_configured_again(server):
    clock = server.clock
    with laser_on(server) as laser:
        laser.scan()
        before = len(commands(server))
        server.emulator.power_cycle(clock.now())  # back at 9600, mode 25: the stream stops
        with pytest.raises(DeviceTimeoutError):
            laser.scan(timeout=0.5)
        check_room(laser.scan(), Variant(180, 100), 0.001)
        assert laser.reconnects == 1 and laser.info.found_baud == 9600
        # the variant survived in the scanner's EEPROM (the emulator's choice): no 3B again
        assert commands(server)[before:] == ["20 25", "20 40", "3A", "31", "74", "20 24"]


def test_a_refused_mode_change_names_the_scanners_answer(server, monkeypatch):
    mode_change = emulated._HANDLERS[Command.MODE]

    def other_password(emu, data, now):  # a scanner whose password was changed
        if data[:1] == bytes([Mode.INSTALLATION]):
            emu._reply(now, bytes([0xA0, 0x01]))
        else:
            mode_change(emu, data, now)

    monkeypatch.setitem(emulated._HANDLERS, Command.MODE, other_password)
    with pytest.raises(DeviceFaultError) as caught:
        laser_on(server, units="cm").connect()
    assert str(caught.value) == (
        "SICK LMS2xx: enter installation mode: the scanner answered A0 01 (refused: wrong "
        "password); check the password (SICK_LMS)"
    )


def test_a_restart_announced_by_90_is_configured_again_without_waiting_for_a_timeout(server):
    clock = server.clock
    with laser_on(server, baud=9600) as laser:  # at 9600 the host hears the 90 telegram
        laser.scan()
        server.emulator.power_cycle(clock.now())
        clock.sleep(0.5)  # the 90 comes 0.2 s after power-up
        # without the 90 the stream's end would only show as this call's time-out
        check_room(laser.scan(timeout=0.6), Variant(180, 100), 0.001)
        assert laser.reconnects == 1
        assert commands(server)[-1] == "20 24"


def test_a_lost_line_is_reopened_and_the_scanner_found_where_it_was(server):
    with laser_on(server) as laser:
        laser.scan()
        server.hangup()  # the cable pulled and put back: the scanner streams on at 38400
        check_room(laser.scan(), Variant(180, 100), 0.001)
        assert laser.reconnects == 1 and laser.info.found_baud == 38400


def test_a_lost_line_without_auto_reconnect_is_connection_lost(server):
    with laser_on(server, auto_reconnect=False) as laser:
        laser.scan()
        server.hangup()
        with pytest.raises(ConnectionLostError, match="lms2xx line was hung up"):
            laser.scan()
        with pytest.raises(ConnectionLostError):
            laser.scan()


def test_identify_reads_type_and_status_and_changes_nothing(server):
    text = laser_on(server).identify()
    assert text == (
        "SICK LMS200;30106;V02.30 at 9600 baud (values on request 25, 180 deg at 0.5 deg "
        "(361 values), mm)"
    )
    assert commands(server) == ["3A", "31"]
    srv = serve(baud=38400, mode=Mode.CONTINUOUS)
    try:
        assert "at 38400 baud (continuous output 24" in laser_on(srv).identify()
    finally:
        srv.stop()


# -- the serial twins' laser ----------------------------------------------------------------------


def test_the_serial_twins_offer_the_laser_on_its_own_memory_line():
    from twin.core.geometry import Pose2D
    from twin.serial_twins.session import SerialTwins
    from twin.sim import make_sim_robot
    from twin.sim.laser import LaserSpec, SimLaser

    clock = ManualClock()
    sim, _ = make_sim_robot("living_room", start=Pose2D(2.5, 3.3, 0.0))
    # the MuJoCo laser without noise, so the emulator's bytes can be compared with it exactly
    exact = LaserSpec(range_sigma=0.0, systematic=0.0, dropout=0.0, resolution=0.0)
    source = SimLaser(sim, exact).ranges_at
    with SerialTwins(sim, clock=clock, lines="memory", laser_source=source) as twins:
        link = twins.lms2xx_link
        assert isinstance(link, BaudMemoryLink)
        laser = LMS2xx(lambda: link.transport("SICK LMS2xx"), clock=clock)
        with laser:
            scan = laser.scan()
            np.testing.assert_allclose(scan.ranges, np.round(source(scan.angles), 3), atol=1e-9)
            assert np.isfinite(scan.ranges).sum() > 100  # a living room has walls within 8 m
            twins.hangup("lms2xx")
            laser.scan()
            assert laser.reconnects == 1
    with SerialTwins(sim, clock=ManualClock(), lines="memory") as twins:
        assert twins.lms2xx_link is None and twins.lms2xx_path is None


# -- end to end over a pseudo-terminal, in real time -----------------------------------------------


@pytest.fixture
def pty_server(tmp_path: Path) -> Iterator[LineServer]:
    def left_half_open(angles: np.ndarray) -> np.ndarray:
        return np.where(angles > math.radians(45), np.nan, ROOM(angles))

    srv = serve_lms2xx(left_half_open, PtyLink(tmp_path / "lms2xx"))
    yield srv
    srv.stop()


def test_over_a_pty_the_rate_is_negotiated_and_scans_stream(pty_server):
    with LMS2xx.open(pty_server.path) as laser:
        assert pty_server.emulator.baud == 38400  # followed the port's termios setting
        for _ in range(3):
            scan = laser.scan()
        assert len(scan.ranges) == 181 and np.isnan(scan.ranges[136:]).all()
        np.testing.assert_allclose(scan.ranges[:135], ROOM(scan.angles[:135]), atol=0.0005)
    assert pty_server.emulator.baud == 9600


def test_over_a_pty_a_hangup_is_recovered(pty_server):
    with LMS2xx.open(pty_server.path) as laser:
        laser.scan()
        pty_server.hangup()  # a new pty behind the same path
        laser.scan()
        assert laser.reconnects == 1


def test_cli_status_and_scan_json(pty_server, capsys):
    from twin.cli import main

    path = pty_server.path
    assert main(["hw", "lms", "--port", path, "status"]) == 0
    out = capsys.readouterr().out
    assert "type: LMS200;30106;V02.30" in out
    assert "variant: 180 deg at 1 deg (181 values)" in out
    assert "units: mm" in out and "baud: 38400" in out and "mode: continuous output (20 24)" in out
    assert main(["hw", "lms", "--port", path, "--resolution", "0.5", "scan", "--json"]) == 0
    data = json.loads(capsys.readouterr().out)
    assert sorted(data) == ["angles_deg", "ranges_m"]
    assert len(data["angles_deg"]) == len(data["ranges_m"]) == 361
    assert data["angles_deg"][0] == -90 and data["angles_deg"][-1] == 90
    assert data["ranges_m"][0] == pytest.approx(2.0) and data["ranges_m"][-1] is None
    assert data["angles_deg"][180] == 0 and data["ranges_m"][180] == pytest.approx(2.0)
    assert main(["hw", "lms", "--port", path, "scan"]) == 0
    assert "181 beams" in capsys.readouterr().out
    assert main(["hw", "lms", "--port", path + ".missing", "status"]) == 2
    assert "SICK LMS2xx: open " in capsys.readouterr().err


def test_serve_hardware_offers_the_laser_and_probe_finds_it(tmp_path, capsys):
    import subprocess
    import sys

    from twin.cli import main

    links = tmp_path / "links"
    argv = ["serve-hardware", "--laser", "--seconds", "60", "--link-dir", str(links)]
    server = subprocess.Popen(
        [sys.executable, "-m", "twin.cli", *argv], stdout=subprocess.PIPE, text=True
    )
    try:
        printed = "".join(server.stdout.readline() for _ in range(4))
        assert f"SICK LMS200: {links / 'lms2xx'} -> /dev/pts/" in printed and "serving" in printed
        assert main(["hw", "probe", "--port", str(links / "lms2xx")]) == 0
        assert (
            f"{links / 'lms2xx'}: SICK LMS200;30106;V02.30 at 9600 baud (values on request 25"
            in capsys.readouterr().out
        )
        assert main(["hw", "lms", "--port", str(links / "lms2xx"), "scan", "--json"]) == 0
        ranges = np.array(json.loads(capsys.readouterr().out)["ranges_m"], dtype=float)
        hits = ranges[np.isfinite(ranges)]
        assert len(ranges) == 181 and len(hits) > 100  # the living room's walls and furniture
        assert hits.min() > 0.1 and hits.max() <= 8.182
    finally:
        server.terminate()
        server.wait(timeout=10)
