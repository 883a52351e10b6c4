"""The emulated SICK LMS200 (shared/specs/sick-lms2xx.md section 11), stepped by hand in virtual
time: replies and their ACK/NAK, installation mode and its password, the variants, the ``77``
rules, the baud switch at the old rate, ``92`` for what it does not know, the streams and the
line's own pace. No threads here; the driver against the emulator is tests/test_lms2xx.py."""

from __future__ import annotations

import numpy as np
import pytest

from hardware import lms2xx_codec as codec
from hardware.lms2xx_codec import Mode, Reply, Signal, Telegram, TelegramParser, Units, Variant
from twin.serial_twins.lms2xx import (
    LMS2xxEmulator,
    square_room,
)


class Bench:
    """An emulator in virtual time, ticked every millisecond, its output parsed as a host
    whose port is at ``host`` baud would."""

    def __init__(self, source=None, **options: object) -> None:
        self.host = 9600
        self.emu = LMS2xxEmulator(source or square_room(), line_speed=lambda: self.host, **options)  # type: ignore[arg-type]
        self.now = 0.0
        self.parser = TelegramParser()
        self.arrivals: list[tuple[float, bytes]] = []  # (time, bytes) as they left the line

    def run(self, seconds: float, step: float = 0.001) -> None:
        for _ in range(round(seconds / step)):
            self.now = round(self.now + step, 9)
            self.emu.tick(self.now)
            out = self.emu.transmit(self.now)
            if out:
                self.arrivals.append((self.now, out))

    def ask(self, frame: bytes, wait: float = 0.25) -> list:
        self.emu.receive(frame, self.now)
        self.run(wait)
        return self.take()

    def take(self) -> list:
        self.parser.feed(b"".join(data for _, data in self.arrivals))
        self.arrivals.clear()
        items = []
        while (item := self.parser.next()) is not None:
            items.append(item)
        return items


def replies(items: list) -> list[Telegram]:
    return [i for i in items if isinstance(i, Telegram)]


def one(items: list, code: int) -> Telegram:
    """The ACK first, then exactly one telegram, with ``code``."""
    assert items[0] is Signal.ACK
    [telegram] = replies(items)
    assert telegram.command == code and telegram.status == 0x10
    return telegram


def status_of(bench: Bench) -> codec.Status:
    return codec.decode_status(one(bench.ask(codec.status_request()), Reply.STATUS))


# -- power-on, replies, ACK / NAK -----------------------------------------------------------------


@pytest.mark.parametrize(("model", "block"), [("LMS200", 32), ("LMS291", 34)])
def test_power_on_state(model, block):
    bench = Bench(model=model)
    status = status_of(bench)
    assert (status.operating_mode, status.baud, status.units, status.measuring_mode) == (
        0x25,
        9600,
        1,
        0,
    )
    assert status.variant == Variant(180, 50)
    kind = codec.decode_type(one(bench.ask(codec.type_request()), Reply.TYPE))
    assert kind.startswith(model + ";")
    config = codec.decode_config(one(bench.ask(codec.read_config_request()), Reply.CONFIG))
    assert len(config.raw) == block and config.units == Units.MM
    assert codec.decode_errors(one(bench.ask(codec.errors_request()), Reply.ERRORS)) == []
    assert codec.decode_counters(one(bench.ask(codec.counters_request()), Reply.COUNTERS)) == (
        200,
        10,
    )


def test_the_ack_goes_at_once_and_the_reply_10_ms_later_each_byte_taking_its_line_time():
    bench = Bench()
    bench.emu.receive(codec.type_request(), 0.0)
    bench.run(0.1)
    (t_ack, ack), (t_first, first), *rest = bench.arrivals
    byte = 10 / 9600  # 1.04 ms
    assert ack == b"\x06" and t_ack == pytest.approx(byte, abs=0.001)
    assert t_first == pytest.approx(0.010 + byte, abs=0.001)
    assert rest[-1][0] == pytest.approx(0.010 + 29 * byte, abs=0.001)
    whole = first + b"".join(data for _, data in rest)
    assert whole == codec.reply(codec.encode_type("LMS200;30106;V02.30"))


def test_a_bad_crc_is_nakked_and_discarded_junk_and_foreign_addresses_ignored():
    bench = Bench()
    bad = bytearray(codec.status_request())
    bad[-2] ^= 0x01
    assert bench.ask(bytes(bad)) == [Signal.NAK]
    assert bench.emu.records.bad_telegrams == 1 and bench.emu.telegrams == []
    foreign = bytes([2, 0x05]) + codec.type_request()[2:]
    items = bench.ask(b"\x00\xffjunk\x06" + foreign + codec.type_request())
    one(items, Reply.TYPE)  # the foreign-address copy was junk: one ACK, one reply


