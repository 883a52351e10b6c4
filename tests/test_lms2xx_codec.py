"""The SICK LMS2xx codec against every worked example of shared/specs/sick-lms2xx.md section 10,
built and parsed, and the incremental parser fuzzed: whatever bytes arrive, nothing but the
codec's own errors escapes, and good telegrams inside junk are still found."""

from __future__ import annotations

import contextlib
import itertools
import math

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from hardware import lms2xx_codec as codec
from hardware.lms2xx_codec import (
    ConfigBlock,
    LmsCodecError,
    ReplyError,
    Signal,
    Telegram,
    TelegramError,
    TelegramParser,
    Units,
    Variant,
)


def h(text: str) -> bytes:
    return bytes.fromhex(text)


ZEROS21 = "00 " * 21
BLOCK_MM = "00 00 00 00 00 00 01 00 00 02 02 " + ZEROS21  # 32 bytes, mode 00, mm

# -- host -> scanner: every request of section 10 ------------------------------------------------

REQUESTS = {
    "reset": (codec.reset_request(), "02 00 01 00 10 34 12"),
    "installation mode": (
        codec.installation_mode_request(),
        "02 00 0A 00 20 00 53 49 43 4B 5F 4C 4D 53 BE C5",
    ),
    "continuous on": (codec.stream_request(True), "02 00 02 00 20 24 34 08"),
    "values on request": (codec.stream_request(False), "02 00 02 00 20 25 35 08"),
    "partial stream": (codec.partial_stream_request(), "02 00 02 00 20 2A 3A 08"),
    "9600 baud": (codec.baud_request(9600), "02 00 02 00 20 42 52 08"),
    "19200 baud": (codec.baud_request(19200), "02 00 02 00 20 41 51 08"),
    "38400 baud": (codec.baud_request(38400), "02 00 02 00 20 40 50 08"),
    "500000 baud": (codec.baud_request(500000), "02 00 02 00 20 48 58 08"),
    "subrange 1..181": (codec.subrange_request(1, 181), "02 00 06 00 20 27 01 00 B5 00 12 09"),
    "single scan": (codec.scan_request(), "02 00 02 00 30 01 31 18"),
    "status": (codec.status_request(), "02 00 01 00 31 15 12"),
    "errors": (codec.errors_request(), "02 00 01 00 32 16 12"),
    "counters": (codec.counters_request(), "02 00 01 00 35 11 12"),
    "type": (codec.type_request(), "02 00 01 00 3A 1E 12"),
    "variant 180/1": (codec.variant_request(Variant(180, 100)), "02 00 05 00 3B B4 00 64 00 97 49"),
    "variant 180/0.5": (
        codec.variant_request(Variant(180, 50)),
        "02 00 05 00 3B B4 00 32 00 3B 1F",
    ),
    "variant 100/0.25": (
        codec.variant_request(Variant(100, 25)),
        "02 00 05 00 3B 64 00 19 00 E7 72",
    ),
    "read configuration": (codec.read_config_request(), "02 00 01 00 74 50 12"),
    "write 32 bytes mm": (
        codec.write_config_request(codec.default_config(32).raw),
        "02 00 21 00 77 " + BLOCK_MM + "FC 7E",
    ),
    "write 34 bytes mm": (
        codec.write_config_request(codec.default_config(34).raw),
        "02 00 23 00 77 " + BLOCK_MM + "02 00 74 BB",
    ),
    "write 34 bytes cm": (
        codec.write_config_request(codec.default_config(34).with_settings(units=Units.CM).raw),
        "02 00 23 00 77 00 00 00 00 00 00 00 00 00 02 02 " + ZEROS21 + "02 00 24 8B",
    ),
    "REVERE centimetre block": (
        codec.write_config_request(h("00 00 00 00 00 0D 00 00 00 02 02 " + ZEROS21)),
        "02 00 21 00 77 00 00 00 00 00 0D 00 00 00 02 02 " + ZEROS21 + "20 CB",
    ),
}


