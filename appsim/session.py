"""A run of the kit as a command gives it: one simulated bus, its boards, how it runs (alone, as fast as it can, or
linked to an outside bus in real time), and what it prints and writes. `appsim.cli` parses; this does.
"""
from __future__ import annotations

import argparse
import functools
import io
import sys
import time
from collections.abc import Callable, Sequence
from pathlib import Path
from typing import TextIO

import can

from appsim.board.app023 import APP023
from appsim.board.usbcdc import LONGEST_LINE, UsbCdc
from appsim.bus.link import BusLink
from appsim.bus.monitor import HEADER, EventFile, LiveTrace, TraceLog, error_counters, summary
from appsim.bus.realtime import WallClock
from appsim.bus.serve import ClassroomServer
from appsim.bus.signals import DbcError, Signals
from appsim.bus.waveform import WaveformLog
from appsim.bus.wire import Bus, BusEvent
from appsim.chip.mcu import PIC18F8680
from appsim.chip.usart import PC_BAUD
from appsim.firmware.loader import constants, load_firmware
from appsim.output import DRAIN_S, OutputFile, cannot_write, check_distinct
from appsim.sim import PS_PER_SECOND, Simulator, ps
from appsim.workshop.checks.demo1 import BAUD_FIX, FRAME_LINE, LOST_COUNT
from appsim.workshop.classroom import Classroom, station_defines
from appsim.workshop.course import CLASSROOM_BIT_RATE, EXERCISE_FILES, SOLUTIONS, STATIONS, station_ids
from appsim.workshop.faults import board_fault
from appsim.workshop.frames import WORKSHOP_DBC

TRACE_LINES_SHOWN = 40
SIGNAL_INDENT = " " * 13        # the lines under a frame's (its signals, a note): not frames of their own
PROGRESS_EVERY_S = 1.0          # wall-clock seconds between two progress lines


class Progress:
    """How far a run is, on one line of stderr rewritten in place at most every `PROGRESS_EVERY_S` of wall time, when
    stderr is a terminal: simulated seconds out of `seconds`, then what `detail()` says."""

    def __init__(self, sim: Simulator, seconds: float, detail: Callable[[], str] = lambda: ""):
        self.sim, self.seconds, self.detail = sim, seconds, detail
        self.shown = False
        self._next = time.monotonic()

    def __call__(self) -> None:
        if not sys.stderr.isatty() or time.monotonic() < self._next:
            return
        self._next = time.monotonic() + PROGRESS_EVERY_S
        detail = self.detail()
        print(f"\r  {self.sim.now / PS_PER_SECOND:6.1f} / {self.seconds:g} s{'  ' + detail if detail else ''}\x1b[K",
              end="", file=sys.stderr, flush=True)
        self.shown = True

    def done(self) -> None:
        """End the line, if one was shown."""
        if self.shown:
            print(file=sys.stderr)
            self.shown = False


def dbc_signals(dbc: str | None) -> Signals | None:
    """--dbc: the signals of the DBC it names ("" for the workshop's, as --dbc alone gives), or None without it."""
    if dbc is None:
        return None
    try:
        return Signals(dbc or WORKSHOP_DBC)
    except DbcError as error:
        raise SystemExit(f"appsim: --dbc: {error}") from None


