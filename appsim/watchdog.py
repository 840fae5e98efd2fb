"""Signals while firmware runs: the watchdog for firmware that runs on without touching the hardware, and Ctrl-C.

The simulated clock only advances when firmware touches a register, so a loop that never does (`while True: pass`),
a sleep or a runaway recursion would hang the simulation. Like the PIC's WDT, the watchdog resets it: after
`WATCHDOG_SECONDS` with no register access (of CPU time spent spinning, or of wall time asleep; a busy machine that
gives the firmware only part of a CPU gets it more wall time), the firmware gets a `FirmwareHung` error saying what
the watchdog saw and where, and the other boards go on. Ctrl-C stops the run, whichever firmware it lands in, once the
simulator's own work in hand (a log record) is done.
"""
from __future__ import annotations

import linecache
import os
import signal
import threading
import time
from collections.abc import Iterator
from contextlib import contextmanager
from pathlib import Path
from types import FrameType
from typing import TYPE_CHECKING

import greenlet

from appsim.errors import FirmwareHung
from appsim.schedstat import read_schedstat, schedstat

if TYPE_CHECKING:
    from appsim.sim import Process, Simulator

__all__ = ["WATCHDOG_SECONDS", "FirmwareHung", "ctrl_c_stops_the_run", "ctrl_c_waits", "watchdog"]

WATCHDOG_SECONDS = 2.0
ASLEEP_SHARE = 0.9          # a firmware asleep (neither on a CPU nor waiting for one) this much of the time waits
SPINNING_SHARE = 0.9        # one that was on a CPU this much of a watchdog period spun all of it
LAST_RESORT = 10            # watchdog periods of wall time after which a firmware is stopped however busy the machine
RECURSION_DEPTH = 1000      # Python's own default limit: a firmware deeper than that raised the limit and recursed on


@contextmanager
def watchdog(sim: Simulator, seconds: float | None = None) -> Iterator[None]:
    """Watch the firmware `sim` runs, from the main thread (elsewhere, on Windows, or if SIGALRM is taken:
    no watch).

    A firmware still at the same point of its simulated time after `seconds` (`WATCHDOG_SECONDS`) gets `FirmwareHung`.
    One that catches it and goes on is frozen where it is at the next bark: it never runs again."""
    seconds = WATCHDOG_SECONDS if seconds is None else seconds
    if (not hasattr(signal, "setitimer")                  # Windows: no interval timers, no watch
            or threading.current_thread() is not threading.main_thread()
            or signal.getsignal(signal.SIGALRM) not in (signal.SIG_DFL, None)):
        yield
        return
    clock = _ThreadClock()
    seen: list = [None, None, clock.now()]      # the running process, its simulated time, the thread's times then

    def bark(signum: int, frame: FrameType | None) -> None:
        process, now = sim.running, clock.now()
        if (process is None or greenlet.getcurrent() is not process or not process.watched or process.finished
                or frame is None):
            seen[:] = None, None, now
            return
        if seen[:2] != [process, process.local_time]:
            seen[:] = process, process.local_time, now
            return
        wall, on_cpu, queued = (now[i] - seen[2][i] for i in range(3))
        asleep = wall - on_cpu - queued
        if (on_cpu < SPINNING_SHARE * seconds and asleep < ASLEEP_SHARE * wall
                and wall < (LAST_RESORT - 0.5) * seconds):
            return                              # computing, on a machine too busy to give it a whole CPU
        if process.failure is None:
            if asleep >= ASLEEP_SHARE * wall:
                ran, waiting = f"{seconds:g} s (wall time)", True
            elif on_cpu >= SPINNING_SHARE * seconds:
                ran, waiting = f"{seconds:g} s (CPU time)", False
            else:
                ran, waiting = f"{round(wall / seconds) * seconds:g} s (wall time, on a machine too busy)", False
            process.failure = FirmwareHung(what_it_saw(process, frame, ran, waiting))
            raise process.failure
        process.freeze()                        # it caught the last bark's FirmwareHung and went on

    signal.signal(signal.SIGALRM, bark)
    signal.setitimer(signal.ITIMER_REAL, seconds, seconds)
    try:
        yield
    finally:
        signal.setitimer(signal.ITIMER_REAL, 0)
        signal.signal(signal.SIGALRM, signal.SIG_DFL)
        clock.close()


