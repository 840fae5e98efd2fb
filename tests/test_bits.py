"""CAN frames at bit level: CRC-15, stuffing, exact lengths, and the errors `decode` names."""
from __future__ import annotations

from itertools import groupby

import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from appsim.can.bits import (
    CrcError,
    FormError,
    StuffError,
    WireError,
    crc15,
    crc15_bytes,
    decode,
    encode,
    encode_annotated,
    frame_bits,
    frame_time,
    frame_time_ps,
    max_frame_bits,
)
from appsim.can.frame import EXTENDED_ID_MAX, STANDARD_ID_MAX, CanFrame

TAIL_BITS = 10  # CRC delimiter, ACK slot, ACK delimiter, 7 EOF bits: never stuffed


@st.composite
def frames(draw: st.DrawFn) -> CanFrame:
    extended = draw(st.booleans())
    remote = draw(st.booleans())
    can_id = draw(st.integers(0, EXTENDED_ID_MAX if extended else STANDARD_ID_MAX))
    dlc = draw(st.integers(0, 15))
    if remote:
        return CanFrame(can_id, extended=extended, remote=True, dlc=dlc)
    data = draw(st.binary(min_size=min(dlc, 8), max_size=min(dlc, 8)))
    return CanFrame(can_id, data, extended=extended, dlc=dlc)


def crc_of(frame: CanFrame) -> int:
    return int("".join(str(b.level) for b in encode_annotated(frame) if b.field == "CRC" and not b.stuff), 2)


def stuff_count(frame: CanFrame) -> int:
    return sum(b.stuff for b in encode_annotated(frame))


def test_crc15_check_value_of_ascii_123456789_is_0x059e() -> None:
    assert crc15_bytes(b"123456789") == 0x059E
    assert crc15(int(bit) for byte in b"123456789" for bit in f"{byte:08b}") == 0x059E


WORKED_FRAMES = [
    pytest.param(CanFrame(500, b"\x54", extended=True), 0x42B2, 5, 77, id="ext ID 500, 'T'"),
    pytest.param(CanFrame(3, b"\x19", extended=True), 0x0EEA, 6, 78, id="ext ID 3, 25"),
    pytest.param(CanFrame(500, b"\x54"), 0x5C69, 2, 54, id="std ID 500, 'T'"),
    pytest.param(CanFrame(3, b"\x19"), 0x1031, 4, 56, id="std ID 3, 25"),
    pytest.param(CanFrame(500, remote=True, dlc=1), 0x7CD0, 3, 47, id="std remote ID 500, DLC 1"),
]


@pytest.mark.parametrize(("frame", "crc", "stuff_bits", "total"), WORKED_FRAMES)
def test_worked_frames_have_the_chapter_crc_stuff_bits_and_length(
    frame: CanFrame, crc: int, stuff_bits: int, total: int
) -> None:
    assert crc_of(frame) == crc
    assert stuff_count(frame) == stuff_bits
    assert frame_bits(frame) == total
    assert len(encode(frame)) == total


@pytest.mark.parametrize(("frame", "crc", "stuff_bits", "total"), WORKED_FRAMES)
def test_worked_frames_take_total_bits_times_10_us_at_100_kbit_s(
    frame: CanFrame, crc: int, stuff_bits: int, total: int
) -> None:
    assert frame_time_ps(frame, 100_000) == total * 10_000_000
    assert frame_time(frame, 100_000) == pytest.approx(total * 10e-6)


def test_frame_time_ps_refuses_a_bit_rate_without_a_whole_picosecond_bit_time() -> None:
    with pytest.raises(ValueError, match="whole-picosecond"):
        frame_time_ps(CanFrame(1), 3)


def fields_in_order(frame: CanFrame) -> list[str]:
    return [field for field, _ in groupby(b.field for b in encode_annotated(frame))]


def test_standard_data_frame_fields_in_wire_order() -> None:
    assert fields_in_order(CanFrame(0x123, b"\x01\x02")) == [
        "SOF", "ID", "RTR", "IDE", "r0", "DLC", "DATA", "CRC",
        "CRC delimiter", "ACK slot", "ACK delimiter", "EOF",
    ]


def test_extended_remote_frame_fields_in_wire_order_without_data() -> None:
    assert fields_in_order(CanFrame(0x1234567, extended=True, remote=True, dlc=4)) == [
        "SOF", "ID", "SRR", "IDE", "ID", "RTR", "r1", "r0", "DLC", "CRC",
        "CRC delimiter", "ACK slot", "ACK delimiter", "EOF",
    ]


