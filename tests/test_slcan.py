"""SLCAN (Lawicel): the protocol as pure functions, and python-can's own slcan bus on the simulated board."""
from __future__ import annotations

import pytest

from appsim.frame import CanFrame
from appsim.slcan import (BIT_RATES, Close, Nothing, Open, Query, SetBitRate, SlcanError, Timestamps,
                          Transmit, encode_frame, parse_command, status_reply, transmit_reply)

FRAMES = [
    CanFrame(0x088, bytes([1, 2, 3, 2, 0x9A])),
    CanFrame(0x000),
    CanFrame(0x7FF, bytes(range(8))),
    CanFrame(0x1ABCDE00, b"\xAA", extended=True),
    CanFrame(0x081, remote=True, dlc=5),
    CanFrame(0x1FFFFFFF, remote=True, dlc=0, extended=True),
]


@pytest.mark.parametrize("frame", FRAMES, ids=str)
def test_a_reported_frame_reads_back_as_the_same_transmit_command(frame):
    line = encode_frame(frame)
    assert line.endswith(b"\r") and line.count(b"\r") == 1
    assert parse_command(line) == Transmit(frame)


def test_lines_look_like_lawicels_examples():
    assert encode_frame(FRAMES[0]) == b"t0885010203029A\r"
    assert encode_frame(FRAMES[3]) == b"T1ABCDE001AA\r"
    assert encode_frame(FRAMES[4]) == b"r0815\r"
    assert encode_frame(FRAMES[5]) == b"R1FFFFFFF0\r"


def test_timestamps_are_four_hex_digits_of_milliseconds_wrapping_at_60000():
    assert encode_frame(FRAMES[1], timestamp_ms=0x1234) == b"t0000" + b"1234\r"
    assert encode_frame(FRAMES[1], timestamp_ms=60_001) == b"t00000001\r"


def test_a_dlc_above_8_is_reported_as_8_so_hosts_can_parse_the_data():
    assert encode_frame(CanFrame(0x100, bytes(8), dlc=12)) == b"t1008" + b"00" * 8 + b"\r"


def test_replies():
    assert transmit_reply(FRAMES[0]) == b"z\r" and transmit_reply(FRAMES[3]) == b"Z\r"
    assert status_reply(0x28) == b"F28\r"


@pytest.mark.parametrize("line, command", [
    (b"S4\r", SetBitRate(4)), ("S0", SetBitRate(0)), (b"O\r", Open()), (b"L\r", Open(listen_only=True)),
    (b"C\r", Close()), (b"V\r", Query("V")), (b"N\r", Query("N")), (b"F\r", Query("F")),
    (b"Z1\r", Timestamps(True)), (b"Z0\r", Timestamps(False)), (b"\r", Nothing()), (b"", Nothing()),
])
def test_commands(line, command):
    assert parse_command(line) == command


def test_s_codes_are_lawicels_bit_rates():
    assert SetBitRate(4).bit_rate == 125_000 and SetBitRate(8).bit_rate == 1_000_000
    assert sorted(BIT_RATES) == list(range(9))


@pytest.mark.parametrize("line, complaint", [
    ("S9", "one digit 0..8"), ("Sx", "one digit 0..8"), ("O1", "no argument"), ("Z2", "0 or 1"),
    ("q", "not a command"), ("t10", "too short"), ("t1005010203", "10 hex digits"),
    ("t1009", "0..8"), ("t8000", "does not fit a standard"), ("T200000000", "does not fit an extended"),
    ("r1002AA", "no data"), ("t10G0", "hex digits"), ("t1 10", "hex digits"), ("t1002010", "4 hex digits"),
])
def test_bad_commands_say_what_is_wrong(line, complaint):
    with pytest.raises(SlcanError, match=complaint):
        parse_command(line)
