"""AN738 as the workshop uses it: names, enum values, quirks, and errors where C would corrupt."""
from __future__ import annotations

import pytest

from appsim.chip.ecan import registers as R
from appsim.chip.sfr import NotOnABoard
from appsim.firmware import *
from appsim.firmware.an738 import AN738Error

CLASSROOM = (4, 10, 8, 4, 3)      # SJW, BRP, PHSEG1, PHSEG2, PROPSEG: 125 kbit/s at 40 MHz


def firmware(world, body, name="station0"):
    """Run `body()` once as firmware; return what it returned."""
    out = {}
    node = world.node(name, lambda: out.setdefault("result", body()))
    world.run(0.05)
    assert "result" in out, "the firmware did not finish"
    return node, out["result"]


def test_enum_values_are_the_an738_header_values():
    assert (CAN_OP_MODE_NORMAL, CAN_OP_MODE_SLEEP, CAN_OP_MODE_LOOP, CAN_OP_MODE_LISTEN,
            CAN_OP_MODE_CONFIG, CAN_OP_MODE_BITS) == (0x00, 0x20, 0x40, 0x60, 0x80, 0xE0)
    assert (CAN_CONFIG_ALL_MSG, CAN_CONFIG_VALID_XTD_MSG, CAN_CONFIG_VALID_STD_MSG,
            CAN_CONFIG_ALL_VALID_MSG) == (0xFF, 0xDF, 0xBF, 0x9F)
    assert (CAN_TX_PRIORITY_0, CAN_TX_XTD_FRAME, CAN_TX_RTR_FRAME) == (0xFC, 0xF7, 0xBF)
    assert (CAN_RX_OVERFLOW, CAN_RX_INVALID_MSG, CAN_RX_XTD_FRAME, CAN_RX_RTR_FRAME,
            CAN_RX_DBL_BUFFERED) == (0x08, 0x10, 0x20, 0x40, 0x80)
    assert (CAN_MASK_B1, CAN_MASK_B2, CAN_FILTER_B1_F1, CAN_FILTER_B2_F1, CAN_FILTER_B2_F4) == (0, 1, 0, 2, 5)


def test_flags_are_combined_with_and():
    flags = CAN_TX_PRIORITY_0 & CAN_TX_XTD_FRAME & CAN_TX_RTR_FRAME
    assert flags & CAN_TX_PRIORITY_BITS == 0
    assert not flags & CAN_TX_FRAME_BIT and not flags & CAN_TX_RTR_BIT


def test_can_initialize_returns_in_normal_mode(world):
    node, _ = firmware(world, lambda: CANInitialize(*CLASSROOM, CAN_CONFIG_VALID_STD_MSG))
    assert node.ecan.read(node.address_of("CANSTAT")) >> 5 == 0b000


def test_can_initialize_writes_each_argument_minus_one(world):
    node, _ = firmware(world, lambda: CANInitialize(*CLASSROOM, CAN_CONFIG_SAMPLE_THRICE & CAN_CONFIG_LINE_FILTER_OFF))
    assert node.ecan.get("BRGCON1") == (3 << 6) | 9
    assert node.ecan.get("BRGCON2") == 0x80 | 0x40 | (7 << 3) | 2      # SEG2PHTS, SAM, PS1 8, Prop 3
    assert node.ecan.get("BRGCON3") == 3                                # PS2 4, no WAKFIL


def test_can_initialize_sets_masks_to_zero_and_rxm_from_the_flags(world):
    def body():
        CANInitialize(*CLASSROOM, CAN_CONFIG_VALID_STD_MSG)
    node, _ = firmware(world, body)
    assert [node.ecan.get(f"RXM{n}SIDH") for n in range(2)] == [0, 0]
    assert node.ecan.get("RXB0CON") & R.RXM_MASK == 0b01 << 5 == node.ecan.get("RXB1CON") & R.RXM_MASK


def test_can_initialize_default_flags_give_rxm_11_receive_all(world):
    node, _ = firmware(world, lambda: CANInitialize(*CLASSROOM))
    assert node.ecan.get("RXB0CON") & R.RXM_MASK == R.RXM_MASK


def test_can_initialize_never_sets_rxb0dben_library_bug(world):
    node, _ = firmware(world, lambda: CANInitialize(*CLASSROOM, CAN_CONFIG_DBL_BUFFER_ON))
    assert node.ecan.get("RXB0CON") & R.RXB0DBEN == 0


