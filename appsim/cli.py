"""The `appsim` command: run the workshop's firmware on simulated APP023 boards from a terminal.

`appsim demo` is the kit's main job; `board`, `classroom`, `monitor` run firmware; `bittiming` calculates.
"""
from __future__ import annotations

import argparse
import sys
from collections.abc import Callable
from pathlib import Path

from typing import TextIO

import can

from appsim.board.app023 import APP023
from appsim.bus.wire import Bus
from appsim.workshop.classroom import EXERCISES, SOLUTIONS, STATIONS, Classroom, station_defines, station_ids
from appsim.bus.link import BusLink
from appsim.firmware.loader import FirmwareError, constants, load_firmware
from appsim.bus.monitor import HEADER, LiveTrace, error_counters, summary, write_log
from appsim.bus.realtime import WallClock
from appsim.sim import PS_PER_SECOND, Simulator
from appsim.board.usbcdc import UsbCdc

KIT = Path(__file__).resolve().parent.parent
CLASSROOM_BIT_RATE = 125_000
TRACE_LINES_SHOWN = 40


def _potentiometer(text: str) -> int:
    value = int(text, 0)
    if not 0 <= value <= 1023:
        raise argparse.ArgumentTypeError(f"the potentiometer on AN0 gives a 10-bit value, 0..1023; got {value}")
    return value


def _seconds(text: str, what: str = "simulated time") -> float:
    value = float(text)
    if not 0 < value <= 3600:
        raise argparse.ArgumentTypeError(f"{what} must be between 0 and 3600 s; got {value}")
    return value


def _wall_seconds(text: str) -> float:
    return _seconds(text, "the time limit (wall-clock seconds)")


def _exercise(text: str) -> int:
    value = int(text.lower().removeprefix("ex"))
    if value not in EXERCISES:
        raise argparse.ArgumentTypeError(f"the workshop has exercises 1..6 (EX1.C .. EX6.C); got {text}")
    return value


def _station(text: str) -> int:
    value = int(text)
    if not 1 <= value <= STATIONS:
        raise argparse.ArgumentTypeError(f"stations are numbered 1..{STATIONS} (MESSAGE_ID1 0x100 .. 0x150)")
    return value


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
    with UsbCdc(board, transport=args.transport) as usb:
        protocol = "SLCAN (python-can: interface='slcan')" if args.slcan else "text lines, 19200 8N1"
        print(f"Demo1 CAN monitor on the USB-CDC port {usb.url}  [{protocol}]\n"
              f"  open it with: python -m serial.tools.miniterm {usb.url} 19200   (or screen, minicom)\n"
              f"  running the classroom (exercise {args.exercise}) in real time for {args.seconds:g} s; "
              "Ctrl-C stops", file=out)
        session.run(args.seconds, live=False, real_time=True, pollers=(usb.poll,))
        print(f"{len(session.bus.frames())} frames on the bus; {usb.lost_bytes} bytes lost on the USB side",
              file=out)
    return 0


def cmd_bittiming(args: argparse.Namespace) -> int:
    from appsim.can.bittiming import calculate, format_table
    solutions = calculate(args.bit_rate, args.fosc)
    if not solutions:
        print(f"no valid bit timing gives exactly {args.bit_rate} bit/s at Fosc {args.fosc} Hz "
              "(8..25 TQ per bit, BRP 1..64)")
        return 1
    print(format_table(solutions[: args.top]))
    return 0


def cmd_check(args: argparse.Namespace) -> int:
    """One exercise, checked as in the notebook: the verdict, and exit status 0 only with full marks."""
    from appsim.workshop.checks import check
    verdict = check(args.exercise, args.firmware, seed=args.seed)
    print(verdict)
    return 0 if verdict.passed else 1


