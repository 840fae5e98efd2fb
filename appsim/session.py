"""A run of the kit as a command gives it: one simulated bus, its boards, how it runs (alone, as fast as it can, or
linked to an outside bus in real time), and what it prints and writes. `appsim.cli` parses; this does.
"""
from __future__ import annotations

import argparse
import functools
import sys
from collections.abc import Callable, Sequence
from pathlib import Path
from typing import TextIO

import can

from appsim.board.app023 import APP023
from appsim.board.usbcdc import UsbCdc
from appsim.bus.link import BusLink
from appsim.bus.monitor import HEADER, EventFile, LiveTrace, TraceLog, cannot_write, error_counters, summary
from appsim.bus.realtime import WallClock
from appsim.bus.waveform import WaveformLog
from appsim.bus.wire import Bus
from appsim.firmware.loader import constants, load_firmware
from appsim.sim import PS_PER_SECOND, Simulator
from appsim.workshop.classroom import Classroom, station_defines
from appsim.workshop.course import CLASSROOM_BIT_RATE, SOLUTIONS, STATIONS, station_ids
from appsim.workshop.faults import board_fault

TRACE_LINES_SHOWN = 40


class Session:
    """One simulated bus, and how it runs: as fast as it can, or linked to an outside bus in real time.

    Its files (`logs`: the --log paths, then the --vcd waveform) are opened first, so a path that cannot be written
    stops the command before anything runs (`OutputError`); each gets every event as the bus carries it. A session is
    closed (files ended, link closed and its report printed) when its `with` block ends."""

    def __init__(self, args: argparse.Namespace, out: TextIO, *, logs: Sequence[Path] = ()):
        self.sim = Simulator()
        self.bus = Bus(self.sim, CLASSROOM_BIT_RATE)
        self.out = out
        self.link: BusLink | None = None
        self.trace = LiveTrace(self.bus)
        self.logs: list[EventFile] = []
        self.reported: set[str] = set()          # boards whose stop was reported
        try:
            for path in logs:
                self._keep(TraceLog(path))
            if getattr(args, "vcd", None):
                self._keep(WaveformLog(args.vcd, self.bus))
            if getattr(args, "interface", None):
                try:
                    self.link = BusLink(self.bus, interface=args.interface, channel=args.channel)
                except (can.CanError, ValueError, OSError, ImportError) as error:
                    raise SystemExit(f"appsim: cannot open the python-can bus interface={args.interface!r} "
                                     f"channel={args.channel!r}: {error}") from None
        except BaseException:
            self.close()
            raise

    def _keep(self, log: EventFile) -> None:
        self.logs.append(log)
        self.bus.trace.listeners.append(log.write)

    def run(self, seconds: float, *, live: bool, real_time: bool = False,
            pollers: tuple[Callable[[], None], ...] = ()) -> None:
        """Run `seconds` of simulated time: as fast as it can, or, linked (or `real_time`), paced to the
        wall clock with `pollers` and the link polled between slices, the trace shown live if `live`, and a board
        that stops reported when it does."""
        if self.link is None and not real_time:
            self._fast(seconds)
            return
        clock = WallClock(self.sim)
        for poll in (*pollers, self.report_failures):
            clock.add_poller(poll)
        if self.link is not None:
            clock.add_poller(self.link.poll)
            print(f"linked to {self.link.outside.channel_info}, running in real time for {seconds:g} s "
                  "(Ctrl-C stops)", file=self.out)
        if live:
            clock.add_poller(lambda: self._show(self.trace.new_lines()))
        clock.run(seconds)

    def _fast(self, seconds: float) -> None:
        end = round(seconds * PS_PER_SECOND)
        step = PS_PER_SECOND // 2
        progress = seconds >= 5 and sys.stderr.isatty()
        while self.sim.now < end:
            self.sim.run(until=min(self.sim.now + step, end))
            if progress:
                print(f"\r  simulated {self.sim.now / PS_PER_SECOND:6.1f} / {seconds:g} s", end="", file=sys.stderr)
        if progress:
            print(file=sys.stderr)

    def _show(self, lines: list[str]) -> None:
        for line in lines:
            print(line, file=self.out)

    def print_trace(self, limit: int | None = TRACE_LINES_SHOWN, *, more: str = "") -> None:
        """The trace's new lines, the first `limit` of them; past the limit, how many more and where they are (in a
        log, or `more`: how this command shows them)."""
        lines = self.trace.new_lines()
        print(HEADER, file=self.out)
        self._show(lines if limit is None else lines[:limit])
        if limit is not None and len(lines) > limit:
            logged = next((log.path for log in self.logs if isinstance(log, TraceLog)), None)
            where = f"all of them are in {logged}" if logged else "--log trace.log keeps them"
            print(f"{'':>11}  ... {len(lines) - limit} more frames ({where}{'; ' + more if more else ''})",
                  file=self.out)
        print(summary(self.bus), file=self.out)

    def print_written(self) -> None:
        """What each of the session's files holds, now that the run is over."""
        for log in self.logs:
            print(f"wrote {log.path} ({log.kind}, {log.written} frames)", file=self.out)

    def report_failures(self) -> None:
        """Say once, for each board whose firmware is no longer running, which file it ran and why it stopped, with
        the line (`reported` names them)."""
        for mcu in self.bus.boards():
            process = mcu.process
            if process is None or mcu.name in self.reported or (fault := board_fault(process)) is None:
                continue
            self.reported.add(mcu.name)
            ran = f" ({process.filename})" if process.filename else ""
            print(f"{mcu.name}{ran} stopped: {fault.message}", file=sys.stderr)

    def interrupted(self) -> str:
        """What a Ctrl-C leaves: where the run stopped and what the logs hold."""
        kept = "".join(f"; {log.path} holds its first {log.written} frames" for log in self.logs)
        return f"interrupted (Ctrl-C) at {self.sim.now / PS_PER_SECOND:.3f} s of simulated time{kept}"

    def close(self) -> None:
        """End the logs, close the link (its report says what it carried and refused)."""
        for log in self.logs:
            log.close()
        if self.link is not None:
            print(self.link.report(), file=self.out)
            self.link.close()
            self.link = None

    def __enter__(self) -> Session:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()


