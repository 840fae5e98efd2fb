"""A board linked in real time to python-can's `virtual` bus (BusLink + WallClock), seen from a python-can peer.

Frame period jitter: the Ex2 solution's Timer1 frames (every 52.4288 ms) as they arrive outside, in wall time.
Receive latency: the peer sends RTR 0x81, the master console's firmware answers; the round trip in wall time.
"""
from __future__ import annotations

import itertools
import threading
import time

import can

from appsim.board.app023 import APP023
from appsim.bus.link import BusLink
from appsim.bus.realtime import WallClock
from appsim.bus.wire import Bus
from appsim.sim import Simulator
from appsim.workshop.course import MASTER_FIRMWARE, SOLUTIONS

EX2_PERIOD_MS = 65536 * 8 * 4 / 40e6 * 1e3      # Timer1 overflow at 1:8 from Fosc/4: 52.4288 ms
START_UP_S = 0.02                                # CANInitialize on the board, in real time
_channels = itertools.count()


class _LinkedBoard:
    """One board running `firmware` on a bus linked to a fresh python-can virtual channel, and a peer on it."""

    def __init__(self, firmware, name: str):
        channel = f"appsim-bench-link-{next(_channels)}"
        self.sim = Simulator()
        self.bus = Bus(self.sim)
        self.board = APP023(self.bus, name)
        self.board.run(firmware)
        self.link = BusLink(self.bus, can.Bus(interface="virtual", channel=channel))
        self.peer = can.Bus(interface="virtual", channel=channel)
        self.clock = WallClock(self.sim)
        self.clock.add_poller(self.link.poll)

    def close(self) -> None:
        self.link.close()
        self.peer.shutdown()


def _in_background(work) -> threading.Thread:
    thread = threading.Thread(target=work, daemon=True)
    thread.start()
    return thread


def frame_spacing_ms(seconds: float = 1.0) -> list[float]:
    """Wall-clock gaps between the Ex2 board's frames as the python-can peer receives them."""
    linked = _LinkedBoard(SOLUTIONS / "ex2.py", "station1")
    arrivals: list[float] = []
    done = threading.Event()

    def listen() -> None:
        while not done.is_set():
            message = linked.peer.recv(timeout=0.05)
            if message is not None and message.arbitration_id == 0x100 and not message.is_remote_frame:
                arrivals.append(time.perf_counter())

    try:
        thread = _in_background(listen)
        linked.clock.run(seconds)
        done.set()
        thread.join()
    finally:
        linked.close()
    return [(b - a) * 1e3 for a, b in itertools.pairwise(arrivals)]


def round_trips_ms(requests: int = 10, spacing_s: float = 0.03) -> list[float]:
    """Wall time from the peer's RTR 0x81 to the master console's data frame 0x81 back, per request."""
    linked = _LinkedBoard(MASTER_FIRMWARE, "master")
    trips: list[float] = []
    done = threading.Event()

    def ask() -> None:
        request = can.Message(arbitration_id=0x81, is_remote_frame=True, dlc=5, is_extended_id=False)
        time.sleep(START_UP_S * 2)
        for _ in range(requests):
            sent = time.perf_counter()
            linked.peer.send(request)
            while (answer := linked.peer.recv(timeout=1.0)) is not None:
                if answer.arbitration_id == 0x81 and not answer.is_remote_frame:
                    trips.append((time.perf_counter() - sent) * 1e3)
                    break
            time.sleep(spacing_s)
        done.set()

    try:
        _in_background(ask)
        linked.clock.run(stop=done.is_set)
    finally:
        linked.close()
    if len(trips) != requests:
        raise RuntimeError(f"the master answered {len(trips)} of {requests} RTR frames from the python-can peer")
    return trips
