"""A run of the kit as a command gives it: one simulated bus, its boards, how it runs (alone, as fast as it can, or
linked to an outside bus in real time), and what it prints and writes. `appsim.cli` parses; this does.
"""
from __future__ import annotations

import argparse
import sys
from collections.abc import Callable
from pathlib import Path
from typing import TextIO

import can

from appsim.board.app023 import APP023
from appsim.board.usbcdc import UsbCdc
from appsim.bus.link import BusLink
from appsim.bus.monitor import HEADER, LiveTrace, error_counters, summary, write_log
from appsim.bus.realtime import WallClock
from appsim.bus.wire import Bus
from appsim.firmware.loader import constants, load_firmware
from appsim.sim import PS_PER_SECOND, Simulator
from appsim.workshop.classroom import Classroom, station_defines
from appsim.workshop.course import CLASSROOM_BIT_RATE, SOLUTIONS, STATIONS, station_ids

TRACE_LINES_SHOWN = 40


class Session:
    """One simulated bus, and how it runs: as fast as it can, or linked to an outside bus in real time."""

    def __init__(self, args: argparse.Namespace, out: TextIO):
        self.sim = Simulator()
        self.bus = Bus(self.sim, CLASSROOM_BIT_RATE)
        self.out = out
        self.link: BusLink | None = None
        self.trace = LiveTrace(self.bus)
        if getattr(args, "interface", None):
            try:
                self.link = BusLink(self.bus, interface=args.interface, channel=args.channel)
            except (can.CanError, ValueError, OSError, ImportError) as error:
                raise SystemExit(f"appsim: cannot open the python-can bus interface={args.interface!r} "
                                 f"channel={args.channel!r}: {error}") from None

    def run(self, seconds: float, *, live: bool, real_time: bool = False,
            pollers: tuple[Callable[[], None], ...] = ()) -> None:
        """Run `seconds` of simulated time: as fast as it can, or, linked (or `real_time`), paced to the
        wall clock with `pollers` and the link polled between slices, and the trace shown live if `live`."""
        if self.link is None and not real_time:
            self._fast(seconds)
            return
        clock = WallClock(self.sim)
        for poll in pollers:
            clock.add_poller(poll)
        if self.link is not None:
            clock.add_poller(self.link.poll)
            print(f"linked to {self.link.outside.channel_info}, running in real time for {seconds:g} s "
                  "(Ctrl-C stops)", file=self.out)
        if live:
            clock.add_poller(lambda: self._show(self.trace.new_lines()))
        try:
            clock.run(seconds)
        except KeyboardInterrupt:
            print("stopped", file=self.out)
        finally:
            if self.link is not None:
                print(self.link.report(), file=self.out)
                self.link.close()

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

    def print_trace(self, limit: int | None = TRACE_LINES_SHOWN) -> None:
        lines = self.trace.new_lines()
        print(HEADER, file=self.out)
        self._show(lines if limit is None else lines[:limit])
        if limit is not None and len(lines) > limit:
            print(f"{'':>11}  ... {len(lines) - limit} more frames (see the trace log)", file=self.out)
        print(summary(self.bus), file=self.out)


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
    figure.savefig(path, dpi=100)
    plt.close(figure)
    return path


def run_board(firmware: Path, *, seconds: float, potentiometer: int, out: TextIO | None = None,
              args: argparse.Namespace | None = None) -> APP023:
    """One board on its own bus (or on an outside bus); prints what it did and its LCD."""
    out = out or sys.stdout
    session = Session(args or argparse.Namespace(), out)
    name = getattr(args, "name", None) or "station1"
    board = APP023(session.bus, name, potentiometer=potentiometer)
    process = board.run(firmware)
    print(f"APP023 '{name}' running {firmware} for {seconds:g} s (simulated), "
          f"potentiometer {potentiometer}, bus {session.bus.bit_rate // 1000} kbit/s", file=out)
    session.run(seconds, live=True)
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
    if process.failure is not None:
        print(f"  the firmware stopped with an error:\n{process.failure_text}", file=out)
    return board


def workshop_in_progress(bus: Bus, seed: int) -> Classroom:
    """The classroom mid-workshop: station k works on exercise k, so every kind of traffic is on the bus."""
    classroom = Classroom(bus, 6, seed=seed)
    for k in range(1, STATIONS):
        firmware = SOLUTIONS / f"ex{k}.py"
        classroom.join(firmware, k, defines=station_defines(constants(firmware), k))
    return classroom


def cmd_demo(args: argparse.Namespace) -> int:
    out = sys.stdout
    session = Session(args, out)
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
    args.out.mkdir(parents=True, exist_ok=True)
    log = write_log(session.bus.trace, args.out / "trace.log")
    asc = write_log(session.bus.trace, args.out / "trace.asc")
    picture = save_lcd_picture(classroom.boards, args.out / "lcds.png")
    print(f"\nwrote {log} (candump -L format), {asc} (Vector ASC) and {picture} (every LCD)", file=out)
    return 0


def cmd_board(args: argparse.Namespace) -> int:
    run_board(Path(args.firmware), seconds=args.seconds, potentiometer=args.potentiometer, args=args)
    return 0


def cmd_classroom(args: argparse.Namespace) -> int:
    out = sys.stdout
    session = Session(args, out)
    classroom = Classroom(session.bus, args.exercise, seed=args.seed, monitor=session.link is None)
    if args.join:
        firmware = load_firmware(args.join)
        expected = station_ids(args.station)["MESSAGE_ID1"]
        own = getattr(firmware, "MESSAGE_ID1", expected)
        if own != expected:
            print(f"warning: {args.join} has MESSAGE_ID1 = 0x{own:03X} but station {args.station}'s is "
                  f"0x{expected:03X}. Two nodes sending one ID with different data destroy each other's "
                  "frames (bit errors): set MESSAGE_ID1 to your station's ID.", file=sys.stderr)
        classroom.join(firmware, args.station)
    who = f"; station{args.station} runs {args.join}" if args.join else ""
    print(f"Classroom at exercise {args.exercise}: the master and six stations running "
          f"solutions/ex{args.exercise}.py{who}.", file=out)
    session.run(args.seconds, live=True)
    if session.link is None:
        session.print_trace(limit=None if args.full_trace else TRACE_LINES_SHOWN)
    print("\n" + error_counters(session.bus) + "\n", file=out)
    print_lcds(classroom.boards, out)
    if args.log:
        print(f"wrote {write_log(session.bus.trace, args.log)}", file=out)
    return 0


def cmd_monitor(args: argparse.Namespace) -> int:
    """Demo1: the classroom plus a board running the CAN monitor, its USB-CDC port open on this PC."""
    out = sys.stdout
    session = Session(args, out)
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
        print(f"{len(session.bus.frames())} frames on the bus\n{usb.report()}", file=out)
    return 0
