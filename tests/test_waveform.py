"""The bus's CAN line as a VCD: each event's bits where the trace puts them, error flags as the wire carries them,
and sigrok-cli's CAN decoder reading back the frames a command ran (`appsim ... --vcd`)."""
from __future__ import annotations

import subprocess
import sys
from pathlib import Path

import can
import pytest
from test_bus_gotchas import normal_node
from test_vcd import level_at, read_vcd, sigrok_cli, sigrok_decode  # noqa: F401 (sigrok_cli: a fixture)

from appsim.bus.bitlevel import ERROR_DELIMITER_BITS, ERROR_FLAG_BITS
from appsim.bus.waveform import WaveformLog, wire_levels, write_waveform
from appsim.can.bits import encode, frame_bits
from appsim.can.frame import CanFrame
from appsim.errors import OutputError
from appsim.firmware import *

KIT = Path(__file__).resolve().parent.parent
BIT_PS = 8_000_000                      # 125 kbit/s
TICK_PS = 1_000_000                     # the VCD's 1 us


def test_a_frame_that_went_through_is_drawn_acknowledged_where_the_trace_puts_it(world, tmp_path):
    world.node("a", normal_node([(0x100, CAN_TX_PRIORITY_0)], delay_ms=1))
    world.node("b", normal_node())
    world.run(0.01)
    path = write_waveform(world.bus, tmp_path / "bus.vcd")
    timescale, changes = read_vcd(path.read_text())
    (event,) = world.bus.trace
    bits = list(encode(event.frame))
    bits[-9] = 0                                                      # the ACK slot: b acknowledged
    start = event.start_ps // TICK_PS
    assert timescale == "1 us" and changes[0] == (0, 1)
    assert [level_at(changes, start + 8 * n + 4) for n in range(len(bits))] == bits
    assert start + 8 * frame_bits(event.frame) == event.end_ps // TICK_PS, "the last EOF bit ends at the frame's time"
    assert changes[-1][0] < int(path.read_text().split()[-1][1:]) == world.sim.now // TICK_PS, "the file lasts the run"


def test_an_ack_error_shows_the_active_flag_in_the_ack_delimiter_and_then_a_passive_senders_recessive_one(world):
    world.node("alone", normal_node([(0x100, CAN_TX_PRIORITY_0)]))
    world.run(0.5)
    first, last = world.bus.trace[0], world.bus.trace[-1]
    frame_bits_up_to_ack = list(encode(first.frame))[:-8]             # up to the ACK slot, left recessive
    assert wire_levels(first, BIT_PS) == frame_bits_up_to_ack + [0] * ERROR_FLAG_BITS + [1] * ERROR_DELIMITER_BITS
    assert wire_levels(last, BIT_PS) == frame_bits_up_to_ack + [1] * (ERROR_FLAG_BITS + ERROR_DELIMITER_BITS), \
        "error-passive (TEC 128): its flag is recessive, the wire shows nothing"


def test_two_stations_with_one_id_are_cut_by_error_flags_at_the_first_bit_they_differ():
    from appsim.bus.wire import Bus
    from appsim.sim import Simulator
    from appsim.workshop.classroom import Classroom
    bus = Bus(Simulator(), 125_000)
    room = Classroom(bus, 2, seed=1)
    room.join(KIT / "solutions" / "ex2.py", 3)                       # MESSAGE_ID1 0x100 on station 3
    room.run(0.1)
    collision = next(e for e in bus.trace if "two nodes sent" in e.error)
    levels = wire_levels(collision, BIT_PS)
    cut = collision.flag_at_bit
    assert levels[:cut - 1] == list(encode(collision.frame))[:cut - 1], "the frame as sent, up to the bit they differ"
    flags = levels[cut:].index(1)
    assert ERROR_FLAG_BITS <= flags <= 2 * ERROR_FLAG_BITS, "flags and their echoes superposed"
    assert levels[cut + flags:] == [1] * ERROR_DELIMITER_BITS
    assert len(levels) * BIT_PS == collision.end_ps - collision.start_ps


def test_a_waveform_that_cannot_be_written_is_refused_when_opened(world, tmp_path):
    with pytest.raises(OutputError, match="there is no directory"):
        WaveformLog(tmp_path / "no" / "bus.vcd", world.bus)


