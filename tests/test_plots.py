"""The notebooks' pictures show what the kit computes: fields, stuff bits, who wins, segments, frames, load,
counters."""
from __future__ import annotations

import matplotlib

matplotlib.use("Agg")

import matplotlib.pyplot as plt
import pytest
from workshop import lone_node

from appsim.board.app023 import APP023
from appsim.bus.monitor import bus_load
from appsim.bus.wire import BUS_IDLE_BITS, Bus
from appsim.can.bits import encode, encode_annotated
from appsim.can.bittiming import BitTiming
from appsim.can.frame import CanFrame
from appsim.chip.ecan.registers import BY_NAME, RXWARN, TXWARN
from appsim.firmware import (
    CAN_CONFIG_ALL_MSG,
    CAN_TX_PRIORITY_0,
    CAN_TX_STD_FRAME,
    CANInitialize,
    CANIsRxReady,
    CANReceiveMessage,
    CANSendMessage,
    Delay1KTCYx,
)
from appsim.sim import PS_PER_SECOND, Simulator
from appsim.workshop import plots
from appsim.workshop.classroom import Classroom

EX1_FRAME = CanFrame(0x100, bytes([1, 2, 3, 0x02, 0x9A]))
CLASSROOM_TIMING = BitTiming(sjw=4, brp=10, seg1ph=8, seg2ph=4, prseg=3)


@pytest.fixture(autouse=True)
def close_figures():
    yield
    plt.close("all")


def texts(figure) -> list[str]:
    return [text.get_text() for text in figure.axes[0].texts]


def patches(figure, gid: str) -> list:
    return [patch for patch in figure.axes[0].patches if patch.get_gid() == gid]


def test_wire_bits_labels_every_field_in_wire_order_and_outlines_each_stuff_bit():
    figure = plots.wire_bits(EX1_FRAME)
    assert texts(figure) == ["SOF", "ID", "RTR", "IDE", "r0", "DLC", "DATA", "CRC", "DEL", "ACK", "DEL", "EOF"]
    stuff = [index for index, bit in enumerate(encode_annotated(EX1_FRAME)) if bit.stuff]
    assert stuff, "this frame has stuff bits"
    assert sorted(patch.get_x() for patch in patches(figure, "stuff")) == stuff
    assert f"{len(encode(EX1_FRAME))} bits on the wire, {len(stuff)} of them stuff bits" in figure.axes[0].get_title()


def test_wire_bits_draws_the_ack_slot_dominant_when_acked_and_recessive_for_a_lone_sender():
    ack_slot = next(index for index, bit in enumerate(encode_annotated(EX1_FRAME)) if bit.field == "ACK slot")
    for acked, level in ((True, 0), (False, 1)):
        line = plots.wire_bits(EX1_FRAME, acked=acked).axes[0].lines[0]
        assert line.get_ydata()[ack_slot] == level


def test_a_frame_nobody_acks_ends_in_an_error_flag_and_the_error_delimiter_instead_of_eof():
    figure = plots.wire_bits(EX1_FRAME, acked=False)
    bits = encode_annotated(EX1_FRAME)
    ack_slot = next(index for index, bit in enumerate(bits) if bit.field == "ACK slot")
    levels = list(figure.axes[0].lines[0].get_ydata())
    assert levels[ack_slot] == 1, "nobody drives the ACK slot dominant"
    assert levels[ack_slot + 1:ack_slot + 7] == [0] * 6, "six dominant bits of error flag from the next bit"
    assert levels[ack_slot + 7:ack_slot + 15] == [1] * 8, "then eight recessive bits of error delimiter"
    assert texts(figure)[-3:] == ["ACK", "error\nflag", "error\ndelimiter"]
    assert "EOF" not in texts(figure)


