"""Identifier packing and acceptance filtering of the ECAN in Mode 0, as pure functions.

How an 11- or 29-bit identifier sits in SIDH/SIDL/EIDH/EIDL, and which filter of a buffer accepts a frame.
"""
from __future__ import annotations

from dataclasses import dataclass

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