class _ThreadClock:
    """This thread's (wall, on a CPU, waiting for a CPU) seconds: schedstat's counts where Linux keeps them, else its
    CPU time alone (a thread that waited for a CPU then looks asleep)."""

    def __init__(self) -> None:
        self._fd = schedstat("/proc/thread-self/schedstat")

    def now(self) -> tuple[float, float, float]:
        counts = None if self._fd is None else read_schedstat(self._fd)
        on_cpu, queued = counts or (time.thread_time(), 0.0)
        return time.monotonic(), on_cpu, queued

    def close(self) -> None:
        if self._fd is not None:
            os.close(self._fd)
            self._fd = None


def what_it_saw(process: Process, frame: FrameType, ran: str, asleep: bool) -> str:
    """The watchdog's message: a wait, a recursion or a loop, at which line of the firmware, and what to do."""
    depth, mine = 0, None
    caller: FrameType | None = frame
    while caller is not None and depth <= RECURSION_DEPTH:
        if mine is None and caller.f_code.co_filename == process.filename:
            mine = caller
        depth += 1
        caller = caller.f_back
    place = ""
    if mine is not None:
        line = linecache.getline(mine.f_code.co_filename, mine.f_lineno).strip()
        place = f" at line {mine.f_lineno} of {Path(mine.f_code.co_filename).name} (`{line}`)"
    ran = f"{process.routine} ran {ran}{place} without touching any register"
    if asleep:
        return (f"{ran}, waiting: a sleep (time.sleep) or a read that blocks. The simulated clock moves only as "
                "firmware works the board, so a sleep stops it; to wait, poll Timer1's PIR1bits.TMR1IF or call "
                "Delay10KTCYx(), as the workshop's C does")
    if depth > RECURSION_DEPTH:
        return (f"{ran}, more than {RECURSION_DEPTH} calls deep in {frame.f_code.co_name}(): a recursion that "
                "does not end. The PIC18's return stack holds 31 calls; loop in main() instead of calling a "
                "function from itself")
    if process.routine != "main()":
        return (f"{ran}: it never returns, so main() never runs again. A real board would hang there too (a routine "
                "runs until its RETFIE); end the loop, and keep the routine short: set a flag that main() acts on")
    endless = "`while(1);`" if str(process.filename or "").lower().endswith(".c") else "`while True: pass`"
    return (f"{ran}: an endless loop such as {endless}. A real board would hang there too; poll a "
            "register in the loop (e.g. CANIsRxReady()) or end it")


class _CtrlC:
    """Blocks of the simulator's own work that Ctrl-C waits for (see `ctrl_c_waits`), and whether it was pressed."""

    waiting_for = 0
    pressed = False


@contextmanager
def ctrl_c_waits() -> Iterator[None]:
    """While the simulator runs, Ctrl-C during this block takes effect at its end: what it does is done whole (a
    log's record written and counted)."""
    _CtrlC.waiting_for += 1
    try:
        yield
    finally:
        _CtrlC.waiting_for -= 1
        if _CtrlC.pressed and not _CtrlC.waiting_for:
            _CtrlC.pressed = False
            raise KeyboardInterrupt         # also in place of an error the block raised: Ctrl-C came first


@contextmanager
def ctrl_c_stops_the_run(sim: Simulator) -> Iterator[None]:
    """While `sim` runs, Ctrl-C raises KeyboardInterrupt in the code running the simulator, never in a firmware
    (which could catch it, or would count it as its own crash): the firmware it lands in is frozen where it was.

    Only over Python's own Ctrl-C handler, from the main thread: a program with a handler of its own keeps it."""
    if (threading.current_thread() is not threading.main_thread()
            or signal.getsignal(signal.SIGINT) is not signal.default_int_handler):
        yield
        return

    def interrupt(signum: int, frame: FrameType | None) -> None:
        process = sim.running
        if process is not None and greenlet.getcurrent() is process:
            process.freeze(KeyboardInterrupt())
        if _CtrlC.waiting_for:
            _CtrlC.pressed = True
            return
        raise KeyboardInterrupt

    signal.signal(signal.SIGINT, interrupt)
    try:
        yield
    finally:
        signal.signal(signal.SIGINT, signal.default_int_handler)
