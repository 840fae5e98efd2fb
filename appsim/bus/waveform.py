"""The CAN line as a logic analyser records it: every event on the bus, bit by bit, from the boards' reset on.

A VCD written as the bus runs, on the trace's and the logs' clock, which PulseView and sigrok-cli's CAN decoder read.
"""
from __future__ import annotations

import io
from pathlib import Path

from appsim.bus.monitor import EventFile
from appsim.bus.wire import Bus, BusEvent
from appsim.can.vcd import VcdWriter, acked_bits, tick_for

PS_PER_NS = 1000


def wire_levels(event: BusEvent, bit_ps: int) -> list[int]:
    """An event's levels on the line, bit by bit from SOF: a frame that went through, acknowledged; or, for a frame the
    bus ran bit by bit (errors), the wire as it was in the middle of each bus bit: the frame up to where an error flag
    cut it, the flags (dominant, or an error-passive node's recessive one), delimiters and any overload flags."""
    if not event.wire:
        return acked_bits(event.frame)
    levels, changes, level = [], iter(event.wire_changes()), 1
    change = next(changes, None)
    for bit in range(-(-(event.end_ps - event.start_ps) // bit_ps)):
        middle = event.start_ps + bit * bit_ps + bit_ps // 2
        while change is not None and change[0] <= middle:
            level = change[1]
            change = next(changes, None)
        levels.append(level)
    return levels


class WaveformLog(EventFile):
    """The bus's CAN line as a VCD, `can_tx`, written as the bus carries each event (`write`, a trace listener): time 0
    is the reset, so an edge is where the trace and the logs put it (a frame's stamp is its last EOF edge). One tick per
    `tick_for` the bit time: 1 us on the classroom's bus. `close()` ends the file at the bus's present."""

    kind = "waveform for PulseView"

    def __init__(self, path: str | Path, bus: Bus):
        if bus.bit_ps % PS_PER_NS:
            raise ValueError(f"a VCD needs a bit time of whole nanoseconds; at {bus.bit_rate} bit/s it is "
                             f"{bus.bit_ps} ps")
        self.bus = bus
        self._tick_ps = tick_for(bus.bit_ps // PS_PER_NS) * PS_PER_NS
        super().__init__(path)
        self._line = VcdWriter(io.TextIOWrapper(self._file, encoding="ascii", write_through=True), bus.bit_rate,
                               tick_ns=self._tick_ps // PS_PER_NS)
        self._commit()                  # the header: a full disk shows now, before the run

    def _record(self, event: BusEvent) -> None:
        self._line.bits(round(event.start_ps / self._tick_ps), wire_levels(event, self.bus.bit_ps),
                        self.bus.bit_ps // self._tick_ps)

    def _finish(self) -> None:
        self._line.end(self.bus.sim.now // self._tick_ps)


def write_waveform(bus: Bus, path: str | Path) -> Path:
    """The bus's CAN line so far as a VCD for PulseView (`docs/traces.md`): what `bus.trace` holds, from the reset to
    now. For a notebook: `write_waveform(room.bus, "classroom.vcd")`."""
    with WaveformLog(path, bus) as log:
        for event in bus.trace:
            log.write(event)
    return log.path
