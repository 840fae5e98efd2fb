"""The `appsim` command: run the workshop's firmware on simulated APP023 boards from a terminal.

`appsim demo` is the kit's main job; `board`, `classroom`, `monitor` run firmware; `bittiming` calculates.
"""
from __future__ import annotations

import argparse
import io
import os
import sys
from collections.abc import Callable
from pathlib import Path
from typing import Any

from appsim.can.bittiming import CLASSIC_CAN_MAX_BIT_RATE, FOSC_MAX_HZ
from appsim.errors import FirmwareError, OutputError
from appsim.workshop.course import CLASSROOM_BIT_RATE, STATIONS, exercise_name
from appsim.workshop.workspace import FOLDER as NOTEBOOKS_FOLDER

HOUR, DAY = 3600, 86400
DEMO_SECONDS, BOARD_SECONDS, CLASSROOM_SECONDS = 2.0, 0.5, 2.0
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
    """NODE:KIND:BIT[:ID] -> the arguments of `Bus.inject` (node, kind, bit, can_id), refused if it could never fire."""
    from appsim.bus.bitlevel import ERROR_KINDS, Injection
    from appsim.errors import InjectionError
    what = (f"an injected error is NODE:KIND:BIT[:ID], KIND one of {', '.join(ERROR_KINDS)}, BIT counted from SOF = 0, "
            "ID the frame's identifier (default: the node's next frame), e.g. station1:stuff:30:0x100")
    parts = text.split(":")
    if not 3 <= len(parts) <= 4 or parts[1] not in ERROR_KINDS:
        raise argparse.ArgumentTypeError(f"{what}; got {text!r}")
    bit = _number(parts[2], what, lambda t: int(t, 0))
    can_id = _number(parts[3], what, lambda t: int(t, 0)) if len(parts) == 4 else None
    try:
        Injection(parts[0], parts[1], bit, can_id)
    except InjectionError as error:
        raise argparse.ArgumentTypeError(f"{text} could never fire: {error}") from None
    return parts[0], parts[1], bit, can_id


def cmd_demo(args: argparse.Namespace) -> int:
    from appsim import session
    return session.cmd_demo(args)


def _serving(args: argparse.Namespace, default_seconds: float, what: str) -> None:
    """--serve: the run lasts a day unless --seconds says (Ctrl-C stops it), and the programs are told what it is."""
    if args.seconds is None:
        args.seconds = DAY if args.serve else default_seconds
    args.serving = what


def cmd_board(args: argparse.Namespace) -> int:
    _serving(args, BOARD_SECONDS, f"{Path(args.firmware).name} on one APP023 board")
    from appsim import session
    return session.cmd_board(args)


def cmd_classroom(args: argparse.Namespace) -> int:
    if args.station is not None and args.join is None:
        args.usage_error("--station says which station your firmware takes, so it goes with --join: "
                         "--join my_ex3.py --station 2")
    _serving(args, CLASSROOM_SECONDS, f"the classroom at exercise {args.exercise}")
    from appsim import session
    return session.cmd_classroom(args)


def cmd_monitor(args: argparse.Namespace) -> int:
    from appsim import session
    return session.cmd_monitor(args)