def test_arbitration_outlines_the_stuff_bits_each_node_sent_and_the_bus_carried():
    frames = {"station1 (RTR)": CanFrame(0x081, remote=True), "master (data)": CanFrame(0x081, bytes([1, 2, 3, 2, 0]))}
    figure = plots.arbitration(frames)
    stuff = [index for index, bit in enumerate(encode_annotated(frames["master (data)"])) if bit.stuff and index < 14]
    assert stuff == [10], "0x081: SOF and ID bits 0000 10000 0: five dominant bits, then a recessive stuff bit"
    boxes = patches(figure, "stuff")
    assert sorted(patch.get_x() for patch in boxes) == [10, 10, 10], "both nodes sent it, and the bus carried it"
    assert "stuff bits" in figure.axes[0].get_xlabel()


def test_arbitration_labels_stay_inside_the_picture():
    frames = {"station1 (RTR)": CanFrame(0x081, remote=True), "master (data)": CanFrame(0x081, bytes([1, 2, 3, 2, 0]))}
    figure = plots.arbitration(frames)
    figure.canvas.draw()
    inside = figure.axes[0].get_window_extent()
    [label] = [text for text in figure.axes[0].texts if text.get_text().startswith("lost at bit")]
    box = label.get_window_extent()
    assert inside.x0 <= box.x0 and box.x1 <= inside.x1 and inside.y0 <= box.y0 and box.y1 <= inside.y1


def test_arbitration_the_lower_id_wins_and_the_loser_stops_at_the_first_differing_bit():
    frames = {"station1": EX1_FRAME, "master": CanFrame(0x088, bytes([1, 2, 3, 2, 0]))}
    figure = plots.arbitration(frames)
    wires = encode(frames["station1"]), encode(frames["master"])
    first_difference = next(i for i, (a, b) in enumerate(zip(*wires, strict=False)) if a != b)
    assert first_difference == 3                                # ID bit 8: 1 in 0x100, 0 in 0x088
    assert figure.axes[0].get_title().startswith("master wins arbitration")
    assert f"lost at bit {first_difference}" in texts(figure)
    assert [label.get_text() for label in figure.axes[0].get_yticklabels()] == [
        "station1  0x100", "master  0x088", "bus (wired-AND)"]


def test_arbitration_between_a_data_and_a_remote_frame_of_one_id_goes_to_the_data_frame():
    frames = {"asks": CanFrame(0x081, remote=True), "answers": CanFrame(0x081, bytes([1, 2, 3, 0, 7]))}
    figure = plots.arbitration(frames)
    rtr = next(i for i, bit in enumerate(encode_annotated(frames["asks"])) if bit.field == "RTR")
    assert figure.axes[0].get_title().startswith("answers wins")
    assert f"lost at bit {rtr}" in texts(figure)            # the RTR bit, after SOF, 11 ID bits and a stuff bit


def test_arbitration_needs_two_nodes():
    with pytest.raises(ValueError, match="at least two nodes"):
        plots.arbitration({"alone": EX1_FRAME})


def test_bit_segments_draws_sync_prop_phase1_phase2_in_tq_and_the_sample_point():
    figure = plots.bit_segments(CLASSROOM_TIMING, 40_000_000)
    widths = [patch.get_width() for patch in patches(figure, "segment")]
    assert widths == [1, CLASSROOM_TIMING.prseg, CLASSROOM_TIMING.seg1ph, CLASSROOM_TIMING.seg2ph]
    sample_line = figure.axes[0].lines[0]
    assert list(sample_line.get_xdata()) == [12, 12]            # 1 + 3 + 8 of 16 TQ
    assert "sample point 75.0%" in texts(figure)
    assert patches(figure, "sjw")[0].get_width() == 2 * CLASSROOM_TIMING.sjw
    assert figure.axes[0].get_title() == "one bit = 16 TQ = 8 µs: 125 kbit/s"


@pytest.fixture(scope="module")
def ex2_room() -> Classroom:
    room = Classroom(Bus(Simulator()), 2, stations=3)
    room.run(0.25)
    return room


def test_bus_timeline_one_row_per_sender_one_box_per_frame(ex2_room):
    trace = ex2_room.bus.trace
    figure = plots.bus_timeline(trace)
    assert len(patches(figure, "frame")) == len(trace)
    assert [label.get_text() for label in figure.axes[0].get_yticklabels()] == list(
        dict.fromkeys(event.sender for event in trace))


