"""python-can and can-utils on a real Linux vcan0: each sees what the other sends."""
from __future__ import annotations

import can


def test_candump_sees_a_frame_python_can_sends(vcan_bus, candump):
    dump = candump()
    vcan_bus.send(can.Message(arbitration_id=0x123, data=[0xDE, 0xAD, 0xBE, 0xEF], is_extended_id=False))
    vcan_bus.send(can.Message(arbitration_id=0x1ABCDE0, data=[], is_extended_id=True))
    assert dump.wait_for(2) == ["123#DEADBEEF", "01ABCDE0#"]


def test_python_can_receives_what_cansend_sends(vcan_bus, cansend):
    cansend("123#DEADBEEF")
    message = vcan_bus.recv(timeout=5)
    assert message is not None, "python-can received nothing from cansend"
    assert (message.arbitration_id, message.is_extended_id, bytes(message.data)) == (0x123, False, b"\xde\xad\xbe\xef")
    assert message.channel == "vcan0"
