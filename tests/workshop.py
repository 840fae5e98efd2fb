"""Test helpers for whole classrooms: build one, the payload a board sends, the frames a node sent."""
from __future__ import annotations

from pathlib import Path

from appsim.board.app023 import APP023
from appsim.bus.wire import Bus, BusEvent
from appsim.firmware import CAN_CONFIG_ALL_MSG, CAN_TX_PRIORITY_0, CANInitialize, CANIsRxReady, CANSendMessage
from appsim.sim import PS_PER_SECOND, Simulator
from appsim.workshop.classroom import Classroom

KIT = Path(__file__).resolve().parent.parent
MS = PS_PER_SECOND // 1000


def payload(potentiometer: int) -> bytes:
    """`01 02 03 ADRESH ADRESL` for a potentiometer value (right-justified 10-bit A/D)."""
    return bytes([1, 2, 3, potentiometer >> 8, potentiometer & 0xFF])


def classroom(exercise: int, seed: int = 202, **options) -> Classroom:
    """The workshop's classroom at `exercise` on a fresh 125 kbit/s bus."""
    return Classroom(Bus(Simulator(), 125_000), exercise, seed=seed, **options)


def sent(room: Classroom, sender: str, *, remote: bool | None = None) -> list[BusEvent]:
    """The frames `sender` put through on the bus (only remote or only data frames if `remote` is given)."""
    return [e for e in room.bus.frames() if e.sender == sender and (remote is None or e.frame.remote == remote)]


def lone_node(seconds: float) -> Bus:
    """A bus with one node, "alone", that sends 0x100 with nobody to ACK it, run for `seconds`: only error frames."""
    def alone():
        CANInitialize(4, 10, 8, 4, 3, CAN_CONFIG_ALL_MSG)
        CANSendMessage(0x100, [1], 1, CAN_TX_PRIORITY_0)
        while True:
            CANIsRxReady()

    bus = Bus(Simulator())
    APP023(bus, "alone").run(alone)
    bus.sim.run_for(seconds)
    return bus
