"""Lessons a student can trust: what the notebooks, docstrings, checks and docs say is what the kit computes.

Where the workshop, the data sheet and the CAN standard differ, the check accepts what each allows and says why when
it refuses; the notebook and its check judge by one definition; the lessons' tools (the mask/filter table, the
physical layer) compute what the simulated chip does; and every number the prose states with a unit (times, bits,
TQ, sample points, bit rates, volts, metres, TEC values from runs) is computed here from the kit and compared. The
second review's defects (D1..D20 of reviews/lessons-2026-12-02.md, D13 aside) each have a test that fails on the text
they were found in: every check section lists its verdict's lines, the docs' example outputs are a real run's, and the
tries that end notebooks 00 and 01 judge what they say they judge.
"""
from __future__ import annotations

import os
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

from appsim import output
from appsim.board import usbcdc
from appsim.board.app023 import APP023
from appsim.bus.bitlevel import ERROR_DELIMITER_BITS, ERROR_FLAG_BITS
from appsim.bus.controller import Mode
from appsim.bus.monitor import error_counters, format_event, stamp
from appsim.bus.wire import BUS_IDLE_BITS, Bus, oscillator_tolerance
from appsim.can import physical
from appsim.can.bits import INTERMISSION_BITS, encode, encode_annotated, frame_bits, frame_time, max_frame_bits
from appsim.can.bittiming import (
    BRP_MAX,
    IPT_TQ,
    MAX_TQ_PER_BIT,
    SEGMENT_MAX_TQ,
    SJW_MAX_TQ,
    BitTiming,
    calculate,
    seed_recipe,
)
from appsim.can.frame import EXTENDED_ID_MAX, STANDARD_ID_MAX, CanFrame
from appsim.chip.ecan.acceptance import id_pattern, passing_ids
from appsim.chip.ecan.registers import BY_NAME, EWARN, RXB0OVFL, TXBP, TXWARN
from appsim.chip.mcu import FOSC_HZ, LOOK_COUNTING_PS, LOOK_FIRST_PS, PIC18F8680, SFR_ACCESS_CYCLES
from appsim.chip.sfr import current_mcu
from appsim.chip.usart import FIFO_DEPTH, PC_BAUD, decode
from appsim.cli import build_parser
from appsim.firmware import (
    CAN_CONFIG_ALL_MSG,
    CAN_CONFIG_PHSEG2_PRG_OFF,
    CAN_CONFIG_STD_MSG,
    CAN_CONFIG_VALID_STD_MSG,
    CAN_FILTER_B1_F1,
    CAN_FILTER_B1_F2,
    CAN_MASK_B1,
    CAN_OP_MODE_CONFIG,
    CAN_OP_MODE_LOOP,
    CAN_OP_MODE_NORMAL,
    CAN_RX_INVALID_MSG,
    CAN_RX_OVERFLOW,
    CAN_TX_PRIORITY_0,
    CAN_TX_STD_FRAME,
    SFR,
    CANInitialize,
    CANIsRxReady,
    CANReceiveMessage,
    CANSendMessage,
    CANSetFilter,
    CANSetMask,
    CANSetOperationMode,
    Delay1KTCYx,
    RXB0CONbits,
)
from appsim.firmware.loader import load_firmware
from appsim.session import MonitorTally
from appsim.sim import PS_PER_SECOND, Simulator
from appsim.watchdog import WATCHDOG_SECONDS
from appsim.workshop import plots, tries
from appsim.workshop.checks import check, check_names
from appsim.workshop.checks import demo1 as demo1_check
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

QUANTITY = re.compile(r"(?<![\w.,])(?:\d{1,3}(?:,\d{3})+|\d+)(?:\.\d+)?\s?"
                      r"(?:µs|ms|ns|s|bits?|TQ|%|kbit/s|Mbit/s|V|Ω|ohm|m|cm/ns|bytes|baud)"
                      r"(?![\w/])|\b(?:TEC|REC) \d+|\bBRGCON[123] (?:=|is) 0x[0-9A-F]{2}")
"""A number with a unit (thousands read whole, 19,231 baud; ranges such as 1..8 TQ are rules, not results, and are
not matched), TEC/REC n, or a BRGCON value."""


def usart_baud(spbrg: int, brgh: bool) -> float:
    """The baud rate a real (simulated) EUSART runs at with this SPBRG and BRGH (BRG16 = 0)."""
    mcu = PIC18F8680(Simulator())
    mcu.write_name("TXSTA", 0x04 if brgh else 0x00)
    mcu.write_name("SPBRG", spbrg)
    return mcu.usart.baud


CLASSROOM = BitTiming(sjw=4, brp=10, seg1ph=8, seg2ph=4, prseg=3)       # CANInitialize(4, 10, 8, 4, 3, ...)
SJW_1 = BitTiming(sjw=1, brp=10, seg1ph=8, seg2ph=4, prseg=3)           # the same with SJW 1 (01's SJW lesson)
WRONG_BRP = BitTiming(sjw=4, brp=5, seg1ph=8, seg2ph=4, prseg=3)        # 01_bit_timing's wrong node
WORKSHOP_FRAME = CanFrame(0x100, bytes([0x01, 0x02, 0x03, 0x01, 0x2C]))  # 00_can_in_15_minutes' frame
EXTENDED_FRAME = CanFrame(0x100 << 18 | 0x2A5A5, WORKSHOP_FRAME.data, extended=True)


def quantities(markdown_text: str) -> list[str]:
    """The numbers with units in prose, outside `code` and ``` blocks (example outputs, held against real runs
    below), spaces normalised."""
    prose = re.sub(r"`[^`]*`", "", re.sub(r"```.*?```", "", markdown_text, flags=re.S))
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
def initialized_brgcon(config: int = CAN_CONFIG_VALID_STD_MSG) -> tuple[int, int, int]:
    """BRGCON1..3 of a board after CANInitialize(4, 10, 8, 4, 3, `config`): by default the exercises' call."""
    def main():
        CANInitialize(4, 10, 8, 4, 3, config)
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


def phase2_not_programmable() -> BitTiming:
    """The classroom's CANInitialize with CAN_CONFIG_PHSEG2_PRG_OFF ANDed in: SEG2PHTS = 0."""
    return BitTiming.from_registers(*initialized_brgcon(CAN_CONFIG_VALID_STD_MSG & CAN_CONFIG_PHSEG2_PRG_OFF))


