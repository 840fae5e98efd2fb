"""CAN 2.0A/2.0B data and remote frames as bits on the wire (dominant 0, recessive 1): fields, CRC-15, stuffing.

`encode` gives a frame's exact SOF..EOF bits and length; `decode` reads bits back, raising the error a controller flags.
"""
from __future__ import annotations

from collections.abc import Iterable, Sequence
from dataclasses import dataclass
from functools import lru_cache

from appsim.can.frame import CanFrame
from appsim.errors import CrcError, FormError, StuffError, WireError

__all__ = [
    "INTERMISSION_BITS",
    "TAIL_BITS",
    "CrcError",
    "FormError",
    "StuffError",
    "WireBit",
    "WireError",
    "crc15",
    "crc15_bytes",
    "decode",
    "encode",
    "encode_annotated",
    "frame_bits",
    "frame_time",
    "frame_time_ps",
    "max_frame_bits",
]

INTERMISSION_BITS = 3
"""Recessive bits after EOF before the next frame may start (interframe space)."""

TAIL_BITS = 10
"""The bits after the stuffed region (SOF..CRC sequence): CRC delimiter, ACK slot, ACK delimiter, 7 EOF bits."""

_CRC15_POLY = 0x4599
_CRC_MASK = 0x7FFF
# CRC delimiter, ACK slot as the transmitter sends it (recessive), ACK delimiter, EOF x7. Never stuffed.
_TAIL = "1" * TAIL_BITS
_TAIL_FIELDS = ("CRC delimiter", "ACK slot", "ACK delimiter") + ("EOF",) * 7
_TO_LEVELS = bytes.maketrans(b"01", b"\x00\x01")


def _crc15_table() -> tuple[int, ...]:
    table = []
    for byte in range(256):
        crc = byte << 7
        for _ in range(8):
            crc = ((crc << 1) ^ _CRC15_POLY) if crc & 0x4000 else crc << 1
        table.append(crc & _CRC_MASK)
    return tuple(table)


_CRC_TABLE = _crc15_table()


def crc15(bits: Iterable[int]) -> int:
    """CRC-15/CAN (poly 0x4599, init 0, no reflection, no final XOR) of unstuffed bits, first bit first."""
    crc = 0
    for bit in bits:
        crc = ((crc << 1) ^ _CRC15_POLY if ((crc >> 14) ^ bit) & 1 else crc << 1) & _CRC_MASK
    return crc


def crc15_bytes(data: bytes) -> int:
    """CRC-15/CAN of whole bytes sent MSB first; `crc15_bytes(b"123456789") == 0x059E` (the check value)."""
    crc = 0
    for byte in data:
        crc = ((crc << 8) & _CRC_MASK) ^ _CRC_TABLE[((crc >> 7) ^ byte) & 0xFF]
    return crc


