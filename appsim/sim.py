"""The simulated clock: integer picoseconds, events in (time, order) sequence, firmware as processes.

Deterministic by construction: nothing here reads the wall clock, and ties are broken by the order
in which things were scheduled. Firmware `main()` loops run as greenlets that spend instruction
cycles; a loop that polls a world that cannot change until the next event parks until that event.
"""
from __future__ import annotations

import contextvars
import heapq
import itertools
import traceback
from collections.abc import Callable
from typing import Any

import greenlet

from appsim.watchdog import ctrl_c_stops_the_run, watchdog

PS_PER_SECOND = 10**12
COMPACT_EVENTS = 1024           # scheduled events beyond which cancelled ones are dropped (a firmware that restarts
                                # Timer1 forever cancels its overflow each time)
TRACEBACK_FRAMES = 50           # of a failing firmware, the innermost a report looks at (a recursion has thousands)


def seconds(ps: int) -> float:
    """Picoseconds of simulated time as seconds."""
    return ps / PS_PER_SECOND


def ps(seconds_: float) -> int:
    """Seconds of simulated time as whole picoseconds."""
    return round(seconds_ * PS_PER_SECOND)


class Timer:
    """A scheduled callback; `cancel()` keeps it from running."""

    __slots__ = ("time", "callback", "cancelled")

    def __init__(self, time: int, callback: Callable[[], Any]):
        self.time = time
        self.callback = callback
        self.cancelled = False

    def cancel(self) -> None:
        self.cancelled = True


class Simulator:
    """The clock of one simulated world (a bus and the boards on it).

    `quantum_ps` lets a running firmware run ahead of other firmware by up to that much simulated
    time before it must hand over; it never runs past a hardware event. The bus sets it below the
    shortest time in which one node's register write can become visible to another (one bit time),
    and sets `quiet_until`: the time (its busy-until) before which nothing any firmware does now can
    reach another node except through events already scheduled. Until then firmware runs on freely.
    """

    def __init__(self, *, quantum_ps: int = 0):
        self.now = 0
        self.quantum_ps = quantum_ps
        self.quiet_until: Callable[[], int] = lambda: 0
        self._events: list[tuple[int, int, Timer]] = []
        self._compact_at = COMPACT_EVENTS
        self._ready: list[tuple[int, int, Process]] = []
        self._order = itertools.count()
        self.processes: list[Process] = []
        self.running: Process | None = None

    # -------------------------------------------------------------- events
    def time(self) -> int:
        """Simulated time as the caller sees it: a running firmware's own clock is ahead of `now`."""
        running = self.running
        return running.local_time if running is not None and greenlet.getcurrent() is running else self.now

    def call_at(self, time: int, callback: Callable[[], Any]) -> Timer:
        """Run `callback` at simulated time `time` (never in the past).

        When firmware causes the event (a register write), it may not run past it without seeing it.
        """
        timer = Timer(max(time, self.now), callback)
        events = self._events
        if len(events) >= self._compact_at:     # cancelled timers stay until their time: drop them now and then
            events[:] = [event for event in events if not event[2].cancelled]
            heapq.heapify(events)
            self._compact_at = max(COMPACT_EVENTS, 2 * len(events))
        heapq.heappush(events, (timer.time, next(self._order), timer))
        running = self.running
        if running is not None and timer.time < running.horizon:
            running.horizon = timer.time
        return timer

    def call_after(self, delay: int, callback: Callable[[], Any]) -> Timer:
        """Run `callback` `delay` picoseconds after the caller's present (see `time`)."""
        return self.call_at(self.time() + delay, callback)

    # -------------------------------------------------------------- processes
    def start(self, name: str, main: Callable[[], Any], *, context: contextvars.Context | None = None) -> Process:
        """Start firmware `main` as a process at the current time, in `context` (its context variables)."""
        process = Process(self, name, main, context)
        self.processes.append(process)
        self._make_ready(process)
        return process

    def _make_ready(self, process: Process) -> None:
        heapq.heappush(self._ready, (process.local_time, next(self._order), process))

    # -------------------------------------------------------------- the loop
    def run(self, until: int | None = None) -> None:
        """Advance simulated time, to `until` (ps) or until nothing is left to happen.

        A firmware that runs on without touching a register is stopped by the watchdog (`FirmwareHung`); Ctrl-C
        stops the run (KeyboardInterrupt here), wherever it lands, and the firmware it landed in stays where it was.
        """
        with watchdog(self), ctrl_c_stops_the_run(self):
            try:
                self._run(until)
            finally:
                self.running = None

    def run_for(self, seconds_: float) -> None:
        """Advance simulated time by `seconds_` from now."""
        self.run(until=self.now + ps(seconds_))

    def _run(self, until: int | None) -> None:
        """Events and ready processes share one (time, order) sequence: `order` comes from one counter,
        so comparing the heads of the two heaps as tuples never gets past it."""
        events, ready = self._events, self._ready
        heappop = heapq.heappop
        last = float("inf") if until is None else until
        scheduler = greenlet.getcurrent()
        while events or ready:
            if ready and (not events or ready[0] < events[0]):
                time = ready[0][0]
                if time > last:
                    break
                process = heappop(ready)[2]
                self.now = time
                # How far it may go before it must hand over: the next event, the next process's quantum, the end.
                horizon = events[0][0] if events and events[0][0] < last else last
                if ready:
                    others = max(ready[0][0], self.quiet_until()) + self.quantum_ps
                    if others < horizon:
                        horizon = others
                process.horizon = horizon
                self.running = process
                if process.parent is not scheduler:
                    process.parent = scheduler      # hand back to whoever runs the simulator
                process.switch()
                self.running = None
            else:
                time = events[0][0]
                if time > last:
                    break
                timer = heappop(events)[2]
                if not timer.cancelled:
                    self.now = time
                    timer.callback()
        if until is not None and until > self.now:
            self.now = until


