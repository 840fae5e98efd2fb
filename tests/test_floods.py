"""Floods: a python-can peer in this process sending as fast as it can on a linked classroom (python-can's queue stays
bounded, every frame it sent is accounted for), a linked run that falls behind real time (said once: how far, since
when), and what a trace event holds in memory under a classroom's frames and under an error flood."""
from __future__ import annotations

import argparse
import gc
import io
import logging
import threading
import time
import tracemalloc

import can
import pytest

from appsim.bus.link import BusLink
from appsim.bus.realtime import WallClock
from appsim.bus.wire import Bus
from appsim.can.frame import CanFrame
from appsim.sim import Simulator, ps
from appsim.workshop.classroom import Classroom

FLOOD_S = 3.0
QUEUE_BOUND = 1024                  # what python-can's queue may hold for the link (appsim.bus.link)


def classroom(trace_window: int = 20_000) -> tuple[Simulator, Bus]:
    sim = Simulator()
    bus = Bus(sim, 125_000, trace_window=trace_window)
    Classroom(bus, 6, seed=6, monitor=False)
    return sim, bus


def test_a_peer_in_this_process_flooding_pythons_virtual_bus_is_read_bounded_and_every_frame_counted():
    sim, bus = classroom()
    sent, stop = [0], threading.Event()
    with BusLink(bus, interface="virtual", channel="appsim-flood-link") as link, \
            can.Bus(interface="virtual", channel="appsim-flood-link") as peer:
        def flood() -> None:
            message = can.Message(arbitration_id=0x7F0, data=bytes(8), is_extended_id=False)
            while not stop.is_set():
                peer.send(message)
                sent[0] += 1

        waiting = [0]
        clock = WallClock(sim)
        clock.add_poller(link.poll)
        clock.add_poller(lambda: waiting.__setitem__(0, max(waiting[0], link.outside.queue.qsize())))
        thread = threading.Thread(target=flood, daemon=True)
        thread.start()
        try:
            clock.run(FLOOD_S)
        finally:
            stop.set()
            thread.join()
        clock.run(0.05)
        assert waiting[0] <= 4 * QUEUE_BOUND, f"python-can's queue held {waiting[0]:,} frames for the link"
        assert sent[0] == link.received + link.dropped_unread + link.unread, "every frame the peer sent is counted"
        assert link.dropped_unread > 0
        report = link.report()
        assert f"{link.dropped_unread} more were dropped before the link read them: python-can's queue held " \
               f"{QUEUE_BOUND} frames" in report
        assert "does not say whether it dropped" not in report


def too_busy(seconds_per_slice: float = 0.003):
    """A poller that makes each 1 ms slice take 3 ms of wall time: a machine the simulation cannot keep up on."""
    return lambda: time.sleep(seconds_per_slice)


def test_a_run_that_falls_behind_real_time_says_so_once_how_far_and_since_when(caplog):
    clock = WallClock(Simulator())
    clock.add_poller(too_busy())
    with caplog.at_level(logging.WARNING):
        clock.run(0.6)
    told = [record.getMessage() for record in caplog.records if "behind real time" in record.getMessage()]
    assert len(told) == 1 and "the simulation has fallen 0.2 s behind real time at " in told[0], told
    late = clock.lateness()
    assert late.startswith("behind real time from 0.1 s (simulated) on: at most ") and " s behind, " in late, late
    assert clock.max_lag_s > 0.9


def test_a_linked_session_says_in_its_summary_how_far_behind_it_fell(capsys):
    from appsim.session import Session
    out = io.StringIO()
    with Session(argparse.Namespace(vcd=None, interface=None), out) as session:
        Classroom(session.bus, 2, seed=3, monitor=False)
        session.run(0.6, live=False, real_time=True, pollers=(too_busy(),))
    assert "the run fell behind real time from 0.1 s (simulated) on: at most" in out.getvalue(), out.getvalue()


class Flood:
    """An outside node with a frame always waiting, each one meeting a bit error: nothing but error frames."""

    name = "outside"

    def __init__(self, bus: Bus):
        self.bus, self.port = bus, bus.attach_outside(self)
        bus.trace.listeners.append(self.keep_sending)
        bus.inject(self.name, "bit", 20, frames=10**9)
        self.keep_sending()

    def frame_from_simulation(self, frame: CanFrame) -> None:
        """Out here nobody needs the classroom's frames."""

    def keep_sending(self, event: object = None) -> None:
        while len(self.port.queue) < 2:
            self.bus.from_outside(self, CanFrame(0x050, bytes(range(8))))


@pytest.mark.parametrize("flood", [False, True], ids=["classroom frames", "error flood"])
def test_a_trace_event_holds_about_200_bytes_as_the_trace_says(flood):
    """What 3,000 events hold in memory (tracemalloc): what the bus frees when its trace lets them go, with what it
    keeps of them (frames, outcomes and wires that events repeat)."""
    events = 3000
    sim, bus = classroom(trace_window=events)
    if flood:
        Flood(bus)
    sim.run(until=ps(0.3))

    def forget() -> None:
        bus.trace._events.clear()
        getattr(bus, "_kept", {}).clear()
        gc.collect()

    tracemalloc.start()
    try:
        forget()
        while len(bus.trace) < events:
            sim.run(until=sim.now + ps(0.05))
        gc.collect()
        held = tracemalloc.get_traced_memory()[0]
        forget()
        each = (held - tracemalloc.get_traced_memory()[0]) / events
    finally:
        tracemalloc.stop()
    if flood:
        assert bus.trace.errors >= events
    assert each < 250, f"{each:.0f} bytes an event"