def _unstuffed(frame: CanFrame) -> str:
    """SOF through the CRC sequence, before stuffing, as a '0'/'1' string."""
    data = frame.data
    if frame.extended:
        ident = frame.can_id
        # base ID, SRR=1, IDE=1, ID17..0, RTR, r1=0, r0=0, DLC
        value = ((((ident >> 18) << 2 | 3) << 18 | (ident & 0x3FFFF)) << 3 | frame.remote << 2) << 4 | frame.dlc
        nbits = 39 + 8 * len(data)
    else:
        # ID10..0, RTR, IDE=0, r0=0, DLC
        value = (frame.can_id << 3 | frame.remote << 2) << 4 | frame.dlc
        nbits = 19 + 8 * len(data)
    if data:
        value = value << 8 * len(data) | int.from_bytes(data, "big")
    # SOF is the leading 0 of the fixed width; leading zeros leave an init-0 CRC at 0, so whole bytes are fine.
    crc = crc15_bytes(value.to_bytes((nbits + 7) // 8, "big"))
    return f"{value << 15 | crc:0{nbits + 15}b}"


class _StuffChunks(dict[str, tuple[str, int]]):
    """Stuffed form of bit chunks (up to 8 bits) from one stuffing state, filled in as chunks are met.

    A state is `last * 5 + run - 1`: the last level sent and how many equal bits end with it (1..5).
    Values are (stuffed chunk, state after it).
    """

    def __init__(self, state: int) -> None:
        super().__init__()
        self.state = state

    def __missing__(self, chunk: str) -> tuple[str, int]:
        last, run = divmod(self.state, 5)
        run += 1
        out = []
        for char in chunk:
            if run == 5:
                last, run = 1 - last, 1
                out.append(str(last))
            level = int(char)
            run = run + 1 if level == last else 1
            last = level
            out.append(char)
        self[chunk] = result = ("".join(out), last * 5 + run - 1)
        return result


_STUFF_TABLE = tuple(_StuffChunks(state) for state in range(10))
_START_STATE = 5  # before SOF: last level recessive, run of 1, so SOF starts a fresh run
_STUFF_AFTER = {4: "1", 9: "0"}  # states ending five equal bits


def _stuff(bits: str) -> str:
    """Insert a complement bit after every 5 equal bits; a stuff bit starts the next run."""
    state = _START_STATE
    parts = []
    for start in range(0, len(bits), 8):
        chunk, state = _STUFF_TABLE[state][bits[start:start + 8]]
        parts.append(chunk)
    parts.append(_STUFF_AFTER.get(state, ""))
    return "".join(parts)


@lru_cache(maxsize=4096)
def _stuffed_region(frame: CanFrame) -> str:
    return _stuff(_unstuffed(frame))


def encode(frame: CanFrame) -> tuple[int, ...]:
    """The frame's bits on the wire, SOF..EOF, stuff bits included, ACK slot recessive as transmitted."""
    return tuple((_stuffed_region(frame) + _TAIL).encode().translate(_TO_LEVELS))


def frame_bits(frame: CanFrame) -> int:
    """Exact frame length on the wire, SOF..EOF including stuff bits, excluding the intermission.

    A simulator that keeps its bit time as whole picoseconds (e.g. from BRGCON1..3) multiplies this by it;
    `frame_time_ps` does that for a bit rate in bit/s. Add `INTERMISSION_BITS` before the next frame may start.
    """
    return len(_stuffed_region(frame)) + len(_TAIL)


def max_frame_bits(data_bytes: int, *, extended: bool = False) -> int:
    """The longest a data frame of `data_bytes` bytes can be on the wire, SOF..EOF, with the most stuff bits.

    Stuffing covers SOF through the CRC sequence: 34 + 8n bits in a standard frame, 54 + 8n in an extended one.
    The first stuff bit may follow the fifth of them and then one every four (a stuff bit starts the next run),
    so at most (stuffed - 1) // 4 stuff bits: the bound the CAN-projects chapter extract derives (section 1.6)
    and that bus-load analysis uses. A remote frame is as long as a data frame with no data. Add
    `INTERMISSION_BITS` for the bus time before the next frame may start.
    """
    if not 0 <= data_bytes <= 8:
        raise ValueError(f"a CAN frame carries 0 to 8 data bytes, got {data_bytes!r}")
    stuffed = (54 if extended else 34) + 8 * data_bytes
    return stuffed + (stuffed - 1) // 4 + len(_TAIL)


def frame_time(frame: CanFrame, bit_rate: float) -> float:
    """Seconds from the start of SOF to the end of EOF at `bit_rate` bit/s (intermission excluded)."""
    return frame_bits(frame) / bit_rate


def frame_time_ps(frame: CanFrame, bit_rate_bps: int) -> int:
    """Integer picoseconds from SOF to the end of EOF; the bit time 1e12/bit_rate_bps must be whole ps."""
    bit_time_ps, rest = divmod(10**12, bit_rate_bps)
    if rest:
        raise ValueError(
            f"{bit_rate_bps} bit/s has no whole-picosecond bit time; "
            "multiply frame_bits(frame) by the bit time in ps instead"
        )
    return frame_bits(frame) * bit_time_ps


@dataclass(frozen=True, slots=True)
class WireBit:
    """One bit on the wire: its level (0 dominant, 1 recessive), the field it belongs to, and if it is a stuff bit.

    A stuff bit carries the field of the bit before it (a stuff bit after the last CRC bit is "CRC").
    """

    level: int
    field: str
    stuff: bool = False


def _fields(frame: CanFrame) -> list[tuple[str, str]]:
    """(field name, bits) pairs of the stuffed region, unstuffed, in wire order."""
    bits = _unstuffed(frame)
    names: tuple[tuple[str, int], ...]
    if frame.extended:
        names = (("SOF", 1), ("ID", 11), ("SRR", 1), ("IDE", 1), ("ID", 18), ("RTR", 1), ("r1", 1), ("r0", 1))
    else:
        names = (("SOF", 1), ("ID", 11), ("RTR", 1), ("IDE", 1), ("r0", 1))
    names += (("DLC", 4), ("DATA", 8 * len(frame.data)), ("CRC", 15))
    fields = []
    start = 0
    for name, width in names:
        if width:
            fields.append((name, bits[start:start + width]))
        start += width
    return fields


def encode_annotated(frame: CanFrame) -> list[WireBit]:
    """The same bits as `encode(frame)`, each labelled with its field and whether it is a stuff bit."""
    out: list[WireBit] = []
    last, run = -1, 0
    for field, bits in _fields(frame):
        for char in bits:
            if run == 5:
                last = 1 - last
                out.append(WireBit(last, out[-1].field, stuff=True))
                run = 1
            level = int(char)
            run = run + 1 if level == last else 1
            last = level
            out.append(WireBit(level, field))
    if run == 5:
        out.append(WireBit(1 - last, out[-1].field, stuff=True))
    out.extend(WireBit(int(level), field) for level, field in zip(_TAIL, _TAIL_FIELDS, strict=True))
    return out


_LEVEL_NAME = ("dominant", "recessive")


class _Destuffer:
    """Reads the stuffed region bit by bit, dropping stuff bits and checking them."""

    def __init__(self, wire: Sequence[int]) -> None:
        self.wire = wire
        self.pos = 0
        self.last = -1
        self.run = 0
        self.bits: list[int] = []

    def level_at(self, pos: int, where: str) -> int:
        if pos >= len(self.wire):
            raise FormError(
                pos, f"form error at bit {pos}: the sequence ends after {len(self.wire)} bits, inside the {where}"
            )
        return self.wire[pos]

    def expect_recessive(self, pos: int, where: str) -> None:
        if self.level_at(pos, where) == 0:
            raise FormError(pos, f"form error at bit {pos}: the {where} must be recessive (1), it is dominant (0)")

    def take_stuff_bit(self, where: str) -> None:
        level = self.level_at(self.pos, where)
        if level == self.last:
            name = _LEVEL_NAME[level]
            raise StuffError(
                self.pos,
                f"stuff error at bit {self.pos} ({where}): six {name} bits in a row "
                f"(bits {self.pos - 5}..{self.pos}); after five equal bits the transmitter must insert "
                f"one {_LEVEL_NAME[1 - level]} stuff bit",
            )
        self.last, self.run = level, 1
        self.pos += 1

    def take(self, count: int, where: str) -> int:
        """Read `count` data bits as an unsigned integer, MSB first."""
        value = 0
        for _ in range(count):
            if self.run == 5:
                self.take_stuff_bit(where)
            level = self.level_at(self.pos, where)
            self.run = self.run + 1 if level == self.last else 1
            self.last = level
            self.bits.append(level)
            self.pos += 1
            value = (value << 1) | level
        return value


def decode(bits: Iterable[int]) -> CanFrame:
    """Parse a wire bit sequence that starts at SOF (stuff bits included) into the frame it carries.

    Checks what a receiving controller checks, in the order it sees them: stuffing from SOF to the end of
    the CRC sequence, CRC delimiter, ACK delimiter, CRC, EOF. The ACK slot may be either level. Bits after
    the seventh EOF bit belong to the interframe space and are not read. Raises a `WireError` subclass.
    """
    wire = tuple(bits)
    if any(level not in (0, 1) for level in wire):
        raise ValueError("wire bits must be 0 (dominant) or 1 (recessive)")
    reader = _Destuffer(wire)
    if reader.take(1, "start of frame") != 0:
        raise FormError(0, "form error at bit 0: a frame starts with a dominant SOF bit, this one is recessive")
    base_id = reader.take(11, "identifier")
    rtr_or_srr = reader.take(1, "RTR/SRR bit")
    extended = reader.take(1, "IDE bit") == 1
    if extended:
        can_id = (base_id << 18) | reader.take(18, "extended identifier")
        remote = reader.take(1, "RTR bit") == 1
        reader.take(2, "reserved bits r1, r0")
    else:
        can_id = base_id
        remote = rtr_or_srr == 1
        reader.take(1, "reserved bit r0")
    dlc = reader.take(4, "DLC")
    data_bytes = 0 if remote else min(dlc, 8)
    data = reader.take(8 * data_bytes, "data field").to_bytes(data_bytes, "big")
    computed = crc15(reader.bits)
    received = reader.take(15, "CRC sequence")
    crc_end = reader.pos - 1
    if reader.run == 5:
        reader.take_stuff_bit("CRC sequence")
    delimiter = reader.pos
    reader.expect_recessive(delimiter, "CRC delimiter")
    reader.level_at(delimiter + 1, "ACK slot")  # either level: receivers drive it dominant
    reader.expect_recessive(delimiter + 2, "ACK delimiter")
    if received != computed:
        raise CrcError(
            crc_end,
            f"CRC error at bit {crc_end}: received CRC 0x{received:04X}, but the bits SOF..data give "
            f"0x{computed:04X}; receivers send an error frame after the ACK delimiter",
            received,
            computed,
        )
    for offset in range(7):
        reader.expect_recessive(delimiter + 3 + offset, f"end-of-frame bit {offset + 1} of 7")
    if remote:
        return CanFrame(can_id, extended=extended, remote=True, dlc=dlc)
    return CanFrame(can_id, data, extended=extended, dlc=dlc)