@cache
def monitor_run(seconds: float = 3.0) -> dict:
    """`appsim monitor` as the docs show it, on the simulated clock: its classroom (its defaults' exercise and seed)
    and the solution on the board "demo1", for `seconds`: the lines it sent, the bus, the tally it prints."""
    defaults = build_parser().parse_args(["monitor"])
    room = Classroom(Bus(Simulator()), defaults.exercise, seed=defaults.seed)
    board = APP023(room.bus, "demo1")
    board.run(solution("demo1"))
    tally = MonitorTally(room.bus, board)
    sent = bytearray()
    board.usb.listeners.append(lambda byte, time_ps: sent.append(byte))
    room.run(seconds)
    return {"lines": sent.decode("latin-1").replace("\0", "").split("\r\n"), "bus": room.bus, "bytes": len(sent),
            "summary": tally.summary(seconds)}


def first_master_frame_end() -> float:
    return next(e for e in monitor_run()["bus"].frames() if e.sender == "master").end_ps / PS_PER_SECOND


def first_lost_note() -> str:
    """The run's first '# lost' line, with its CR LF."""
    return next(line for line in monitor_run()["lines"] if line.startswith("# lost")) + "\r\n"


def monitor_line_gap(first: str, then: str) -> str:
    """The time between the run's first lines for the frames with IDs `first` and `then`, in µs."""
    times: dict[str, Fraction] = {}
    for line in monitor_run()["lines"]:
        if demo1_check.FRAME_LINE.match(line):
            times.setdefault(line.split()[1], Fraction(line.split()[0]))
    return micro(times[then] - times[first])


def overload_bits(event) -> int:
    """The bit times a frame that went through held the bus past its EOF: its overload frames."""
    return (event.end_ps - event.start_ps) // (PS_PER_SECOND // 125_000) - frame_bits(event.frame)


def same(*claims: Claim) -> Claim:
    """A quantity the prose states more than once, each time for a reason of its own: every computation gives it."""
    def claim(ns: dict) -> str:
        computed = {each(ns) for each in claims}
        return computed.pop() if len(computed) == 1 else f"the kit computes {sorted(computed)}"
    return claim


def most_common_rec(room: Classroom) -> str:
    recs = [board.ecan.rec for board in innocent_boards(room)]
    return f"REC {max(set(recs), key=recs.count)}"


def verdict_says(exercise: str, firmware: Path, words: str) -> Callable[[dict], str]:
    """The time in `words` if the check of `firmware` (seed 202) says exactly that."""
    def claim(ns: dict) -> str:
        messages = " ".join(c.message for c in check(exercise, firmware, seed=202).checks)
        found = re.search(r"\d+\.\d ms", words)
        assert found
        return found.group(0) if words in messages else f"the {exercise} check does not say {words!r}"
    return claim


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


def timeout_ps(turns: int) -> int:
    """How long a loop of `turns` turns that reads RXB0CON each turn and never sees a frame takes here, from its first
    read to its end (docs/differences.md, "Busy-waiting")."""
    from appsim.firmware import RXB0CONbits
    span: list[int] = []

    def timing_out() -> None:
        process = current_mcu().process
        assert process is not None
        start, turn = process.local_time, 0
        while turn < turns and not RXB0CONbits.RXFUL:
            turn += 1
        span.append(process.local_time - start)

    sim = Simulator()
    process = PIC18F8680(sim, "timeout").run(timing_out)
    sim.run(until=PS_PER_SECOND)
    assert process.failure is None, process.failure_text
    (taken,) = span
    return taken


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

PER_SOURCE_DEMO1: dict[str, Claim] = {
    "55 bytes": lambda ns: f"{len(demo1_lines()['solution'])} bytes",
    "29 ms": lambda ns: line_time("solution"),
    "10 bits": lambda ns: f"{demo1_lines()['usart'].frame_ps() // demo1_lines()['usart'].bit_ps()} bits",
}

