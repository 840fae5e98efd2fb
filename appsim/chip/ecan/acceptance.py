"""Identifier packing and acceptance filtering of the ECAN in Mode 0, as pure functions.

How an 11- or 29-bit identifier sits in SIDH/SIDL/EIDH/EIDL, and which filter of a buffer accepts a frame.
"""
from __future__ import annotations

from dataclasses import dataclass

from appsim.can.frame import STANDARD_ID_MAX
from appsim.chip.ecan.registers import EXIDE

SID_BITS = 0x1FFC_0000      # the 11 bits SID10..0 (EID28..18) in a 29-bit identifier
STANDARD_SHIFT = 18         # a standard identifier sits in the SID bits

# RXBnCON.RXM<1:0>
RXM_ALL_VALID, RXM_VALID_STD, RXM_VALID_XTD, RXM_ALL = 0b00, 0b01, 0b10, 0b11


def pack_id(can_id: int, extended: bool) -> tuple[int, int, int, int]:
    """(SIDH, SIDL, EIDH, EIDL) for an identifier, the way TX buffers, filters and masks hold it.

    SIDL gets EXIDE/EXIDEN (bit 3) set for an extended identifier; the EID bytes are 0 for a standard one.
    """
    if extended:
        return ((can_id >> 21) & 0xFF,
                ((can_id >> 13) & 0xE0) | EXIDE | ((can_id >> 16) & 0x03),
                (can_id >> 8) & 0xFF,
                can_id & 0xFF)
    return (can_id >> 3) & 0xFF, (can_id << 5) & 0xE0, 0, 0


def unpack_id(sidh: int, sidl: int, eidh: int, eidl: int) -> tuple[int, bool]:
    """(identifier, extended) from the four ID registers; bit 3 of SIDL says which format."""
    extended = bool(sidl & EXIDE)
    sid = (sidh << 3) | (sidl >> 5)
    if extended:
        return (sid << 18) | ((sidl & 0x03) << 16) | (eidh << 8) | eidl, True
    return sid, False


def raw29(sidh: int, sidl: int, eidh: int, eidl: int) -> int:
    """The 29 identifier bits of a filter or mask, SID10..0 on top, whatever the format bit says."""
    return (sidh << 21) | ((sidl >> 5) << 18) | ((sidl & 0x03) << 16) | (eidh << 8) | eidl


@dataclass(frozen=True, slots=True)
class Filter:
    """One acceptance filter RXFn: its 29 identifier bits and its EXIDEN bit."""

    number: int
    bits: int
    exiden: bool


def filter_matches(can_id: int, extended: bool, flt: Filter, mask_bits: int) -> bool:
    """The truth table: every mask bit that is 1 must see equal filter and identifier bits.

    A standard frame compares only SID10..0; the frame format must equal the filter's EXIDEN,
    and the mask cannot excuse that (Mode 0 masks have no EXIDEN bit).
    """
    if extended != flt.exiden:
        return False
    if extended:
        return ((can_id ^ flt.bits) & mask_bits) == 0
    return (((can_id << STANDARD_SHIFT) ^ flt.bits) & mask_bits & SID_BITS) == 0


def buffer_hit(can_id: int, extended: bool, rxm: int, filters: tuple[Filter, ...],
               mask_bits: int) -> int | None:
    """The filter number by which a buffer in receive mode `rxm` accepts a valid frame, or None.

    RXM = 11 accepts everything and reports the lowest-numbered filter that matches, or the
    buffer's first filter if none does. RXM = 01 / 10 take only standard / extended frames.
    """
    if rxm == RXM_ALL:
        for flt in filters:
            if filter_matches(can_id, extended, flt, mask_bits):
                return flt.number
        return filters[0].number
    if (rxm == RXM_VALID_STD and extended) or (rxm == RXM_VALID_XTD and not extended):
        return None
    for flt in filters:
        if filter_matches(can_id, extended, flt, mask_bits):
            return flt.number
    return None


def passing_ids(mask: int, filter_: int) -> list[int]:
    """The standard identifiers 0x000..0x7FF that a standard filter RXFn = `filter_` takes under mask RXMn = `mask`.

    The data sheet's truth table, bit by bit: where the mask bit is 0 any identifier bit passes; where it is 1
    the identifier bit must equal the filter bit. This is `filter_matches`, the test the simulated ECAN makes.
    """
    for name, value in (("mask", mask), ("filter", filter_)):
        if not 0 <= value <= STANDARD_ID_MAX:
            raise ValueError(f"a standard {name} is 11 bits, 0x000..0x{STANDARD_ID_MAX:03X}; got {value!r}")
    flt = Filter(0, filter_ << STANDARD_SHIFT, exiden=False)
    mask_bits = mask << STANDARD_SHIFT
    return [can_id for can_id in range(STANDARD_ID_MAX + 1) if filter_matches(can_id, False, flt, mask_bits)]


def id_pattern(mask: int, filter_: int) -> str:
    """The identifiers a standard filter takes, as 11 bits SID10..SID0: the filter's bit where the mask compares,
    `x` where it does not care (mask 0x7F0, filter 0x120 -> '001 0010 xxxx')."""
    bits = "".join("x" if not mask >> n & 1 else str(filter_ >> n & 1) for n in range(10, -1, -1))
    return f"{bits[:3]} {bits[3:7]} {bits[7:]}"