class Process(greenlet.greenlet):
    """One firmware `main()` running on the simulated clock.

    It owns a local time that runs ahead of the simulator's `now` as it spends instruction cycles.
    It hands control back when that time passes the horizon (the next thing that must happen
    first), or parks when it is polling a world that has not changed.

    Whatever main() raises (an error, sys.exit(), KeyboardInterrupt, the watchdog's FirmwareHung) stops this board
    only: it is kept in `failure`. A main() that returns leaves `finished` set and no failure.
    """

    # Slots: attributes of a greenlet subclass are otherwise looked up the slow way, on every register access.
    __slots__ = ("failure", "finished", "horizon", "local_time", "main", "name", "parked", "routine", "sim",
                 "stopping", "watched")

    def __init__(self, sim: Simulator, name: str, main: Callable[[], Any], context: contextvars.Context | None):
        super().__init__(self._body)
        if context is not None:
            self.gr_context = context   # type: ignore[misc]  # greenlet's own attribute (its context), not a slot
        self.sim = sim
        self.name = name
        self.main = main
        self.local_time = sim.now
        self.horizon: float = 0
        self.parked = False
        self.watched = True           # by the watchdog (a sandboxed firmware has its own limits)
        self.routine = "main()"       # what runs now, in messages: main(), or the interrupt routine that interrupted it
        self.finished = False
        self.stopping = False
        self.failure: BaseException | None = None

    def _body(self) -> None:
        try:
            self.main()
        except BaseException as failure:        # a crash, sys.exit(), KeyboardInterrupt: this board stops, no other
            if self.failure is None and not self.stopping:
                self.failure = failure
        finally:
            self.finished = True

    @property
    def filename(self) -> str | None:
        """The file main() was loaded from (where a failure's line is looked for), if it has one."""
        code = getattr(self.main, "__code__", None)
        return code.co_filename if code is not None else None

    @property
    def failure_text(self) -> str:
        """The failure's traceback, its last `TRACEBACK_FRAMES` frames (a runaway recursion has thousands)."""
        if self.failure is None:
            return ""
        return "".join(traceback.format_exception(self.failure, limit=-TRACEBACK_FRAMES))

    def spend(self, time_ps: int) -> None:
        """Account for instructions executed; hand over if that passes the horizon."""
        self.local_time += time_ps
        if self.local_time > self.horizon:
            if self.failure is not None:        # it caught the watchdog's FirmwareHung and went on
                self.freeze()
            self.sim._make_ready(self)
            self.parent.switch()

    def park(self) -> None:
        """Wait, without spending cycles one by one, until `wake()` says something changed."""
        if self.failure is not None:
            self.freeze()
        self.parked = True
        self.parent.switch()

    def wake(self) -> None:
        if self.parked:
            self.parked = False
            self.local_time = max(self.local_time, self.sim.now)
            self.sim._make_ready(self)

    def freeze(self, failure: BaseException | None = None) -> None:
        """Stop this firmware for good where it is, from inside it (the watchdog's and Ctrl-C's last resort): it hands
        over to the simulator and is never resumed. Nor is it ever killed, which would run its code again (and a
        firmware that catches GreenletExit would run on): it stays in `FROZEN`. With `failure`, the simulator gets
        that raised; it is the board's failure unless it had one."""
        FROZEN.append(self)
        self.finished = True
        if failure is None:
            self.parent.switch()
        else:
            if self.failure is None:
                self.failure = failure
            self.parent.throw(failure)

    def stop(self) -> None:
        """End the firmware (as a reset would), wherever it is."""
        self.stopping = True
        if not self.dead:
            self.throw(greenlet.GreenletExit)
        self.finished = True


FROZEN: list[Process] = []      # firmware stopped where it was (see Process.freeze), never to run again