PER_SOURCE: dict[str, dict[str, Claim]] = {
    "00_can_in_15_minutes": {
        "TEC 128": lambda ns: f"TEC {ns['alone'].ecan.tec}",
        "15 bit": lambda ns: f"{overload_bits(ns['trace'][0])} bit",
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
        "8 TQ": same(lambda ns: f"{SEGMENT_MAX_TQ} TQ", lambda ns: f"{CLASSROOM.seg1ph} TQ",
                     lambda ns: f"{ns['trap'].effective_seg2ph} TQ" if "trap" in ns else "8 TQ"),
        "20 TQ": same(lambda ns: f"{phase2_not_programmable().tq_per_bit} TQ",
                      lambda ns: "20 TQ" if any(s.timing.tq_per_bit == 20 for s in calculate(250_000, FOSC_HZ))
                      else "no 20 TQ setting at 250 kbit/s"),
        "100 kbit/s": same(lambda ns: kbit(phase2_not_programmable().bit_rate(FOSC_HZ)),
                           lambda ns: in_length_tables("100 kbit/s")),
        "250 kbit/s": same(lambda ns: kbit(WRONG_BRP.bit_rate(FOSC_HZ)), lambda ns: kbit(tries.BUS_RATE),
                           lambda ns: kbit(tries.OTHERS_TIMING.bit_rate(FOSC_HZ))),
        "13.1 ms": lambda ns: milli(Fraction(0x10000 * 4 * tries.TIMER1_PRESCALE, FOSC_HZ), 1),
        "0.3 s": lambda ns: f"{tries.TRY_SECONDS:g} s",
        "REC 128": lambda ns: most_common_rec(ns["room"]),
        "0.25 µs": lambda ns: micro(WRONG_BRP.tq_seconds(FOSC_HZ)),
        "4 µs": lambda ns: micro(WRONG_BRP.tq_seconds(FOSC_HZ) * WRONG_BRP.tq_per_bit),
        "48 m": lambda ns: metres(physical.workshop_max_bus_length_metres(1_000_000)),
        "445 m": lambda ns: metres(physical.workshop_max_bus_length_metres(125_000)),
        "100 ms": lambda ns: milli(Fraction(100 * 10_000 * 4, FOSC_HZ)),    # the culprit's Delay10KTCYx(100)
        "53 ms": lambda ns: milli(Fraction(next(e for e in ns["room"].bus.trace if e.error).start_ps, PS_PER_SECOND)),
        "300 ms": lambda ns: milli(Fraction(ns["room"].bus.sim.now, PS_PER_SECOND)),
        "TEC 256": lambda ns: f"TEC {ns['room'].stations[2].ecan.tec}",
        "TEC 168": lambda ns: f"TEC {ns['culprit'].ecan.tec}",
        "REC 138": lambda ns: f"REC {min(board.ecan.rec for board in innocent_boards(ns['room']))}",
        "REC 255": lambda ns: f"REC {ns['culprit'].ecan.rec}",
        "0.405 s": lambda ns: f"{ns['bus_off_at']['station2'][0]:.3f} s",
        "6 TQ": lambda ns: f"{ns['LATE']} TQ" if ns["LATE"] > CLASSROOM.sjw else "not beyond SJW",
        "0.98 %": lambda ns: f"{float(oscillator_tolerance(CLASSROOM)) * 100:.2f} %",
        "0.31 %": lambda ns: f"{float(oscillator_tolerance(SJW_1)) * 100:.2f} %",
    },
    "ex4": {
        "TEC 128": lambda ns: "TEC " + str(8 * sum(1 for e in ns['lonely'].bus.trace
                                                   if e.error and 'form error' in str(e.received))),
        "TEC 127": lambda ns: f"TEC {ns['lonely'].master.ecan.tec}",
    },
    "demo1_monitor": {
        "44 bytes": lambda ns: f"{len(demo1_lines()['starter'].lstrip(chr(0)))} bytes",
        "23 ms": lambda ns: line_time("starter"),
        **PER_SOURCE_DEMO1,
        "19231 baud": lambda ns: f"{round(demo1_lines()['usart'].baud)} baud",
        "0.16 %": lambda ns: percent(round(Fraction(demo1_lines()['usart'].baud) / PC_BAUD - 1, 4)),
        "35 ms": lambda ns: milli(demo1_check.TIME_SLACK_S),
    },
    "differences.md": {
        "200 ns": lambda ns: f"{SFR_ACCESS_CYCLES * 4 * 10**9 // FOSC_HZ} ns",     # the 2 cycles of one access
        "1 ms": lambda ns: milli(Fraction(LOOK_FIRST_PS, PS_PER_SECOND)),
        "8 ms": lambda ns: milli(Fraction(LOOK_COUNTING_PS, PS_PER_SECOND)),
        "34 ms": lambda ns: milli(Fraction(timeout_ps(5000), PS_PER_SECOND)),
        "2 s": lambda ns: f"{WATCHDOG_SECONDS:g} s",
        "24 µs": lambda ns: micro(Fraction(acquiring_4_tad_at_fosc_64()[0], PS_PER_SECOND)),
        "25.6 µs": lambda ns: micro(Fraction(sum(acquiring_4_tad_at_fosc_64()), PS_PER_SECOND)),
        "32 bits": lambda ns: f"{wire_bits_of(EXTENDED_FRAME, 'ID', 'SRR', 'IDE', 'RTR')} bits",
        "132 bits": lambda ns: f"{max_frame_bits(8)} bits",
        "11 bits": lambda ns: f"{BUS_IDLE_BITS} bits",
        **{text: lambda ns, text=text: verified_in("01_bit_timing", text) for text in ("TEC 256", "300 ms", "0.405 s")},
        "20 TQ": lambda ns: f"{phase2_not_programmable().tq_per_bit} TQ",
        "100 kbit/s": same(lambda ns: kbit(phase2_not_programmable().bit_rate(FOSC_HZ)),
                           lambda ns: in_length_tables("100 kbit/s")),
    },
    "notebooks.md": {
        "250 kbit/s": lambda ns: kbit(tries.BUS_RATE),
    },
    "traces.md": {
        "3.2 ms": verdict_says("ex1", starter("ex1"), "the frame went round in Loopback mode at 3.2 ms"),
        "53.9 ms": verdict_says("ex4", solution("ex4"), "until the master's first 0x088 ended at 53.9 ms"),
        "8 µs": lambda ns: micro(Fraction(1, CLASSROOM.bit_rate(FOSC_HZ))),
        "0.7 ms": lambda ns: milli(frame_time(WORKSHOP_FRAME, 125_000), 1),
        "3 bits": lambda ns: f"{INTERMISSION_BITS} bits",
        "60 s": lambda ns: f"{output.FIFO_WAIT_S:g} s",
    },
    "monitor-format.md": {
        "64 bytes": same(lambda ns: f"{usbcdc.OUT_ENDPOINT_BYTES} bytes",
                         lambda ns: f"{load_firmware(solution('demo1')).OUTPUT_BYTES} bytes"),
        "50 ms": lambda ns: milli(Fraction(usbcdc.ANSWER_PS, PS_PER_SECOND)),
        "0.053949 s": lambda ns: f"{first_master_frame_end():.6f} s",
        "744 µs": same(lambda ns: monitor_line_gap("0x100", "0x110"),
                       lambda ns: micro(Fraction(frame_bits(CanFrame(0x110, payload(0x3C0))) + INTERMISSION_BITS,
                                                 CLASSROOM.bit_rate(FOSC_HZ)))),
        "0.8 µs": lambda ns: micro(Fraction(8 * 4, FOSC_HZ)),
        "29 bits": lambda ns: f"{EXTENDED_ID_MAX.bit_length()} bits",
        "8 bytes": lambda ns: f"{len(CanFrame(0x100, bytes(8), dlc=15).data)} bytes",
        "30 bytes": lambda ns: f"{round(len(first_lost_note()), -1)} bytes",
        "12.5 kbit/s": lambda ns: kbit(Fraction(FOSC_HZ, 2 * BRP_MAX * MAX_TQ_PER_BIT)),
        "32 bytes": lambda ns: f"{load_firmware(solution('demo1')).RECEIVED_BYTES} bytes",
        "1 ms": lambda ns: milli(Fraction(FIFO_DEPTH * demo1_lines()['usart'].frame_ps(), PS_PER_SECOND)),
        **{text: PER_SOURCE_DEMO1[text] for text in ("55 bytes", "29 ms", "10 bits")},
        "19,231 baud": lambda ns: f"{usart_baud(129, True):,.0f} baud",
        "0.16 %": lambda ns: f"{(usart_baud(129, True) / PC_BAUD - 1) * 100:.2f} %",
    },
}

