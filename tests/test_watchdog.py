"""Firmware that never touches a register cannot stop the simulation: the watchdog resets it."""
from __future__ import annotations

import sys

from appsim.firmware import *  # noqa: F403
from appsim.watchdog import FirmwareHung


def test_an_endless_loop_without_register_access_is_stopped_and_the_others_go_on(world):
    def stuck():
        CANInitialize(4, 10, 8, 4, 3, CAN_CONFIG_ALL_MSG)
        while True:
            pass

    def sender():
        CANInitialize(4, 10, 8, 4, 3, CAN_CONFIG_ALL_MSG)
        Delay1KTCYx(10)                             # 1 ms
        CANSendMessage(0x100, [1], 1, CAN_TX_STD_FRAME)
        while True:
            CANIsRxReady()

    hung = world.node("stuck", stuck)
    world.node("sender", sender)
    world.sim.run(until=world.sim.now + 10**10)
    assert isinstance(hung.process.failure, FirmwareHung)
    assert "while True: pass" in str(hung.process.failure)
    assert {str(e.frame) for e in world.bus.trace} == {"100 [1] 01"}, "the other board went on sending"


def test_sys_exit_in_firmware_stops_that_board_only(world):
    def quitter():
        sys.exit(0)

    board = world.node("quitter", quitter)
    world.sim.run(until=10**9)
    assert isinstance(board.process.failure, SystemExit)
