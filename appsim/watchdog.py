"""A watchdog for firmware that spins without touching the hardware (`while True: pass`).

The simulated clock only advances when firmware touches a register, so such a loop would hang the
simulation. Like the PIC's WDT, the watchdog resets it: after `WATCHDOG_SECONDS` of wall time with no
register access, the firmware gets a `FirmwareHung` error, and the other boards go on.
"""
from __future__ import annotations

import signal
import threading
from collections.abc import Iterator
from contextlib import contextmanager
from typing import TYPE_CHECKING
from appsim.errors import FirmwareHung

if TYPE_CHECKING:
    from appsim.sim import Simulator

WATCHDOG_SECONDS = 2.0


@contextmanager
def watchdog(sim: "Simulator", seconds: float = WATCHDOG_SECONDS) -> Iterator[None]:
    """Watch the firmware `sim` runs, from the main thread (elsewhere, on Windows, or if SIGALRM is taken:
    no watch)."""
    if (not hasattr(signal, "setitimer")                  # Windows: no interval timers, no watch
            or threading.current_thread() is not threading.main_thread()
            or signal.getsignal(signal.SIGALRM) not in (signal.SIG_DFL, None)):
        yield
        return
    seen: list = [None, None]

    def bark(signum: int, frame: object) -> None:
        process = sim.running
        now = None if process is None or not process.watched else (process, process.local_time)
        if now is not None and now == tuple(seen):
            raise FirmwareHung(f"the firmware of {process.name} ran {seconds:g} s (wall time) without touching "
                               "any register: an endless loop such as `while True: pass`. A real board would "
                               "hang there too; poll a register in the loop (e.g. CANIsRxReady()) or end it")
        seen[:] = now if now is not None else (None, None)

    signal.signal(signal.SIGALRM, bark)
    signal.setitimer(signal.ITIMER_REAL, seconds, seconds)
    try:
        yield
    finally:
        signal.setitimer(signal.ITIMER_REAL, 0)
        signal.signal(signal.SIGALRM, signal.SIG_DFL)