def test_bus_timeline_paints_error_frames_apart():
    bus = lone_node(0.01)
    figure = plots.bus_timeline(bus.trace)
    assert bus.trace and all(event.error for event in bus.trace), "nobody ACKs a lone node"
    assert len(patches(figure, "error")) == len(bus.trace)
    assert not patches(figure, "frame")


def test_bus_load_over_time_bars_are_the_monitors_bus_load_per_window(ex2_room):
    trace, end = ex2_room.bus.trace, ex2_room.bus.sim.now
    window = PS_PER_SECOND // 20
    figure = plots.bus_load_over_time(trace, 0, end, window)
    heights = [bar.get_height() for bar in figure.axes[0].patches]
    expected = [100 * bus_load(trace, start, min(start + window, end)) for start in range(0, end, window)]
    assert heights == pytest.approx(expected)
    assert any(height > 0 for height in heights)


def test_error_counter_history_draws_tec_rec_and_the_error_passive_threshold():
    samples = [(0.0, 0, 0), (0.001, 8, 0), (0.002, 16, 1), (0.05, 128, 1)]
    figure = plots.error_counter_history(samples, node="alone")
    tec, rec = figure.axes[0].lines[:2]
    assert list(tec.get_ydata()) == [0, 8, 16, 128]
    assert list(rec.get_ydata()) == [0, 0, 1, 1]
    assert "error-passive (128)" in texts(figure)
    assert figure.axes[0].get_title() == "error counters of alone"
    figure.canvas.draw()
    inside = figure.axes[0].get_window_extent()
    for label in figure.axes[0].texts:
        box = label.get_window_extent()
        assert inside.y0 <= box.y0 and box.y1 <= inside.y1, f"{label.get_text()!r} is cut by the frame"


def smallest(counter: str, holds) -> int:
    """The smallest value of an ECAN's TEC or REC at which `holds(ecan)`, the other counter at 0."""
    ecan = APP023(Bus(Simulator()), "probe").ecan
    for value in range(300):
        setattr(ecan, counter, value)
        if holds(ecan):
            return value
    raise AssertionError(f"{counter} never makes it hold")


def sending(frame: CanFrame):
    def main():
        CANInitialize(4, 10, 8, 4, 3, CAN_CONFIG_ALL_MSG)
        Delay1KTCYx(10)
        CANSendMessage(frame.can_id, list(frame.data), frame.dlc, CAN_TX_PRIORITY_0 & CAN_TX_STD_FRAME)
        listening_loop()
    return main


def listening_loop():
    while True:
        if CANIsRxReady():
            CANReceiveMessage()


def listening():
    CANInitialize(4, 10, 8, 4, 3, CAN_CONFIG_ALL_MSG)
    listening_loop()


