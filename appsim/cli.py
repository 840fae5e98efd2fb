"""The `appsim` command: run the workshop's firmware on simulated APP023 boards from a terminal.

`appsim demo` is the kit's main job; `board`, `classroom`, `monitor` run firmware; `bittiming` calculates.
"""
from __future__ import annotations

import argparse
import sys
from collections.abc import Callable
from pathlib import Path
from typing import Any

from appsim.can.bittiming import CLASSIC_CAN_MAX_BIT_RATE, FOSC_MAX_HZ
from appsim.errors import FirmwareError, OutputError
from appsim.workshop.course import CLASSROOM_BIT_RATE, STATIONS, exercise_name

HOUR, DAY = 3600, 86400
INTERRUPTED = 130               # the exit status after Ctrl-C: 128 + SIGINT, as shells report it


def _number(text: str, what: str, kind: Callable[[str], float] = int) -> Any:
    """`text` as a number of `kind`, or an argument error that says `what` was expected."""
    try:
        return kind(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"{what}; got {text!r}") from None


def _in_range(text: str, what: str, fits: Callable[[float], bool], kind: Callable[[str], float] = int) -> Any:
    value = _number(text, what, kind)
    if not fits(value):
        raise argparse.ArgumentTypeError(f"{what}; got {text}")
    return value


def _potentiometer(text: str) -> int:
    from appsim.chip.adc import FULL_SCALE
    return _in_range(text, f"the potentiometer on AN0 gives a 10-bit A/D value, a whole number 0..{FULL_SCALE}",
                     lambda value: 0 <= value <= FULL_SCALE, lambda t: int(t, 0))


def _seconds(text: str) -> float:
    return _in_range(text, f"a run lasts more than 0 and at most {DAY} seconds (a day)",
                     lambda value: 0 < value <= DAY, float)


def _cpu_seconds(text: str) -> float:
    return _in_range(text, f"the time limit is CPU seconds, more than 0 and at most {HOUR} (an hour)",
                     lambda value: 0 < value <= HOUR, float)


def _exercise_name(text: str) -> str:
    try:
        return exercise_name(text)
    except ValueError as error:
        raise argparse.ArgumentTypeError(str(error)) from None


def _classroom_exercise(text: str) -> int:
    try:
        name = exercise_name(text)
    except ValueError:
        name = None
    if name is None or name == "demo1":
        monitor = " (Demo1, the monitor, runs with: appsim monitor)" if name else ""
        raise argparse.ArgumentTypeError(f"the classroom's stations run Ex1..Ex6 (1..6, ex1..ex6); got {text!r}"
                                         + monitor)
    return int(name.removeprefix("ex"))


def _jobs(text: str) -> int:
    return _in_range(text, "--jobs is how many exercises are graded at once, a whole number: 1 or more",
                     lambda value: value >= 1)


def _station(text: str) -> int:
    return _in_range(text, f"stations are numbered 1..{STATIONS} (MESSAGE_ID1 0x100 .. 0x150)",
                     lambda value: 1 <= value <= STATIONS)


def _seed(text: str) -> int:
    return _number(text, "a seed is a whole number, e.g. 2024")


def _bit_rate(text: str) -> int:
    return _in_range(text, f"classic CAN runs at 1 bit/s .. {CLASSIC_CAN_MAX_BIT_RATE:,} bit/s (1 Mbit/s, ISO 11898): "
                           "give the bit rate in bit/s, e.g. 125000",
                     lambda value: 1 <= value <= CLASSIC_CAN_MAX_BIT_RATE)


def _fosc(text: str) -> int:
    return _in_range(text, f"Fosc is the PIC18F8680's clock in Hz, 1 .. {FOSC_MAX_HZ:,} (the data sheet's 40 MHz), "
                           "e.g. 40000000", lambda value: 1 <= value <= FOSC_MAX_HZ)


def _top(text: str) -> int:
    return _in_range(text, "--top is how many settings to list, a whole number: 1 or more", lambda value: value >= 1)