def cmd_bittiming(args: argparse.Namespace) -> int:
    """The settings for a bit rate, the classroom's first where it is one of them; where none gives the rate exactly,
    those of the nearest rate, and exit status 1."""
    from appsim.can.bittiming import TOLERATED_RATE_ERROR, calculate, error_percent, format_table, nearest
    from appsim.chip.clock import FOSC_HZ
    from appsim.workshop.course import CLASSROOM_TIMING
    fosc = args.fosc or FOSC_HZ
    at = f"at Fosc = {fosc // 10**6} MHz" if fosc % 10**6 == 0 else f"at Fosc = {fosc:,} Hz"
    solutions = calculate(args.bit_rate, fosc)
    if solutions:
        title = f"{args.bit_rate:,} bit/s {at}: {len(solutions)} valid settings give it exactly"
    else:
        solutions = nearest(args.bit_rate, fosc)
        rates = " and ".join(sorted({f"{float(s.bit_rate):,.2f} bit/s ({error_percent(s.error)} %)"
                                     for s in solutions}))
        many = f"{len(solutions)} settings give it" if len(solutions) > 1 else "1 setting gives it"
        title = (f"no valid setting gives exactly {args.bit_rate:,} bit/s {at} (8..25 TQ a bit, BRP 1..64); the "
                 f"nearest rate is {rates}: {many}")
        if abs(solutions[0].error) > TOLERATED_RATE_ERROR:
            title += (f"; that is further off than any CAN node tolerates ({float(TOLERATED_RATE_ERROR) * 100:g} % "
                      f"at best), so it could not talk with nodes at {args.bit_rate:,} bit/s")
    workshop = [s for s in solutions if s.timing == CLASSROOM_TIMING]
    shown = (workshop + [s for s in solutions if s.timing != CLASSROOM_TIMING])[: args.top]
    order = "the classroom's first, then by" if workshop else "by"
    print(f"{title}; {len(shown)} listed (--top), {order} sample point nearest 87.5 % (CiA), then more TQ a bit")
    print(format_table(shown, {CLASSROOM_TIMING: "the classroom's: every exercise's CANInitialize"}))
    return 0 if solutions[0].error == 0 else 1


def cmd_check(args: argparse.Namespace) -> int:
    """One exercise, checked as in the notebook: the verdict, and exit status 0 only with full marks (2: no firmware
    file to check, as `board` and `classroom` say)."""
    from appsim.workshop.checks import check, refusal
    problem = None if args.firmware is None else refusal(args.exercise, args.firmware)
    if problem is not None:
        raise FirmwareError(problem)
    verdict = check(args.exercise, args.firmware, seed=args.seed, c_options=args.c_option)
    print(verdict)
    return 0 if verdict.passed else 1


def cmd_notebooks(args: argparse.Namespace) -> int:
    """Your copy of the workshop's notebooks, to open in JupyterLab: the kit's own stay as shipped."""
    from appsim.workshop.workspace import copy_notebooks
    print(copy_notebooks(args.folder).report())
    return 0


def cmd_dbc(args: argparse.Namespace) -> int:
    from appsim.workshop.frames import WORKSHOP_DBC
    print(WORKSHOP_DBC)
    return 0


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


class _Version(argparse.Action):
    """--version: the kit as its grades record it (version and code digest) and its git commit, then exit."""

    def __init__(self, option_strings: list[str], dest: str, **kwargs: Any):
        super().__init__(option_strings, dest, nargs=0, default=argparse.SUPPRESS, **kwargs)

    def __call__(self, parser: argparse.ArgumentParser, *_: Any) -> None:
        from appsim import provenance
        from appsim.workshop.grading.results import kit_version
        commit = provenance.commit()
        if commit is None:
            where = "unknown: the kit runs from no git checkout, and its wheel recorded none"
        elif commit.endswith(provenance.DIRTY):
            where = (f"{commit}: its code differs from that commit (changed or new files), so no commit has it; "
                     "the digest above is its only identity")
        else:
            where = commit
        print(f"appsim {kit_version()}\ngit commit {where}")
        parser.exit()


def cmd_gradescope_autograder(args: argparse.Namespace) -> int:
    import random

    from appsim.errors import GradeError
    from appsim.workshop.grading.autograder import build
    seed = args.seed if args.seed is not None else random.SystemRandom().randrange(2**32)
    try:
        build(args.out, seed=seed, time_limit_s=args.time_limit, visibility=args.visibility,
              c_options=tuple(args.c_option))
    except GradeError as error:
        print(f"appsim gradescope-autograder: {error}", file=sys.stderr)
        return 2
    print(f"wrote {args.out}: upload it as the assignment's autograder (Gradescope: Configure Autograder, zip file "
          f"upload). Seed {seed}: `appsim grade SUBMISSION --seed {seed}` gives the same marks (docs/grading.md)")
    return 0


