"""The bus monitor the workshop used CANKing for: a trace of every frame and error frame, bus load,
each node's error counters, and logs in python-can's file formats (candump .log, .asc, .blf ...), written as it runs.
"""
from __future__ import annotations

import errno
import html
import io
import os
from collections.abc import Callable, Iterable, Sequence
from contextlib import suppress
from pathlib import Path
from typing import BinaryIO, cast

import can

from appsim.bus.wire import Bus, BusEvent
from appsim.errors import OutputError
from appsim.sim import PS_PER_SECOND
from appsim.watchdog import ctrl_c_waits

HEADER = f"{'time (s)':>11}  {'sender':<9} {'ID':>8}  {'type':<8} DLC  {'data':<23}  ACK by / error"
# The formats a trace is logged in, by the file's suffix: python-can writes them and `can.LogReader` reads them back
# (not .trc: python-can's TRC writer leaves remote frames out).
LOG_FORMATS: dict[str, type[can.io.generic.FileIOMessageWriter]] = {
    ".log": can.CanutilsLogWriter, ".asc": can.ASCWriter, ".blf": can.BLFWriter, ".csv": can.CSVWriter}
LOG_KINDS = {".log": "candump -L format", ".asc": "Vector ASC", ".blf": "Vector BLF", ".csv": "python-can CSV"}


def stamp(event: BusEvent) -> float:
    """When the trace and every log say an event happened: its end (the end of EOF, or of an error frame's delimiter),
    in seconds since the boards' reset. A receiver has a frame then, and stamps it then: candump shows the kernel's
    time of reception, CANKing the interface's (docs/traces.md)."""
    return event.end_ps / PS_PER_SECOND


def format_event(event: BusEvent) -> str:
    """One line per frame: its time (`stamp`), sender, ID, STD/EXT and RTR, DLC, data, who ACKed (or the error)."""
    frame = event.frame
    ident = f"{frame.can_id:08X}" if frame.extended else f"{frame.can_id:03X}"
    kind = ("EXT" if frame.extended else "STD") + (" RTR" if frame.remote else "")
    data = "" if frame.remote else frame.data.hex(" ").upper()
    tail = f"** {event.error}" if event.error else (",".join(event.acked_by) or "-")
    return (f"{stamp(event):11.6f}  {event.sender:<9} {ident:>8}  {kind:<8} "
            f"{frame.dlc:>3}  {data:<23}  {tail}")


def acks(event: BusEvent, nodes: Sequence[str]) -> str:
    """Who ACKed a frame, in a few words: "all" (every other node of `nodes`), "none", "all but station3", or the few
    that did ("monitor")."""
    if not event.acked_by:
        return "none"
    missing = [node for node in nodes if node != event.sender and node not in event.acked_by]
    if not missing:
        return "all"
    if len(missing) < len(event.acked_by):
        return "all but " + ", ".join(missing)
    return ", ".join(event.acked_by)


class TraceTable:
    """Bus events as the monitor lists them, one line a frame: in a terminal `format_event`'s lines, in Jupyter a table
    whose ACK column says who ACKed in a few words (`acks` among `nodes`) and whose error frames stand out in red.
    `column`, if given, is one more column: its title and what it shows for each event; `signals` (a DBC's reading,
    `appsim.bus.signals.Signals`) one more: each frame's message and signal values."""

    def __init__(self, events: Iterable[BusEvent], nodes: Sequence[str], *,
                 column: tuple[str, Callable[[BusEvent], str]] | None = None,
                 signals: Callable[[BusEvent], str] | None = None):
        self.events = list(events)
        self.nodes = list(nodes)
        self.column = column
        self.signals = signals

    def __len__(self) -> int:
        return len(self.events)

    def __str__(self) -> str:
        lines = [HEADER]
        for event in self.events:
            lines.append(format_event(event))
            if self.column is not None:
                lines.append(f"{'':>13}{self.column[0]}: {self.column[1](event)}")
            lines += signal_lines(event, self.signals)
        return "\n".join(lines)

    def _repr_html_(self) -> str:
        titles = ["time (s)", "sender", "ID", "type", "DLC", "data", "ACK", *([self.column[0]] if self.column else []),
                  *(["signals (DBC)"] if self.signals else [])]
        head = "".join(f"<th style='text-align:left;padding:1px 8px'>{html.escape(title)}</th>" for title in titles)
        rows = "".join(self._row(event) for event in self.events) or \
            f"<tr><td colspan='{len(titles)}' style='padding:1px 8px'>no frames</td></tr>"
        return (f"<table class='appsim-trace' style='border-collapse:collapse;font-size:12px;white-space:nowrap'>"
                f"<thead><tr>{head}</tr></thead><tbody>{rows}</tbody></table>")

    def _row(self, event: BusEvent) -> str:
        frame = event.frame
        ident = f"{frame.can_id:08X}" if frame.extended else f"{frame.can_id:03X}"
        kind = ("EXT" if frame.extended else "STD") + (" RTR" if frame.remote else "")
        data = "" if frame.remote else frame.data.hex(" ").upper()
        ack = (f"<b style='color:#cf222e'>error: {html.escape(event.error)}</b>" if event.error
               else html.escape(acks(event, self.nodes)))
        cells = [f"{event.start_ps / PS_PER_SECOND:.6f}", html.escape(event.sender), f"<code>{ident}</code>", kind,
                 str(frame.dlc), f"<code>{data}</code>" if data else "", ack]
        if self.column is not None:
            cells.append(html.escape(self.column[1](event)))
        if self.signals is not None:
            cells.append(html.escape(self.signals(event)))
        style = " style='background:#ffebe9'" if event.error else ""
        row = "".join(f"<td style='padding:1px 8px;text-align:left'>{cell}</td>" for cell in cells)
        return f"<tr{style}>{row}</tr>"