def levels_of(frame: CanFrame, field: str) -> str:
    return "".join(str(b.level) for b in encode_annotated(frame) if b.field == field and not b.stuff)


def test_extended_frame_sends_id28_18_then_srr_ide_recessive_then_id17_0() -> None:
    frame = CanFrame(0x1ABCDEF, b"\xA5", extended=True)
    assert levels_of(frame, "ID") == f"{0x1ABCDEF >> 18:011b}{0x1ABCDEF & 0x3FFFF:018b}"
    assert (levels_of(frame, "SRR"), levels_of(frame, "IDE"), levels_of(frame, "RTR")) == ("1", "1", "0")
    assert (levels_of(frame, "r1"), levels_of(frame, "r0")) == ("0", "0")


def test_remote_frame_has_recessive_rtr_and_the_requested_dlc() -> None:
    frame = CanFrame(0x081, remote=True, dlc=5)
    assert (levels_of(frame, "RTR"), levels_of(frame, "IDE"), levels_of(frame, "DLC")) == ("1", "0", "0101")


def test_dlc_above_8_is_sent_as_is_with_8_data_bytes_msb_first() -> None:
    frame = CanFrame(0x100, bytes([0x80, 1, 2, 3, 4, 5, 6, 0x7F]), dlc=12)
    assert levels_of(frame, "DLC") == "1100"
    assert levels_of(frame, "DATA") == "".join(f"{b:08b}" for b in frame.data)
    assert decode(encode(frame)) == frame


def test_frame_ends_with_recessive_delimiters_ack_slot_and_seven_eof_bits() -> None:
    annotated = encode_annotated(CanFrame(0x7F0, bytes(8)))
    assert [(b.field, b.level) for b in annotated[-TAIL_BITS:]] == [
        ("CRC delimiter", 1), ("ACK slot", 1), ("ACK delimiter", 1)] + [("EOF", 1)] * 7


def test_stuff_bit_is_the_complement_after_five_equal_bits_and_starts_the_next_run() -> None:
    # SOF + ID10..7 = 00000 -> stuff 1; that 1 plus ID6..3 = 1111 is a run of five -> stuff 0;
    # that 0 plus ID2..0 and RTR = 0000 -> stuff 1.
    annotated = encode_annotated(CanFrame(0b0000_1111_000))
    assert tuple(b.level for b in annotated[:16]) == (0, 0, 0, 0, 0, 1, 1, 1, 1, 1, 0, 0, 0, 0, 0, 1)
    assert [i for i, b in enumerate(annotated[:16]) if b.stuff] == [5, 10, 15]


def test_stuff_bit_after_the_last_crc_bit_when_the_crc_ends_a_run_of_five() -> None:
    frame = next(
        CanFrame(i) for i in range(STANDARD_ID_MAX + 1) if encode_annotated(CanFrame(i))[-TAIL_BITS - 1].stuff
    )
    annotated = encode_annotated(frame)
    assert annotated[-TAIL_BITS - 1].field == "CRC"
    assert len({b.level for b in annotated[-TAIL_BITS - 6:-TAIL_BITS - 1]}) == 1
    assert annotated[-TAIL_BITS - 1].level != annotated[-TAIL_BITS - 2].level
    assert frame_bits(frame) == len(annotated)
    assert decode(encode(frame)) == frame


def test_a_stuff_bit_missing_gives_a_stuff_error_naming_the_bit() -> None:
    wire = list(encode(CanFrame(0x000)))
    wire[5] = 0  # the first stuff bit, after SOF and ID10..7, made dominant
    with pytest.raises(StuffError, match=r"stuff error at bit 5 .*six dominant bits in a row") as caught:
        decode(wire)
    assert caught.value.position == 5


def test_six_recessive_bits_in_the_data_field_give_a_stuff_error() -> None:
    frame = CanFrame(0x100, b"\xFF")
    annotated = encode_annotated(frame)
    stuff_at = next(i for i, b in enumerate(annotated) if b.stuff and b.field == "DATA")
    wire = list(encode(frame))
    wire[stuff_at] = 1
    with pytest.raises(StuffError, match=f"stuff error at bit {stuff_at} .*six recessive bits"):
        decode(wire)