def test_set_mask_outside_configuration_mode_silently_does_nothing(world):
    def body():
        CANInitialize(*CLASSROOM, CAN_CONFIG_VALID_STD_MSG)      # back in Normal mode
        CANSetMask(CAN_MASK_B1, 0x7FF, CAN_CONFIG_STD_MSG)
        CANSetFilter(CAN_FILTER_B1_F1, 0x100, CAN_CONFIG_STD_MSG)
    node, _ = firmware(world, body)
    assert node.ecan.get("RXM0SIDH") == 0 and node.ecan.get("RXF0SIDH") == 0
    assert ("RXM0SIDH", 0xFF) in node.ecan.ignored_writes


def test_set_operation_mode_blocks_until_opmode_follows(world):
    def body():
        CANSetOperationModeNoWait(CAN_OP_MODE_NORMAL)
        requested, reached = CANGetOperationMode(), SFR.CANSTAT & CAN_OP_MODE_BITS
        CANSetOperationMode(CAN_OP_MODE_LOOP)
        return requested, reached, SFR.CANSTAT & CAN_OP_MODE_BITS
    _, (requested, reached_before, reached_after) = firmware(world, body)
    assert requested == CAN_OP_MODE_NORMAL and reached_before == CAN_OP_MODE_CONFIG
    assert reached_after == CAN_OP_MODE_LOOP


def test_send_message_fills_txb0_then_txb1_then_txb2_then_returns_false(world):
    def body():
        CANSetOperationMode(CAN_OP_MODE_CONFIG)   # off the bus: nothing is sent
        return [CANSendMessage(0x100 + i, [i], 1) for i in range(4)] + [CANIsTxReady()]
    node, result = firmware(world, body)
    assert result == [True, True, True, False, False]
    assert [node.ecan.frame_in(b).can_id for b in ("TXB0", "TXB1", "TXB2")] == [0x100, 0x101, 0x102]
    assert node.ecan.read(node.address_of("CANCON")) & R.WIN_MASK == 0, "WIN restored to 000"


def test_send_message_writes_priority_id_dlc_and_rtr_through_the_window(world):
    def body():
        CANSendMessage(0x1ABCDE, None, 0, CAN_TX_PRIORITY_2 & CAN_TX_XTD_FRAME & CAN_TX_RTR_FRAME)
    node, _ = firmware(world, body)
    assert node.ecan.get("TXB0CON") & R.TXPRI_MASK == 2
    frame = node.ecan.frame_in("TXB0")
    assert (frame.can_id, frame.extended, frame.remote, frame.dlc) == (0x1ABCDE, True, True, 0)


@pytest.mark.parametrize("call, message", [
    (lambda: CANSendMessage(0x1234, [1], 1, CAN_TX_STD_FRAME), "does not fit an 11-bit standard identifier"),
    (lambda: CANSendMessage(0x100, bytes(9), 9), "at most 8 data bytes"),
    (lambda: CANSendMessage(0x100, [1, 2], 5), "only 2 data bytes"),
    (lambda: CANSetOperationMode(CAN_OP_MODE_LOOP | CAN_OP_MODE_CONFIG), "would never happen"),
    (lambda: CANSetFilter(7, 0x88, CAN_CONFIG_STD_MSG), "not one CAN_FILTER"),
    (lambda: CANSetFilter(CAN_FILTER_B1_F1, 0x888, CAN_CONFIG_STD_MSG), "drop the upper bits"),
    (lambda: CANInitialize(5, 10, 8, 4, 3), "SJW = 5 is outside 1..4"),
    (lambda: CANInitialize(4, 0, 8, 4, 3), "BRP = 0 is outside 1..64"),
])
def test_what_c_would_silently_corrupt_raises_an_explaining_error(world, call, message):
    def body():
        with pytest.raises(AN738Error, match=message):
            call()
    firmware(world, body)


def test_firmware_functions_called_outside_a_board_explain_how_to_run_them():
    with pytest.raises(NotOnABoard, match="runs on a simulated board"):
        CANIsRxReady()


def loopback_setup(rxm=CAN_CONFIG_VALID_STD_MSG, dben=False):
    CANInitialize(*CLASSROOM, rxm)
    CANSetOperationMode(CAN_OP_MODE_CONFIG)
    if dben:
        RXB0CONbits.RXB0DBEN = 1
    CANSetOperationMode(CAN_OP_MODE_LOOP)


def send_and_wait(can_id, data=(1,), flags=CAN_TX_PRIORITY_0):
    assert CANSendMessage(can_id, list(data), len(data), flags)
    while not PIR3bits.TXB0IF and not PIR3bits.TXB1IF and not PIR3bits.TXB2IF:
        pass
    SFR.PIR3 = SFR.PIR3 & ~0x1C