def bus_load(trace: Sequence[BusEvent], start_ps: int, end_ps: int) -> float:
    """Fraction of [start, end) during which the bus carried a frame or an error frame."""
    if end_ps <= start_ps:
        raise ValueError("bus load needs a time window with end after start")
    busy = sum(max(0, min(e.end_ps, end_ps) - max(e.start_ps, start_ps)) for e in trace)
    return busy / (end_ps - start_ps)


def error_counters(bus: Bus) -> str:
    """Each board's TEC, REC and error state, as CANKing's node status shows them."""
    lines = [f"{'node':<10} {'mode':<12} {'TEC':>4} {'REC':>4}  state"]
    for node in bus.boards():
        can = node.controller
        state = ("bus-off" if can.bus_off else "error-passive" if can.error_passive
                 else "warning" if max(can.tec, can.rec) >= 96 else "error-active")
        mode = can.opmode.words.lower()
        lines.append(f"{node.name:<10} {mode:<12} {can.tec:>4} {can.rec:>4}  {state}")
    return "\n".join(lines)


def summary(bus: Bus) -> str:
    """Frames, error frames and bus load over the whole run (not only what the trace keeps)."""
    trace, now = bus.trace, bus.sim.now
    load = trace.busy_ps / now if now > 0 else 0.0
    return (f"{trace.frames} frames, {trace.errors} error frames in {now / PS_PER_SECOND:.3f} s; "
            f"bus load {load:.1%} at {bus.bit_rate // 1000} kbit/s")


def signal_lines(event: BusEvent, signals: Callable[[BusEvent], str] | None) -> list[str]:
    """The line under an event's line that gives its signals (a DBC's reading), if there is one."""
    text = signals(event) if signals is not None else ""
    return [f"{'':>13}{text}"] if text else []


class LiveTrace:
    """Follows a bus trace as the simulation runs: `new_lines()` gives what appeared since last time (with `signals`,
    each frame's signal values on a line under it)."""

    def __init__(self, bus: Bus, signals: Callable[[BusEvent], str] | None = None):
        self.bus = bus
        self.seen = 0
        self.signals = signals

    def new_lines(self) -> list[str]:
        """The new events' lines; first, if some went out of the trace's window unseen, a line that says how many."""
        trace = self.bus.trace
        events = trace.since(self.seen)
        missed = trace.total - self.seen - len(events)
        self.seen = trace.total
        lines = [line for event in events for line in (format_event(event), *signal_lines(event, self.signals))]
        if missed:
            lines.insert(0, f"{'':>11}  ... frames not kept in memory: {missed} (the trace keeps the last "
                            f"{trace.window}; a log keeps every one)")
        return lines


def to_message(event: BusEvent, channel: str | int) -> can.Message:
    """The frame as python-can logs it, at its `stamp`."""
    frame = event.frame
    if event.error:
        return can.Message(timestamp=stamp(event), is_error_frame=True, channel=channel)
    return can.Message(timestamp=stamp(event), arbitration_id=frame.can_id,
                       is_extended_id=frame.extended, is_remote_frame=frame.remote, dlc=frame.dlc,
                       data=frame.data, channel=channel)


class WholeRecords(io.RawIOBase):
    """The file under a python-can writer. What the writer writes waits here until `commit()` gives it to the operating
    system in one go, so the file grows by whole records only; a write that fails (a full disk) cuts the file back to
    its last whole record."""

    def __init__(self, path: Path):
        super().__init__()
        self.name = str(path)
        self._fd = os.open(path, os.O_WRONLY | os.O_CREAT | os.O_TRUNC, 0o666)
        self._pending = bytearray()
        self._position = 0              # the operating system's file position
        self._whole = 0                 # the file's length after the last commit

    def writable(self) -> bool:
        return True

    def seekable(self) -> bool:
        return True

    def write(self, data: bytes) -> int:    # type: ignore[override]
        self._pending += data
        return len(data)

    def tell(self) -> int:
        return self._position + len(self._pending)

    def seek(self, offset: int, whence: int = os.SEEK_SET) -> int:
        self.commit()
        self._position = os.lseek(self._fd, offset, whence)
        return self._position

    def commit(self) -> None:
        """Write everything pending; if that fails, the file is cut back to what the last commit left, and it raises."""
        pending, self._pending = bytes(self._pending), bytearray()
        try:
            done = 0
            while done < len(pending):
                done += os.write(self._fd, pending[done:])
        except OSError:
            os.ftruncate(self._fd, self._whole)
            self._position = os.lseek(self._fd, self._whole, os.SEEK_SET)
            raise
        self._position += len(pending)
        self._whole = max(self._whole, self._position)

    def close(self) -> None:
        if self.closed:
            return
        try:
            self.commit()
        finally:
            os.close(self._fd)
            super().close()