AFTER_THE_NEXT_CODE_CELL = {("01_bit_timing", "100 ms"), ("01_bit_timing", "6 TQ")}
"""Quantities that describe what the code cell right below the prose does: checked once it has run."""

GIVEN = {
    "70 %": "DS39500's worked example: a sample point of 'normally about 60-70 %' (ds39500 extract section 6.7)",
    "30 cm/ns": "the workshop's '2/3 x 30 cm/ns' (workshop extract section 1.5, [GARBLED])",
    "150 ms": "ex4: the span of the timeline the code cell below draws",
    "60 ms": "01: the span of the timeline the code cell below draws",
    "60 bytes": "monitor-format.md: what the PC program typed in the example run, its input",
}
"""Numbers the sources give and the kit does not compute, each with where it comes from."""

RUN = ("00_can_in_15_minutes", "01_bit_timing", "ex4")
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
    if source in NAMESPACES:
        return
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
        elif source in RUN:
            run_code_cell(source, cell.source, namespace, workdir)
    for text in deferred:
        compare(source, text, namespace)
    NAMESPACES[source] = namespace


NAMESPACES: dict[str, dict] = {}
"""Each notebook's namespace once `check_prose` has run its code cells and judged its prose: it does so once."""


def run_code_cell(source: str, code: str, namespace: dict, workdir: Path | None) -> None:
    """One code cell of notebook `source` run as a reader runs it, in `namespace`: a firmware cell writes the
    solution into `workdir` (the working directory), the sliders' cells are left out (they only run it all again)."""
    if "interact(" in code:
        return
    if code.startswith("%%writefile"):
        name = code.split("\n", 1)[0].split()[1]
        assert workdir is not None
        shutil.copy(KIT / "solutions" / name, workdir / name)
        return
    exec(compile(code, f"{source}.ipynb", "exec"), namespace)
    plt.close("all")


@pytest.fixture(scope="module")
def ran(tmp_path_factory) -> Callable[[str], dict]:
    """A notebook's namespace once all its code cells have run and its prose was judged (`check_prose`)."""
    def namespace(name: str) -> dict:
        if name not in NAMESPACES:
            workdir = tmp_path_factory.mktemp(name)
            before = os.getcwd()
            os.chdir(workdir)
            try:
                check_prose(name, workdir)
            finally:
                os.chdir(before)
        return NAMESPACES[name]
    return namespace


DOCS = ("differences.md", "traces.md", "monitor-format.md", "notebooks.md")
"""The docs whose numbers are the lessons': docs/errors.md's are its scenarios' (tests/test_errors_doc.py)."""


@pytest.mark.parametrize("source", [*sorted(p.stem for p in (KIT / "notebooks").glob("*.ipynb")), *DOCS])
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


# ---------------------------------------------------------------- the second review: D1..D20 (lessons-2026-12-02)

def flat(text: str) -> str:
    return " ".join(text.split())


def cell_with(name: str, words: str) -> str:
    """The markdown cell of notebook `name` that says `words` (spaces normalised)."""
    [found] = [flat(c.source) for c in read(name).cells if c.cell_type == "markdown" and words in flat(c.source)]
    return found