class Session:
    """One simulated bus, and how it runs: as fast as it can, or linked to an outside bus in real time.

    Its files (`logs`: (option, path) of each log, then the --vcd waveform, then the `picture` written at the end)
    are checked first: two that name one file, or one that names the firmware it runs, stop the command before
    anything runs (`OutputError`), as does a path that cannot be written; each log gets every event as the bus carries
    it. A session is closed (files ended, link closed and its report printed) when its `with` block ends."""

    def __init__(self, args: argparse.Namespace, out: TextIO, *, logs: Sequence[tuple[str, Path]] = (),
                 picture: tuple[str, Path] | None = None):
        self.sim = Simulator()
        self.bus = Bus(self.sim, CLASSROOM_BIT_RATE)
        self.out = out
        self.link: BusLink | None = None
        self.server: ClassroomServer | None = None
        self.trace = LiveTrace(self.bus, signals=dbc_signals(getattr(args, "dbc", None)))
        self.logs: list[EventFile] = []
        self.picture: OutputFile | None = None
        self.reported: set[str] = set()          # boards whose stop was reported
        vcd = getattr(args, "vcd", None)
        check_distinct([*logs, ("--vcd", vcd), *([picture] if picture else [])], firmware_read(args))
        try:
            for _, path in logs:
                self._keep(TraceLog(path))
            if vcd:
                self._keep(WaveformLog(vcd, self.bus))
            if picture:
                self.picture = OutputFile(picture[1], keep_until_written=True)
            if getattr(args, "interface", None):
                try:
                    self.link = BusLink(self.bus, interface=args.interface, channel=args.channel)
                except (can.CanError, ValueError, OSError, ImportError) as error:
                    raise SystemExit(f"appsim: cannot open the python-can bus interface={args.interface!r} "
                                     f"channel={args.channel!r}: {error}") from None
            if getattr(args, "serve", None):
                try:
                    self.server = ClassroomServer(self.bus, args.serve, what=getattr(args, "serving", ""))
                except (can.CanError, OSError) as error:
                    raise SystemExit(f"appsim: cannot serve the classroom to python-can: {error}") from None
        except BaseException:
            self.close()
            raise

    @property
    def real_time(self) -> bool:
        """Linked to an outside bus or served to python-can programs: it runs paced to the wall clock, its trace shown
        as it goes."""
        return self.link is not None or self.server is not None

    def _keep(self, log: EventFile) -> None:
        self.logs.append(log)
        self.bus.trace.listeners.append(log.write)

    def run(self, seconds: float, *, live: bool, real_time: bool = False,
            pollers: tuple[Callable[[], None], ...] = (), progress: Progress | None = None) -> None:
        """Run `seconds` of simulated time: as fast as it can, or, linked (or `real_time`), paced to the
        wall clock with `pollers` and the link polled between slices, the trace shown live if `live`, and a board
        that stops reported when it does. `progress` shows how far it is on a terminal (as fast as it can, runs of
        5 s or more show their simulated time anyway)."""
        real_time = real_time or self.real_time
        if not real_time and progress is None and seconds >= 5:
            progress = Progress(self.sim, seconds)
        try:
            if not real_time:
                self._fast(seconds, progress)
                return
            clock = WallClock(self.sim)
            polls: tuple[Callable[[], None], ...] = (*pollers, self.report_failures, *([progress] if progress else []))
            for poll in polls:
                clock.add_poller(poll)
            if self.link is not None:
                clock.add_poller(self.link.poll)
                print(f"linked to {self.link.outside.channel_info}, running in real time for {seconds:g} s "
                      "(Ctrl-C stops)", file=self.out)
            if self.server is not None:
                clock.add_poller(self.server.poll)
                print(f"{self.server.how_to_join}; running in real time for {seconds:g} s (Ctrl-C stops)",
                      file=self.out, flush=True)
            if live:
                clock.add_poller(lambda: self._show(self.trace.new_lines()))
            try:
                clock.run(seconds)
            finally:
                if late := clock.lateness():
                    print(f"the run fell {late}", file=self.out)
        finally:
            if progress:
                progress.done()

    def _fast(self, seconds: float, progress: Progress | None) -> None:
        end = ps(seconds)
        step = PS_PER_SECOND // 2
        while self.sim.now < end:
            self.sim.run(until=min(self.sim.now + step, end))
            if progress:
                progress()

    def _show(self, lines: list[str]) -> None:
        for line in lines:
            print(line, file=self.out)

    def print_trace(self, limit: int | None = TRACE_LINES_SHOWN, *, more: str = "") -> None:
        """The trace's new lines, those of the first `limit` frames (a frame's signals, with --dbc, on the line under
        it); past the limit, how many more and where they are (in a log, or `more`: how this command shows them)."""
        lines = self.trace.new_lines()
        starts = [n for n, line in enumerate(lines) if not line.startswith(SIGNAL_INDENT)]    # each frame's line
        print(HEADER, file=self.out)
        self._show(lines if limit is None or len(starts) <= limit else lines[:starts[limit]])
        if limit is not None and len(starts) > limit:
            logged = next((log.path for log in self.logs if isinstance(log, TraceLog)), None)
            where = f"all of them are in {logged}" if logged else "--log trace.log keeps them"
            print(f"{'':>11}  ... {len(starts) - limit} more frames ({where}{'; ' + more if more else ''})",
                  file=self.out)
        print(summary(self.bus), file=self.out)

    def print_written(self) -> None:
        """What each of the session's files holds, now that the run is over (and what a FIFO's reader did not get)."""
        until = time.monotonic() + DRAIN_S          # every FIFO's reader together: Ctrl-C ends a run within 1 s
        for log in self.logs:
            log.close(until)
        for log in self.logs:
            losses = log.losses()
            print(f"wrote {log.path} ({log.kind}, {log.written} frames){'; ' + losses if losses else ''}",
                  file=self.out)

    def report_failures(self) -> None:
        """Say once, for each board whose firmware is no longer running, which file it ran and why it stopped, with
        the line (`reported` names them)."""
        for mcu in self.bus.boards():
            if not isinstance(mcu, PIC18F8680):
                continue
            process = mcu.process
            if process is None or mcu.name in self.reported or (fault := board_fault(process)) is None:
                continue
            self.reported.add(mcu.name)
            ran = f" ({process.filename})" if process.filename else ""
            print(f"{mcu.name}{ran} stopped: {fault.message}", file=sys.stderr)

    def report_unfired(self) -> int:
        """Say which injected errors never fired (all their frames), and why: how many."""
        lines = self.bus.injections.not_fired()
        for line in lines:
            print(f"--inject {line}", file=sys.stderr)
        return len(lines)

    def interrupted(self) -> str:
        """What a Ctrl-C leaves: where the run stopped and what the logs hold."""
        kept = "".join(f"; {log.path} holds its first {log.written} frames"
                       + (f" ({losses})" if (losses := log.losses()) else "") for log in self.logs)
        return f"interrupted (Ctrl-C) at {self.sim.now / PS_PER_SECOND:.3f} s of simulated time{kept}"

    def close(self) -> None:
        """End the logs, close the link (its report says what it carried and refused)."""
        until = time.monotonic() + DRAIN_S
        for log in self.logs:
            log.close(until)
        if self.picture is not None:
            self.picture.close(until)
        if self.link is not None:
            print(self.link.report(), file=self.out)
            self.link.close()
            self.link = None
        if self.server is not None:
            self.server.close()
            print(self.server.report(), file=self.out)
            self.server = None

    def __enter__(self) -> Session:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()