def test_a_flipped_crc_bit_gives_a_crc_error_with_both_values_in_hex() -> None:
    frame = CanFrame(500, b"\x54")  # CRC 0x5C69
    wire = list(encode(frame))
    last_crc_bit = len(wire) - TAIL_BITS - 1
    wire[last_crc_bit] ^= 1
    with pytest.raises(CrcError, match="received CRC 0x5C68, but the bits SOF..data give 0x5C69") as caught:
        decode(wire)
    assert (caught.value.received, caught.value.computed) == (0x5C68, 0x5C69)


@pytest.mark.parametrize(
    ("from_end", "field"),
    [(TAIL_BITS, "CRC delimiter"), (TAIL_BITS - 2, "ACK delimiter"), (7, "end-of-frame bit 1"), (1, "end-of-frame bit 7")],
)
def test_a_dominant_fixed_form_bit_gives_a_form_error(from_end: int, field: str) -> None:
    wire = list(encode(CanFrame(0x120, b"\x01\x02\x03")))
    position = len(wire) - from_end
    wire[position] = 0
    with pytest.raises(FormError, match=f"form error at bit {position}: (the )?{field} .*it is dominant"):
        decode(wire)


def test_a_dominant_ack_slot_is_a_receivers_normal_view() -> None:
    frame = CanFrame(0x120, b"\x01\x02\x03")
    wire = list(encode(frame))
    wire[-TAIL_BITS + 1] = 0
    assert decode(wire) == frame


def test_a_sequence_cut_before_eof_ends_gives_a_form_error() -> None:
    wire = encode(CanFrame(0x120, b"\x01"))
    with pytest.raises(FormError, match="ends after"):
        decode(wire[:-1])
    with pytest.raises(FormError, match="inside the data field"):
        decode(wire[:25])


def test_a_recessive_first_bit_is_not_a_start_of_frame() -> None:
    with pytest.raises(FormError, match="SOF"):
        decode((1,) + encode(CanFrame(0x120))[1:])


def test_decode_reads_no_further_than_eof() -> None:
    frame = CanFrame(0x120, b"\x01")
    assert decode(encode(frame) + (1, 1, 1) + encode(CanFrame(0x7FF))) == frame


@settings(max_examples=400)
@given(frames())
def test_decode_gives_back_the_encoded_frame(frame: CanFrame) -> None:
    assert decode(encode(frame)) == frame


@given(frames())
def test_annotated_bits_are_the_encoded_bits_and_frame_bits_is_their_count(frame: CanFrame) -> None:
    annotated = encode_annotated(frame)
    assert tuple(b.level for b in annotated) == encode(frame)
    assert frame_bits(frame) == len(annotated)


@given(frames())
def test_stuffing_never_leaves_six_equal_bits_between_sof_and_crc_delimiter(frame: CanFrame) -> None:
    stuffed = encode(frame)[: -TAIL_BITS + 1]  # up to and including the CRC delimiter
    longest = max(len(list(run)) for _, run in groupby(stuffed))
    assert longest <= 5


@given(frames())
def test_length_stays_within_the_worst_case_stuffing_bound(frame: CanFrame) -> None:
    n = 0 if frame.remote else len(frame.data)
    if frame.extended:
        bound = 64 + 8 * n + (54 + 8 * n - 1) // 4
    else:
        bound = 44 + 8 * n + (34 + 8 * n - 1) // 4
    assert frame_bits(frame) <= bound == max_frame_bits(n, extended=frame.extended)
    assert frame_bits(frame) <= (157 if frame.extended else 132)


def test_the_longest_frames_are_the_chapters_132_and_157_bits_and_a_remote_frame_52():
    assert (max_frame_bits(8), max_frame_bits(8, extended=True), max_frame_bits(0)) == (132, 157, 52)
    with pytest.raises(ValueError, match="0 to 8 data bytes"):
        max_frame_bits(9)


@settings(max_examples=400)
@given(frames(), st.data())
def test_a_single_flipped_bit_between_sof_and_crc_is_never_silently_accepted(frame: CanFrame, data: st.DataObject) -> None:
    wire = list(encode(frame))
    position = data.draw(st.integers(0, len(wire) - TAIL_BITS - 1), label="flipped bit")
    wire[position] ^= 1
    try:
        decoded = decode(wire)
    except WireError:
        return
    assert decoded != frame