def three_boards(*injections: tuple) -> tuple[Bus, dict[str, APP023]]:
    """00's three boards: station 1 sends 0x100 once a millisecond after reset, the master and a third receive; each
    injection (node, kind, bit, frames) in turn, each given the frames before it to happen."""
    def sender():
        CANInitialize(4, 10, 8, 4, 3, CAN_CONFIG_ALL_MSG)
        Delay1KTCYx(10)
        CANSendMessage(0x100, [1, 2, 3, 0, 0], 5, CAN_TX_PRIORITY_0 & CAN_TX_STD_FRAME)
        while True:
            if CANIsRxReady():
                CANReceiveMessage()

    def receiver():
        CANInitialize(4, 10, 8, 4, 3, CAN_CONFIG_ALL_MSG)
        while True:
            if CANIsRxReady():
                CANReceiveMessage()

    sim = Simulator()
    bus = Bus(sim)
    boards = {name: APP023(bus, name) for name in ("station1", "master", "third")}
    boards["station1"].run(sender)
    boards["master"].run(receiver)
    boards["third"].run(receiver)
    done = 0
    for node, kind, bit, frames in injections:
        bus.inject(node, kind, bit, frames=frames)
        done += frames
        while len(bus.trace) < done:
            sim.run(until=sim.now + MS // 10)
    sim.run(until=sim.now + 3 * MS)
    return bus, boards


def test_d1_a_passive_flag_ends_its_own_senders_frame_not_another_nodes_as_00_says():
    """Error-passive station 1 (16 ACK errors) reads bit 20 wrong: its recessive flag still ends its own frame, for
    every receiver. An error-passive receiver's flag (the master after 15 stuff errors) leaves the frame standing."""
    bus, boards = three_boards(("station1", "ack", 0, 16), ("station1", "bit", 20, 1))
    passive_sender = bus.trace[16]
    assert passive_sender.error and "bit error at bit 20" in passive_sender.error
    assert dict(passive_sender.received) == {name: "stuff error at bit 25: six recessive bits in a row"
                                             for name in ("master", "third")}, "its passive flag: bits 21-26"
    assert boards["master"].ecan.rec == boards["third"].ecan.rec == 1, \
        "each ACK-error frame: - 1 at its ACK slot (rule 8), + 1 at the form error after it; then + 1 at bit 25"
    bus, boards = three_boards(("master", "stuff", 30, 16))
    assert [e.ok for e in bus.trace] == [False] * 15 + [True], "the 16th: the master flags it, passive"
    assert boards["master"].ecan.error_passive, "15 x 9 = 135: its flag in the 16th was recessive"
    row = next(line for line in read("00_can_in_15_minutes").cells[[c.get("id") for c in read(
        "00_can_in_15_minutes").cells].index("40e3d1e5")].source.splitlines() if "**error-passive**" in line)
    assert "cannot destroy anyone's frame" not in row
    for words in ("cannot destroy another node's frame", "Sent by the transmitter itself, a passive flag still ends "
                  "that frame where stuffing applies", "a stuff error", "After an ACK error it falls in the recessive "
                  "ACK delimiter and EOF instead, and the receivers keep the frame"):
        assert words in row, row


def test_d2_ex4_the_master_is_error_active_again_after_one_good_frame_in_the_warning_zone(ran):
    lonely = ran("ex4")["lonely"]
    master = lonely.master.ecan
    assert master.tec == 127 and master.error_state == "error-active"
    [line] = [line for line in error_counters(lonely.bus).splitlines() if line.startswith("master")]
    assert line.split()[-1] == "warning"
    text = cell_with("ex4", "The classroom recovers")
    assert "stays error-passive" not in text
    assert "from TEC 128 to TEC 127, error-active again" in text and "warning zone (COMSTAT.TXWARN" in text
    comstat = BY_NAME["COMSTAT"].address
    master.tec = 96
    assert master.read(comstat) & TXWARN
    master.tec = 127 - 32
    assert not master.read(comstat) & TXWARN, "32 good frames from TEC 127 take TXWARN away"
    assert "until 32 more good frames" in text


def fenced_blocks(text: str) -> list[str]:
    """The ``` blocks of a markdown text, without their fences."""
    blocks, inside = [], None
    for line in text.splitlines(keepends=True):
        if line.startswith("```"):
            if inside is None:
                inside = []
            else:
                blocks.append("".join(inside))
                inside = None
        elif inside is not None:
            inside.append(line)
    return blocks


def test_d3_monitor_format_shows_lines_and_a_summary_of_a_real_run():
    """Every line of the doc's example is a line of `appsim monitor`'s run, in order, `...` where lines are left out;
    the summary's frame lines are the run's tally; the check's help quotes a line of the example."""
    text = (KIT / "docs" / "monitor-format.md").read_text()
    blocks = fenced_blocks(text)
    [example] = [b for b in blocks if b.startswith("# APP023 CAN monitor")]
    lines = monitor_run()["lines"]
    position, skipped = -1, False
    for shown in example.splitlines():
        if shown == "...":
            skipped = True
            continue
        if skipped:
            assert shown in lines[position + 2:], f"{shown!r} is not a later line of the run"
            position = lines.index(shown, position + 2)
        else:
            assert lines[position + 1] == shown, f"{shown!r} is not the run's next line"
            position += 1
        skipped = False
    assert "0x053210" not in text and "0.053210" not in text
    [summary] = [b for b in blocks if b.startswith(f"{monitor_run()['bus'].trace.frames} frames on the bus")
                 ] or [b for b in blocks if "frames on the bus" in b]
    assert summary.startswith(monitor_run()["summary"] + "\nUSB-CDC port socket://127.0.0.1:"), summary
    sent = re.search(r"board -> PC: (\d+) bytes, (\d+) of them lost \((\d+): [^;]*; (\d+): ", summary)
    assert int(sent[1]) == monitor_run()["bytes"] and int(sent[2]) == int(sent[3]) + int(sent[4])
    example_line = re.search(r"`(    [^`]*)`", demo1_check.FORMAT_HELP)[1]
    assert example_line in example.splitlines()
    assert all(note in lines for note in re.findall(r"^# lost \d+ frames \(queue full\)$", text, flags=re.M))


def test_d4_the_trace_table_gives_each_frame_its_end_of_frame_as_every_log(tmp_path):
    firmware = tmp_path / "ex2.py"
    shutil.copy(solution("ex2"), firmware)
    table = Station("ex2", firmware, seconds=0.2).trace()
    shown = re.findall(r"<tr><td style='padding:1px 8px;text-align:left'>([0-9.]+)</td>", table._repr_html_())
    assert shown == [f"{stamp(event):.6f}" for event in table.events]
    assert shown == [format_event(event).split()[0] for event in table.events]
    traces = flat((KIT / "docs" / "traces.md").read_text())
    assert "the notebooks' trace table (`station.trace()`, its \"time (s)\" column) | the same" in traces
    text = cell_with("ex2", "as CANKing listed them")
    assert "time of SOF" not in text and "its end of frame" in text


def test_d5_demo1s_terminal_shows_what_the_19200_baud_pic18f2550_decodes(tmp_path):
    sent = b"    0.053946  0x088  STD  DATA  DLC 5  01 02 03 02 00\r\n"
    for baud, same_bytes in ((19_231, True), (19_200, True), (2_500_000, False), (9_600, False)):
        bit = round(PS_PER_SECOND / baud)
        decoded = decode([(i * 10 * bit, byte, bit) for i, byte in enumerate(sent)])
        assert (bytes(r.data for r in decoded) == sent) is same_bytes
    starter_copy = tmp_path / "demo1_monitor.py"
    shutil.copy(starter("demo1"), starter_copy)
    garbled = repr(Station("demo1", starter_copy, seconds=0.3).terminal())
    assert garbled.startswith("[the USART sends at 2500000 baud, the PIC18F2550 reads 19200")
    assert "0x088  DLC 5" not in garbled
    starter_copy.write_text(starter("demo1").read_text().replace("SPBRG = 0 ", "SPBRG = 129 "))
    clean = repr(Station("demo1", starter_copy, seconds=0.3).terminal())
    assert not clean.startswith("[") and re.search(r"0x088  DLC 5  01 02 03 02 00\r?\n", clean)
    assert "reads the USART's line at 19200 baud" in cell_with("demo1_monitor", "Put your monitor on")


def test_d6_ex3s_extension_goes_in_a_copy_because_the_check_judges_the_0x088_version(tmp_path):
    firmware = tmp_path / "ex3.py"
    source = solution("ex3").read_text()
    firmware.write_text(source.replace("RX_Filter0 = 0x088 ", "RX_Filter0 = 0x110 "))
    verdict = check("ex3", firmware, seed=3)
    assert [c.name for c in verdict.failed()] == list(check_names("ex3")[1:4])
    for text in (cell_with("ex3", "**Extension:**"), flat(starter("ex3").read_text()), flat(source)):
        assert "in a copy" in text.replace("Do it", "do it in") or "Do it in a copy" in text, text
        assert "ex3_ext.py" in text and "the check judges the 0x088 version" in text
    assert "fails three of its lines" in cell_with("ex3", "**Extension:**")


@pytest.mark.parametrize("mask, passes", [(0x7FF, True), (0x0FF, True), (0x000, False)])
def test_d7_ex6_mask_0_fails_the_rxb1_line_and_0x0ff_passes_it_by_luck(tmp_path, mask, passes):
    firmware = tmp_path / "ex6.py"
    firmware.write_text(solution("ex6").read_text().replace("RX_Mask1 = 0x7FF ", f"RX_Mask1 = 0x{mask:03X} "))
    verdict = check("ex6", firmware, seed=6)
    rxb1 = verdict.checks[check_names("ex6").index("RXB1 takes only MESSAGE_ID1")]
    assert rxb1.passed is passes and verdict.passed is passes
    if not passes:
        assert "0x7FF is the safe one; 0x0FF passes here by luck" in rxb1.message
        assert len(verdict.failed()) == 1, "the software test keeps its answers right"
    answer = cell_with("ex6", "Answer 2")
    assert "the check's line \"RXB1 takes only MESSAGE_ID1\" fails it" in answer
    assert "The check passes 0x0FF, by luck" in answer


def check_section(name: str) -> str:
    [section] = [c.source for c in read(name).cells
                 if c.cell_type == "markdown" and c.source.startswith("## The check")]
    return section


@pytest.mark.parametrize("name, exercise", [(n, e) for n, e in (
    ("ex1", "ex1"), ("ex2", "ex2"), ("ex3", "ex3"), ("ex4", "ex4"), ("ex5", "ex5"), ("ex6", "ex6"),
    ("demo1_monitor", "demo1"))])
def test_d8_d14_every_check_section_names_every_line_of_its_verdict_in_its_order(name, exercise):
    listed = re.findall(r"^- \*\*(.+?)\*\*:", check_section(name), flags=re.M)
    assert listed == list(check_names(exercise))
    verdict = check(exercise, solution(exercise), seed=8)
    assert [c.name for c in verdict.checks] == listed


def test_d8_demo1s_starter_fails_lines_each_a_todo_of_its_own_in_the_notebook_and_the_starter():
    verdict = check("demo1", starter("demo1"), seed=8)
    failed = verdict.failed()
    assert len(failed) == len(check_names("demo1")) - 1, "only 'firmware runs' passes"
    section = check_section("demo1_monitor")
    intro = read("demo1_monitor").cells[0].source
    source = starter("demo1").read_text()
    todos = set()
    for line in failed:
        bullet = flat(section.split(f"- **{line.name}**:")[1].split("\n- ")[0])
        [todo] = re.findall(r"TODO (\d)", bullet)
        todos.add(todo)
        assert f"  TODO {todo}: " in source and f"# TODO {todo}" in source or todo in "12", (line.name, todo)
        assert re.search(rf"^{todo}\. ", intro, flags=re.M), f"the notebook's list has no TODO {todo}"
    assert sorted(todos) == ["1", "2", "3", "4", "5"] and "Its five `TODO`s" in intro
    assert "STD/XTD" in source and "PIR1bits.TMR1IF" in source.split("TODO 5")[1]


def test_d9_00_defines_overload_frames_and_shows_one_that_costs_bus_time_and_no_counter(ran):
    box = cell_with("00_can_in_15_minutes", "### Overload frames")
    assert f"an overload flag of {ERROR_FLAG_BITS} dominant bits" in box
    assert f"an {ERROR_DELIMITER_BITS}-bit recessive overload delimiter" in box
    for when in ("first two bits of the intermission", "last bit of EOF", "last bit of an error or overload "
                 "delimiter", "no counter moves"):
        assert when in box
    names = [c.get("id") for c in read("00_can_in_15_minutes").cells]
    assert names.index("a1b2c3d4") == names.index("40e3d1e5") + 1, "the box right under 'Error states'"
    ns = ran("00_can_in_15_minutes")
    bus, boards = three_boards(("master", "form", ns["ack_delimiter"] + 7, 1))
    [event] = bus.trace
    assert event.ok and all((b.ecan.tec, b.ecan.rec) == (0, 0) for b in boards.values())
    extra = overload_bits(event)
    assert ERROR_FLAG_BITS + ERROR_DELIMITER_BITS <= extra <= 2 * ERROR_FLAG_BITS + ERROR_DELIMITER_BITS
    assert "an overload frame: `00_can_in_15_minutes`" in cell_with("01_bit_timing", "## When a node's timing")


def test_d10_a_good_frame_brings_rec_above_127_straight_back_to_127(ran):
    trace, counters = ran("00_can_in_15_minutes")["with_an_error"]("master", "stuff", 30, 15)
    assert [e.ok for e in trace] == [False] * 15 + [True]
    assert counters["master"] == (0, 127), "15 x 9 = 135, then one good frame: 127, not 134"
    rules = cell_with("00_can_in_15_minutes", "## Error states")
    assert "a good frame received with REC above 127 brings it straight back to 127" in rules
    assert "any value from 119 to 127" in rules
    assert "above 127 one good frame sets it to 127" in cell_with("01_bit_timing", "Let the classroom run on")
    assert "each good frame they receive sets their REC back to 127" in cell_with("01_bit_timing", "Station 2 goes")


def test_d11_00_draws_the_error_states_and_says_what_the_firmware_reads(ran):
    ecan = ran("00_can_in_15_minutes")["alone"].ecan
    comstat = ecan.read(BY_NAME["COMSTAT"].address)
    assert ecan.tec == 128 and comstat == TXBP | TXWARN | EWARN
    codes = [c.source for c in read("00_can_in_15_minutes").cells if c.cell_type == "code"]
    assert any("plots.error_states()" in code for code in codes)
    assert any('plots.register_bits("COMSTAT", comstat)' in code for code in codes)
    note = cell_with("00_can_in_15_minutes", "### What your firmware can read")
    for words in ("TXWARN", "RXWARN", "EWARN", "TXBP", "RXBP", "TXBO", "PIR3.ERRIF", "CANIsBusOff()",
                  "above 95", "above 127", "Bus-off ends on its own"):
        assert words in note, words


def test_d13_01_teaches_sjw_with_a_resynchronisation_picture_and_a_try_where_sjw_changes_what_happens(ran):
    """The kit resynchronises within SJW (tests/test_resynchronisation.py): 01 says so next to the lesson, draws an edge
    moving the sample point by at most SJW, and its try shows SJW 1 failing where SJW 4 holds."""
    lesson = cell_with("01_bit_timing", "## SJW: how the nodes keep in step")
    for words in ("**lengthens Phase1**", "**shortens Phase2**", "at most SJW", "hard synchronisation"):
        assert words in lesson, words
    ns = ran("01_bit_timing")
    assert ns["LATE"] > CLASSROOM.sjw, "the picture's edge is later than SJW: the sample point moves SJW only"
    figure = plots.resynchronisation(CLASSROOM, ns["LATE"], ns["EARLY"])
    [ax] = figure.axes
    moved = [line.get_xdata()[0] for line in ax.lines if line.get_gid() == "sample point"]
    sample = 1 + CLASSROOM.prseg + CLASSROOM.seg1ph
    assert moved == [sample + CLASSROOM.sjw, sample], "late: moved by SJW, not by the whole phase error"
    plt.close(figure)
    codes = [c.source for c in read("01_bit_timing").cells if c.cell_type == "code"]
    assert any("plots.resynchronisation(workshop, LATE, EARLY)" in code for code in codes)
    [try_cell] = [code for code in codes if "tries.oscillator_drift(SJW, PPM)" in code]
    shipped: dict = {}
    exec(try_cell.replace("tries.oscillator_drift(SJW, PPM)", ""), {"tries": tries}, shipped)
    holds, fails = tries.oscillator_drift(shipped["SJW"], shipped["PPM"]), tries.oscillator_drift(1, shipped["PPM"])
    assert shipped["SJW"] == CLASSROOM.sjw and holds.received == holds.sent and not holds.errors
    assert fails.received < fails.sent and fails.errors, "SJW 1: the same drift breaks frames"
    assert f"= {holds.tolerance_ppm:,.0f} ppm" in str(holds) and "0.31%" in str(fails)
    assert "docs/differences.md" in cell_with("01_bit_timing", "The kit models this")


def test_d12_01_decodes_brgcon2_bit_by_bit_and_shows_the_phseg2_prg_off_trap(ran):
    ns = ran("01_bit_timing")
    assert ns["written"][1] == 0xBA and BitTiming.from_registers(*ns["written"]).seg2phts
    trap = ns["trap"]
    assert trap == phase2_not_programmable() and not trap.seg2phts
    assert trap.effective_seg2ph == max(trap.seg1ph, IPT_TQ) and trap.bit_rate(FOSC_HZ) == 100_000
    decoded = cell_with("01_bit_timing", "**SEG2PHTS** = 1")
    for words in ("**SAM** = 0", "`CAN_CONFIG_PHSEG2_PRG_ON`", "`CAN_CONFIG_PHSEG2_PRG_OFF`", "max(Phase1, IPT)",
                  "**SEG1PH<2:0>** = 111", "**PRSEG<2:0>** = 010"):
        assert words in decoded, words
    assert any('plots.register_bits("BRGCON2", written[1])' in c.source for c in read("01_bit_timing").cells)


def test_d15_ex1_fix_b_says_rxm_11_also_keeps_frames_with_errors():
    answer = cell_with("ex1", "Answer (try first!)")
    assert "*including those with errors*" in answer and "a trap on a bus (EX4 shows it)" in answer
    assert "*including those with errors*" in read("ex4").cells[0].source


def test_d16_demo1_with_rollover_the_lost_frame_is_rxb1s_and_an738_wipes_rxb0s_overflow(world):
    """RXB0DBEN = 1: a frame for a full RXB0 goes into RXB1, one for both full is RXB1's overflow, reported with
    RXB1's message; AN738's RXB0 branch with RXB0DBEN set reports no CAN_RX_OVERFLOW (its `flags &= 0x01`)."""
    got = []

    def rollover(first_read_ms: int):
        def main():
            CANInitialize(4, 10, 8, 4, 3, CAN_CONFIG_ALL_MSG)
            CANSetOperationMode(CAN_OP_MODE_CONFIG)
            RXB0CONbits.RXB0DBEN = 1
            CANSetOperationMode(CAN_OP_MODE_NORMAL)
            Delay1KTCYx(10 * first_read_ms)
            while True:
                if CANIsRxReady():
                    got.append((CANReceiveMessage(), SFR.COMSTAT))
        return main

    def sends_three():
        CANInitialize(4, 10, 8, 4, 3, CAN_CONFIG_ALL_MSG)
        for can_id in (0x101, 0x102, 0x103):
            CANSendMessage(can_id, [1], 1, CAN_TX_PRIORITY_0 & CAN_TX_STD_FRAME)
            Delay1KTCYx(10)
        while True:
            Delay1KTCYx(10)

    world.node("sender", sends_three)
    monitor = world.node("monitor", rollover(8))
    world.run(0.02)
    (first, _), (second, _) = got
    assert (first.id, second.id) == (0x101, 0x102), "0x103 found both full"
    assert not first.flags & CAN_RX_OVERFLOW and second.flags & CAN_RX_OVERFLOW
    assert not monitor.ecan.get("COMSTAT") & RXB0OVFL
    answer = cell_with("demo1_monitor", "3. What about the frames")
    for words in ("`RXB0DBEN = 1`", "COMSTAT.RXB1OVFL, reported with the next message read from RXB1",
                  "`flags &= 0x01`", "wipes `CAN_RX_OVERFLOW`"):
        assert words in answer, words


def test_d17_rec_stops_at_255_and_takes_no_node_bus_off(ran):
    room = Classroom(Bus(Simulator()), 2, stations=5)
    culprit = APP023(room.bus, "wrong")
    culprit.run(ran("01_bit_timing")["wrong_bit_rate"])
    highest: dict[str, int] = {}
    for _ in range(60):
        room.run(0.005)
        for board in (room.master, *room.stations.values(), culprit):
            highest[board.name] = max(highest.get(board.name, 0), board.ecan.rec)
            assert board.ecan.rec <= 255
            assert board.ecan.bus_off == (board.ecan.tec > 255)
    assert max(highest.values()) == 255
    for name in ("00_can_in_15_minutes", "01_bit_timing"):
        text = flat(markdown(name))
        assert "REC stops at 255" in text or "REC stops there" in text
        assert "(RXERRCNT is an 8-bit register)" in text and ("it never takes a node bus-off" in text
                                                              or "it takes no node bus-off" in text)


def test_d18_00_ends_with_the_students_try_and_its_check_then_what_next():
    cells = read("00_can_in_15_minutes").cells
    assert cells[-1].source.startswith("## What next") and sum("## What next" in c.source for c in cells) == 1
    assert cells[-3].metadata.get("tags") == ["try"] and cells[-2].metadata.get("tags") == ["try-check"]
    five_kinds = next(i for i, c in enumerate(cells) if c.source.startswith("## Five kinds of error"))
    assert five_kinds < len(cells) - 3
    cells = read("01_bit_timing").cells
    tags = [c.metadata.get("tags") for c in cells]
    assert tags.index(["try"]) > next(i for i, c in enumerate(cells) if c.source.startswith("## Questions"))
    assert tags.index(["try-check"]) == tags.index(["try"]) + 1


def test_d19_demo1_says_why_the_classrooms_monitor_is_in_normal_mode():
    room = Classroom(Bus(Simulator()), 4)
    room.run(0.01)
    assert room.monitor.ecan.opmode == Mode.NORMAL
    answer = cell_with("demo1_monitor", "2. Which mode, and why?")
    for words in ("is in Normal mode on purpose", "is a participant", "that is why EX4 works", "listens only"):
        assert words in answer, words


def test_d20_01_says_the_workshop_samples_earlier_than_cias_87_5_percent():
    assert CLASSROOM.sample_point < Fraction(calculate.__kwdefaults__["sample_point"])
    text = flat(markdown("01_bit_timing"))
    assert "samples earlier than CiA's 87.5 %" in text and "later sample point" not in text
    assert f"leaves {CLASSROOM.effective_seg2ph} TQ of Phase2 and so allows SJW = {CLASSROOM.sjw} TQ" in text


def test_also_noted_01_flags_the_garbled_17_cm_per_ns_and_the_readme_two_senders_of_one_id():
    assert "17 cm/ns along the cable (so the slide prints it; its own 2/3 x 30 cm/ns would be 20" in cell_with(
        "01_bit_timing", "## Prop, and how long")
    readme = flat((KIT / "README.md").read_text())
    assert "destroy station 1's frames and its own" not in readme
    assert "two senders of one ID that do not start together never collide" in readme


# ---------------------------------------------------------------- the tries that end notebooks 00 and 01

def test_00s_try_holds_a_prediction_against_the_run_and_shows_no_numbers_before_one(ran):
    ns = ran("00_can_in_15_minutes")
    trace, counters = ns["with_an_error"](ns["node"], ns["kind"], ns["bit"], ns["frames"])
    assert counters == {"station1": (15, 0), "master": (0, 1), "third": (0, 1)}, "2 x 8 - 1; 2 x 1 - 1 each"
    shipped = tries.predicted_counters(ns["prediction"], trace, counters)
    assert not shipped.passed and "15" not in str(shipped).split("Not judged")[0].split("failed")[-1]
    right = tries.predicted_counters(counters, trace, counters)
    assert right.passed and [c.name for c in right.checks][2:] == [f"{b}'s TEC and REC" for b in counters]
    wrong = tries.predicted_counters({**counters, "master": (0, 2)}, trace, counters)
    [missed] = wrong.failed()
    assert missed.name == "master's TEC and REC" and "the kit counted TEC 0, REC 1" in missed.message
    typo = tries.predicted_counters({**counters, "masters": (0, 1)}, trace, counters)
    assert "there is no board masters" in typo.checks[1].message.lower()
    for clumsy, says in (([15, 0, 0, 1], "prediction is a dict"), ({**counters, "third": (0,)}, "for third"),
                         ({**counters, "third": ("0", "1")}, "for third"), (None, "got NoneType")):
        tried = tries.predicted_counters(clumsy, trace, counters)
        assert says in tried.checks[1].message and "the kit counted" not in str(tried)
    nothing = tries.predicted_counters(counters, [], counters)
    assert not nothing.checks[0].passed


@pytest.mark.parametrize("registers, joins", [
    ((0xC9, 0xBA, 0x43), False),            # the classroom's 125 kbit/s, as shipped: it wrecks the bus
    ((0xC4, 0xBA, 0x43), True),             # BRP 5: CANInitialize(4, 5, 8, 4, 3)
    ((0xC3, 0xBE, 0x03), True),             # 20 TQ: 1 + 7 + 8 + 4
    ((0xC3, 0x3E, 0x03), False),            # the same with SEG2PHTS = 0: Phase2 = 8 TQ, 24 TQ, 208 kbit/s
])
def test_01s_try_your_bit_timing_joins_the_250_kbit_bus_or_wrecks_it(registers, joins):
    tried = tries.own_bit_timing(*registers)
    assert tried.passed is joins and [c.name for c in tried.checks] == list(tries.TIMING_LINES)
    errors = [e for e in tried.bus.trace if e.error]
    assert (not errors) is joins
    if not registers[1] & 0x80:
        assert "SEG2PHTS (BRGCON2 bit 7) is 0, so Phase2 is max(Phase1, 2) = 8 TQ" in tried.checks[0].message


def test_01s_try_the_calculators_first_250_kbit_setting_joins_and_a_register_out_of_range_is_said_so():
    best = calculate(250_000, FOSC_HZ)[0].timing
    assert tries.own_bit_timing(*best.to_registers()).passed
    refused = tries.own_bit_timing(0x1C4, 0xBA, 0x43)
    assert "BRGCON1 is an 8-bit register" in refused.checks[0].message and refused.bus is None
    shipped = [c.source for c in read("01_bit_timing").cells if c.metadata.get("tags") == ["try"]][0]
    namespace: dict = {}
    exec(shipped, namespace)
    assert (namespace["BRGCON1"], namespace["BRGCON2"], namespace["BRGCON3"]) == initialized_brgcon()