def build_parser() -> argparse.ArgumentParser:
    parser = argparse.ArgumentParser(
        prog="appsim",
        description="CAN Workshop 202 on simulated Microchip APP023 boards (PIC18F8680 ECAN + AN738). "
                    "Firmware is a Python file that reads like the workshop's C: "
                    "`from appsim.firmware import *` and a main() that loops forever; or the workshop's C itself, "
                    "a .c file for MPLAB C18 (see docs/c-firmware.md). "
                    "Everything runs on a simulated clock, deterministic, with no hardware; "
                    "--interface/--channel join any python-can bus (a vcan, a real adapter) in real time.")
    parser.add_argument("--version", action=_Version,
                        help="the kit's version with the digest of its code (as grade records keep it) and its git "
                             "commit (docs/grading.md: matching a gradebook to a commit)")
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
                           help="make NODE see an error in its next frame in Normal mode (with identifier ID): KIND "
                                "bit, stuff, crc, form, ack or dominant, at bit BIT from SOF (docs/errors.md); give it "
                                "again for more (for one node: in successive frames); one that never fires is reported")

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

    demo.add_argument("--seconds", type=_seconds, default=DEMO_SECONDS,
                      help=f"simulated time to run, up to a day (default {DEMO_SECONDS:g} s)")
    for sub, default_seconds in ((board, BOARD_SECONDS), (classroom, CLASSROOM_SECONDS)):
        sub.add_argument("--seconds", type=_seconds, default=None,
                         help=f"simulated time to run, up to a day (default {default_seconds:g} s; with --serve a "
                              "day, until Ctrl-C)")
        sub.add_argument("--serve", nargs="?", const="classroom", metavar="NAME",
                         help="serve the bus to python-can programs of this user on this machine (127.0.0.1 only), "
                              "in real time: can.Bus(interface='appsim', channel=NAME), python -m can.viewer -i appsim "
                              "-c NAME (default NAME: classroom; docs/pythoncan.md)")
    monitor.add_argument("--seconds", type=_seconds, default=60.0,
                         help="how long the monitor runs, in seconds of real time: it stops then (default 60 s, "
                              "up to a day; Ctrl-C stops it sooner)")
    for sub in (demo, classroom, monitor):
        sub.add_argument("--seed", type=_seed, default=202,
                         help="seed of the stations' potentiometer values (default 202): same seed, same run")
    for sub in (demo, board, classroom, monitor):
        sub.add_argument("--vcd", type=Path, metavar="FILE",
                         help="write the CAN line's waveform as it goes, a VCD for PulseView or sigrok-cli's CAN "
                              "decoder; a FIFO or a pipe too, which never holds the run up (docs/traces.md)")
    for sub in (demo, board, classroom):
        sub.add_argument("--dbc", nargs="?", const="", metavar="FILE",
                         help="show each frame's signals under it, read through a CAN database: FILE, or without "
                              "it the workshop's (appsim dbc prints where it is)")
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
                                             "1 Mbit/s) as CANInitialize takes it, with the BRGCON1..3 values: the "
                                             "workshop's first, then by sample point. Where none gives the rate "
                                             "exactly, those of the nearest rate, and exit status 1.")
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
    grade.add_argument("--gradescope", metavar="PATH",
                       help="Gradescope results.json (one submission), else a folder of NAME.json (always with a "
                            "PATH that is a folder or ends in /)")
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

    notebooks = commands.add_parser(
        "notebooks", help="copy the workshop's notebooks into a folder of your own, to open in JupyterLab",
        description="Copy the workshop's notebooks (notebooks/ in the kit's clone) into FOLDER, where you run and "
                    "edit them; the kit's own stay as shipped, so `git pull` updates the kit without a conflict. A "
                    "notebook already in FOLDER is never overwritten: run it again after `git pull` to get the new "
                    "notebooks, and to hear which of yours the kit has changed since you copied them.")
    notebooks.add_argument("folder", nargs="?", type=Path, default=Path(NOTEBOOKS_FOLDER), metavar="FOLDER",
                           help=f"where your notebooks go (default ./{NOTEBOOKS_FOLDER}, which git ignores)")
    notebooks.set_defaults(handler=cmd_notebooks)


    dbc = commands.add_parser(
        "dbc", help="where the workshop's CAN database (DBC) is, for cantools and other DBC tools",
        description="Print the path of workshop.dbc, the workshop's frames as a CAN database (0x088, 0x081..0x086, "
                    "0x100..0x150 with their A/D value): cantools decode \"$(appsim dbc)\" < trace.log")
    dbc.set_defaults(handler=cmd_dbc)

    autograder = commands.add_parser(
        "gradescope-autograder", help="write a Gradescope autograder zip that grades as appsim grade does",
        description="Write OUT.zip for a Gradescope programming assignment: setup.sh installs the kit (from a wheel "
                    "inside the zip) and bubblewrap; run_autograder grades /autograder/submission with appsim grade's "
                    "checks, seed and verdict, into results.json, one test per check. See docs/grading.md.")
    autograder.add_argument("out", type=Path, metavar="OUT.zip", help="the zip to write")
    autograder.add_argument("--seed", type=_seed, help="seed of the random inputs, the same for every student "
                                                       "(default: drawn and printed)")
    autograder.add_argument("--time-limit", type=_cpu_seconds, default=60.0,
                            help="CPU seconds per exercise, as appsim grade's (default 60)")
    autograder.add_argument("--visibility", default="visible",
                            choices=("visible", "after_due_date", "after_published", "hidden"),
                            help="when students see each check's result on Gradescope (default visible)")
    _c_option(autograder)
    autograder.set_defaults(handler=cmd_gradescope_autograder)

    checking = commands.add_parser(
        "check", help="check your firmware for one exercise, as the notebook does",
        description="Run FIRMWARE (default: exercises/exN.py) in a simulated classroom and judge what it did on "
                    "the bus and the board: the same check the notebook's last cell runs and `appsim grade` uses. "
                    "Exit status 0 with full marks.")
    checking.add_argument("exercise", type=_exercise_name, metavar="EXERCISE",
                          help="ex1 .. ex6 (or 1 .. 6, EX3 ...) or demo1")
    checking.add_argument("firmware", nargs="?",
                          help="your firmware file, .py or .c, or your notebook (its firmware cell, as appsim grade "
                               "reads it) (default: exercises/EXERCISE.py)")
    checking.add_argument("--seed", type=_seed, help="seed of the random inputs (default: a fresh one, printed)")
    _c_option(checking)
    checking.set_defaults(handler=cmd_check)
    return parser