def test_a_request_that_stops_arriving_is_dropped_after_100_ms():
    bench = Bench()
    bench.emu.receive(codec.status_request()[:4], 0.0)
    bench.run(0.15)
    assert bench.take() == [] and bench.emu.records.bad_telegrams == 1
    one(bench.ask(codec.type_request()), Reply.TYPE)


@pytest.mark.parametrize(
    "frame",
    [
        codec.request(bytes([0x3E])),  # a code this emulator does not know
        codec.mode_request(0x10),  # diagnostic mode: not offered
        codec.request(bytes([0x20])),  # a mode change without its mode
        codec.scan_request(8),  # an interlaced single scan: not offered
        codec.request(bytes([0x3B, 0xB4, 0x00])),  # a short variant
        codec.mode_request(Mode.SUBRANGE, b"\x01\x00"),  # a short subrange
    ],
)
def test_what_the_emulator_does_not_offer_is_acked_and_refused_with_92(frame):
    one(Bench().ask(frame), Reply.INCORRECT)


# -- installation mode, 77 ------------------------------------------------------------------------


def test_installation_mode_needs_the_password():
    bench = Bench()
    for password in (b"SICK_PLS", b"SICK_"):
        reply = one(bench.ask(codec.installation_mode_request(password)), Reply.MODE)
        assert codec.decode_mode_reply(reply) == 1
        assert bench.emu.mode == Mode.ON_REQUEST
    reply = one(bench.ask(codec.installation_mode_request()), Reply.MODE)
    assert codec.decode_mode_reply(reply) == 0 and bench.emu.mode == Mode.INSTALLATION


def test_77_only_in_installation_mode_and_only_valid_blocks():
    bench = Bench()
    block = codec.default_config(32)
    cm = block.with_settings(units=Units.CM)
    one(bench.ask(codec.write_config_request(cm.raw)), Reply.INCORRECT)  # not installation mode
    assert bench.emu.config == block
    bench.ask(codec.installation_mode_request())
    written = one(bench.ask(codec.write_config_request(cm.raw)), Reply.CONFIG_WRITTEN)
    assert codec.decode_config_written(written) == (True, cm) and bench.emu.config == cm
    for bad in (block.with_settings(units=5), block.with_settings(measuring_mode=0x07)):
        refused = one(bench.ask(codec.write_config_request(bad.raw)), Reply.CONFIG_WRITTEN)
        assert codec.decode_config_written(refused) == (False, cm)
    assert status_of(bench).units == 0


def test_77_with_a_short_block_changes_its_bytes_and_a_long_one_is_cut_to_the_models():
    bench = Bench()
    bench.ask(codec.installation_mode_request())
    short = bytes([0, 0, 0, 0, 0, 0x05, 0x00])  # Player's 7 bytes: mode 05, cm
    ok, block = codec.decode_config_written(
        one(bench.ask(codec.write_config_request(short)), Reply.CONFIG_WRITTEN)
    )
    assert ok and block.raw[:7] == short and block.raw[7:] == codec.default_config(32).raw[7:]
    longer = codec.default_config(34).raw  # [TBX] writes 34 bytes to any model
    ok, block = codec.decode_config_written(
        one(bench.ask(codec.write_config_request(longer)), Reply.CONFIG_WRITTEN)
    )
    assert ok and block.raw == longer[:32]


# -- variants -------------------------------------------------------------------------------------


def test_variants_switch_or_are_refused_keeping_the_old_one():
    bench = Bench()
    reply = one(bench.ask(codec.variant_request(Variant(180, 100))), Reply.VARIANT)
    assert codec.decode_variant_reply(reply) == (True, Variant(180, 100))
    reply = one(bench.ask(codec.variant_request(Variant(180, 25))), Reply.VARIANT)
    assert codec.decode_variant_reply(reply) == (False, Variant(180, 100))
    assert status_of(bench).variant == Variant(180, 100)


def test_a_variant_change_while_streaming_stops_the_stream():
    bench = Bench()
    bench.ask(codec.stream_request(True), wait=0.01)
    assert bench.emu.mode == Mode.CONTINUOUS
    bench.ask(codec.variant_request(Variant(180, 100)), wait=1.0)
    assert bench.emu.mode == Mode.ON_REQUEST
    bench.run(1.0)
    assert [t for t in replies(bench.take()) if t.command == Reply.SCAN] == []


# -- baud rates -----------------------------------------------------------------------------------


def test_a_baud_change_is_answered_at_the_old_rate_then_only_the_new_rate_is_heard():
    bench = Bench()
    reply = one(bench.ask(codec.baud_request(38400)), Reply.MODE)
    assert codec.decode_mode_reply(reply) == 0 and bench.emu.baud == 38400
    assert bench.ask(codec.type_request()) == []  # the host's port is still at 9600: noise
    bench.host = 38400
    assert status_of(bench).baud == 38400
    one(bench.ask(codec.baud_request(9600)), Reply.MODE)
    bench.host = 9600
    assert status_of(bench).baud == 9600


