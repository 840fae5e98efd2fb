"""The `appsim` command: run the workshop's firmware on simulated APP023 boards from a terminal.

`appsim demo` is the kit's main job; `appsim board FILE` runs one firmware file; `appsim bittiming` calculates.
"""
from __future__ import annotations

import argparse
import sys
from pathlib import Path

from appsim.board import APP023
from appsim.bus import Bus
from appsim.loader import FirmwareError
from appsim.sim import PS_PER_SECOND, Simulator

KIT = Path(__file__).resolve().parent.parent
CLASSROOM_BIT_RATE = 125_000


def _potentiometer(text: str) -> int:
    value = int(text, 0)
    if not 0 <= value <= 1023:
        raise argparse.ArgumentTypeError(f"the potentiometer on AN0 gives a 10-bit value, 0..1023; got {value}")
    return value


def _seconds(text: str) -> float:
    value = float(text)
    if not 0 < value <= 3600:
        raise argparse.ArgumentTypeError(f"simulated time must be between 0 and 3600 s; got {value}")
    return value


def run_board(firmware: Path, *, seconds: float, potentiometer: int, out=sys.stdout) -> APP023:
    """One board on its own bus; prints what it sent and what its receive buffers took."""
    sim = Simulator()
    bus = Bus(sim, CLASSROOM_BIT_RATE)
    board = APP023(bus, "station0", potentiometer=potentiometer)
    process = board.run(firmware)
    sim.run(until=round(seconds * PS_PER_SECOND))
    print(f"APP023 'station0' running {firmware} for {seconds:g} s (simulated), "
          f"potentiometer {potentiometer}, bus {bus.bit_rate // 1000} kbit/s", file=out)
    mode = board.ecan.opmode.name.replace("_", "-").lower()
    print(f"  ECAN ends in {mode} mode (CANSTAT = 0x{board.ecan.read(0xF6E):02X}), "
          f"TEC {board.ecan.tec}, REC {board.ecan.rec}", file=out)
    for event in bus.loopback_trace:
        print(f"  {event.start_ps / PS_PER_SECOND:10.6f} s  sent {event.frame}  (loopback: inside the chip)",
              file=out)
        for _, what in event.received:
            print(f"  {event.end_ps / PS_PER_SECOND:10.6f} s  received: {what}", file=out)
    for event in bus.trace:
        print(f"  {event}", file=out)
    print(f"  frames on the bus: {len(bus.trace)}", file=out)
    if process.failure is not None:
        print(f"  the firmware stopped with an error:\n{process.failure_text}", file=out)
    return board


def cmd_demo(args: argparse.Namespace) -> int:
    print("Ex1, the workshop's first exercise: one board in Loopback mode sends itself a frame.\n")
    print("1. The starter as handed out (RX_Filter0 = 0x088, mask 0x7FF): will RXB0 receive it?")
    run_board(KIT / "exercises" / "ex1.py", seconds=args.seconds, potentiometer=args.potentiometer)
    print("\n   Normally, no! Loopback still applies the masks and filters, and 0x100 is not 0x088.\n")
    print("2. The solution (RX_Filter0 = MESSAGE_ID1):")
    run_board(KIT / "solutions" / "ex1.py", seconds=args.seconds, potentiometer=args.potentiometer)
    return 0


def cmd_board(args: argparse.Namespace) -> int:
    run_board(Path(args.firmware), seconds=args.seconds, potentiometer=args.potentiometer)
    return 0


def cmd_bittiming(args: argparse.Namespace) -> int:
    from appsim.bittiming import calculate, format_table
    solutions = calculate(args.bit_rate, args.fosc)
    if not solutions:
        print(f"no valid bit timing gives exactly {args.bit_rate} bit/s at Fosc {args.fosc} Hz "
              "(8..25 TQ per bit, BRP 1..64)")
        return 1
    print(format_table(solutions[: args.top]))
    return 0


def build_parser() -> argparse.ArgumentParser:
    parser = argparse.ArgumentParser(
        prog="appsim",
        description="A simulated Microchip APP023 CAN training board (PIC18F8680 ECAN + AN738) for "
                    "CAN Workshop 202. Firmware is a Python file that reads like the workshop's C: "
                    "`from appsim.firmware import *` and a main() that loops forever.")
    commands = parser.add_subparsers(dest="command", required=True, metavar="COMMAND")

    demo = commands.add_parser("demo", help="the main job: Ex1 in loopback, starter then solution",
                               description="Run Ex1 on one simulated board: the starter, whose filter "
                                           "rejects its own frame, then the solution.")
    board = commands.add_parser("board", help="run one firmware file on one simulated board",
                                description="Run FIRMWARE (a .py file with main()) on one APP023 board "
                                            "and print what it sent and received.")
    board.add_argument("firmware", metavar="FIRMWARE", help="path of the firmware file, e.g. exercises/ex1.py")
    for sub in (demo, board):
        sub.add_argument("--seconds", type=_seconds, default=0.5,
                         help="simulated time to run (default 0.5 s)")
        sub.add_argument("--potentiometer", type=_potentiometer, default=666,
                         help="the A/D value on AN0, 0..1023 (default 666)")
    demo.set_defaults(handler=cmd_demo)
    board.set_defaults(handler=cmd_board)

    timing = commands.add_parser("bittiming", help="list BRGCON settings for a bit rate",
                                 description="Every valid PIC18F8680 bit timing for a bit rate, best "
                                             "sample point first, with the BRGCON1..3 values.")
    timing.add_argument("bit_rate", type=int, nargs="?", default=CLASSROOM_BIT_RATE,
                        help="bit rate in bit/s (default 125000, the classroom bus)")
    timing.add_argument("--fosc", type=int, default=40_000_000, help="oscillator frequency in Hz (default 40 MHz)")
    timing.add_argument("--top", type=int, default=10, help="how many settings to list (default 10)")
    timing.set_defaults(handler=cmd_bittiming)
    return parser


def main(argv: list[str] | None = None) -> int:
    args = build_parser().parse_args(argv)
    try:
        return args.handler(args)
    except FirmwareError as error:
        print(f"appsim: {error}", file=sys.stderr)
        return 2


if __name__ == "__main__":
    sys.exit(main())