def cmd_grade(args: argparse.Namespace) -> int:
    from appsim.workshop.grade import GradeError, run
    from appsim.workshop.sandbox import Limits
    try:
        run(args.paths, results=args.json, csv_path=args.csv, gradescope_path=args.gradescope, jobs=args.jobs,
            seed=args.seed, limits=Limits(time_s=args.time_limit, stall_s=min(10.0, args.time_limit)))
    except GradeError as error:
        print(f"appsim grade: {error}", file=sys.stderr)
        return 2
    except KeyboardInterrupt:
        print(f"\nappsim grade: interrupted; what was graded is in {args.json}: run the same command again to "
              "resume without regrading it", file=sys.stderr)
        return 130
    return 0


def build_parser() -> argparse.ArgumentParser:
    parser = argparse.ArgumentParser(
        prog="appsim",
        description="CAN Workshop 202 on simulated Microchip APP023 boards (PIC18F8680 ECAN + AN738). "
                    "Firmware is a Python file that reads like the workshop's C: "
                    "`from appsim.firmware import *` and a main() that loops forever. "
                    "Everything runs on a simulated clock, deterministic, with no hardware; "
                    "--interface/--channel join any python-can bus (a vcan, a real adapter) in real time.")
    commands = parser.add_subparsers(dest="command", required=True, metavar="COMMAND")

    demo = commands.add_parser(
        "demo", help="the main job: a whole classroom at work, its trace and every LCD",
        description="The master console and six stations, station k working on exercise k, for a few "
                    "simulated seconds: prints the monitor trace, the error counters and every LCD, and "
                    "writes the trace (candump .log and .asc) and a picture of the LCDs into --out.")
    demo.add_argument("--out", type=Path, default=Path("appsim-demo"),
                      help="directory for trace.log, trace.asc and lcds.png (default ./appsim-demo)")

    board = commands.add_parser(
        "board", help="run one firmware file on one simulated board",
        description="Run FIRMWARE (a .py file with main()) on one APP023 board (station 1) and print what "
                    "it sent and received and its LCD. Alone on the simulated bus a Normal-mode node gets "
                    "no ACK; with --interface/--channel it joins that bus in real time.")
    board.add_argument("firmware", metavar="FIRMWARE", help="path of the firmware file, e.g. exercises/ex1.py")
    board.add_argument("--potentiometer", type=_potentiometer, default=666,
                       help="the A/D value on AN0, 0..1023 (default 666)")
    board.add_argument("--name", default="station1", help="the board's name in the trace (default station1)")

    classroom = commands.add_parser(
        "classroom", help="the master and six stations at one exercise",
        description="The master console and six stations running the solution of one exercise. "
                    "--join puts your firmware on a station. With --interface socketcan --channel vcan0 the "
                    "whole workshop goes on that bus in real time (candump vcan0 shows it).")
    classroom.add_argument("--exercise", type=_exercise, default=6, help="1..6 (default 6)")
    classroom.add_argument("--join", metavar="FIRMWARE", help="your firmware file, on --station")
    classroom.add_argument("--station", type=_station, default=1, help="which station your board is (1..6)")
    classroom.add_argument("--log", type=Path, help="write the trace: .log (candump), .asc, .blf, .csv, .trc")
    classroom.add_argument("--full-trace", action="store_true", help="print every frame, not the first 40")

    monitor = commands.add_parser(
        "monitor", help="Demo1: the CAN monitor's USB-CDC serial port, live",
        description="The classroom runs in real time with one more board running Demo1, the CAN monitor. "
                    "Its USB-CDC port appears on this PC as a serial port (a pty) that screen, minicom, "
                    "pyserial open. --slcan sets DSW2 switch 1: the board speaks SLCAN, so python-can's "
                    "'slcan' interface can use it as a CAN adapter.")
    monitor.add_argument("--exercise", type=_exercise, default=2, help="what the classroom runs (default 2)")
    monitor.add_argument("--slcan", action="store_true", help="SLCAN (Lawicel) protocol instead of text lines")
    monitor.add_argument("--transport", choices=("pty", "socket"), default="pty",
                         help="pty (a /dev/pts path) or socket (socket://127.0.0.1:PORT for pyserial)")

    for sub, default_seconds in ((demo, 2.0), (board, 0.5), (classroom, 2.0), (monitor, 60.0)):
        sub.add_argument("--seconds", type=_seconds, default=default_seconds,
                         help=f"simulated time to run (default {default_seconds:g} s)")
    for sub in (demo, classroom, monitor):
        sub.add_argument("--seed", type=int, default=202,
                         help="seed of the stations' potentiometer values (default 202): same seed, same run")
    for sub in (board, classroom, monitor):
        sub.add_argument("--interface", help="python-can interface to join: socketcan, virtual, udp_multicast, "
                                             "pcan, kvaser, slcan ... (default: the simulated bus alone)")
        sub.add_argument("--channel", help="python-can channel, e.g. vcan0, can0, /dev/ttyACM0")
    demo.set_defaults(handler=cmd_demo)
    board.set_defaults(handler=cmd_board)
    classroom.set_defaults(handler=cmd_classroom)
    monitor.set_defaults(handler=cmd_monitor)

    timing = commands.add_parser("bittiming", help="list BRGCON settings for a bit rate",
                                 description="Every valid PIC18F8680 bit timing for a bit rate, best "
                                             "sample point first, with the BRGCON1..3 values.")
    timing.add_argument("bit_rate", type=int, nargs="?", default=CLASSROOM_BIT_RATE,
                        help="bit rate in bit/s (default 125000, the classroom bus)")
    timing.add_argument("--fosc", type=int, default=40_000_000, help="oscillator frequency in Hz (default 40 MHz)")
    timing.add_argument("--top", type=int, default=10, help="how many settings to list (default 10)")
    timing.set_defaults(handler=cmd_bittiming)

    grade = commands.add_parser(
        "grade", help="grade a class: every submission's exercises, each firmware in a sandboxed process",
        description="Grade submissions: PATH is a directory holding ex1.py .. ex6.py, demo1_monitor.py (or "
                    "notebooks whose firmware cell is tagged `firmware`), a directory of those, or a .zip. "
                    "Each record is appended to --json as it is graded; the same command again resumes. "
                    "See docs/grading.md.")
    grade.add_argument("paths", nargs="+", type=Path, metavar="PATH", help="submissions, classes or zips")
    grade.add_argument("--json", type=Path, default=Path("appsim-grades.jsonl"),
                       help="JSON-lines results, one record per submission (default ./appsim-grades.jsonl)")
    grade.add_argument("--csv", type=Path, help="write the gradebook: a row per submission, a column per exercise")
    grade.add_argument("--gradescope", type=Path,
                       help="Gradescope results.json (one submission), else a directory of NAME.json")
    grade.add_argument("--jobs", type=int, default=None, help="submissions graded at once (default: the cores)")
    grade.add_argument("--seed", type=int, help="seed of the random inputs (default: drawn, printed, recorded)")
    grade.add_argument("--time-limit", type=_wall_seconds, default=60.0,
                       help="wall-clock seconds per exercise (default 60; a few seconds without a register "
                            "access stop it)")
    grade.set_defaults(handler=cmd_grade)

    checking = commands.add_parser(
        "check", help="check your firmware for one exercise, as the notebook does",
        description="Run FIRMWARE (default: exercises/exN.py) in a simulated classroom and judge what it did on "
                    "the bus and the board: the same check the notebook's last cell runs and `appsim grade` uses. "
                    "Exit status 0 with full marks.")
    checking.add_argument("exercise", choices=("ex1", "ex2", "ex3", "ex4", "ex5", "ex6", "demo1"),
                          metavar="EXERCISE", help="ex1 .. ex6 or demo1")
    checking.add_argument("firmware", nargs="?", help="your firmware file (default: exercises/EXERCISE.py)")
    checking.add_argument("--seed", type=int, help="seed of the random inputs (default: a fresh one, printed)")
    checking.set_defaults(handler=cmd_check)
    return parser


def main(argv: list[str] | None = None) -> int:
    args = build_parser().parse_args(argv)
    try:
        return args.handler(args)
    except FirmwareError as error:
        print(f"appsim: {error}", file=sys.stderr)
        return 2
    except BrokenPipeError:          # `appsim demo | head`: the reader has all it wanted
        sys.stdout = None
        return 0


if __name__ == "__main__":
    sys.exit(main())