Body = Callable[[argparse.Namespace, Session], None]
Command = Callable[[argparse.Namespace], int]


def logs_asked(args: argparse.Namespace) -> list[Path]:
    """The logs `--log` names, if any."""
    return list(args.log or [])


def session_command(logs: Callable[[argparse.Namespace], list[Path]] = logs_asked) -> Callable[[Body], Command]:
    """A command that runs a session: its `logs` are checked before anything runs (an `OutputError` for the caller);
    a board that stopped is reported and makes the exit status 1; after Ctrl-C, the KeyboardInterrupt for the caller
    says where the run stopped and what the logs hold."""
    def decorate(body: Body) -> Command:
        @functools.wraps(body)
        def command(args: argparse.Namespace) -> int:
            with Session(args, sys.stdout, logs=logs(args)) as session:
                try:
                    body(args, session)
                except KeyboardInterrupt:
                    session.close()
                    raise KeyboardInterrupt(session.interrupted()) from None
                session.report_failures()
                return 1 if session.reported else 0
        return command
    return decorate


def check_writable(path: Path) -> None:
    """An `OutputError` now if `path` could not be written later; the file is left as it was."""
    existed = path.exists()
    try:
        with path.open("ab"):
            pass
    except OSError as error:
        raise cannot_write(path, error) from None
    if not existed:
        path.unlink()


def print_lcds(boards: list[APP023], out: TextIO) -> None:
    """Every board's LCD, side by side, three to a row."""
    for row in range(0, len(boards), 3):
        group = boards[row:row + 3]
        print("   ".join(f"{board.name:<23}" for board in group), file=out)
        screens = [str(board.glcd).splitlines() for board in group]
        for lines in zip(*screens):
            print("   ".join(f"{line:<23}" for line in lines), file=out)