def test_receive_message_reads_rxb0_before_rxb1_and_reports_double_buffering(world):
    def body():
        loopback_setup(dben=True)
        send_and_wait(0x101)                       # RXB0 (masks 0 accept all)
        send_and_wait(0x102)                       # RXB0 full, DBEN: rolls over to RXB1
        send_and_wait(0x103)                       # both full: lost, RXB1OVFL
        first, second, third = CANReceiveMessage(), CANReceiveMessage(), CANReceiveMessage()
        return first, second, third
    node, (first, second, third) = firmware(world, body)
    assert first.id == 0x101 and not first.flags & CAN_RX_DBL_BUFFERED
    assert second.id == 0x102 and second.flags & CAN_RX_OVERFLOW
    assert not second.flags & CAN_RX_DBL_BUFFERED, (
        "library quirk: `if (*MsgFlags < 0x02)` runs after the overflow bit is OR-ed in")
    assert not third, "nothing left: CANReceiveMessage is false"


def test_rollover_into_rxb1_reports_filhit_of_rxb0_and_can_rx_dbl_buffered(world):
    def body():
        loopback_setup(dben=True)
        send_and_wait(0x101)
        send_and_wait(0x102)
        return CANReceiveMessage(), CANReceiveMessage()
    _, (first, second) = firmware(world, body)
    assert (first.id, second.id) == (0x101, 0x102)
    assert second.flags == CAN_RX_DBL_BUFFERED | CAN_RX_FILTER_1


def test_full_rxb0_without_double_buffering_loses_the_frame_even_if_rxb1_is_empty(world):
    def body():
        loopback_setup()
        send_and_wait(0x101)
        send_and_wait(0x102)
        return CANReceiveMessage(), CANReceiveMessage(), SFR.COMSTAT
    node, (first, second, comstat) = firmware(world, body)
    assert first.id == 0x101 and first.flags == CAN_RX_OVERFLOW, "0x102 was lost while RXB0 was full"
    assert not second, "RXB1 was empty and accepts everything, yet nothing went there"
    assert node.ecan.get("PIR3") & R.ERRIF


def test_rxful_must_be_cleared_before_the_buffer_takes_a_new_message(world):
    def body():
        loopback_setup()
        send_and_wait(0x101)
        send_and_wait(0x102)
        RXB0CONbits.RXFUL = 0
        send_and_wait(0x103)
        return CANReceiveMessage()
    _, message = firmware(world, body)
    assert message.id == 0x103


def test_received_remote_frame_sets_rxrtr_and_can_rx_rtr_frame_and_nothing_answers_it(world):
    def body():
        loopback_setup(rxm=CAN_CONFIG_ALL_MSG)
        assert CANSendMessage(0x81, None, 0, CAN_TX_RTR_FRAME)
        while not CANIsRxReady():
            pass
        rtrro = RXB0CONbits.RXRTRRO
        return rtrro, CANReceiveMessage()
    node, (rtrro, message) = firmware(world, body)
    assert rtrro == 1 and message.flags & CAN_RX_RTR_FRAME and message.length == 0
    assert len(world.bus.loopback_trace) == 1, "Mode 0 hardware never answers an RTR by itself"


def test_extended_frame_reported_with_can_rx_xtd_frame(world):
    def body():
        loopback_setup(rxm=CAN_CONFIG_ALL_MSG)
        send_and_wait(0x1234567, (9, 8), CAN_TX_XTD_FRAME)
        return CANReceiveMessage()
    _, message = firmware(world, body)
    assert message.id == 0x1234567 and message.flags & CAN_RX_XTD_FRAME and message.data == b"\x09\x08"


def test_status_macros_read_comstat_and_the_error_counters(world):
    def body():
        return CANIsBusOff(), CANIsTxPassive(), CANIsRxPassive(), CANGetTxErrorCount(), CANGetRxErrorCount()
    _, result = firmware(world, body)
    assert result == (False, False, False, 0, 0)


def test_bits_structs_read_and_write_fields_like_c18(world):
    def body():
        CANCONbits.REQOP = 0b010
        while CANSTATbits.OPMODE != 0b010:
            pass
        return SFR.CANCON, CANSTATbits.OPMODE2, CANSTATbits.OPMODE1
    _, (cancon, op2, op1) = firmware(world, body)
    assert cancon == 0x40 and (op2, op1) == (0, 1)
