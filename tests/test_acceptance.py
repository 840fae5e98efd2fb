"""Masks and filters: the datasheet's truth table against a brute-force reference, through the registers."""
from __future__ import annotations

from hypothesis import given
from hypothesis import strategies as st

from appsim.can.frame import CanFrame
from appsim.chip.ecan import registers as R
from appsim.chip.ecan.acceptance import Filter, filter_matches, pack_id, raw29, unpack_id
from appsim.chip.ecan.controller import ECAN

TRUTH_TABLE = {  # (mask bit, filter bit, identifier bit) -> accept, as DS39500 prints it
    (0, 0, 0): True, (0, 0, 1): True, (0, 1, 0): True, (0, 1, 1): True,
    (1, 0, 0): True, (1, 0, 1): False, (1, 1, 0): False, (1, 1, 1): True,
}


def reference(can_id: int, extended: bool, filter_id: int, exiden: bool, mask: int) -> bool:
    """Bit by bit with the truth table: SID10..0 for standard frames, all 29 bits for extended."""
    if extended != exiden:
        return False
    positions = range(29) if extended else range(18, 29)
    wire_id = can_id if extended else can_id << 18
    return all(TRUTH_TABLE[(mask >> b & 1, filter_id >> b & 1, wire_id >> b & 1)] for b in positions)


ids29 = st.integers(0, 0x1FFF_FFFF)


@given(st.integers(0, 0x7FF), ids29, ids29, ids29, st.booleans(), st.booleans())
def test_mask_filter_truth_table_matches_brute_force_reference(std_id, ext_id, filter_bits, mask_bits,
                                                               exiden, extended):
    can_id = ext_id if extended else std_id
    noise = filter_bits & ~mask_bits if filter_bits & 1 else filter_bits   # half the cases must match
    filter_bits = (can_id if extended else can_id << 18) ^ noise
    flt = Filter(0, filter_bits, exiden)
    assert filter_matches(can_id, extended, flt, mask_bits) == reference(can_id, extended, filter_bits,
                                                                          exiden, mask_bits)


@given(ids29, ids29, ids29, st.booleans(), st.booleans())
def test_acceptance_through_the_registers_matches_reference(can_id, filter_id, mask, exiden, extended):
    """Filter RXF0 and mask RXM0 written as registers, RXB0 in RXM = 00; RXB1 accepts nothing."""
    can_id = can_id if extended else can_id & 0x7FF
    ecan = ECAN()
    f_regs = pack_id(filter_id, True)
    f_regs = (f_regs[0], (f_regs[1] & ~R.EXIDE) | (R.EXIDE if exiden else 0), f_regs[2], f_regs[3])
    for offset, value in enumerate(f_regs):
        ecan.write(0xF00 + offset, value)
        ecan.write(0xF04 + offset, value)                 # RXF1 the same
    for offset, value in enumerate(pack_id(mask, True)):
        ecan.write(0xF18 + offset, value)
    for offset in range(4):
        ecan.write(0xF1C + offset, 0xFF)                  # RXM1 compares all bits ...
    for n in range(2, 6):
        ecan.write(0xF00 + 4 * n + 1, 0x00)               # ... against standard filters of ID 0
    ecan.write(0xF50, 0b10 << 5)                          # and RXB1 takes extended frames only
    frame = CanFrame(can_id, b"\x01", extended=extended)
    expected = reference(can_id, extended, filter_id, exiden, raw29(*pack_id(mask, True)))
    assert (ecan.frame_received(frame).buffer == "RXB0") == expected


@given(ids29, st.booleans())
def test_id_packing_round_trips_for_tx_buffers_filters_and_masks(can_id, extended):
    can_id = can_id if extended else can_id & 0x7FF
    assert unpack_id(*pack_id(can_id, extended)) == (can_id, extended)


def test_reference_sees_both_verdicts():
    assert reference(0x100, False, 0x100 << 18, False, 0x7FF << 18)
    assert not reference(0x101, False, 0x100 << 18, False, 0x7FF << 18)


def test_mask_of_zero_accepts_everything():
    flt = Filter(0, 0x088 << 18, False)
    assert all(filter_matches(i, False, flt, 0) for i in range(0x800))


def test_mask_0xff_ignores_id_bits_10_to_8_so_0x000_0x100_0x200_alias():
    flt = Filter(0, 0x000 << 18, False)
    mask = 0x0FF << 18
    assert [i for i in range(0x800) if filter_matches(i, False, flt, mask)] == [
        0x000, 0x100, 0x200, 0x300, 0x400, 0x500, 0x600, 0x700]


def test_filter_type_must_match_frame_type_and_the_mask_cannot_excuse_it():
    assert not filter_matches(0x100, True, Filter(0, 0x100 << 18, False), 0)
    assert not filter_matches(0x100, False, Filter(0, 0x100, True), 0)
