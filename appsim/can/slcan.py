"""The Lawicel SLCAN protocol (CAN232/CANUSB, python-can's `slcan` interface): ASCII lines ending in CR.

Pure functions: a received frame to the line an adapter sends, a command line to what it asks for.
"""
from __future__ import annotations

import string
from dataclasses import dataclass

from appsim.can.frame import CanFrame, FrameError
from appsim.errors import SlcanError

OK = b"\r"                 # a command done
ERROR = b"\a"              # BELL: a command refused
TIMESTAMP_WRAP_MS = 60_000  # Z1 time stamps count milliseconds 0..59999, then wrap

# Sn: Lawicel's standard bit rates. S7 is 800 kbit/s in Lawicel's manual; python-can sends it for 750000.
BIT_RATES = {0: 10_000, 1: 20_000, 2: 50_000, 3: 100_000, 4: 125_000,
             5: 250_000, 6: 500_000, 7: 800_000, 8: 1_000_000}
VERSION = "V1013"          # hardware 1.0, software 1.3 (python-can reads two decimal digits of each)


@dataclass(frozen=True)
class SetBitRate:
    """`Sn`: choose bit rate n (0..8) while the channel is closed."""
    code: int

    @property
    def bit_rate(self) -> int:
        return BIT_RATES[self.code]


@dataclass(frozen=True)
class Open:
    """`O`: open the channel (Normal mode: it ACKs and can transmit); `L`: listen only (silent)."""
    listen_only: bool = False


@dataclass(frozen=True)
class Close:
    """`C`: close the channel."""


@dataclass(frozen=True)
class Query:
    """`V` version, `N` serial number, `F` status flags: answered with one line."""
    what: str


@dataclass(frozen=True)
class Timestamps:
    """`Z0`/`Z1`: add a millisecond time stamp (4 hex digits) to each received frame, or not."""
    on: bool


@dataclass(frozen=True)
class Transmit:
    """`t`, `T`, `r`, `R`: send this frame."""
    frame: CanFrame


@dataclass(frozen=True)
class Nothing:
    """An empty line: a bare CR, which python-can sends for "no data bit rate" and hosts send to resync."""


Command = SetBitRate | Open | Close | Query | Timestamps | Transmit | Nothing


def encode_frame(frame: CanFrame, timestamp_ms: int | None = None) -> bytes:
    """The line an adapter sends for a received frame: `tIIILDD..`, `TIIIIIIIILDD..`, `rIIIL`, `RIIIIIIIIL`, CR.

    The DLC is one digit: a DLC of 9..15 (legal on the wire, 8 bytes) is reported as 8.
    With `timestamp_ms` (Z1), 4 hex digits of milliseconds (modulo 60000) come before the CR.
    """
    kind = ("R" if frame.extended else "r") if frame.remote else ("T" if frame.extended else "t")
    ident = f"{frame.can_id:08X}" if frame.extended else f"{frame.can_id:03X}"
    line = f"{kind}{ident}{min(frame.dlc, 8)}{frame.data.hex().upper()}"
    if timestamp_ms is not None:
        line += f"{timestamp_ms % TIMESTAMP_WRAP_MS:04X}"
    return line.encode("ascii") + OK


def transmit_reply(frame: CanFrame) -> bytes:
    """What the adapter answers to a transmit command it accepted: `z` (standard) or `Z` (extended), CR."""
    return b"Z\r" if frame.extended else b"z\r"


def status_reply(flags: int) -> bytes:
    """`Fxx`: bit 0 RX queue full, 1 TX queue full, 2 error warning, 3 data overrun, 5 error passive, 7 bus error."""
    return f"F{flags & 0xFF:02X}".encode("ascii") + OK


def parse_command(line: bytes | str) -> Command:
    """One command line (with or without its CR) as a `Command`; `SlcanError` says what is wrong."""
    text = line.decode("ascii", "replace") if isinstance(line, bytes) else line
    text = text.removesuffix("\r")
    if not text:
        return Nothing()
    head, rest = text[0], text[1:]
    if head in "tTrR":
        return Transmit(_parse_frame(head, rest))
    if head == "S":
        if len(rest) != 1 or rest not in string.digits or int(rest) not in BIT_RATES:
            raise SlcanError(f"{text!r}: S takes one digit 0..8 "
                             f"({', '.join(f'S{c} = {r} bit/s' for c, r in BIT_RATES.items())})")
        return SetBitRate(int(rest))
    if head in "OLCVNF" and not rest:
        if head in "OL":
            return Open(listen_only=head == "L")
        return Close() if head == "C" else Query(head)
    if head == "Z" and rest in ("0", "1"):
        return Timestamps(rest == "1")
    if head in "OLCVNFZ":
        raise SlcanError(f"{text!r}: {head} takes {'0 or 1' if head == 'Z' else 'no argument'}")
    raise SlcanError(f"{text!r} is not a command this adapter knows: it speaks "
                     "S0..S8, O, L, C, V, N, F, Z0/Z1 and t/T/r/R frames")


def _parse_frame(kind: str, rest: str) -> CanFrame:
    extended = kind in "TR"
    remote = kind in "rR"
    id_digits = 8 if extended else 3
    example = {"t": "t1005010203029A", "T": "T0000012342AABB", "r": "r0815", "R": "R000001230"}[kind]
    what = repr(kind + rest)
    if len(rest) < id_digits + 1:
        raise SlcanError(f"{what} is too short: {kind} needs {id_digits} hex digits of identifier and a DLC "
                         f"digit (e.g. {example})")
    hex_part = rest[:id_digits] + rest[id_digits + 1:]
    if not all(c in string.hexdigits for c in hex_part) or rest[id_digits] not in string.digits:
        raise SlcanError(f"{what}: identifier and data are hex digits, the DLC one decimal digit "
                         f"(e.g. {example})")
    can_id, dlc = int(rest[:id_digits], 16), int(rest[id_digits])
    data_digits = rest[id_digits + 1:]
    if dlc > 8:
        raise SlcanError(f"{what}: the DLC digit is 0..8")
    if remote and data_digits:
        raise SlcanError(f"{what}: a remote frame carries no data, only the DLC it asks for (e.g. {example})")
    if not remote and len(data_digits) != 2 * dlc:
        raise SlcanError(f"{what}: DLC {dlc} needs {2 * dlc} hex digits of data, got {len(data_digits)}")
    try:
        return CanFrame(can_id, bytes.fromhex(data_digits), extended=extended, remote=remote, dlc=dlc)
    except FrameError as error:
        raise SlcanError(f"{what}: {error}") from None

