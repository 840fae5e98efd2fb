"""The bus monitor the workshop used CANKing for: a trace of every frame and error frame, bus load,
each node's error counters, and logs in python-can's file formats (candump .log, .asc, .blf ...).
"""
from __future__ import annotations

from collections.abc import Iterable, Sequence
from pathlib import Path

import can

from appsim.bus.wire import Bus, BusEvent
from appsim.sim import PS_PER_SECOND

HEADER = f"{'time (s)':>11}  {'sender':<9} {'ID':>8}  {'type':<8} DLC  {'data':<23}  ACK by / error"


def format_event(event: BusEvent) -> str:
    """One line per frame: time of SOF, sender, ID, STD/EXT and RTR, DLC, data, who ACKed (or the error)."""
    frame = event.frame
    ident = f"{frame.can_id:08X}" if frame.extended else f"{frame.can_id:03X}"
    kind = ("EXT" if frame.extended else "STD") + (" RTR" if frame.remote else "")
    data = "" if frame.remote else frame.data.hex(" ").upper()
    tail = f"** {event.error}" if event.error else (",".join(event.acked_by) or "-")
    return (f"{event.start_ps / PS_PER_SECOND:11.6f}  {event.sender:<9} {ident:>8}  {kind:<8} "
            f"{frame.dlc:>3}  {data:<23}  {tail}")


def bus_load(trace: Sequence[BusEvent], start_ps: int, end_ps: int) -> float:
    """Fraction of [start, end) during which the bus carried a frame or an error frame."""
    if end_ps <= start_ps:
        raise ValueError("bus load needs a time window with end after start")
    busy = sum(max(0, min(e.end_ps, end_ps) - max(e.start_ps, start_ps)) for e in trace)
    return busy / (end_ps - start_ps)


def error_counters(bus: Bus) -> str:
    """Each board's TEC, REC and error state, as CANKing's node status shows them."""
    lines = [f"{'node':<10} {'mode':<12} {'TEC':>4} {'REC':>4}  state"]
    for mcu in bus.boards():
        ecan = mcu.ecan
        state = ("bus-off" if ecan.bus_off else "error-passive" if ecan.error_passive
                 else "warning" if max(ecan.tec, ecan.rec) >= 96 else "error-active")
        mode = ecan.opmode.name.lower().replace("_", "-")
        lines.append(f"{mcu.name:<10} {mode:<12} {ecan.tec:>4} {ecan.rec:>4}  {state}")
    return "\n".join(lines)


def summary(bus: Bus, start_ps: int = 0) -> str:
    trace = bus.trace
    good = sum(1 for e in trace if e.ok)
    load = bus_load(trace, start_ps, bus.sim.now) if bus.sim.now > start_ps else 0.0
    return (f"{good} frames, {len(trace) - good} error frames in {(bus.sim.now - start_ps) / PS_PER_SECOND:.3f} s; "
            f"bus load {load:.1%} at {bus.bit_rate // 1000} kbit/s")


class LiveTrace:
    """Follows a bus trace as the simulation runs: `new_lines()` gives what appeared since last time."""

    def __init__(self, bus: Bus):
        self.bus = bus
        self.seen = 0

    def new_lines(self) -> list[str]:
        events = self.bus.trace[self.seen:]
        self.seen += len(events)
        return [format_event(event) for event in events]


def to_message(event: BusEvent, channel: str | int) -> can.Message:
    """The frame as python-can logs it, timestamped at its end of frame (when receivers have it)."""
    frame = event.frame
    if event.error:
        return can.Message(timestamp=event.end_ps / PS_PER_SECOND, is_error_frame=True, channel=channel)
    return can.Message(timestamp=event.end_ps / PS_PER_SECOND, arbitration_id=frame.can_id,
                       is_extended_id=frame.extended, is_remote_frame=frame.remote, dlc=frame.dlc,
                       data=frame.data, channel=channel)


def write_log(events: Iterable[BusEvent], path: str | Path, *, channel: str = "vcan0") -> Path:
    """Write the trace in the format the file's suffix names: .log (candump -L), .asc, .blf, .csv, .trc ..."""
    path = Path(path)
    try:
        writer = can.Logger(path, channel=channel) if path.suffix == ".log" else can.Logger(path)
    except ValueError as error:
        raise ValueError(f"cannot write a CAN log named {path.name}: {error}. "
                         "Use .log (candump), .asc (Vector), .blf (Vector binary), .csv or .trc") from None
    with writer:
        for event in events:
            writer.on_message_received(to_message(event, channel if path.suffix == ".log" else 1))
    return path