def test_without_enforce_baud_every_rate_is_heard():
    bench = Bench(enforce_baud=False, baud=38400)
    one(bench.ask(codec.type_request()), Reply.TYPE)


# -- scans ----------------------------------------------------------------------------------------


def scans(items: list) -> list[Telegram]:
    return [t for t in replies(items) if t.command in (Reply.SCAN, Reply.SUBRANGE_SCAN)]


def test_the_stream_sends_the_square_room_byte_for_byte_at_10_hz():
    bench = Bench()
    bench.ask(codec.variant_request(Variant(180, 100)))
    bench.ask(codec.baud_request(38400))
    bench.host = 38400
    got = scans(bench.ask(codec.stream_request(True), wait=2.05))
    words = codec.words_from_ranges(square_room()(Variant(180, 100).angles_rad()), Units.MM, 0)
    golden = codec.reply(codec.encode_scan(words, Units.MM))
    assert len(golden) == 372 and golden.endswith(bytes.fromhex("10 2B 2F"))
    assert len(got) == 19 and all(t.to_bytes() == golden for t in got)
    assert bench.emu.scans_dropped == 0 and bench.emu.scans_sent == 19  # the 20th on the line


def test_scans_that_do_not_fit_the_line_are_dropped_whole():
    bench = Bench()  # 361 values at 9600 baud: 0.76 s on the line, emitted every 0.1 s
    got = scans(bench.ask(codec.stream_request(True), wait=4.0))
    assert 4 <= len(got) <= 6 and all(t.data[:2] == bytes.fromhex("6941") for t in got)
    assert bench.emu.scans_dropped >= 30


def test_units_measuring_mode_and_real_time_indices_follow_the_configuration():
    bench = Bench()
    bench.ask(codec.installation_mode_request())
    block = codec.default_config(32).with_settings(
        units=Units.CM, measuring_mode=0x05, availability=0x02
    )
    bench.ask(codec.write_config_request(block.raw))
    bench.ask(codec.baud_request(500000))
    bench.host = 500000
    got = [codec.decode_scan(t) for t in scans(bench.ask(codec.stream_request(True), wait=0.55))]
    assert [s.rti for s in got] == list(range(len(got))) and len(got) >= 4
    first = got[0]
    assert first.units == Units.CM and first.count == 361
    np.testing.assert_allclose(first.ranges(0x05)[[0, 90, 180]], [2.0, 2.83, 2.0])


def test_partial_scans_interleave_k_0_and_2_and_the_subrange_sends_b7():
    bench = Bench(enforce_baud=False, baud=500000)
    got = [codec.decode_scan(t) for t in scans(bench.ask(codec.partial_stream_request(), 0.45))]
    assert [(s.partial, s.index, s.count) for s in got[:4]] == [
        (True, 0, 181),
        (True, 2, 180),
        (True, 0, 181),
        (True, 2, 180),
    ]
    bench.ask(codec.stream_request(False))
    bench.take()
    items = bench.ask(codec.subrange_request(179, 183), wait=0.2)
    assert codec.decode_mode_reply(replies(items)[0]) == 0
    first, last, data = codec.decode_subrange_scan(scans(items)[0])
    assert (first, last, data.count) == (179, 183, 5)
    np.testing.assert_allclose(data.ranges(0), 2.0, atol=0.002)  # around 0 deg: the front wall
    refused = [t for t in replies(bench.ask(codec.subrange_request(300, 400))) if t.command == 0xA0]
    assert [codec.decode_mode_reply(t) for t in refused] == [2]


def test_a_single_scan_on_request_and_no_return_as_1ff7():
    def half_open(angles: np.ndarray) -> np.ndarray:
        return np.where(angles > 0, np.nan, 3.0)  # nothing to the left

    bench = Bench(half_open)
    data = codec.decode_scan(one(bench.ask(codec.scan_request(), wait=1.0), Reply.SCAN))
    assert data.count == 361 and data.words[0] == 3000 and data.words[-1] == 0x1FF7
    assert np.isnan(data.ranges(0)[181:]).all()


def test_reset_confirms_returns_to_9600_and_announces_itself():
    bench = Bench(baud=38400, mode=Mode.CONTINUOUS)
    bench.host = 38400
    bench.run(0.3)
    bench.take()
    items = bench.ask(codec.reset_request(), wait=0.2)
    confirmations = [t for t in replies(items) if t.command == Reply.RESET_CONFIRM]
    assert len(confirmations) == 1
    codec.decode_reset_confirmation(confirmations[0])
    assert bench.emu.baud == 9600 and bench.emu.mode == Mode.ON_REQUEST
    bench.host = 9600
    bench.run(0.3)
    [ready] = replies(bench.take())
    assert ready.command == Reply.POWER_ON and len(codec.decode_power_on(ready)) == 21