def _injection(text: str) -> tuple[str, str, int, int | None]:
    """NODE:KIND:BIT[:ID] -> the arguments of `Bus.inject` (node, kind, bit, can_id)."""
    from appsim.bus.bitlevel import ERROR_KINDS
    what = (f"an injected error is NODE:KIND:BIT[:ID], KIND one of {', '.join(ERROR_KINDS)}, BIT counted from SOF = 0, "
            "ID the frame's identifier (default: the node's next frame), e.g. station1:stuff:30:0x100")
    parts = text.split(":")
    if not 3 <= len(parts) <= 4 or parts[1] not in ERROR_KINDS:
        raise argparse.ArgumentTypeError(f"{what}; got {text!r}")
    bit = _in_range(parts[2], what, lambda value: value >= 0)
    can_id = _number(parts[3], what, lambda t: int(t, 0)) if len(parts) == 4 else None
    return parts[0], parts[1], bit, can_id


def cmd_demo(args: argparse.Namespace) -> int:
    from appsim import session
    return session.cmd_demo(args)


def cmd_board(args: argparse.Namespace) -> int:
    from appsim import session
    return session.cmd_board(args)


def cmd_classroom(args: argparse.Namespace) -> int:
    if args.station is not None and args.join is None:
        args.usage_error("--station says which station your firmware takes, so it goes with --join: "
                         "--join my_ex3.py --station 2")
    from appsim import session
    return session.cmd_classroom(args)


def cmd_monitor(args: argparse.Namespace) -> int:
    from appsim import session
    return session.cmd_monitor(args)


def cmd_bittiming(args: argparse.Namespace) -> int:
    from appsim.can.bittiming import calculate, format_table
    from appsim.chip.clock import FOSC_HZ
    fosc = args.fosc or FOSC_HZ
    solutions = calculate(args.bit_rate, fosc)
    if not solutions:
        print(f"no valid bit timing gives exactly {args.bit_rate} bit/s at Fosc {fosc} Hz "
              "(8..25 TQ per bit, BRP 1..64)")
        return 1
    print(format_table(solutions[: args.top]))
    return 0


def cmd_check(args: argparse.Namespace) -> int:
    """One exercise, checked as in the notebook: the verdict, and exit status 0 only with full marks."""
    from appsim.workshop.checks import check
    verdict = check(args.exercise, args.firmware, seed=args.seed, c_options=args.c_option)
    print(verdict)
    return 0 if verdict.passed else 1


def cmd_grade(args: argparse.Namespace) -> int:
    from appsim.errors import GradeError
    from appsim.workshop.grading.grade import run
    from appsim.workshop.sandbox.children import Limits
    try:
        run(args.paths, results=args.json, csv_path=args.csv, gradescope_path=args.gradescope, jobs=args.jobs,
            seed=args.seed, limits=Limits(time_s=args.time_limit, stall_s=min(10.0, args.time_limit),
                                          c_options=tuple(args.c_option)),
            trusted=args.trusted, regrade=args.regrade)
    except GradeError as error:
        print(f"appsim grade: {error}", file=sys.stderr)
        return 2
    except KeyboardInterrupt:
        print("\nappsim grade: interrupted; what was graded is kept in the results file: run the same command again "
              "to resume without grading it again", file=sys.stderr)
        return INTERRUPTED
    return 0


C18_OPTIONS = ("-Oi", "-k")          # appsim.firmware.c18.OPTIONS (not imported here: the C translator loads slowly)


def _c_option_value(text: str) -> str:
    option = text if text.startswith("-") else f"-{text}"
    if option not in C18_OPTIONS:
        raise argparse.ArgumentTypeError(f"{text!r} is not a C18 option the kit knows: -Oi (integer promotions, as "
                                         "ISO C has them), -k (plain char unsigned)")
    return option


