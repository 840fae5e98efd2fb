"""What a polling loop costs: wall time per simulated second of a node spinning on `CANIsRxReady()`.

A frame every 100 ms from a second node (the loop wakes for each), or no frame at all (a lone node).
"""
from __future__ import annotations

import time

from appsim.board.app023 import APP023
from appsim.bus.wire import Bus
from appsim.firmware import (
    CAN_CONFIG_ALL_VALID_MSG,
    CAN_TX_STD_FRAME,
    CANInitialize,
    CANIsRxReady,
    CANReceiveMessage,
    CANSendMessage,
    Delay10KTCYx,
)
from appsim.sim import PS_PER_SECOND, Simulator

CLASSROOM = (4, 10, 8, 4, 3)        # 125 kbit/s at 40 MHz


def poller() -> None:
    CANInitialize(*CLASSROOM, CAN_CONFIG_ALL_VALID_MSG)
    while True:
        if CANIsRxReady():
            CANReceiveMessage()


def sender() -> None:
    CANInitialize(*CLASSROOM, CAN_CONFIG_ALL_VALID_MSG)
    while True:
        Delay10KTCYx(100)                              # 100 ms
        CANSendMessage(0x100, [1, 2, 3], 3, CAN_TX_STD_FRAME)


def wall_ms_per_simulated_second(with_frames: bool, simulated_s: float = 10.0) -> float:
    sim = Simulator()
    bus = Bus(sim)
    APP023(bus, "poller").run(poller)
    if with_frames:
        APP023(bus, "sender").run(sender)
    sim.run(until=PS_PER_SECOND // 100)             # initialised
    started = time.perf_counter()
    sim.run_for(simulated_s)
    return (time.perf_counter() - started) * 1e3 / simulated_s