class _UntilItsReaderGoes(io.RawIOBase):
    """A file descriptor of the process's own (1, 2) that becomes /dev/null once its reader has gone (`appsim check
    ex1 | head -2`): the command ends its work (a class graded, the files written) with its own exit status."""

    def __init__(self, fd: int):
        super().__init__()
        self.fd = fd

    def writable(self) -> bool:
        return True

    def fileno(self) -> int:
        return self.fd

    def isatty(self) -> bool:
        return os.isatty(self.fd)

    def write(self, data: Any) -> int:
        try:
            return os.write(self.fd, data)
        except BrokenPipeError:
            nowhere = os.open(os.devnull, os.O_WRONLY)
            os.dup2(nowhere, self.fd)
            os.close(nowhere)
            return len(data)


def _outliving_their_readers() -> None:
    """stdout and stderr, where they are the process's own, as `_UntilItsReaderGoes`."""
    for name in ("stdout", "stderr"):
        stream = getattr(sys, name)
        if stream is not None and stream is getattr(sys, f"__{name}__"):
            setattr(sys, name, io.TextIOWrapper(io.BufferedWriter(_UntilItsReaderGoes(stream.fileno())),
                                                encoding=stream.encoding, errors=stream.errors,
                                                line_buffering=stream.line_buffering))


def main(argv: list[str] | None = None) -> int:
    args = build_parser().parse_args(argv)
    _outliving_their_readers()
    try:
        return args.handler(args)
    except (FirmwareError, OutputError) as error:
        print(f"appsim: {error}", file=sys.stderr)
        return 2
    except KeyboardInterrupt as interrupt:       # one line, which says what was kept where the command knows it
        print(f"appsim {args.command}: {str(interrupt) or 'interrupted (Ctrl-C)'}", file=sys.stderr)
        return INTERRUPTED


if __name__ == "__main__":
    sys.exit(main())