Body = Callable[[argparse.Namespace, Session], None]
Command = Callable[[argparse.Namespace], int]


def logs_asked(args: argparse.Namespace) -> list[tuple[str, Path]]:
    """The logs `--log` names, if any."""
    return [("--log", path) for path in args.log or []]


def firmware_read(args: argparse.Namespace) -> list[tuple[str, Path | None]]:
    """The firmware files a command reads (no output may be one of them)."""
    board = getattr(args, "firmware", None)
    join = getattr(args, "join", None)
    return [("FIRMWARE", Path(board) if board else None), ("--join", Path(join) if join else None)]


def session_command(logs: Callable[[argparse.Namespace], list[tuple[str, Path]]] = logs_asked,
                    picture: Callable[[argparse.Namespace], tuple[str, Path]] | None = None
                    ) -> Callable[[Body], Command]:
    """A command that runs a session: its `logs` (and the `picture` it saves at the end) are checked before anything
    runs (an `OutputError` for the caller); a board that stopped is reported and makes the exit status 1; after Ctrl-C,
    the KeyboardInterrupt for the caller says where the run stopped and what the logs hold."""
    def decorate(body: Body) -> Command:
        @functools.wraps(body)
        def command(args: argparse.Namespace) -> int:
            with Session(args, sys.stdout, logs=logs(args), picture=picture(args) if picture else None) as session:
                try:
                    body(args, session)
                except KeyboardInterrupt:
                    session.close()
                    raise KeyboardInterrupt(session.interrupted()) from None
                session.report_failures()
                unfired = session.report_unfired()
                return 1 if session.reported or unfired else 0
        return command
    return decorate


