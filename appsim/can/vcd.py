"""CAN frames on the TX line as a VCD (Value Change Dump) waveform at the real bit rate.

One wire, recessive (1) between frames, ACK slot dominant when acknowledged; PulseView and sigrok's `can` decode it.
"""
from __future__ import annotations

import os
from collections.abc import Iterable
from fractions import Fraction
from itertools import groupby
from typing import TextIO

from appsim.can.bits import INTERMISSION_BITS, encode
from appsim.can.frame import CanFrame

__all__ = ["BUS_IDLE_BITS", "TIMESCALE", "FrameAt", "write_vcd"]

TIMESCALE = "1 ns"
"""VCD time unit. Every PIC18 bit time (a whole number of 50 ns steps at 40 MHz) is a whole number of these."""

BUS_IDLE_BITS = 11
"""Recessive bits a CAN node needs to see before it takes the bus as idle."""

_NS_PER_S = 10**9
# From the end: CRC delimiter, ACK slot, ACK delimiter, EOF x7.
_ACK_SLOT_FROM_END = 9

FrameAt = CanFrame | tuple[float | None, CanFrame]
"""A frame sent as soon as the bus is free, or `(start in seconds or None, frame)`."""


def _bit_time_ns(bit_rate: float) -> int:
    bit_time = Fraction(_NS_PER_S) / Fraction(bit_rate)
    if bit_time.denominator != 1:
        raise ValueError(
            f"at {bit_rate} bit/s a bit lasts {float(bit_time)} ns, "
            f"not a whole number of nanoseconds (VCD unit {TIMESCALE})"
        )
    return int(bit_time)


def write_vcd(
    out: str | os.PathLike[str] | TextIO,
    frames: Iterable[FrameAt],
    bit_rate: float,
    *,
    acked: bool = True,
    idle_bits: int = BUS_IDLE_BITS,
    signal: str = "can_tx",
) -> None:
    """Write `frames` as the waveform of one CAN line, `signal`, to a path or an open text file.

    Each item is a `CanFrame` or `(start, frame)` with `start` in seconds from time 0 (when SOF begins).
    A frame without a start (or with `start=None`) follows the previous one after the 3-bit intermission;
    the first such frame starts after `idle_bits` of idle bus. The file ends `idle_bits` after the last EOF.
    With `acked=True` the ACK slot is dominant, as on a bus where a receiver acknowledged the frame;
    `acked=False` leaves it recessive, as a transmitter alone on the bus sends it (an ACK error).
    Raises ValueError if a frame would start before the previous one and its intermission are over.

    To read it back: `sigrok-cli -i bus.vcd -I vcd -P can:can_rx=can_tx:nominal_bitrate=125000 -A can`,
    or PulseView with the CAN decoder on `can_tx`. sigrok's decoder (libsigrokdecode 0.5.3) expects data
    bytes after the DLC of a remote frame too, so it misreads remote frames whose DLC is not 0.
    """
    bit_ns = _bit_time_ns(bit_rate)
    lines = [
        "$version appsim.can.vcd $end",
        f"$comment CAN line at {bit_rate:g} bit/s: dominant = 0, recessive = 1 $end",
        f"$timescale {TIMESCALE} $end",
        "$scope module can $end",
        f"$var wire 1 ! {signal} $end",
        "$upscope $end",
        "$enddefinitions $end",
        "#0",
        "$dumpvars",
        "1!",
        "$end",
    ]
    level = 1
    gap_ns = INTERMISSION_BITS * bit_ns
    last_eof_ns: int | None = None  # end of the previous frame's EOF
    for number, item in enumerate(frames, 1):
        start, frame = item if isinstance(item, tuple) else (None, item)
        bus_free_ns = 0 if last_eof_ns is None else last_eof_ns + gap_ns
        if start is None:
            start_ns = idle_bits * bit_ns if last_eof_ns is None else bus_free_ns
        else:
            start_ns = round(start * _NS_PER_S)
            if start_ns < bus_free_ns:
                raise ValueError(
                    f"frame {number} ({frame}) starts at {start} s, before the bus is free at "
                    f"{bus_free_ns / _NS_PER_S} s (end of the previous frame plus "
                    f"{INTERMISSION_BITS} intermission bits)"
                )
        bits = list(encode(frame))
        if acked:
            bits[-_ACK_SLOT_FROM_END] = 0
        time_ns = start_ns
        for value, run in groupby(bits):
            if value != level:
                lines.append(f"#{time_ns}\n{value}!")
                level = value
            time_ns += bit_ns * len(list(run))
        last_eof_ns = time_ns
    end_ns = (0 if last_eof_ns is None else last_eof_ns) + idle_bits * bit_ns
    lines.append(f"#{end_ns}\n")
    text = "\n".join(lines)
    if isinstance(out, (str, os.PathLike)):
        with open(out, "w", encoding="ascii") as file:
            file.write(text)
    else:
        out.write(text)
