"""The CANKing-like monitor: trace lines, bus load, error counters, logs other CAN tools open, written as the bus runs;
the trace kept in memory is a window, the counts and the log are whole."""
from __future__ import annotations

import re
import shutil
import subprocess

import can
import pytest
from conftest import World
from test_bus_gotchas import normal_node

from appsim.bus.monitor import (
    HEADER,
    LOG_FORMATS,
    LiveTrace,
    TraceLog,
    bus_load,
    error_counters,
    format_event,
    summary,
    write_log,
)
from appsim.bus.trace import TRACE_WINDOW
from appsim.bus.wire import Bus
from appsim.can.bits import INTERMISSION_BITS
from appsim.errors import OutputError
from appsim.firmware import *
from appsim.workshop import checks
from appsim.workshop.course import CLASSROOM_BIT_RATE, EXERCISE_FILES


@pytest.fixture
def traffic(world):
    world.node("a", normal_node([(0x100, CAN_TX_STD_FRAME), (0x1ABCDE, CAN_TX_XTD_FRAME)], delay_ms=1))
    world.node("b", normal_node([(0x088, CAN_TX_STD_FRAME & CAN_TX_RTR_FRAME)], delay_ms=1))
    world.node("quiet", normal_node(mode=CAN_OP_MODE_LISTEN))
    world.run(0.02)
    return world


def test_trace_lines_show_id_kind_dlc_data_sender_and_who_acked(traffic):
    lines = [format_event(e) for e in traffic.bus.trace]
    assert "ID" in HEADER and "ACK by" in HEADER
    assert [line.split()[0] for line in lines] == [f"{e.end_ps / 1e12:.6f}" for e in traffic.bus.trace], "end of frame"
    rtr, ext, std = lines          # equal TX priority: TXB1 (the extended frame) leaves before TXB0
    assert rtr.split()[1:5] == ["b", "088", "STD", "RTR"] and rtr.endswith("a")
    assert std.split()[1:8] == ["a", "100", "STD", "3", "01", "02", "03"] and std.endswith("b")
    assert ext.split()[1:4] == ["a", "001ABCDE", "EXT"]


def test_bus_load_is_the_share_of_time_frames_occupy(traffic):
    trace = traffic.bus.trace
    busy = sum(e.end_ps - e.start_ps for e in trace)
    assert bus_load(trace, 0, traffic.sim.now) == pytest.approx(busy / traffic.sim.now)
    assert bus_load(trace, trace[0].start_ps, trace[0].end_ps) == 1.0
    assert "3 frames, 0 error frames" in summary(traffic.bus)


def test_error_counters_show_an_ack_error_victim(world):
    world.node("alone", normal_node([(0x100, CAN_TX_STD_FRAME)], delay_ms=1))
    world.node("listener", normal_node(mode=CAN_OP_MODE_LISTEN))
    world.run(0.2)
    table = error_counters(world.bus).splitlines()
    assert table[1].split() == ["alone", "normal", "128", "0", "error-passive"]
    assert table[2].split() == ["listener", "listen-only", "0", "0", "error-active"]


@pytest.mark.parametrize("suffix", sorted(LOG_FORMATS))
def test_logs_read_back_with_python_can(traffic, tmp_path, suffix):
    path = write_log(traffic.bus.trace, tmp_path / f"trace{suffix}")
    messages = list(can.LogReader(path))
    assert [(m.arbitration_id, m.is_extended_id, m.is_remote_frame, bytes(m.data)) for m in messages] == [
        (0x088, False, True, b""), (0x1ABCDE, True, False, b"\x01\x02\x03"), (0x100, False, False, b"\x01\x02\x03")]
    assert [m.timestamp for m in messages] == pytest.approx([e.end_ps / 1e12 for e in traffic.bus.trace], abs=1e-6), \
        "every format counts from reset and stamps the end of frame"


@pytest.mark.skipif(shutil.which("log2asc") is None, reason="can-utils' log2asc not installed (apt-get install can-utils)")
def test_candump_log_is_read_by_can_utils(traffic, tmp_path):
    path = write_log(traffic.bus.trace, tmp_path / "trace.log")
    asc = subprocess.run(["log2asc", "-I", str(path), "vcan0"], capture_output=True, text=True, check=True).stdout
    assert "88" in asc and "1ABCDEx" in asc


def test_unknown_log_format_says_which_ones_work(traffic, tmp_path):
    with pytest.raises(OutputError, match=r"\.log \(candump\)"):
        write_log(traffic.bus.trace, tmp_path / "trace.xyz")


@pytest.mark.parametrize("suffix", sorted(LOG_FORMATS))
def test_a_log_is_on_disk_frame_by_frame_as_the_bus_runs(traffic, tmp_path, suffix):
    """What a kill or a crash would leave: after each frame, the file as it is reads back to that frame."""
    path = tmp_path / f"trace{suffix}"
    log = TraceLog(path)
    for n, event in enumerate(traffic.bus.trace, start=1):
        log.write(event)
        assert [m.arbitration_id for m in can.LogReader(path)] == [e.frame.can_id for e in traffic.bus.trace[:n]]
    log.close()


@pytest.mark.parametrize("path, complaint", [
    ("no/such/folder/trace.log", "there is no directory"),
    ("folder.log", "that is a directory"),
    ("trace.trc", "use .log (candump), .asc (Vector), .blf (Vector binary) or .csv"),
])
def test_a_log_that_cannot_be_written_is_refused_when_opened(tmp_path, path, complaint):
    (tmp_path / "folder.log").mkdir()
    with pytest.raises(OutputError, match=re.escape(complaint)):
        TraceLog(tmp_path / path)


def test_the_trace_keeps_a_window_and_the_counts_and_the_listeners_get_everything():
    world = World()
    world.bus = Bus(world.sim, CLASSROOM_BIT_RATE, trace_window=2)
    everything = []
    world.bus.trace.listeners.append(everything.append)
    live = LiveTrace(world.bus)
    world.node("a", normal_node([(0x100 + n, CAN_TX_STD_FRAME) for n in range(3)], delay_ms=1))
    world.node("b", normal_node())
    world.run(0.01)
    trace = world.bus.trace
    assert len(everything) == 3 and list(trace) == everything[1:] and trace.dropped == 1
    assert "3 frames, 0 error frames" in summary(world.bus)
    assert live.new_lines() == [f"{'':>11}  ... frames not kept in memory: 1 (the trace keeps the last 2; a log keeps "
                                "every one)", *map(format_event, everything[1:])]


def test_a_checks_whole_run_fits_in_the_trace_window():
    """Checks read `bus.trace` after runs of at most a second: the window holds more events than the classroom bus can
    carry in the longest, even if every one were the shortest error frame (cut at bit 10, flags and delimiter)."""
    longest_s = max(getattr(getattr(checks, name), "SECONDS", 0) for name in EXERCISE_FILES)
    shortest_event_bits = 10 + 2 * 6 + 8 + INTERMISSION_BITS
    most_events = longest_s * CLASSROOM_BIT_RATE / shortest_event_bits
    assert longest_s >= 1.0 and TRACE_WINDOW > 4 * most_events