@pytest.mark.parametrize("name", sorted(REQUESTS))
def test_requests_are_built_byte_for_byte_and_parsed_back_by_the_scanner_side(name):
    built, golden = REQUESTS[name]
    assert built == h(golden)
    parser = TelegramParser(codec.LMS_ADDRESS, signals=False)
    parser.feed(built)
    telegram = parser.next()
    assert isinstance(telegram, Telegram)
    assert telegram.address == 0 and telegram.status is None
    assert telegram.payload == built[4:-2] and telegram.to_bytes() == built
    assert parser.next() is None and parser.junk == 0


def test_the_crc_trace_of_section_3():
    data = h("02 00 01 00 31")
    trace = [codec.crc16(data[: i + 1]) for i in range(len(data))]
    assert trace == [0x0002, 0x0204, 0x0409, 0x0912, 0x1215]


def test_bad_requests_are_refused():
    with pytest.raises(LmsCodecError, match="not an LMS2xx rate"):
        codec.baud_request(57600)
    with pytest.raises(LmsCodecError):
        codec.frame(0, b"")
    with pytest.raises(LmsCodecError):
        codec.frame(0, bytes(codec.MAX_LEN + 1))
    with pytest.raises(LmsCodecError):
        codec.default_config(33)


# -- scanner -> host: every reply of section 10 ---------------------------------------------------


def parse_all(data: bytes) -> list:
    parser = TelegramParser()
    parser.feed(data)
    out = []
    while (item := parser.next()) is not None:
        out.append(item)
    return out


def one_reply(data: bytes) -> Telegram:
    [telegram] = parse_all(data)
    assert isinstance(telegram, Telegram) and telegram.to_bytes() == data
    return telegram


def test_ack_nak_and_a_mode_change_reply():
    assert parse_all(h("06")) == [Signal.ACK] and parse_all(h("15")) == [Signal.NAK]
    golden = h("06 02 80 03 00 A0 00 10 16 0A")
    assert bytes([codec.ACK]) + codec.reply(bytes([0xA0, 0x00])) == golden
    ack, telegram = parse_all(golden)
    assert ack is Signal.ACK
    assert codec.decode_mode_reply(telegram) == 0 and telegram.status == 0x10


@pytest.mark.parametrize(
    ("result", "golden"),
    [(1, "02 80 03 00 A0 01 10 14 0B"), (2, "02 80 03 00 A0 02 10 12 08")],
)
def test_refused_mode_changes(result, golden):
    assert codec.reply(bytes([0xA0, result])) == h(golden)
    assert codec.decode_mode_reply(one_reply(h(golden))) == result


@pytest.mark.parametrize(
    ("ok", "variant", "golden"),
    [
        (True, Variant(180, 100), "02 80 07 00 BB 01 B4 00 64 00 10 5B 30"),
        (True, Variant(180, 50), "02 80 07 00 BB 01 B4 00 32 00 10 03 9D"),
        (False, Variant(180, 100), "02 80 07 00 BB 00 B4 00 64 00 10 7B 20"),
    ],
)
def test_variant_replies(ok, variant, golden):
    body = bytes([0xBB, int(ok)]) + codec.variant_request(variant)[5:-2]
    assert codec.reply(body) == h(golden)
    assert codec.decode_variant_reply(one_reply(h(golden))) == (ok, variant)


def test_errors_counters_incorrect_command_and_reset_confirmation():
    assert codec.reply(bytes([0xB2])) == h("02 80 02 00 B2 10 3F 13")
    assert codec.decode_errors(one_reply(h("02 80 02 00 B2 10 3F 13"))) == []
    counters = h("02 80 06 00 B5 64 00 0A 00 10 62 72")
    assert codec.reply(h("B5 64 00 0A 00")) == counters
    assert codec.decode_counters(one_reply(counters)) == (200, 10)
    assert codec.reply(bytes([0x92])) == h("02 80 02 00 92 10 7F 33")
    codec.decode_incorrect_command(one_reply(h("02 80 02 00 92 10 7F 33")))
    assert codec.reply(bytes([0x91])) == h("02 80 02 00 91 10 79 30")
    codec.decode_reset_confirmation(one_reply(h("02 80 02 00 91 10 79 30")))
    with pytest.raises(ReplyError, match="expected a 92"):
        codec.decode_incorrect_command(one_reply(h("02 80 02 00 91 10 79 30")))
    with pytest.raises(ReplyError, match="0 data bytes"):
        codec.decode_reset_confirmation(one_reply(codec.reply(bytes([0x91, 0x00]))))


