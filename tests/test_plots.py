"""The notebooks' pictures show what the kit computes: fields, stuff bits, who wins, segments, frames, load,
counters."""
from __future__ import annotations

import matplotlib

matplotlib.use("Agg")

import matplotlib.pyplot as plt
import pytest
from workshop import lone_node

from appsim.bus.monitor import bus_load
from appsim.bus.wire import Bus
from appsim.can.bits import encode, encode_annotated
from appsim.can.bittiming import BitTiming
from appsim.can.frame import CanFrame
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