def save_lcd_picture(boards: list[APP023], path: Path) -> Path:
    """One PNG with every board's LCD, named, as they would look on the desks."""
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    columns = min(3, len(boards))
    rows = -(-len(boards) // columns)
    figure, axes = plt.subplots(rows, columns, figsize=(4.2 * columns, 2.4 * rows), squeeze=False)
    for ax in axes.flat:
        ax.axis("off")
    for ax, board in zip(axes.flat, boards):
        board.glcd.picture(ax=ax)
        ax.set_title(board.name, fontsize=10)
    figure.tight_layout()
    try:
        figure.savefig(path, dpi=100)
    except OSError as error:
        raise cannot_write(path, error) from None
    finally:
        plt.close(figure)
    return path


def workshop_in_progress(bus: Bus, seed: int) -> Classroom:
    """The classroom mid-workshop: station k works on exercise k, so every kind of traffic is on the bus."""
    classroom = Classroom(bus, 6, seed=seed)
    for k in range(1, STATIONS):
        firmware = SOLUTIONS / f"ex{k}.py"
        classroom.join(firmware, k, defines=station_defines(constants(firmware), k))
    return classroom


def _demo_logs(args: argparse.Namespace) -> list[Path]:
    """The demo's --out folder, made if need be, and the logs it holds."""
    try:
        args.out.mkdir(parents=True, exist_ok=True)
    except OSError as error:
        raise cannot_write(args.out, error) from None
    return [args.out / "trace.log", args.out / "trace.asc"]


@session_command(logs=_demo_logs)
def cmd_demo(args: argparse.Namespace, session: Session) -> None:
    out = session.out
    check_writable(args.out / "lcds.png")
    classroom = workshop_in_progress(session.bus, args.seed)
    print("CAN Workshop 202, simulated: the master console and six APP023 stations on one 125 kbit/s bus.\n"
          "Station k is working on exercise k: Ex1 loopback (off the bus), Ex2 periodic data, Ex3 filters,\n"
          "Ex4 listen-only first, Ex5 RTR requests to the master, Ex6 answering the master's polls.\n"
          f"The PC's CAN interface (CANKing's) is on the bus too and ACKs. Running {args.seconds:g} s...\n",
          file=out)
    session.run(args.seconds, live=False)
    session.print_trace()
    print("\n" + error_counters(session.bus) + "\n", file=out)
    print_lcds(classroom.boards, out)
    picture = save_lcd_picture(classroom.boards, args.out / "lcds.png")
    print("", file=out)
    session.print_written()
    print(f"wrote {picture} (every LCD)", file=out)


@session_command()
def cmd_board(args: argparse.Namespace, session: Session) -> None:
    """One firmware file on one board, on its own bus (or on an outside bus): what it did and its LCD."""
    out, firmware = session.out, Path(args.firmware)
    board = APP023(session.bus, args.name, potentiometer=args.potentiometer)
    board.run(firmware)
    print(f"APP023 '{args.name}' running {firmware} for {args.seconds:g} s (simulated), "
          f"potentiometer {args.potentiometer}, bus {session.bus.bit_rate // 1000} kbit/s", file=out)
    session.run(args.seconds, live=True)
    mode = board.ecan.opmode.name.replace("_", "-").lower()
    print(f"  ECAN ends in {mode} mode (CANSTAT = 0x{board.ecan.read(0xF6E):02X}), "
          f"TEC {board.ecan.tec}, REC {board.ecan.rec}", file=out)
    for event in session.bus.loopback_trace:
        print(f"  {event.start_ps / PS_PER_SECOND:10.6f} s  sent {event.frame}  (loopback: inside the chip)",
              file=out)
        for _, what in event.received:
            print(f"  {event.end_ps / PS_PER_SECOND:10.6f} s  received: {what}", file=out)
    if session.link is None:
        session.print_trace()
    print(board.glcd, file=out)
    session.print_written()


@session_command()
def cmd_classroom(args: argparse.Namespace, session: Session) -> None:
    out = session.out
    classroom = Classroom(session.bus, args.exercise, seed=args.seed, monitor=session.link is None)
    station = args.station or 1
    if args.join:
        firmware = load_firmware(args.join)
        expected = station_ids(station)["MESSAGE_ID1"]
        own = getattr(firmware, "MESSAGE_ID1", expected)
        if own != expected:
            print(f"warning: {args.join} has MESSAGE_ID1 = 0x{own:03X} but station {station}'s is "
                  f"0x{expected:03X}. Two nodes sending one ID with different data destroy each other's "
                  "frames (bit errors): set MESSAGE_ID1 to your station's ID.", file=sys.stderr)
        classroom.join(firmware, station)
    who = f"; station{station} runs {args.join}" if args.join else ""
    print(f"Classroom at exercise {args.exercise}: the master and six stations running "
          f"solutions/ex{args.exercise}.py{who}.", file=out)
    session.run(args.seconds, live=True)
    if session.link is None:
        session.print_trace(limit=None if args.full_trace else TRACE_LINES_SHOWN, more="--full-trace prints them")
    print("\n" + error_counters(session.bus) + "\n", file=out)
    print_lcds(classroom.boards, out)
    session.print_written()


@session_command()
def cmd_monitor(args: argparse.Namespace, session: Session) -> None:
    """Demo1: the classroom plus a board running the CAN monitor, its USB-CDC port open on this PC."""
    out = session.out
    Classroom(session.bus, args.exercise, seed=args.seed, monitor=session.link is None)
    board = APP023(session.bus, "demo1")
    if args.slcan:
        board.dsw2.on(1)
    board.run(SOLUTIONS / "demo1_monitor.py")
    try:
        usb = UsbCdc(board, transport=args.transport)
    except OSError as error:
        raise SystemExit(f"appsim: cannot open the USB-CDC port ({args.transport}): {error}") from None
    with usb:
        protocol = "SLCAN (python-can: interface='slcan')" if args.slcan else "text lines, 19200 8N1"
        print(f"Demo1 CAN monitor on the USB-CDC port {usb.url}  [{protocol}]\n"
              f"  open it with: python -m serial.tools.miniterm {usb.url} 19200   (or screen, minicom)\n"
              f"  running the classroom (exercise {args.exercise}) in real time for {args.seconds:g} s; "
              "Ctrl-C stops", file=out)
        session.run(args.seconds, live=False, real_time=True, pollers=(usb.poll,))
        print(f"{session.bus.trace.frames} frames on the bus\n{usb.report()}", file=out)
        session.print_written()