def test_the_type_string():
    golden = h(
        "02 80 17 00 BA 4C 4D 53 32 30 30 3B 33 30 31 30 36 3B 56 30 32 2E 33 30 20 00 10 2D C1"
    )
    assert codec.reply(codec.encode_type("LMS200;30106;V02.30")) == golden
    assert codec.decode_type(one_reply(golden)) == "LMS200;30106;V02.30"


def test_configuration_read_and_written():
    read = h("02 80 22 00 F4 " + BLOCK_MM + "10 AC 85")
    assert codec.reply(bytes([0xF4]) + codec.default_config(32).raw) == read
    block = codec.decode_config(one_reply(read))
    assert len(block.raw) == 32 and block.units == Units.MM and block.measuring_mode == 0
    written = h("02 80 23 00 F7 01 " + BLOCK_MM + "10 9C 61")
    assert codec.reply(bytes([0xF7, 0x01]) + block.raw) == written
    assert codec.decode_config_written(one_reply(written)) == (True, block)


SMALL_SCANS = {
    "mm": ("02 80 0E 00 B0 05 40 E8 03 D0 07 C4 09 F7 1F 0A 00 10 40 A5", Units.MM, None),
    "cm": ("02 80 0E 00 B0 05 00 64 00 C8 00 FA 00 F7 1F 01 00 10 2A 00", Units.CM, None),
    "rti": ("02 80 0F 00 B0 05 40 E8 03 D0 07 C4 09 F7 1F 0A 00 2A 10 E7 E3", Units.MM, 0x2A),
}


@pytest.mark.parametrize("name", sorted(SMALL_SCANS))
def test_the_small_b0_in_mm_cm_and_with_a_real_time_index(name):
    golden, units, rti = SMALL_SCANS[name]
    ranges = np.array([1.0, 2.0, 2.5, np.nan, 0.01])
    words = codec.words_from_ranges(ranges, units, 0x00)
    assert codec.reply(codec.encode_scan(words, units, rti=rti)) == h(golden)
    scan = codec.decode_scan(one_reply(h(golden)))
    assert (scan.count, scan.units, scan.partial, scan.index, scan.rti) == (5, units, False, 0, rti)
    assert scan.status == 0x10
    np.testing.assert_allclose(scan.ranges(0x00), ranges, equal_nan=True)


def square_room(angles: np.ndarray) -> np.ndarray:
    """Section 10's room: 4 m square, the scanner in its centre."""
    return 2.0 / np.maximum(np.abs(np.cos(angles)), np.abs(np.sin(angles)))