def _c_option(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("--c-option", type=_c_option_value, action="append", default=[], metavar="OPTION",
                        help="an MPLAB C18 option for .c firmware, as its command line takes it: --c-option=-Oi "
                             "(integer promotions; C18's default has none), --c-option=-k (plain char unsigned); "
                             "may be given more than once")
    parser.add_argument("-Oi", dest="c_option", action="append_const", const="-Oi",
                        help="the same as --c-option=-Oi, as C18's command line writes it")


def build_parser() -> argparse.ArgumentParser:
    parser = argparse.ArgumentParser(
        prog="appsim",
        description="CAN Workshop 202 on simulated Microchip APP023 boards (PIC18F8680 ECAN + AN738). "
                    "Firmware is a Python file that reads like the workshop's C: "
                    "`from appsim.firmware import *` and a main() that loops forever; or the workshop's C itself, "
                    "a .c file for MPLAB C18 (see docs/c-firmware.md). "
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
        description="Run FIRMWARE (a .py file with main(), or a .c file) on one APP023 board (station 1) and print "
                    "what it sent and received and its LCD. Alone on the simulated bus a Normal-mode node gets "
                    "no ACK; with --interface/--channel it joins that bus in real time.")
    board.add_argument("firmware", metavar="FIRMWARE", help="path of the firmware file, e.g. exercises/ex1.py")
    board.add_argument("--potentiometer", type=_potentiometer, default=666,
                       help="the A/D value on AN0, 0..1023 (default 666)")
    board.add_argument("--name", default="station1", help="the board's name in the trace (default station1)")
    _c_option(board)

    classroom = commands.add_parser(
        "classroom", help="the master and six stations at one exercise",
        description="The master console and six stations running the solution of one exercise. "
                    "--join puts your firmware on a station. With --interface socketcan --channel vcan0 the "
                    "whole workshop goes on that bus in real time (candump vcan0 shows it).")
    classroom.add_argument("--exercise", type=_classroom_exercise, default=6, help="1..6, ex1..ex6 (default 6)")
    classroom.add_argument("--join", metavar="FIRMWARE", help="your firmware file (.py or .c), on --station")
    _c_option(classroom)
    classroom.add_argument("--station", type=_station,
                           help="with --join: which station your board takes, 1..6 (default 1); its MESSAGE_ID1 "
                                "must be that station's, 0x100 + 0x10 x (station - 1)")
    classroom.add_argument("--full-trace", action="store_true", help="print every frame, not the first 40")
    classroom.add_argument("--inject", type=_injection, action="append", metavar="NODE:KIND:BIT[:ID]",
                           help="make NODE see an error in its next frame (with identifier ID): KIND bit, stuff, "
                                "crc, form, ack or dominant, at bit BIT from SOF (docs/errors.md); give it again "
                                "for more")

    monitor = commands.add_parser(
        "monitor", help="Demo1: the CAN monitor's USB-CDC serial port, live",
        description="The classroom runs in real time with one more board running Demo1, the CAN monitor. "
                    "Its USB-CDC port appears on this PC as a serial port (a pty) that screen, minicom, "
                    "pyserial open. --slcan sets DSW2 switch 1: the board speaks SLCAN, so python-can's "
                    "'slcan' interface can use it as a CAN adapter.")
    monitor.add_argument("--exercise", type=_classroom_exercise, default=2,
                         help="what the classroom runs, 1..6 or ex1..ex6 (default 2)")
    monitor.add_argument("--firmware", type=Path, metavar="FIRMWARE",
                         help="your Demo1 firmware on the monitor board (default: solutions/demo1_monitor.py)")
    monitor.add_argument("--slcan", action="store_true", help="SLCAN (Lawicel) protocol instead of text lines")
    monitor.add_argument("--transport", choices=("pty", "socket"), default="pty",
                         help="pty (a /dev/pts path) or socket (socket://127.0.0.1:PORT for pyserial)")

    for sub, default_seconds in ((demo, 2.0), (board, 0.5), (classroom, 2.0)):
        sub.add_argument("--seconds", type=_seconds, default=default_seconds,
                         help=f"simulated time to run, up to a day (default {default_seconds:g} s)")
    monitor.add_argument("--seconds", type=_seconds, default=60.0,
                         help="how long the monitor runs, in seconds of real time: it stops then (default 60 s, "
                              "up to a day; Ctrl-C stops it sooner)")
    for sub in (demo, classroom, monitor):
        sub.add_argument("--seed", type=_seed, default=202,
                         help="seed of the stations' potentiometer values (default 202): same seed, same run")
    for sub in (demo, board, classroom, monitor):
        sub.add_argument("--vcd", type=Path, metavar="FILE",
                         help="write the CAN line's waveform as it goes, a VCD for PulseView or sigrok-cli's CAN "
                              "decoder (docs/traces.md)")
    for sub in (board, classroom, monitor):
        sub.add_argument("--log", type=Path, action="append", metavar="FILE",
                         help="write every frame as it goes: .log (candump), .asc, .blf or .csv (give --log again "
                              "for more formats); Ctrl-C or a crash leaves it readable to its last frame")
        sub.add_argument("--interface", help="python-can interface to join: socketcan, virtual, udp_multicast, "
                                             "pcan, kvaser, slcan ... (default: the simulated bus alone)")
        sub.add_argument("--channel", help="python-can channel, e.g. vcan0, can0, /dev/ttyACM0")
    demo.set_defaults(handler=cmd_demo)
    board.set_defaults(handler=cmd_board)
    classroom.set_defaults(handler=cmd_classroom, usage_error=classroom.error)
    monitor.set_defaults(handler=cmd_monitor)

    timing = commands.add_parser("bittiming", help="list BRGCON settings for a bit rate",
                                 description="Every valid PIC18F8680 bit timing for a classic CAN bit rate (up to "
                                             "1 Mbit/s), best sample point first, with the BRGCON1..3 values.")
    timing.add_argument("bit_rate", type=_bit_rate, nargs="?", default=CLASSROOM_BIT_RATE,
                        help="bit rate in bit/s, 1 .. 1000000 (default 125000, the classroom bus)")
    timing.add_argument("--fosc", type=_fosc, help="oscillator frequency in Hz, up to 40 MHz (default 40 MHz, the "
                                                   "APP023's)")
    timing.add_argument("--top", type=_top, default=10, help="how many settings to list (default 10)")
    timing.set_defaults(handler=cmd_bittiming)

    grade = commands.add_parser(
        "grade", help="grade a class: every submission's exercises, each firmware in a sandboxed process",
        description="Grade submissions: PATH is a directory holding ex1.py .. ex6.py, demo1_monitor.py (or in C "
                    "ex1.c .. ex6.c, demo1_monitor.c; or notebooks whose firmware cell is tagged `firmware`), a "
                    "directory of those, or a .zip. "
                    "Each record is appended to --json as it is graded; the same command again resumes. "
                    "See docs/grading.md.")
    grade.add_argument("paths", nargs="+", type=Path, metavar="PATH", help="submissions, classes or zips")
    grade.add_argument("--json", type=Path, default=None,
                       help="JSON-lines results, one record per submission (default: CLASS.grades.jsonl beside the "
                            "first PATH)")
    grade.add_argument("--csv", type=Path, help="write the gradebook: a row per submission, a column per exercise")
    grade.add_argument("--gradescope", type=Path,
                       help="Gradescope results.json (one submission), else a folder of NAME.json")
    grade.add_argument("--jobs", type=_jobs, default=None, help="exercises graded at once (default: the cores)")
    grade.add_argument("--seed", type=_seed, help="seed of the random inputs (default: the results file's, else drawn)")
    grade.add_argument("--time-limit", type=_cpu_seconds, default=60.0,
                       help="CPU seconds per exercise, the firmware's and the grader's for it (default 60); waiting "
                            "for a busy machine's CPU does not count; 10 s asleep stop it")
    grade.add_argument("--regrade", action="store_true",
                       help="grade every submission again (by default a submission whose files, seed and kit are "
                            "unchanged keeps its record)")
    grade.add_argument("--trusted", action="store_true",
                       help="run firmware WITHOUT operating-system isolation, where the machine has none (macOS, no "
                            "bubblewrap): only for code you trust")
    _c_option(grade)
    grade.set_defaults(handler=cmd_grade)

    checking = commands.add_parser(
        "check", help="check your firmware for one exercise, as the notebook does",
        description="Run FIRMWARE (default: exercises/exN.py) in a simulated classroom and judge what it did on "
                    "the bus and the board: the same check the notebook's last cell runs and `appsim grade` uses. "
                    "Exit status 0 with full marks.")
    checking.add_argument("exercise", type=_exercise_name, metavar="EXERCISE",
                          help="ex1 .. ex6 (or 1 .. 6, EX3 ...) or demo1")
    checking.add_argument("firmware", nargs="?",
                          help="your firmware file, .py or .c (default: exercises/EXERCISE.py)")
    checking.add_argument("--seed", type=_seed, help="seed of the random inputs (default: a fresh one, printed)")
    _c_option(checking)
    checking.set_defaults(handler=cmd_check)
    return parser


def main(argv: list[str] | None = None) -> int:
    args = build_parser().parse_args(argv)
    try:
        return args.handler(args)
    except (FirmwareError, OutputError) as error:
        print(f"appsim: {error}", file=sys.stderr)
        return 2
    except KeyboardInterrupt as interrupt:       # one line, which says what was kept where the command knows it
        print(f"appsim {args.command}: {str(interrupt) or 'interrupted (Ctrl-C)'}", file=sys.stderr)
        return INTERRUPTED
    except BrokenPipeError:          # `appsim demo | head`: the reader has all it wanted
        sys.stdout = None
        return 0


if __name__ == "__main__":
    sys.exit(main())
