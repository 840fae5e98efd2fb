"""Floods: the bit-level bus under a continuous error flood from outside, what a trace event costs in memory, and a
python-can peer in this process flooding a linked classroom for minutes (memory and lateness).

The classroom is the Ex6 one: the master console and six stations running the solutions, as `appsim classroom` runs.
"""
from __future__ import annotations

import gc
import logging
import random
import sys
import threading
import time
import tracemalloc
from dataclasses import dataclass

import can

from appsim.bus.link import BusLink
from appsim.bus.realtime import WallClock
from appsim.bus.wire import Bus, BusEvent
from appsim.can.frame import CanFrame
from appsim.sim import Simulator, ps
from appsim.workshop.classroom import Classroom

BIT_RATE = 125_000
FLOOD_ID = 0x050                # below every classroom identifier: the outside node takes the bus at every SOF
STEADY_ERROR_BIT = 20           # where a steady flood's frames meet their bit error (a data bit of an 8-byte frame)
EVENTS_MEASURED = 3000          # trace events whose memory is measured
EVENT_BYTES = 250               # what one may hold at most: appsim/bus/trace.py says about 200
WARM_UP_S = 0.05                # the boards' CANInitialize, not timed


def _classroom(trace_window: int | None = None) -> tuple[Simulator, Bus, Classroom]:
    sim = Simulator()
    bus = Bus(sim, BIT_RATE) if trace_window is None else Bus(sim, BIT_RATE, trace_window=trace_window)
    room = Classroom(bus, 6, seed=6, monitor=False)
    sim.run(until=ps(WARM_UP_S))
    return sim, bus, room


class ErrorFlood:
    """An outside node that always has a frame waiting, every one of which meets a bit error: as behind a broken
    transceiver, so the bus carries nothing but error frames. `varied`: random data, and each try's error at another
    bit, so no two error frames are alike; else it sends one frame again and again, the error always at one bit."""

    name = "outside"

    def __init__(self, bus: Bus, *, varied: bool, seed: int = 1):
        self.bus, self.varied, self.random = bus, varied, random.Random(seed)
        self.port = bus.attach_outside(self)
        bus.trace.listeners.append(self._next)
        if not varied:
            bus.inject(self.name, "bit", STEADY_ERROR_BIT, frames=10**9)
        self._next()

    def frame_from_simulation(self, frame: CanFrame) -> None:
        """Out here nobody needs the classroom's frames."""

    def _next(self, event: BusEvent | None = None) -> None:
        draw = self.random
        while len(self.port.queue) < 2:
            payload = bytes(draw.randrange(256) for _ in range(8)) if self.varied else bytes(range(8))
            self.bus.from_outside(self, CanFrame(FLOOD_ID, payload))
        if self.varied:
            self.bus.inject(self.name, "bit", draw.randrange(12, 60))


@dataclass(frozen=True)
class FloodRun:
    simulated_s: float
    wall_s: float
    events: int
    error_frames: int

    @property
    def real_time_factor(self) -> float:
        return self.simulated_s / self.wall_s


def error_flood(simulated_s: float, *, varied: bool) -> FloodRun:
    """`simulated_s` of the classroom under an `ErrorFlood`, timed."""
    sim, bus, _ = _classroom()
    ErrorFlood(bus, varied=varied)
    before, errors_before = bus.trace.total, bus.trace.errors
    started = time.perf_counter()
    sim.run(until=sim.now + ps(simulated_s))
    wall = time.perf_counter() - started
    for process in sim.processes:
        if process.failure is not None:
            raise RuntimeError(f"classroom firmware {process.name} crashed:\n{process.failure_text}")
    return FloodRun(simulated_s, wall, bus.trace.total - before, bus.trace.errors - errors_before)