def test_error_states_draws_the_three_states_and_the_thresholds_the_ecan_switches_at():
    comstat = BY_NAME["COMSTAT"].address
    passive = smallest("tec", lambda ecan: ecan.error_state == "error-passive")
    assert passive == smallest("rec", lambda ecan: ecan.error_state == "error-passive")
    bus_off = smallest("tec", lambda ecan: ecan.error_state == "bus-off")
    warning = smallest("tec", lambda ecan: ecan.read(comstat) & TXWARN)
    assert smallest("rec", lambda ecan: ecan.read(comstat) & RXWARN) == warning
    board = APP023(Bus(Simulator()), "off")
    board.run(listening)                                       # CANInitialize: on the bus, in Normal mode
    board.bus.sim.run(until=PS_PER_SECOND // 100)
    ecan = board.ecan
    ecan.tec = bus_off
    ecan.bus_off_recovery(plots.RECOVERY_SEQUENCES - 1)
    assert ecan.bus_off
    ecan.bus_off_recovery(1)
    assert (ecan.tec, ecan.rec, ecan.error_state) == (0, 0, "error-active")
    figure = plots.error_states()
    shown = texts(figure)
    assert shown[0:6:2] == ["error-active", "error-passive", "bus-off"]
    conditions = [t.get_text() for t in figure.axes[0].texts if t.get_gid() == "condition"]
    assert conditions[:3] == [f"TEC > {passive - 1}\nor REC > {passive - 1}",
                              f"TEC <= {passive - 1}\nand REC <= {passive - 1}", f"TEC > {bus_off - 1}"]
    assert conditions[3].startswith(f"after {plots.RECOVERY_SEQUENCES} x {BUS_IDLE_BITS} recessive bits: TEC = REC = 0")
    says = " ".join(shown)
    for words in (f"TEC or REC > {warning - 1}", f"COMSTAT.TXBP (TEC > {passive - 1})",
                  f"COMSTAT.RXBP (REC > {passive - 1})", f"COMSTAT.TXBO (TEC > {bus_off - 1})", "PIR3.ERRIF"):
        assert words in says
    assert len(patches(figure, "state")) == 3 and len(patches(figure, "transition")) == 4
    figure.canvas.draw()
    inside = figure.get_window_extent()
    for text in figure.axes[0].texts:
        box = text.get_window_extent()
        assert inside.x0 <= box.x0 and box.x1 <= inside.x1, f"{text.get_text()!r} is cut at the side"


def test_register_bits_draws_each_bit_by_its_data_sheet_name_and_decodes_each_field():
    figure = plots.register_bits("BRGCON2", 0xBA)
    names = [t.get_text() for t in figure.axes[0].texts][0:24:3]
    assert names == ["PRSEG0", "PRSEG1", "PRSEG2", "SEG1PH0", "SEG1PH1", "SEG1PH2", "SAM", "SEG2PHTS"], "bit 0 first"
    values = [t.get_text() for t in figure.axes[0].texts][1:24:3]
    assert values == [str(0xBA >> bit & 1) for bit in range(8)]
    fields = [t.get_text() for t in figure.axes[0].texts if t.get_gid() == "field"]
    assert fields == ["SEG1PH<2:0> = 111 (7)", "PRSEG<2:0> = 010 (2)"]
    assert [p.get_x() for p in patches(figure, "bit")] == list(range(7, -1, -1)), "bit 7 on the left"
    assert figure.axes[0].get_title() == "BRGCON2 = 0xBA"
    assert not [t for t in plots.register_bits("COMSTAT", 0x15).axes[0].texts if t.get_gid() == "field"]
    with pytest.raises(ValueError, match="no bit names for TXB0D0"):
        plots.register_bits("TXB0D0", 0)
    with pytest.raises(ValueError, match="8-bit register"):
        plots.register_bits("COMSTAT", 0x100)


def test_recorded_wire_draws_what_the_bus_carried_past_eof_as_the_overload_frame():
    frame = CanFrame(0x100, bytes([1, 2, 3, 0, 0]))
    bus = Bus(Simulator())
    for name in ("sender", "receiver", "other"):
        APP023(bus, name).run(sending(frame) if name == "sender" else listening)
    bus.inject("receiver", "form", len(encode(frame)) - 1)          # a dominant bit in the last bit of EOF
    bus.sim.run(until=4 * PS_PER_SECOND // 1000)
    [event] = bus.trace
    assert event.ok and event.wire
    figure = plots.recorded_wire(event, 125_000)
    drawn = list(figure.axes[0].lines[0].get_ydata())[:-1]
    bit_ps = PS_PER_SECOND // 125_000
    changes = event.wire_changes()
    on_wire = [next(level for time, level in reversed(changes) if time <= event.start_ps + i * bit_ps + bit_ps // 2)
               for i in range((event.end_ps - event.start_ps) // bit_ps)]
    assert drawn == on_wire
    labels = texts(figure)
    assert labels[-3:] == ["EOF", "overload\nflag(s)", "overload\ndelimiter"]
    flags = len(on_wire) - len(encode(frame)) - 8
    assert on_wire[len(encode(frame)):] == [0] * flags + [1] * 8 and 6 <= flags <= 12
    assert f"then {flags + 8} bits of overload frame" in figure.axes[0].get_title()
    with pytest.raises(ValueError, match="run bit by bit"):
        plots.recorded_wire(lone_node(0.002).trace[0], 125_000)