def cannot_write(path: Path, error: OSError) -> OutputError:
    """The error for a file the kit cannot write, in words that say what to do."""
    reason = {errno.ENOENT: f"there is no directory {path.parent}: create it first, or give another path",
              errno.ENOSPC: "the disk is full",
              errno.EDQUOT: "the disk quota is used up",
              errno.EROFS: "that file system is read-only: give a path where you can write",
              errno.EACCES: "no permission to write there: give a path where you can write",
              errno.EISDIR: "that is a directory: give a file name such as trace.log"}.get(error.errno or 0)
    reason = reason or error.strerror or str(error)
    return OutputError(f"cannot write {path}: {reason}")


class EventFile:
    """A file the bus's events go to as it carries them, each record handed to the operating system whole as it
    happens: a run cut short (Ctrl-C, a crash, a kill) leaves a file readable to its last event, and a full disk ends it
    at its last whole record with an `OutputError` that says so. Opening it is the check that the path can be written.
    A format says what `kind` of file it is, how it `_record`s an event and how it `_finish`es."""

    kind = ""

    def __init__(self, path: str | Path):
        self.path = Path(path)
        self.written = 0                 # events in the file
        self._closed = False
        try:
            self._file = WholeRecords(self.path)
        except OSError as error:
            raise cannot_write(self.path, error) from None

    def _record(self, event: BusEvent) -> None:
        raise NotImplementedError

    def _finish(self) -> None:
        raise NotImplementedError

    def write(self, event: BusEvent) -> None:
        """One more event in the file, given to the operating system before this returns; Ctrl-C waits for it."""
        with ctrl_c_waits():
            self._record(event)
            self._commit()
            self.written += 1

    def _commit(self) -> None:
        try:
            self._file.commit()
        except OSError as error:
            self.close()
            holds = f". The log holds the run's first {self.written} frames, each one whole" if self.written else ""
            raise OutputError(f"{cannot_write(self.path, error)}{holds}") from None

    def close(self) -> None:
        """End the file as its format ends: after a failed write, as far as it goes."""
        if self._closed:
            return
        self._closed = True
        with suppress(OSError):         # after a failed write: the file was cut back to its last whole record
            self._finish()
        with suppress(OSError):
            self._file.close()

    def __enter__(self) -> EventFile:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()


class TraceLog(EventFile):
    """A CAN log in the format its file's suffix names (`LOG_FORMATS`), written by python-can's writer as the bus
    carries each event: `can.LogReader` reads it back to its last frame, at the times the trace shows (`stamp`)."""

    def __init__(self, path: str | Path, *, channel: str = "vcan0"):
        suffix = Path(path).suffix.lower()
        if suffix not in LOG_FORMATS:
            raise OutputError(f"cannot write a CAN log named {Path(path).name}: use .log (candump), .asc (Vector), "
                              ".blf (Vector binary) or .csv")
        super().__init__(path)
        self.kind = LOG_KINDS[suffix]
        self._channel: str | int = channel if suffix == ".log" else 0    # python-can's first; Vector's channel 1
        self._writer: can.io.generic.FileIOMessageWriter
        # python-can counts an .asc's and a .blf's times from their first frame: these count from reset (time 0), as
        # the trace, the .log and the .csv do, so every one gives a frame the same time.
        if suffix == ".blf":            # one container per frame: stored, as there is nothing to compress in one
            # BLFWriter's annotation names typing.BinaryIO, which no io class subclasses; it writes, tells and seeks
            self._writer = can.BLFWriter(cast(BinaryIO, self._file), compression_level=0)
            self._writer.start_timestamp = 0.0
        else:
            text = io.TextIOWrapper(self._file, encoding="utf-8", write_through=True)
            writer = LOG_FORMATS[suffix]
            self._writer = writer(text, channel=channel) if suffix == ".log" else writer(text)
            if isinstance(self._writer, can.ASCWriter):     # the measurement starts at reset, every node error active
                self._writer.log_event("CAN 1 Status:chip status error active", 0.0)
        self._commit()                  # the format's header: a full disk shows now, before the run

    def _record(self, event: BusEvent) -> None:
        self._writer.on_message_received(to_message(event, self._channel))
        if isinstance(self._writer, can.BLFWriter):
            self._writer._flush()       # the writer's own buffer would hold 128 kB of frames back

    def _finish(self) -> None:
        """ASC's last line, BLF's header."""
        self._writer.stop()


def write_log(events: Iterable[BusEvent], path: str | Path, *, channel: str = "vcan0") -> Path:
    """Write a trace in the format the file's suffix names: .log (candump -L), .asc, .blf or .csv."""
    with TraceLog(path, channel=channel) as log:
        for event in events:
            log.write(event)
    return log.path