@pytest.mark.parametrize(
    ("variant", "head", "tail", "size"),
    [
        (Variant(180, 100), "02 80 6E 01 B0 B5 40 D0 07 D0 07 D1 07", "D0 07 D0 07 10 2B 2F", 372),
        (Variant(180, 50), "02 80 D6 02 B0 69 41 D0 07 D0 07 D0 07", "D0 07 D0 07 10 2A 65", 732),
    ],
)
def test_full_scans_of_the_square_room(variant, head, tail, size):
    words = codec.words_from_ranges(square_room(variant.angles_rad()), Units.MM, 0x00)
    built = codec.reply(codec.encode_scan(words, Units.MM))
    assert len(built) == size and built.startswith(h(head)) and built.endswith(h(tail))
    scan = codec.decode_scan(one_reply(built))
    ranges = scan.ranges(0x00)
    assert scan.count == variant.count
    assert ranges[[0, variant.count // 2, -1]] == pytest.approx([2.0, 2.0, 2.0])
    quarter = variant.count // 4
    assert ranges[[quarter, -1 - quarter]] == pytest.approx([2.828, 2.828])


def test_count_word_bit_10_is_sent_zero_and_ignored_when_read():
    """No source uses bit 10 (the spec marks it): 0 out, and the count is bits 0-9 only, never
    [PLAYER]'s 14-bit or [MRPT]'s 9-bit mask."""
    assert codec.count_word(721, Units.MM) == 0x42D1 and not codec.count_word(721, 1) & 0x400
    scan = codec.decode_scan(one_reply(codec.reply(h("B0 02 44 E8 03 D0 07"))))
    assert scan.count == 2 and scan.units == Units.MM and not scan.partial


def test_a_34_byte_configuration_block_is_read_as_long_as_len_says():
    block = codec.default_config(34)
    read = codec.decode_config(one_reply(codec.reply(bytes([0xF4]) + block.raw)))
    assert read == block and len(read.raw) == 34 and read.raw[32:] == h("02 00")


def test_partial_scan_count_words_of_mode_2a():
    assert codec.count_word(181, Units.MM, partial=True, index=0) == 0x60B5
    assert codec.count_word(180, Units.MM, partial=True, index=2) == 0x70B4
    body = codec.encode_scan([1000] * 180, Units.MM, partial=True, index=2)
    assert body[1:3] == h("B4 70")
    scan = codec.decode_scan(one_reply(codec.reply(body)))
    assert (scan.count, scan.partial, scan.index, scan.units) == (180, True, 2, Units.MM)


# -- value words: widths, flags, special codes -----------------------------------------------------


@pytest.mark.parametrize(
    ("mode", "bits", "no_echo", "top_mm"),
    [
        (0x00, 13, 0x1FF7, 8182),
        (0x03, 14, 0x3FF7, 16374),
        (0x05, 15, 0x7FF7, 32758),
        (0x0F, 16, 0xFFF7, 65526),
    ],
)
def test_measuring_modes_set_the_range_width_and_its_special_codes(mode, bits, no_echo, top_mm):
    assert codec.range_bits(mode) == bits
    assert codec.special_code(mode, codec.NO_ECHO_OFFSET) == no_echo
    assert codec.max_range(Units.MM, mode) == pytest.approx(top_mm / 1000)
    flags = (0xFFFF << bits) & 0xFFFF  # every flag bit set: they must not leak into the range
    words = np.array([1234 | flags, no_echo, no_echo + 8, top_mm, top_mm + 3], dtype=np.uint16)
    ranges = codec.ranges_from_words(words, Units.MM, mode)
    assert ranges[0] == pytest.approx(1.234) and ranges[3] == pytest.approx(top_mm / 1000)
    assert np.isnan(ranges[[1, 2, 4]]).all()


def test_mode_01_reflector_bits_are_split_off_and_mode_5_is_15_bits():
    values, flags = codec.split_words(np.array([0xE3E8, 0x03E8]), 0x01)
    assert list(values) == [1000, 1000] and list(flags) == [7, 0]
    # mode 05 keeps 15 bits ([TBX], ARIA); [RL]'s 14 would read 0x63E8 as 9192 mm
    assert codec.ranges_from_words(np.array([0x63E8]), Units.MM, 0x05)[0] == pytest.approx(25.576)


def test_units_codes_and_unknown_modes():
    assert [Units(u).metres for u in (0, 1, 2)] == [0.01, 0.001, 0.1]
    scan = codec.decode_scan(one_reply(codec.reply(h("B0 02 80 0A 00 F7 1F"))))
    assert scan.units == Units.TEN_CM
    np.testing.assert_allclose(scan.ranges(0), [1.0, np.nan])
    with pytest.raises(ReplyError, match="units code 3"):
        codec.decode_scan(one_reply(codec.reply(h("B0 01 C0 0A 00"))))
    with pytest.raises(LmsCodecError, match="reflectivity"):
        codec.range_bits(0x3F)
    with pytest.raises(LmsCodecError, match="unknown measuring mode 07"):
        codec.range_bits(0x07)


def test_ranges_to_words_round_and_map_no_return_beyond_range_and_negative():
    words = codec.words_from_ranges(
        np.array([1.0004, 1.0006, np.inf, np.nan, 9.0, -1.0]), Units.MM, 0x00
    )
    assert list(words) == [1000, 1001, 0x1FF7, 0x1FF7, 0x1FF7, 0x1FFF]
    assert list(codec.words_from_ranges(np.array([9.0]), Units.CM, 0x00)) == [900]


def test_a_scan_whose_count_word_disagrees_with_len_is_refused():
    with pytest.raises(ReplyError, match="announces 5 values"):
        codec.decode_scan(one_reply(codec.reply(h("B0 05 40 E8 03"))))
    with pytest.raises(ReplyError, match="expected a B0"):
        codec.decode_scan(one_reply(codec.reply(h("B1 00"))))


# -- status ---------------------------------------------------------------------------------------


def test_status_fields_at_the_offsets_of_section_5_5():
    data = bytearray(152)
    data[0:7] = b"V02.30 "
    data[7] = 0x25  # p 8: operating mode
    data[9:17] = b"TWIN0001"  # p 10-17: serial
    data[101] = 0x05  # p 102: measuring mode
    data[106:110] = h("B4 00 32 00")  # p 107-110: 180 deg, 0.50 deg
    data[115:117] = h("19 80")  # p 116-117: 38400 baud
    data[121] = 1  # p 122: mm
    data[123:130] = b"V01.10 "
    status = codec.decode_status(one_reply(codec.reply(bytes([0xB1]) + bytes(data))))
    assert (status.operating_mode, status.measuring_mode, status.units) == (0x25, 5, 1)
    assert status.variant == Variant(180, 50) and status.baud == 38400
    assert status.software_version == "V02.30" and status.boot_version == "V01.10"
    assert status.serial == "TWIN0001"
    assert codec.encode_status(status) == bytes([0xB1]) + bytes(data)
    with pytest.raises(ReplyError, match="152"):
        codec.decode_status(one_reply(codec.reply(bytes([0xB1, 0]))))


def test_variants_count_their_values_and_angles_run_right_to_left():
    counts = {v: v.count for v in codec.VARIANTS}
    assert counts == {
        Variant(180, 100): 181,
        Variant(180, 50): 361,
        Variant(100, 100): 101,
        Variant(100, 50): 201,
        Variant(100, 25): 401,
    }
    angles = Variant(100, 25).angles_deg()
    assert angles[0] == -50 and angles[-1] == 50 and np.all(np.diff(angles) == 0.25)
    assert Variant(180, 50).mirror_turns == 2
    assert math.isclose(Variant(180, 100).angles_rad()[0], -math.pi / 2)


def test_config_block_settings_change_only_their_bytes():
    block = codec.default_config(34)
    changed = block.with_settings(units=Units.CM, measuring_mode=0x05, availability=0x02)
    assert (changed.units, changed.measuring_mode, changed.availability) == (0, 5, 2)
    assert changed.raw[7:] == block.raw[7:] and changed.raw[:4] == block.raw[:4]
    with pytest.raises(ReplyError):
        ConfigBlock(b"\x00" * 6)


# -- the parser: resynchronisation and fuzzing ----------------------------------------------------


def test_a_bad_crc_drops_only_the_leading_stx_and_finds_a_telegram_begun_inside():
    good = codec.reply(bytes([0xA0, 0x00]))
    # a broken telegram whose "length" swallows the good one
    broken = h("02 80 08 00 B0") + good
    parser = TelegramParser()
    parser.feed(broken)
    with pytest.raises(TelegramError, match="bad CRC"):
        parser.next()
    assert parser.next() == Telegram(0x80, h("A0 00 10"))


def test_bad_lengths_foreign_addresses_and_truncation():
    parser = TelegramParser()
    parser.feed(h("02 80 00 00") + h("02 81 02 00 92 10") + h("02 80 FF 7F"))
    with pytest.raises(TelegramError, match=r"length 0 outside 2\.\.806"):
        parser.next()
    with pytest.raises(TelegramError, match="length 32767"):
        parser.next()  # 02 81 was skipped as junk (a foreign address)
    good = codec.reply(bytes([0x91]))
    parser.feed(good[:5])
    assert parser.next() is None and parser.partial == good[:5]
    with pytest.raises(TelegramError, match="truncated"):
        parser.expire_partial()
    parser.feed(good)
    assert parser.next() == Telegram(0x80, h("91 10"))


def test_the_scanner_side_discards_a_bad_telegram_whole_and_ignores_ack_bytes():
    parser = TelegramParser(codec.LMS_ADDRESS, signals=False, discard_bad=True)
    bad = bytearray(codec.status_request())
    bad[-1] ^= 0xFF
    parser.feed(h("06 15") + bytes(bad) + codec.type_request())
    with pytest.raises(TelegramError, match="bad CRC"):
        parser.next()
    assert parser.next() == Telegram(0, h("3A"))
    assert parser.junk == 2


GOOD_REPLIES = st.sampled_from(
    [
        codec.reply(bytes([0xA0, 0x00])),
        codec.reply(codec.encode_type("LMS200;30106;V02.30")),
        codec.reply(codec.encode_scan(list(range(0, 3620, 10)), Units.MM)),
        codec.reply(bytes([0xF4]) + codec.default_config(34).raw),
        codec.reply(bytes([0x92])),
    ]
)


def drain(parser: TelegramParser, chunks: list[bytes]) -> list:
    """Everything the parser yields for ``chunks``, its own errors skipped, and what a silent
    line lets it find in a truncated tail."""
    found: list = []

    def pull() -> None:
        while True:
            try:
                item = parser.next()
            except TelegramError:
                continue
            if item is None:
                return
            found.append(item)

    for chunk in chunks:
        parser.feed(chunk)
        pull()
    while parser.partial:
        with contextlib.suppress(TelegramError):
            parser.expire_partial()
        pull()
    return found


def chunked(data: bytes, cuts: list[int]) -> list[bytes]:
    points = sorted({c % (len(data) + 1) for c in cuts} | {0, len(data)})
    return [data[a:b] for a, b in itertools.pairwise(points)]


@settings(max_examples=300, deadline=None)
@given(
    data=st.binary(max_size=2000),
    cuts=st.lists(st.integers(min_value=0, max_value=2000), max_size=8),
    side=st.sampled_from(["host", "scanner"]),
)
def test_whatever_bytes_arrive_only_the_codecs_errors_escape(data, cuts, side):
    if side == "host":
        parser = TelegramParser()
    else:
        parser = TelegramParser(codec.LMS_ADDRESS, signals=False, discard_bad=True)
    items = drain(parser, chunked(data, cuts))
    assert all(isinstance(i, (Telegram, Signal)) for i in items)
    assert parser.partial == b""


@settings(max_examples=300, deadline=None)
@given(
    pieces=st.lists(st.tuples(st.binary(max_size=120), GOOD_REPLIES), min_size=1, max_size=5),
    tail=st.binary(max_size=60),
    cuts=st.lists(st.integers(min_value=0, max_value=4000), max_size=10),
)
def test_good_telegrams_inside_junk_are_found_in_order(pieces, tail, cuts):
    stream = b"".join(junk + good for junk, good in pieces) + tail
    items = drain(TelegramParser(), chunked(stream, cuts))
    found = iter([i.to_bytes() for i in items if isinstance(i, Telegram)])
    for _, good in pieces:  # a subsequence: junk may hold stray 06/15 bytes or be skipped
        assert any(t == good for t in found)