def test_appsim_vcd_is_decoded_by_sigrok_into_the_frames_of_the_log_at_their_times(sigrok_cli, tmp_path):
    vcd, log = tmp_path / "classroom.vcd", tmp_path / "classroom.log"
    result = subprocess.run([sys.executable, "-m", "appsim", "classroom", "--exercise", "2", "--seconds", "0.5",
                             "--vcd", str(vcd), "--log", str(log)], capture_output=True, text=True, timeout=120)
    assert result.returncode == 0, result.stderr
    assert f"wrote {vcd} (waveform for PulseView, " in result.stdout
    logged = list(can.LogReader(log))
    decoded = sigrok_decode(sigrok_cli, vcd, 125_000)        # samples are the VCD's ticks: microseconds
    assert len(decoded) == len(logged) > 50
    assert [d.frame() for d in decoded] == [CanFrame(m.arbitration_id, bytes(m.data), extended=m.is_extended_id,
                                                     remote=m.is_remote_frame, dlc=m.dlc) for m in logged]
    assert [d.ack for d in decoded] == ["ACK"] * len(logged) and not any(d.warnings for d in decoded)
    ends = [(d.start + frame_bits(d.frame()) * 8) / 1e6 for d in decoded]
    assert ends == pytest.approx([m.timestamp for m in logged], abs=1e-6), "each frame ends at its time in the log"


@pytest.mark.parametrize("argv", [["demo", "--out", "{tmp}/demo"], ["board", str(KIT / "solutions" / "ex2.py")],
                                  ["classroom"], ["monitor", "--transport", "socket"]])
def test_every_command_that_runs_a_bus_writes_its_waveform(tmp_path, argv):
    vcd = tmp_path / "bus.vcd"
    result = subprocess.run([sys.executable, "-m", "appsim", *(a.format(tmp=tmp_path) for a in argv),
                             "--seconds", "0.3", "--vcd", str(vcd)], capture_output=True, text=True, timeout=120)
    assert result.returncode == 0, result.stderr
    timescale, changes = read_vcd(vcd.read_text())
    assert timescale == "1 us" and len(changes) > 100
    assert f"wrote {vcd} (waveform for PulseView, " in result.stdout


def test_an_injected_error_frame_shows_at_its_bit_and_sigrok_decodes_the_frames_around_it(world, tmp_path,
                                                                                           sigrok_cli):
    """sigrok's CAN decoder has no error frames (decode_error_frame is a TODO in its can/pd.py): it reads on through
    the flags as if the frame went on, and so misreads the retry that follows 3 bits after the delimiter. It warns
    about what it misreads; the valid frames before and after decode intact."""
    world.node("b", normal_node([(0x088, CAN_TX_PRIORITY_0)], delay_ms=1))
    world.node("a", normal_node([(0x100, CAN_TX_PRIORITY_0)], delay_ms=3))
    world.node("c", normal_node([(0x0F0, CAN_TX_PRIORITY_0)], delay_ms=6))
    world.bus.inject("c", "stuff", 30, can_id=0x100)
    world.run(0.01)
    before, error, retry, after = world.bus.trace
    levels = wire_levels(error, BIT_PS)
    assert error.flag_at_bit == 31 and levels[:30] == list(encode(error.frame))[:30]
    assert levels[31:31 + ERROR_FLAG_BITS] == [0] * ERROR_FLAG_BITS
    assert retry.ok and retry.start_ps == error.end_ps + 3 * BIT_PS
    path = write_waveform(world.bus, tmp_path / "bus.vcd")
    decoded = sigrok_decode(sigrok_cli, path, 125_000)
    clean = [d for d in decoded if d.ack == "ACK" and not d.warnings]
    assert [d.frame() for d in clean] == [before.frame, after.frame]
    assert [d.start * TICK_PS for d in clean] == pytest.approx([before.start_ps, after.start_ps], abs=TICK_PS)
    assert any(d.warnings for d in decoded if abs(d.start * TICK_PS - error.start_ps) <= TICK_PS), \
        "it warns at the error frame"