def bytes_per_event(flood: str) -> float:
    """What a trace event holds in memory (tracemalloc: what `EVENTS_MEASURED` of them and what the bus keeps for them
    take, freed when they go): the classroom's own frames (`flood` ""), or "steady" or "varied" error frames."""
    sim, bus, _ = _classroom(EVENTS_MEASURED)
    if flood:
        ErrorFlood(bus, varied=flood == "varied")
    sim.run(until=sim.now + ps(0.2))

    def forget() -> None:
        bus.trace._events.clear()
        bus._kept.clear()
        gc.collect()

    tracemalloc.start()
    try:
        forget()
        while len(bus.trace) < EVENTS_MEASURED:
            sim.run(until=sim.now + ps(0.05))
        gc.collect()
        held = tracemalloc.get_traced_memory()[0]
        forget()
        return (held - tracemalloc.get_traced_memory()[0]) / EVENTS_MEASURED
    finally:
        tracemalloc.stop()


def _rss_mb() -> float:
    with open("/proc/self/status", encoding="ascii") as status:
        for line in status:
            if line.startswith("VmRSS:"):
                return int(line.split()[1]) / 1024
    return float("nan")


@dataclass(frozen=True)
class PeerRun:
    seconds: float
    rss_mb: tuple[float, ...]            # the process's resident memory, sampled every `sample_s`
    sample_s: float
    sent: int                            # frames the peer sent
    accounted: int                       # of them, counted by the link: received, dropped unread, still unread
    max_lag_s: float
    lateness: str
    most_unread: int                     # the most frames python-can's queue held for the link at a poll
    lcd_writes: int                      # what the boards' LCD histories hold at the end (HISTORY_WRITES each at most)
    lcd_mb: float                        # and about how much memory that is

    def growth_mb(self, after_s: float) -> float:
        """How much the resident memory grew from `after_s` into the run to its end."""
        start = min(len(self.rss_mb) - 1, round(after_s / self.sample_s))
        return self.rss_mb[-1] - self.rss_mb[start]


def virtual_peer(seconds: float, *, sample_s: float = 1.0) -> PeerRun:
    """The classroom linked in real time to python-can's virtual bus, and a peer in this process sending 8-byte frames
    on it as fast as it can (reading and dropping what it receives, as a peer does) for `seconds` of wall time."""
    sim, bus, room = _classroom()
    channel = f"appsim-bench-flood-{time.monotonic_ns()}"
    link = BusLink(bus, interface="virtual", channel=channel)
    peer = can.Bus(interface="virtual", channel=channel)
    stop, sent = threading.Event(), [0]

    def flood() -> None:
        message = can.Message(arbitration_id=0x7F0, data=bytes(8), is_extended_id=False)
        while not stop.is_set():
            peer.send(message)
            sent[0] += 1
            while peer.recv(timeout=0) is not None:
                pass

    clock = WallClock(sim)
    clock.add_poller(link.poll)
    most = [0]
    clock.add_poller(lambda: most.__setitem__(0, max(most[0], link.unread)))
    thread = threading.Thread(target=flood, daemon=True)
    samples = [_rss_mb()]
    told = logging.getLogger("appsim")
    level, told.level = told.level, logging.ERROR          # the link tells of its drops every second: counted here
    try:
        thread.start()
        for _ in range(max(1, round(seconds / sample_s))):
            clock.run(sample_s)
            samples.append(_rss_mb())
        stop.set()
        thread.join()
        clock.run(0.05)                 # what is left in python-can's queue is counted
        accounted = link.received + link.dropped_unread + link.unread
    finally:
        told.setLevel(level)
        stop.set()
        link.close()
        peer.shutdown()
    writes = [write for board in room.boards for write in board.glcd.history]
    lcd_mb = sum(sys.getsizeof(w) + sys.getsizeof(w.text) + sys.getsizeof(w.time_ps) + 8 for w in writes) / 2**20
    return PeerRun(seconds, tuple(samples), sample_s, sent[0], accounted, clock.max_lag_s, clock.lateness(), most[0],
                   len(writes), lcd_mb)