def print_lcds(boards: list[APP023], out: TextIO) -> None:
    """Every board's LCD, side by side, three to a row."""
    for row in range(0, len(boards), 3):
        group = boards[row:row + 3]
        print("   ".join(f"{board.name:<23}" for board in group), file=out)
        screens = [str(board.glcd).splitlines() for board in group]
        for lines in zip(*screens, strict=True):
            print("   ".join(f"{line:<23}" for line in lines), file=out)


def save_lcd_picture(boards: list[APP023], file: OutputFile) -> str:
    """One PNG with every board's LCD, named, as they would look on the desks, into `file`: what it holds, in a few
    words."""
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    columns = min(3, len(boards))
    rows = -(-len(boards) // columns)
    figure, axes = plt.subplots(rows, columns, figsize=(4.2 * columns, 2.4 * rows), squeeze=False)
    for ax in axes.flat:
        ax.axis("off")
    for ax, board in zip(axes.flat, boards, strict=False):
        board.glcd.picture(ax=ax)
        ax.set_title(board.name, fontsize=10)
    figure.tight_layout()
    png = io.BytesIO()
    try:
        figure.savefig(png, format="png", dpi=100)
    finally:
        plt.close(figure)
    file.write(png.getvalue())
    try:
        file.commit()
        file.close()
    except OSError as error:
        raise cannot_write(file.path, error) from None
    return "every LCD" if file.delivered else "every LCD, but its reader did not take the picture whole"


def workshop_in_progress(bus: Bus, seed: int) -> Classroom:
    """The classroom mid-workshop: station k works on exercise k, so every kind of traffic is on the bus."""
    classroom = Classroom(bus, 6, seed=seed)
    for k in range(1, STATIONS):
        firmware = SOLUTIONS / f"ex{k}.py"
        classroom.join(firmware, k, defines=station_defines(constants(firmware), k))
    return classroom


def _demo_logs(args: argparse.Namespace) -> list[tuple[str, Path]]:
    """The demo's --out folder, made if need be, and the logs it holds."""
    try:
        args.out.mkdir(parents=True, exist_ok=True)
    except OSError as error:
        raise cannot_write(args.out, error) from None
    return [("--out", args.out / "trace.log"), ("--out", args.out / "trace.asc")]


@session_command(logs=_demo_logs, picture=lambda args: ("--out", args.out / "lcds.png"))
def cmd_demo(args: argparse.Namespace, session: Session) -> None:
    out = session.out
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
    assert session.picture is not None
    holds = save_lcd_picture(classroom.boards, session.picture)
    print("", file=out)
    session.print_written()
    print(f"wrote {session.picture.path} ({holds})", file=out)


@session_command()
def cmd_board(args: argparse.Namespace, session: Session) -> None:
    """One firmware file on one board, on its own bus (or on an outside bus): what it did and its LCD."""
    out, firmware = session.out, Path(args.firmware)
    board = APP023(session.bus, args.name, potentiometer=args.potentiometer)
    board.run(load_firmware(firmware, c_options=args.c_option))
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
    if not session.real_time:
        session.print_trace()
    print(board.glcd, file=out)
    session.print_written()


@session_command()
def cmd_classroom(args: argparse.Namespace, session: Session) -> None:
    out = session.out
    classroom = Classroom(session.bus, args.exercise, seed=args.seed, monitor=session.link is None)
    station = args.station or 1
    if args.join:
        firmware = load_firmware(args.join, c_options=args.c_option)
        expected = station_ids(station)["MESSAGE_ID1"]
        own = getattr(firmware, "MESSAGE_ID1", expected)
        if own != expected:
            print(f"warning: {args.join} has MESSAGE_ID1 = 0x{own:03X} but station {station}'s is "
                  f"0x{expected:03X}. Two nodes sending one ID with different data destroy each other's "
                  "frames (bit errors): set MESSAGE_ID1 to your station's ID.", file=sys.stderr)
        classroom.join(firmware, station)
    for node, kind, bit, can_id in args.inject or ():
        try:
            session.bus.inject(node, kind, bit, can_id=can_id)
        except KeyError:
            raise SystemExit(f"appsim: --inject {node}:...: no node {node!r} in the classroom; its nodes are "
                             f"{', '.join(board.name for board in session.bus.boards())}") from None
    who = f"; station{station} runs {args.join}" if args.join else ""
    print(f"Classroom at exercise {args.exercise}: the master and six stations running "
          f"solutions/ex{args.exercise}.py{who}.", file=out)
    session.run(args.seconds, live=True)
    if not session.real_time:
        session.print_trace(limit=None if args.full_trace else TRACE_LINES_SHOWN, more="--full-trace prints them")
    print("\n" + error_counters(session.bus) + "\n", file=out)
    print_lcds(classroom.boards, out)
    session.print_written()


class MonitorTally:
    """What became of each frame on the bus, as the Demo1 `board` saw it: listed on its serial port (a line in the
    documented format, or an SLCAN frame), lost on the CAN side (its RAM queue was full: what its `# lost N frames`
    lines add up to; its RXB0 and RXB1 were full: counted on the bus), or neither. It counts the lines as they leave
    the board's USART, whether or not a program reads them: what the USB-CDC bridge loses is `UsbCdc.report()`'s."""


    def __init__(self, bus: Bus, board: APP023):
        self.name = board.name
        self.usart = board.usart
        self.frames = 0                   # frames that went through on the bus
        self.listed_bytes = 0             # the bytes of the frame lines, line ends included
        self.not_listening = 0            # of them, sent while the monitor's ECAN was not on the bus
        self.lost_in_ecan = 0             # of them, lost because RXB0 and RXB1 were full
        self.listed = 0                   # frame lines on the serial port
        self.lost_in_queue = 0            # what its '# lost' lines add up to
        self._line = bytearray()
        bus.trace.listeners.append(self._event)
        board.usb.listeners.append(self._byte)

    def _event(self, event: BusEvent) -> None:
        if not event.ok:
            return
        self.frames += 1
        what = dict(event.received).get(self.name)
        if what is None:
            self.not_listening += 1
        elif what.startswith("lost"):
            self.lost_in_ecan += 1

    def _byte(self, byte: int, time_ps: int) -> None:
        if byte not in b"\r\n":
            if len(self._line) < LONGEST_LINE:
                self._line.append(byte)
            return
        line = self._line.decode("latin-1").replace("\0", "")   # C18's putsUSART sends the NUL too
        self._line.clear()
        if FRAME_LINE.match(line) or line[:1] in ("t", "T", "r", "R"):
            self.listed += 1
            self.listed_bytes += len(line) + (2 if FRAME_LINE.match(line) else 1)      # CR LF; SLCAN's CR
        elif line.startswith("#"):
            self.lost_in_queue += sum(int(n) for n in LOST_COUNT.findall(line))

    @property
    def lost(self) -> int:
        """Frames lost on the CAN side: in the board's RAM queue and in its ECAN."""
        return self.lost_in_queue + self.lost_in_ecan

    def progress(self) -> str:
        return f"{self.frames:,} frames on the bus: {self.listed:,} listed, {self.lost:,} lost on the CAN side"

    def summary(self, seconds: float) -> str:
        """What became of the frames of a run of `seconds`, and why frames were lost in the board's queue."""
        def share(count: int) -> str:
            return f"{count:,} ({count / self.frames:.0%})" if self.frames else f"{count:,}"

        neither = self.frames - self.listed - self.lost
        lines = [f"{self.frames:,} frames on the bus",
                 f"  {share(self.listed)} listed by the monitor on its serial port",
                 f"  {share(self.lost)} lost on the CAN side: {self.lost_in_queue:,} when its RAM queue was full "
                 f"(its '# lost' lines), {self.lost_in_ecan:,} when RXB0 and RXB1 were full"]
        if self.lost_in_queue and self.listed and seconds > 0:
            lines.append("    " + self._why_the_queue_was_full(seconds))
        if neither:
            lines.append(f"  {share(neither)} neither listed nor said lost: {self.not_listening:,} went by before the "
                         "monitor listened; the others were still inside it when the run ended (queued, or counted "
                         "for a '# lost' line not sent yet), or were dropped without a '# lost' line")
        return "\n".join(lines)

    def _why_the_queue_was_full(self, seconds: float) -> str:
        """The USART's budget against the bus's frame rate: the faithful 19200-baud limit, or a slow firmware."""
        line_bytes = self.listed_bytes / self.listed
        bytes_per_s = self.usart.baud / 10                          # 8N1: start, 8 data bits, stop
        can_list, listed, offered = bytes_per_s / line_bytes, self.listed / seconds, self.frames / seconds
        budget = (f"why: a frame's line is about {line_bytes:.0f} bytes and the USART sends {bytes_per_s:,.0f} bytes "
                  f"a second ({self.usart.baud:,.0f} baud, 8N1), so the monitor can list about {can_list:.0f} frames "
                  f"a second, while the bus carried {offered:.0f} a second")
        if listed >= 0.9 * can_list:
            return (f"{budget}: its RAM queue fills, and it says '# lost N'. That is the APP023's own limit, as on the "
                    "real board, not a fault of the firmware (docs/monitor-format.md)")
        return (f"{budget}; it listed {listed:.0f} a second, fewer than its USART could send: the firmware is slower "
                "than its serial link")


@session_command()
def cmd_monitor(args: argparse.Namespace, session: Session) -> None:
    """Demo1: the classroom plus a board running the CAN monitor (your firmware, or the solution), its USB-CDC port
    open on this PC; a tally of every frame, and a port that a program can leave in its own time."""
    out = session.out
    Classroom(session.bus, args.exercise, seed=args.seed, monitor=session.link is None)
    board = APP023(session.bus, "demo1")
    if args.slcan:
        board.dsw2.on(1)
    firmware = args.firmware or SOLUTIONS / EXERCISE_FILES["demo1"]
    board.run(firmware)
    tally = MonitorTally(session.bus, board)
    try:
        usb = UsbCdc(board, transport=args.transport)
    except OSError as error:
        raise SystemExit(f"appsim: cannot open the USB-CDC port ({args.transport}): {error}") from None
    with usb:
        protocol = "SLCAN (python-can: interface='slcan')" if args.slcan else "text lines, 19200 8N1"
        running = args.firmware or f"the solution, {firmware.name}"
        print(f"Demo1 CAN monitor ({running}) on the USB-CDC port {usb.url}  [{protocol}]\n"
              f"  open it with: python -m serial.tools.miniterm {usb.url} 19200   (or screen, minicom)\n"
              f"  the classroom (exercise {args.exercise}) runs in real time for {args.seconds:g} s, then stops "
              "(--seconds to change; Ctrl-C stops sooner)", file=out, flush=True)
        try:
            session.run(args.seconds, live=False, real_time=True, pollers=(usb.poll,),
                        progress=Progress(session.sim, args.seconds,
                                          lambda: f"{tally.progress()}; USB: {usb.lost_to_pc:,} bytes lost"))
        finally:            # after Ctrl-C too: what became of the frames, and a port left as a program expects
            print(f"{tally.summary(session.sim.now / PS_PER_SECOND)}\n{usb.report()}", file=out)
            for baud in usb.misread:
                print(f"Demo1's firmware set its USART to {baud:,} baud, but the port runs at {PC_BAUD:,} baud (the "
                      f"PIC18F2550 bridge's UART, 19200 8N1): what reached the PC is garbage. {BAUD_FIX}: "
                      "OpenUSART(..., 129) with USART_BRGH_HIGH.", file=out)
            session.print_written()
            out.flush()
            if usb.in_use():
                print(f"{usb.url} stays open until the program using it closes it (miniterm: Ctrl-]; Ctrl-C here "
                      "leaves now)", file=out, flush=True)
                ended = f"# appsim monitor: the run ended at {session.sim.now / PS_PER_SECOND:.1f} s, nothing more " \
                        "comes: close the port (miniterm: Ctrl-])\r\n"
                ignored = usb.linger("" if args.slcan else ended)
                if ignored:
                    print(f"  it wrote {ignored} bytes after the run; they reached nothing", file=out)
