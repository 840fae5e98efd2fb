"""Lessons a student can trust: what the notebooks, docstrings, checks and docs say is what the kit computes.

Where the workshop, the data sheet and the CAN standard differ, the check accepts what each allows and says why when
it refuses; the notebook and its check judge by one definition; the lessons' tools (the mask/filter table, the
physical layer) compute what the simulated chip does; and every number the prose states with a unit (times, bits,
TQ, sample points, bit rates, volts, metres, TEC values from runs) is computed here from the kit and compared.
"""
from __future__ import annotations

import random
import re
import shutil
from collections.abc import Callable
from fractions import Fraction
from functools import cache
from pathlib import Path

import matplotlib

matplotlib.use("Agg")

import matplotlib.pyplot as plt
import nbformat
import pytest

from appsim.board.app023 import APP023
from appsim.bus.wire import BUS_IDLE_BITS, Bus
from appsim.can import physical
from appsim.can.bits import INTERMISSION_BITS, encode, encode_annotated, frame_bits, frame_time, max_frame_bits
from appsim.can.bittiming import IPT_TQ, SEGMENT_MAX_TQ, SJW_MAX_TQ, BitTiming, calculate, seed_recipe
from appsim.can.frame import STANDARD_ID_MAX, CanFrame
from appsim.chip.ecan.acceptance import id_pattern, passing_ids
from appsim.chip.mcu import FOSC_HZ, PIC18F8680, SFR_ACCESS_CYCLES
from appsim.chip.usart import PC_BAUD
from appsim.firmware import (
    CAN_CONFIG_STD_MSG,
    CAN_CONFIG_VALID_STD_MSG,
    CAN_FILTER_B1_F1,
    CAN_FILTER_B1_F2,
    CAN_MASK_B1,
    CAN_OP_MODE_CONFIG,
    CAN_OP_MODE_LOOP,
    CAN_RX_INVALID_MSG,
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
from appsim.firmware.loader import load_firmware
from appsim.sim import PS_PER_SECOND, Simulator
from appsim.watchdog import WATCHDOG_SECONDS
from appsim.workshop import plots
from appsim.workshop.checks import check, check_names
from appsim.workshop.checks.ex4 import before_the_first_0x088
from appsim.workshop.checks.trial import TIMER1_PERIOD_PS, payload
from appsim.workshop.classroom import Classroom
from appsim.workshop.course import MASTER_ID, solution, starter
from appsim.workshop.notebook import KNOB_SECONDS, Station

KIT = Path(__file__).resolve().parent.parent
MS = PS_PER_SECOND // 1000
RTR_LINE = "CANSendMessage(RTR_ID, None, 0,"


# ---------------------------------------------------------------- the checks judge what the lessons teach

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


def test_ex1_fix_c_both_ways_passes_as_the_notebook_and_the_solution_say(tmp_path):
    """The workshop's fix (c), MESSAGE_ID1 and RX_Filter0 equal: the filter set to the ID, or the ID to the filter."""
    source = solution("ex1").read_text()
    firmware = tmp_path / "ex1.py"
    firmware.write_text(source.replace("MESSAGE_ID1 = 0x100 ", "MESSAGE_ID1 = 0x088 "))
    assert check("ex1", firmware, seed=5).passed
    answer = markdown("ex1")
    for words in ("`RX_Filter0 = MESSAGE_ID1`", "`MESSAGE_ID1 = 0x088`", "the check accepts each"):
        assert words in answer
    assert "MESSAGE_ID1 to 0x088" in source


def ex4_classroom(firmware: Path) -> tuple[Classroom, APP023]:
    """The classroom of notebook ex4 (station 1 runs `firmware`), run for its 0.5 s."""
    room = Classroom(Bus(Simulator()), 4)
    board = room.join(firmware, station=1)
    room.run(0.5)
    return room, board


@pytest.mark.parametrize("exercise, keeps_quiet", [(starter, False), (solution, True)])
def test_ex4_the_notebook_and_the_check_list_the_same_frames_before_the_first_0x088_ends(exercise, keeps_quiet):
    """One definition: frames the node sent or ACKed that started before the master's first 0x088 ended."""
    room, board = ex4_classroom(exercise("ex4"))
    first, before = before_the_first_0x088(room.bus, board.name)
    assert first.sender == "master" and first.frame.can_id == MASTER_ID
    assert (before == []) is keeps_quiet
    if not keeps_quiet:
        assert first in before, "the starter is in Normal mode and ACKs the 0x088 itself"
    listens = check("ex4", exercise("ex4"), seed=4).checks[1]
    assert listens.name == check_names("ex4")[1] and listens.passed is keeps_quiet
    if not keeps_quiet:
        assert "ACKed 0x088" in listens.message and "not even the 0x088 it is waiting for" in listens.message
    assert any(c.source == "station.before_the_master()" for c in read("ex4").cells), "the notebook shows the list"
    shown = Station("ex4", exercise("ex4"), seconds=0.5).before_the_master().events
    assert shown[0].sender == "master" and shown[0].frame.can_id == MASTER_ID
    assert (shown == [shown[0]] and board.name not in shown[0].acked_by) is keeps_quiet


def test_ex4_waits_for_a_0x088_without_can_rx_invalid_msg():
    """With RXM = 11 the buffers also take frames with errors: a 0x088 flagged invalid does not count."""
    firmware = load_firmware(solution("ex4"))
    receive, flagged = firmware.CANReceiveMessage, []

    def first_0x088_flagged_invalid():
        message = receive()
        if message.id == MASTER_ID and not flagged:
            flagged.append(message)
            return message._replace(flags=message.flags | CAN_RX_INVALID_MSG)
        return message
    firmware.CANReceiveMessage = first_0x088_flagged_invalid
    room = Classroom(Bus(Simulator()), 4, stations=2)
    board = room.join(firmware, station=1)
    room.run(0.4)
    broadcasts = [e for e in room.bus.frames() if e.sender == "master" and e.frame.can_id == MASTER_ID]
    mine = [e for e in room.bus.frames() if e.sender == board.name]
    assert flagged and mine
    assert broadcasts[0].end_ps < broadcasts[1].end_ps < mine[0].start_ps, "it joined only after the second 0x088"


def test_ex6_names_the_data_frame_with_the_own_id_a_faulty_nodes(tmp_path):
    """Only one node sends an identifier's data frames: the check's test node sending the station's is a fault."""
    assert "faulty node" in check_names("ex6")[4]
    source = solution("ex6").read_text()
    firmware = tmp_path / "ex6.py"
    firmware.write_text(source.replace("if RX_ID2 == MESSAGE_ID1 and CANMessageFlag & CAN_RX_RTR_FRAME:",
                                       "if RX_ID2 == MESSAGE_ID1:"))
    [data] = check("ex6", firmware, seed=6).failed()
    assert "plays a faulty node" in data.message and "only you send" in data.message
    assert "A faulty node might send one anyway" in " ".join(markdown("ex6").split())


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
    levels = encode(CanFrame(0x100, bytes([1, 2, 3, 1, 0x2C])))[:20]
    figure = plots.bus_levels(levels)
    wires, difference, bus = figure.axes
    canh, canl = wires.lines[:2]
    assert [canh.get_ydata()[i] - canl.get_ydata()[i] for i in range(20)] == [2.0 * (1 - level) for level in levels]
    assert len([p for p in bus.patches if p.get_gid() == "terminator"]) == 2
    assert "60 Ω" in bus.get_title()
    figure.canvas.draw()
    legend = wires.get_legend().get_window_extent()
    box = wires.get_window_extent()
    assert box.x0 < legend.x0 and legend.x1 < box.x1 and box.y0 < legend.y0 and legend.y1 < box.y1, "inside the plot"
    lowest = wires.transData.transform((0, min(min(canh.get_ydata()), min(canl.get_ydata()))))[1]
    assert legend.y1 < lowest, "below both wires: the legend hides no level"
    plt.close(figure)


# ---------------------------------------------------------------- every number in the prose is the kit's

QUANTITY = re.compile(r"(?<![\w.])\d+(?:\.\d+)?\s?(?:µs|ms|ns|s|bits?|TQ|%|kbit/s|Mbit/s|V|Ω|ohm|m|cm/ns|bytes|baud)"
                      r"(?![\w/])|\b(?:TEC|REC) \d+|\bBRGCON[123] (?:=|is) 0x[0-9A-F]{2}")
"""A number with a unit (ranges such as 1..8 TQ are rules, not results, and are not matched), TEC/REC n, or a
BRGCON value."""

CLASSROOM = BitTiming(sjw=4, brp=10, seg1ph=8, seg2ph=4, prseg=3)       # CANInitialize(4, 10, 8, 4, 3, ...)
WRONG_BRP = BitTiming(sjw=4, brp=5, seg1ph=8, seg2ph=4, prseg=3)        # 01_bit_timing's wrong node
WORKSHOP_FRAME = CanFrame(0x100, bytes([0x01, 0x02, 0x03, 0x01, 0x2C]))  # 00_can_in_15_minutes' frame
EXTENDED_FRAME = CanFrame(0x100 << 18 | 0x2A5A5, WORKSHOP_FRAME.data, extended=True)


def quantities(markdown_text: str) -> list[str]:
    """The numbers with units in prose, outside `code`, spaces normalised."""
    prose = re.sub(r"`[^`]*`", "", markdown_text)
    return [" ".join(match.group(0).split()) for match in QUANTITY.finditer(prose)]


def g(value) -> str:
    return f"{float(value):g}"


def micro(seconds) -> str:
    return f"{g(Fraction(seconds) * 10**6)} µs"


def milli(seconds, digits: int | None = None) -> str:
    value = float(Fraction(seconds) * 1000)
    return f"{round(value) if digits is None else round(value, digits):g} ms"


def kbit(rate) -> str:
    return f"{g(Fraction(rate) / 1000)} kbit/s"


def percent(fraction) -> str:
    return f"{g(Fraction(fraction) * 100)} %"


def metres(value) -> str:
    return f"{round(value)} m"


def in_length_tables(quantity: str) -> str:
    """A bus length or bit rate the workshop's slides give, as `physical.WORKSHOP_LENGTH_TABLES` holds it."""
    pairs = [pair for table in physical.WORKSHOP_LENGTH_TABLES.values() for pair in table]
    given = {f"{m} m" for m, _ in pairs} | {kbit(r) for _, r in pairs} | {f"{g(r / 10**6)} Mbit/s" for _, r in pairs}
    return quantity if quantity in given else f"{quantity} is not in the workshop's tables"


@cache
def initialized_brgcon() -> tuple[int, int, int]:
    """BRGCON1..3 of a board after CANInitialize(4, 10, 8, 4, 3, CAN_CONFIG_VALID_STD_MSG), the exercises' call."""
    def main():
        CANInitialize(4, 10, 8, 4, 3, CAN_CONFIG_VALID_STD_MSG)
        while True:
            Delay1KTCYx(10)
    sim = Simulator()
    board = APP023(Bus(sim), "board")
    board.run(main)
    sim.run(until=10 * MS)
    return tuple(board.ecan.get(f"BRGCON{n}") for n in (1, 2, 3))


@cache
def classroom_periods() -> dict[str, str]:
    """The master's broadcast period and the stations' period, from a second of the EX2 classroom."""
    room = Classroom(Bus(Simulator()), 2)
    room.run(1.0)

    def period(sender: str, can_id: int) -> int:
        starts = [e.start_ps for e in room.bus.frames() if e.sender == sender and e.frame.can_id == can_id]
        return round(sum(b - a for a, b in zip(starts, starts[1:], strict=False)) / (len(starts) - 1))
    return {"master": milli(Fraction(period("master", MASTER_ID), PS_PER_SECOND)),
            "station": milli(Fraction(period("station1", 0x100), PS_PER_SECOND))}


@cache
def demo1_lines() -> dict[str, object]:
    """The first line for a 5-byte frame that Demo1's starter (at SPBRG 129) and solution send, and the USART."""
    found = {}
    for name, path, defines in (("starter", starter("demo1"), {"SPBRG": 129}), ("solution", solution("demo1"), None)):
        room = Classroom(Bus(Simulator()), 2)
        board = APP023(room.bus, "demo1")
        board.run(load_firmware(path, defines))
        received = bytearray()
        board.usb.listeners.append(lambda byte, time_ps, received=received: received.append(byte))
        room.run(0.3)
        found[name] = next(line for line in received.decode().split("\r\n") if "DLC 5" in line) + "\r\n"
        found["usart"] = board.usart
    return found


def line_time(name: str) -> str:
    usart = demo1_lines()["usart"]
    bits = usart.frame_ps() // usart.bit_ps()
    return milli(Fraction(len(demo1_lines()[name].lstrip("\0")) * bits, PC_BAUD))


def wire_bits_of(frame: CanFrame, *fields: str) -> int:
    return sum(1 for bit in encode_annotated(frame) if bit.field in fields and not bit.stuff)


def acquiring_4_tad_at_fosc_64() -> tuple[int, int]:
    """The kit's conversion time with ADCON2.ACQT = 4 TAD at Fosc/64, and one TAD (the data sheet allows one more)."""
    mcu = PIC18F8680(Simulator(), "adc")
    mcu.write_name("ADCON2", 0x80 | 0b010 << 3 | 0b110)
    return mcu.adc.conversion_ps(), 64 * PS_PER_SECOND // FOSC_HZ


Claim = Callable[[dict], str]
"""How the kit computes a quantity the prose states, from the notebook's namespace where that prose stands."""

COMMON: dict[str, Claim] = {
    "125 kbit/s": lambda ns: kbit(CLASSROOM.bit_rate(FOSC_HZ)),
    "5 bytes": lambda ns: f"{len(payload(0))} bytes",
    "11 bits": lambda ns: f"{STANDARD_ID_MAX.bit_length()} bits",
    "100 ms": lambda ns: classroom_periods()["master"],
    "52.4288 ms": lambda ns: milli(Fraction(TIMER1_PERIOD_PS, PS_PER_SECOND), 4),
    "52 ms": lambda ns: classroom_periods()["station"],
    "105 bit": lambda ns: f"{max_frame_bits(5) + INTERMISSION_BITS} bit",
    "102 bits": lambda ns: f"{max_frame_bits(5)} bits",
    "0.84 ms": lambda ns: milli(Fraction(max_frame_bits(5) + INTERMISSION_BITS, CLASSROOM.bit_rate(FOSC_HZ)), 2),
    "2 TQ": lambda ns: f"{IPT_TQ} TQ",
    "3 TQ": lambda ns: f"{CLASSROOM.prseg} TQ",
    "5 TQ": lambda ns: f"{seed_recipe(125_000, 16_000_000).sjw} TQ",
    "75 %": lambda ns: percent(CLASSROOM.sample_point),
    "87.5 %": lambda ns: percent(calculate.__kwdefaults__["sample_point"]),
    "2 V": lambda ns: f"{g(physical.differential_volts(physical.DOMINANT))} V",
    "2.5 V": lambda ns: f"{g(physical.CANH_CANL_VOLTS[physical.RECESSIVE][0])} V",
    "0.5 V": lambda ns: f"{physical.RECESSIVE_BELOW_VOLTS} V",
    "0.9 V": lambda ns: f"{physical.DOMINANT_ABOVE_VOLTS} V",
    "1.0 V": lambda ns: f"{physical.WORKSHOP_DOMINANT_ABOVE_VOLTS} V",
    "120 Ω": lambda ns: f"{physical.TERMINATION_OHMS} Ω",
    "120 ohm": lambda ns: f"{physical.TERMINATION_OHMS} ohm",
    "60 Ω": lambda ns: f"{physical.bus_resistance_ohms()} Ω",
    "25 ns": lambda ns: f"{g(physical.TRANSCEIVER_DELAY_SECONDS * 10**9)} ns",
    "17 cm/ns": lambda ns: f"{g(physical.CABLE_METRES_PER_SECOND / 10**7)} cm/ns",
    "119 m": lambda ns: metres(physical.max_bus_length_metres(CLASSROOM.prseg * CLASSROOM.tq_seconds(FOSC_HZ))),
    "19200 baud": lambda ns: f"{PC_BAUD} baud",
    "BRGCON3 is 0x43": lambda ns: f"BRGCON3 is 0x{initialized_brgcon()[2]:02X}",
    f"{KNOB_SECONDS:g} s": lambda ns: f"{KNOB_SECONDS:g} s",
    **{text: lambda ns, text=text: station_run(ns, text) for text in ("0.5 s", "1.0 s")},
    "BRGCON3 = 0x43": lambda ns: f"BRGCON3 = 0x{initialized_brgcon()[2]:02X}",
    **{text: lambda ns, text=text: in_length_tables(text)
       for text in ("40 m", "400 m", "500 m", "1000 m", "1 Mbit/s", "100 kbit/s", "40 kbit/s")},
}

PER_SOURCE: dict[str, dict[str, Claim]] = {
    "00_can_in_15_minutes": {
        "90 bits": lambda ns: f"{frame_bits(WORKSHOP_FRAME)} bits",
        "720 µs": lambda ns: micro(Fraction(frame_bits(WORKSHOP_FRAME), CLASSROOM.bit_rate(FOSC_HZ))),
        "3 bits": lambda ns: f"{INTERMISSION_BITS} bits",
        "840 µs": lambda ns: micro(Fraction(max_frame_bits(5) + INTERMISSION_BITS, CLASSROOM.bit_rate(FOSC_HZ))),
        "29 bits": lambda ns: f"{wire_bits_of(EXTENDED_FRAME, 'ID')} bits",
        "18 bits": lambda ns: f"{wire_bits_of(EXTENDED_FRAME, 'ID') - STANDARD_ID_MAX.bit_length()} bits",
        "1 ms": lambda ns: milli(Fraction(10 * 1000 * 4, FOSC_HZ)),         # the firmware's Delay1KTCYx(10)
    },
    "01_bit_timing": {
        "16 TQ": lambda ns: f"{CLASSROOM.tq_per_bit} TQ",
        "0.5 µs": lambda ns: micro(CLASSROOM.tq_seconds(FOSC_HZ)),
        "8 µs": lambda ns: micro(CLASSROOM.tq_seconds(FOSC_HZ) * CLASSROOM.tq_per_bit),
        "12 TQ": lambda ns: f"{1 + CLASSROOM.prseg + CLASSROOM.seg1ph} TQ",
        "4 TQ": lambda ns: f"{SJW_MAX_TQ} TQ" if CLASSROOM.effective_seg2ph == SJW_MAX_TQ else "SJW max != PS2",
        "8 TQ": lambda ns: f"{SEGMENT_MAX_TQ} TQ",
        "250 kbit/s": lambda ns: kbit(WRONG_BRP.bit_rate(FOSC_HZ)),
        "0.25 µs": lambda ns: micro(WRONG_BRP.tq_seconds(FOSC_HZ)),
        "4 µs": lambda ns: micro(WRONG_BRP.tq_seconds(FOSC_HZ) * WRONG_BRP.tq_per_bit),
        "48 m": lambda ns: metres(physical.workshop_max_bus_length_metres(1_000_000)),
        "445 m": lambda ns: metres(physical.workshop_max_bus_length_metres(125_000)),
        "100 ms": lambda ns: milli(Fraction(100 * 10_000 * 4, FOSC_HZ)),    # the culprit's Delay10KTCYx(100)
        "53 ms": lambda ns: milli(Fraction(next(e for e in ns["room"].bus.trace if e.error).start_ps, PS_PER_SECOND)),
        "300 ms": lambda ns: milli(Fraction(ns["room"].bus.sim.now, PS_PER_SECOND)),
        "TEC 248": lambda ns: f"TEC {ns['room'].stations[2].ecan.tec}",
        "TEC 136": lambda ns: f"TEC {ns['culprit'].ecan.tec}",
        "REC 255": lambda ns: f"REC {min(board.ecan.rec for board in innocent_boards(ns['room']))}",
        "0.305 s": lambda ns: f"{ns['bus_off_at']['station2']:.3f} s",
    },
    "ex4": {
        "TEC 128": lambda ns: "TEC " + str(8 * sum(1 for e in ns['lonely'].bus.trace
                                                   if e.error and 'form error' in str(e.received))),
    },
    "demo1_monitor": {
        "44 bytes": lambda ns: f"{len(demo1_lines()['starter'].lstrip(chr(0)))} bytes",
        "23 ms": lambda ns: line_time("starter"),
        "55 bytes": lambda ns: f"{len(demo1_lines()['solution'])} bytes",
        "29 ms": lambda ns: line_time("solution"),
        "10 bits": lambda ns: f"{demo1_lines()['usart'].frame_ps() // demo1_lines()['usart'].bit_ps()} bits",
        "19231 baud": lambda ns: f"{round(demo1_lines()['usart'].baud)} baud",
        "0.16 %": lambda ns: percent(round(Fraction(demo1_lines()['usart'].baud) / PC_BAUD - 1, 4)),
    },
    "differences.md": {
        "200 ns": lambda ns: f"{SFR_ACCESS_CYCLES * 4 * 10**9 // FOSC_HZ} ns",     # the 2 cycles of one access
        "2 s": lambda ns: f"{WATCHDOG_SECONDS:g} s",
        "24 µs": lambda ns: micro(Fraction(acquiring_4_tad_at_fosc_64()[0], PS_PER_SECOND)),
        "25.6 µs": lambda ns: micro(Fraction(sum(acquiring_4_tad_at_fosc_64()), PS_PER_SECOND)),
        "32 bits": lambda ns: f"{wire_bits_of(EXTENDED_FRAME, 'ID', 'SRR', 'IDE', 'RTR')} bits",
        "132 bits": lambda ns: f"{max_frame_bits(8)} bits",
        "11 bits": lambda ns: f"{BUS_IDLE_BITS} bits",
        **{text: lambda ns, text=text: verified_in("01_bit_timing", text) for text in ("TEC 248", "300 ms", "0.305 s")},
    },
}

AFTER_THE_NEXT_CODE_CELL = {("01_bit_timing", "100 ms")}
"""Quantities that describe what the code cell right below the prose does: checked once it has run."""

GIVEN = {
    "70 %": "DS39500's worked example: a sample point of 'normally about 60-70 %' (ds39500 extract section 6.7)",
    "30 cm/ns": "the workshop's '2/3 x 30 cm/ns' (workshop extract section 1.5, [GARBLED])",
    "150 ms": "ex4: the span of the timeline the code cell below draws",
}
"""Numbers the sources give and the kit does not compute, each with where it comes from."""

RUN = ("01_bit_timing", "ex4")
"""Notebooks whose prose quotes their own runs: their code cells run here, solutions in the firmware cells."""

VERIFIED: dict[str, set[str]] = {}


def innocent_boards(room: Classroom) -> list:
    """Notebook 01's good nodes but station 2, which the prose quotes on its own (its TEC)."""
    return [b for b in (room.master, *room.stations.values()) if b is not room.stations[2]]


def station_run(ns: dict, text: str) -> str:
    """`text` if the notebook's Station runs that long (its `seconds=`), which is what its prose says."""
    runs = {f"{match} s" for cell in read(ns["__notebook__"]).cells if cell.cell_type == "code"
            for match in re.findall(r"Station\([^)]*seconds=([0-9.]+)", cell.source)}
    return text if text in runs else f"the Station runs {sorted(runs)}"


def verified_in(source: str, text: str) -> str:
    if source not in VERIFIED:
        check_prose(source)
    return text if text in VERIFIED[source] else f"{text} is not what {source} computes"


def read(name: str) -> nbformat.NotebookNode:
    return nbformat.read(KIT / "notebooks" / f"{name}.ipynb", as_version=4)


def markdown(name: str) -> str:
    return "\n".join(cell.source for cell in read(name).cells if cell.cell_type == "markdown")


def compare(source: str, text: str, ns: dict) -> None:
    if text in GIVEN:
        return
    claims = {**COMMON, **PER_SOURCE.get(source, {})}
    assert text in claims, (f"{source} states {text!r}: compute it from the kit here (PER_SOURCE or COMMON), "
                            "or say in GIVEN which source gives it")
    computed = claims[text](ns)
    assert computed == text, f"{source} states {text!r}, the kit computes {computed!r}"
    VERIFIED.setdefault(source, set()).add(text)


def check_prose(source: str, workdir: Path | None = None) -> None:
    """Compare every quantity of a notebook's markdown (or a doc's text) with the kit, running the code cells of
    the notebooks in RUN as a reader would, so that a quantity is judged where the prose states it."""
    if source.endswith(".md"):
        for text in quantities((KIT / "docs" / source).read_text()):
            compare(source, text, {})
        return
    namespace: dict = {"__notebook__": source}
    deferred: list[str] = []
    for cell in read(source).cells:
        if cell.cell_type == "markdown":
            for text in deferred:
                compare(source, text, namespace)
            deferred = []
            for text in quantities(cell.source):
                if (source, text) in AFTER_THE_NEXT_CODE_CELL:
                    deferred.append(text)
                else:
                    compare(source, text, namespace)
        elif source in RUN and "interact(" not in cell.source:          # the sliders only run it all again
            code = cell.source
            if code.startswith("%%writefile"):
                name = code.split("\n", 1)[0].split()[1]
                shutil.copy(KIT / "solutions" / name, workdir / name)
                continue
            exec(compile(code, f"{source}.ipynb", "exec"), namespace)
            plt.close("all")
    for text in deferred:
        compare(source, text, namespace)


@pytest.mark.parametrize("source", [*sorted(p.stem for p in (KIT / "notebooks").glob("*.ipynb")), "differences.md"])
def test_every_number_the_prose_states_is_the_one_the_kit_computes(source, tmp_path, monkeypatch):
    monkeypatch.chdir(tmp_path)
    check_prose(source, tmp_path)


def test_the_frame_time_and_the_slcan_status_in_monitor_format():
    text = " ".join((KIT / "docs" / "monitor-format.md").read_text().split())
    longest = max_frame_bits(5) + INTERMISSION_BITS
    assert (f"at most {longest} bit times, {milli(Fraction(longest, CLASSROOM.bit_rate(FOSC_HZ)), 2)} at 125 kbit/s"
            in text)
    assert f"`max_frame_bits(5)` = {max_frame_bits(5)} bits" in text
    assert "55 bytes: 29 ms at 19200 baud" in text and line_time("solution") == "29 ms"
    assert len(demo1_lines()["solution"]) == 55
    assert "7 bus error" in text and "7 bus off" not in text


def test_the_readme_states_the_recipes_slip_and_where_masks_apply_as_the_kit_does():
    text = " ".join((KIT / "README.md").read_text().split())
    at_16, at_40 = seed_recipe(125_000, 16_000_000), seed_recipe(125_000, FOSC_HZ)
    assert f"at 16 MHz gives SJW = {at_16.sjw} TQ" in text
    assert f"40 MHz the same recipe gives SJW = {at_40.sjw} TQ" in text
    assert "masks are ignored" not in text and "the masks and filters apply in every mode" in text


def test_the_frame_time_the_prose_quotes_is_the_longest_5_byte_frame_not_this_one():
    """00 computes one frame (90 bits) and the longest 5-byte one (105 bit times with intermission); nothing else."""
    assert frame_time(WORKSHOP_FRAME, 125_000) < max_frame_bits(5) / 125_000
    for name in ("00_can_in_15_minutes", "demo1_monitor"):
        assert "0.75 ms" not in markdown(name) and "0.9 ms" not in markdown(name)
