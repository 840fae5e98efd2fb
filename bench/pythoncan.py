"""The kit's full model against python-can's own `virtual` bus: one sender, six receivers, frames per wall second.

The kit runs seven APP023 boards at 1 Mbit/s (ECAN, filters, AN738 on both ends); python-can only moves messages.
"""
from __future__ import annotations

import itertools
import time

import can

from appsim.board.app023 import APP023
from appsim.bus.wire import Bus
from appsim.firmware import CAN_CONFIG_VALID_STD_MSG, CANInitialize, CANIsRxReady, CANReceiveMessage
from appsim.sim import Simulator, ps
from bench import fullload

RECEIVERS = 6
_channels = itertools.count()


def kit_fps(simulated_s: float = 0.05) -> float:
    """Frames per wall second one saturating sender delivers to six receivers' CANReceiveMessage."""
    sim = Simulator()
    bus = Bus(sim, fullload.BIT_RATE)
    received = [0] * (RECEIVERS + 1)
    APP023(bus, "sender").run(fullload.node_firmware(0, 1, received))
    for k in range(1, RECEIVERS + 1):
        APP023(bus, f"receiver{k}").run(receiver_firmware(k, received))
    sim.run(until=ps(fullload.WARM_UP_S))
    before = sum(received)
    started = time.perf_counter()
    sim.run_for(simulated_s)
    wall = time.perf_counter() - started
    return (sum(received) - before) / RECEIVERS / wall


def receiver_firmware(node: int, received: list[int]):
    """A receiver's main(): every frame read with CANReceiveMessage, counted in `received[node]`."""
    def main() -> None:
        CANInitialize(*fullload.MBIT, CAN_CONFIG_VALID_STD_MSG)
        while True:
            if CANIsRxReady():
                CANReceiveMessage()
                received[node] += 1
    return main


def python_can_fps(frames: int = 20_000) -> float:
    """Frames per wall second python-can's virtual bus passes from one sender to six receivers."""
    channel = f"appsim-bench-{next(_channels)}"
    sender = can.Bus(interface="virtual", channel=channel)
    receivers = [can.Bus(interface="virtual", channel=channel) for _ in range(RECEIVERS)]
    try:
        message = can.Message(arbitration_id=0x100, data=bytes(range(8)), is_extended_id=False)
        got = 0
        started = time.perf_counter()
        for _ in range(frames):
            sender.send(message)
            for receiver in receivers:
                got += receiver.recv(timeout=0) is not None
        wall = time.perf_counter() - started
    finally:
        for bus in (sender, *receivers):
            bus.shutdown()
    if got != frames * RECEIVERS:
        raise RuntimeError(f"python-can's virtual bus delivered {got} of {frames * RECEIVERS} frames")
    return frames / wall
