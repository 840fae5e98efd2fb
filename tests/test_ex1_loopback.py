"""Ex1 end to end on one board: the starter receives nothing, the fixes receive the own frame."""
from __future__ import annotations

from pathlib import Path

import pytest

from appsim.board.app023 import APP023
from appsim.firmware.loader import FirmwareError, load_firmware

KIT = Path(__file__).resolve().parent.parent


def run_ex1(world, path=KIT / "exercises" / "ex1.py", potentiometer=666, **overrides):
    """Run Ex1 with some module constants changed, recording every message the firmware reads."""
    module = load_firmware(path)
    vars(module).update(overrides)
    received = []
    original = module.CANReceiveMessage
    module.CANReceiveMessage = lambda: received.append(original()) or received[-1]
    board = APP023(world.bus, "station0", potentiometer=potentiometer)
    board.run(module)
    world.run(0.2)
    return board, received


def test_ex1_starter_with_filter_0x088_never_sees_its_own_frame(world):
    board, received = run_ex1(world)
    assert received == []
    assert world.bus.trace == [], "loopback never drives the bus"
    [event] = world.bus.loopback_trace
    assert event.frame.can_id == 0x100 and event.received == (("station0", "rejected by the masks and filters"),)


def test_ex1_with_the_filter_fixed_receives_its_own_5_byte_frame(world):
    board, received = run_ex1(world, potentiometer=666, RX_Filter0=0x100)
    [message] = received
    assert message.id == 0x100 and message.length == 5 and message.flags == 0
    assert message.data == bytes([1, 2, 3, 666 >> 8, 666 & 0xFF])
    assert world.bus.trace == []


def test_ex1_with_rxm_11_receives_everything_despite_the_filter(world):
    from appsim.firmware import CAN_CONFIG_ALL_MSG
    module_init = load_firmware(KIT / "exercises" / "ex1.py").CANInitialize

    def init_all(*args):
        module_init(*args[:5], CAN_CONFIG_ALL_MSG)
    board, received = run_ex1(world, CANInitialize=init_all)
    [message] = received
    assert message.id == 0x100 and message.data[:3] == b"\x01\x02\x03"


def test_ex1_solution_file_receives_the_potentiometer_value(world):
    board, received = run_ex1(world, path=KIT / "solutions" / "ex1.py", potentiometer=1023)
    assert [m.data for m in received] == [bytes([1, 2, 3, 0x03, 0xFF])]


def test_firmware_file_without_main_is_refused_with_what_to_do(tmp_path):
    path = tmp_path / "nomain.py"
    path.write_text("from appsim.firmware import *\nMESSAGE_ID1 = 0x100\n")
    with pytest.raises(FirmwareError, match="has no main"):
        load_firmware(path)
    with pytest.raises(FirmwareError, match="there is no firmware file"):
        load_firmware(tmp_path / "missing.py")
