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

__all__ = ["BUS_IDLE_BITS", "TIMESCALE", "FrameAt", "VcdWriter", "acked_bits", "tick_for", "write_vcd"]

TIMESCALE = "1 ns"
"""`write_vcd`'s time unit: every PIC18 bit time (a whole number of 50 ns steps at 40 MHz) is a whole number of it."""

BUS_IDLE_BITS = 11
"""Recessive bits a CAN node needs to see before it takes the bus as idle."""

TICKS_NS = (1000, 100, 10, 1)
"""The time units a VCD can have here, in ns (its $timescale is 1, 10 or 100 of a unit)."""
FEWEST_TICKS_PER_BIT = 8
"""`tick_for`: enough for sigrok's CAN decoder to sample each bit in its middle."""

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


def tick_for(bit_ns: int) -> int:
    """The coarsest time unit (ns) that puts every bit edge on a tick, with at least `FEWEST_TICKS_PER_BIT` per bit:
    1 us at the classroom's 125 kbit/s, 100 ns at 1 Mbit/s. PulseView holds a VCD as one sample per tick, so a coarse
    tick lets it open minutes of bus."""
    for tick in TICKS_NS:
        if bit_ns % tick == 0 and bit_ns // tick >= FEWEST_TICKS_PER_BIT:
            return tick
    raise ValueError(f"a bit of {bit_ns} ns is too short for a VCD of whole ns ticks, {FEWEST_TICKS_PER_BIT} a bit")


def acked_bits(frame: CanFrame) -> list[int]:
    """The frame's bits SOF..EOF as the wire carries them when a receiver acknowledges it: the ACK slot dominant."""
    bits = list(encode(frame))
    bits[-_ACK_SLOT_FROM_END] = 0
    return bits


class VcdWriter:
    """One CAN line, `signal`, as a VCD written as it goes, in whole ticks of `tick_ns`: recessive (1) from time 0,
    `bits()` draws levels from a tick on, `end()` gives the file its last time."""

    def __init__(self, out: TextIO, bit_rate: float, *, tick_ns: int = 1, signal: str = "can_tx"):
        if tick_ns not in TICKS_NS:
            raise ValueError(f"a VCD tick here is one of {TICKS_NS} ns, not {tick_ns}")
        self.out = out
        self.level = 1
        self.time = 0                   # ticks: the end of what is drawn
        unit = f"{tick_ns // 1000} us" if tick_ns >= 1000 else f"{tick_ns} ns"
        out.write(f"$version appsim.can.vcd $end\n"
                  f"$comment CAN line at {bit_rate:g} bit/s: dominant = 0, recessive = 1 $end\n"
                  f"$timescale {unit} $end\n"
                  f"$scope module can $end\n$var wire 1 ! {signal} $end\n$upscope $end\n$enddefinitions $end\n"
                  f"#0\n$dumpvars\n1!\n$end\n")

    def bits(self, start: int, bits: Iterable[int], ticks_per_bit: int) -> int:
        """Draw `bits`, each `ticks_per_bit` long, from tick `start` (not before the end of what is drawn); the tick
        after the last one."""
        if start < self.time:
            raise ValueError(f"bits from tick {start}, before the end of what is drawn ({self.time})")
        changes, time = [], start
        for value, run in groupby(bits):
            if value != self.level:
                changes.append(f"#{time}\n{value}!\n")
                self.level = value
            time += ticks_per_bit * len(list(run))
        self.out.write("".join(changes))
        self.time = time
        return time

    def end(self, time: int) -> None:
        """The file's last time (the line as it was, up to `time`)."""
        self.out.write(f"#{max(time, self.time)}\n")


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
    (`appsim.bus.waveform` writes what a simulated bus carried.)
    """
    if isinstance(out, (str, os.PathLike)):
        with open(out, "w", encoding="ascii") as file:
            write_vcd(file, frames, bit_rate, acked=acked, idle_bits=idle_bits, signal=signal)
        return
    bit_ns = _bit_time_ns(bit_rate)
    line = VcdWriter(out, bit_rate, signal=signal)
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
        last_eof_ns = line.bits(start_ns, acked_bits(frame) if acked else encode(frame), bit_ns)
    line.end((0 if last_eof_ns is None else last_eof_ns) + idle_bits * bit_ns)
