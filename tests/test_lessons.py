"""What the lessons teach agrees with the checks: where the workshop, the data sheet and the CAN standard differ, the
check accepts what each of them allows, and says why when it refuses."""
from __future__ import annotations

import random

import matplotlib

matplotlib.use("Agg")

import matplotlib.pyplot as plt
import pytest

from appsim.can import physical
from appsim.can.bits import encode
from appsim.can.frame import CanFrame
from appsim.chip.ecan.acceptance import id_pattern, passing_ids
from appsim.firmware import (
    CAN_CONFIG_STD_MSG,
    CAN_CONFIG_VALID_STD_MSG,
    CAN_FILTER_B1_F1,
    CAN_FILTER_B1_F2,
    CAN_MASK_B1,
    CAN_OP_MODE_CONFIG,
    CAN_OP_MODE_LOOP,
    CAN_TX_PRIORITY_0,
    CAN_TX_STD_FRAME,
    CANInitialize,
    CANIsRxReady,
    CANReceiveMessage,
    CANSendMessage,
    CANSetFilter,
    CANSetMask,
    CANSetOperationMode,
    Delay1KTCYx,
)
from appsim.workshop import plots
from appsim.workshop.checks import check
from appsim.workshop.course import solution

RTR_LINE = "CANSendMessage(RTR_ID, None, 0,"


@pytest.mark.parametrize("dlc, passes", [(0, True), (5, True), (3, False), (8, False)])
def test_an_ex5_request_may_have_the_workshops_dlc_0_or_the_standards_5(tmp_path, dlc, passes):
    source = solution("ex5").read_text()
    assert source.count(RTR_LINE) == 1
    firmware = tmp_path / "ex5.py"
    firmware.write_text(source.replace(RTR_LINE, f"CANSendMessage(RTR_ID, None, {dlc},"))
    verdict = check("ex5", firmware, seed=11)
    requests = verdict.checks[1]
    assert requests.passed is passes, str(verdict)
    assert verdict.passed is passes
    if passes:
        assert f"RTR DLC {dlc}" in requests.message
    else:
        for words in (f"RTR DLC {dlc}", "The workshop sends DataLen 0", "CAN 2.0 advises", "5 here", "bit error"):
            assert words in requests.message, requests.message


# ---------------------------------------------------------------- the lessons' tools compute what the kit does

@pytest.mark.parametrize("mask, filter_", [(0x7FF, 0x088), (0x7F0, 0x120), (0x0FF, 0x100), (0x000, 0x5A5),
                                           (0x70F, 0x100)])
def test_the_mask_filter_table_lists_exactly_the_ids_the_simulated_ecan_takes(world, mask, filter_):
    """`passing_ids`, the notebooks' truth-table tool, against a board in Loopback mode sending candidate IDs."""
    passing = set(passing_ids(mask, filter_))
    candidates = sorted(set(random.Random(mask ^ filter_).sample(range(0x800), 40)) | set(list(passing)[:24]))

    def main():
        CANInitialize(4, 10, 8, 4, 3, CAN_CONFIG_VALID_STD_MSG)
        CANSetOperationMode(CAN_OP_MODE_CONFIG)
        CANSetMask(CAN_MASK_B1, mask, CAN_CONFIG_STD_MSG)
        CANSetFilter(CAN_FILTER_B1_F1, filter_, CAN_CONFIG_STD_MSG)
        CANSetFilter(CAN_FILTER_B1_F2, filter_, CAN_CONFIG_STD_MSG)
        CANSetOperationMode(CAN_OP_MODE_LOOP)
        for can_id in candidates:
            CANSendMessage(can_id, [], 0, CAN_TX_PRIORITY_0 & CAN_TX_STD_FRAME)
            Delay1KTCYx(10)
            while CANIsRxReady():
                CANReceiveMessage()
        while True:
            Delay1KTCYx(10)

    world.node("board", main)
    world.run(0.02 + 0.001 * len(candidates))
    into_rxb0 = {e.frame.can_id for e in world.bus.loopback_trace if e.received[0][1].startswith("RXB0")}
    assert len(world.bus.loopback_trace) == len(candidates)
    assert into_rxb0 == passing & set(candidates)
    assert id_pattern(mask, filter_).replace(" ", "").count("x") == 11 - bin(mask).count("1")


def test_the_truth_table_rows_of_the_data_sheet():
    """DS39500 section 5.3 / workshop section 2.7: mask bit 0 accepts, mask bit 1 accepts only equal bits."""
    for mask_bit, filter_bit, id_bit, accepts in [(0, 0, 0, True), (0, 1, 1, True), (0, 0, 1, True),
                                                  (1, 0, 0, True), (1, 0, 1, False), (1, 1, 0, False),
                                                  (1, 1, 1, True)]:
        assert (id_bit in passing_ids(mask_bit, filter_bit)) is accepts
    assert id_pattern(0x7F0, 0x120) == "001 0010 xxxx"
    assert passing_ids(0x0FF, 0x100)[:3] == [0x000, 0x100, 0x200], "a 0x0FF mask aliases 0x100 with 0x000, 0x200"


def test_the_physical_layer_numbers_are_the_sources_and_the_picture_draws_them():
    assert [physical.differential_volts(level) for level in (physical.DOMINANT, physical.RECESSIVE)] == [2.0, 0.0]
    assert physical.RECESSIVE_BELOW_VOLTS < physical.DOMINANT_ABOVE_VOLTS < physical.WORKSHOP_DOMINANT_ABOVE_VOLTS
    assert physical.bus_resistance_ohms() == 60
    # the workshop's approximation against its own tables: 48 m at 1 Mbit/s (the tables: 40 m)
    assert round(physical.workshop_max_bus_length_metres(1_000_000)) == 48
    levels = encode(CanFrame(0x100, bytes([1, 2, 3, 1, 0x2C])))[:20]
    figure = plots.bus_levels(levels)
    wires, difference, bus = figure.axes
    canh, canl = wires.lines[:2]
    assert [canh.get_ydata()[i] - canl.get_ydata()[i] for i in range(20)] == [2.0 * (1 - level) for level in levels]
    assert len([p for p in bus.patches if p.get_gid() == "terminator"]) == 2
    assert "60 Ω" in bus.get_title()
    plt.close(figure)
