"""SLCAN (Lawicel): the protocol as pure functions, and python-can's own slcan bus on the simulated board."""
from __future__ import annotations

import re
import threading
import time
from pathlib import Path

import can
import pytest

from appsim.board.app023 import APP023
from appsim.bus.wire import Bus
from appsim.firmware import *  # noqa: F403
from appsim.can.frame import CanFrame
from appsim.bus.realtime import WallClock
from appsim.sim import PS_PER_SECOND, Simulator
from appsim.can.slcan import (BIT_RATES, Close, Nothing, Open, Query, SetBitRate, SlcanError, Timestamps,
                          Transmit, encode_frame, parse_command, status_reply, transmit_reply)
from appsim.board.usbcdc import UsbCdc

FRAMES = [
    CanFrame(0x088, bytes([1, 2, 3, 2, 0x9A])),
    CanFrame(0x000),
    CanFrame(0x7FF, bytes(range(8))),
    CanFrame(0x1ABCDE00, b"\xAA", extended=True),
    CanFrame(0x081, remote=True, dlc=5),
    CanFrame(0x1FFFFFFF, remote=True, dlc=0, extended=True),
]


@pytest.mark.parametrize("frame", FRAMES, ids=str)
def test_a_reported_frame_reads_back_as_the_same_transmit_command(frame):
    line = encode_frame(frame)
    assert line.endswith(b"\r") and line.count(b"\r") == 1
    assert parse_command(line) == Transmit(frame)


def test_lines_look_like_lawicels_examples():
    assert encode_frame(FRAMES[0]) == b"t0885010203029A\r"
    assert encode_frame(FRAMES[3]) == b"T1ABCDE001AA\r"
    assert encode_frame(FRAMES[4]) == b"r0815\r"
    assert encode_frame(FRAMES[5]) == b"R1FFFFFFF0\r"


def test_timestamps_are_four_hex_digits_of_milliseconds_wrapping_at_60000():
    assert encode_frame(FRAMES[1], timestamp_ms=0x1234) == b"t0000" + b"1234\r"
    assert encode_frame(FRAMES[1], timestamp_ms=60_001) == b"t00000001\r"


def test_a_dlc_above_8_is_reported_as_8_so_hosts_can_parse_the_data():
    assert encode_frame(CanFrame(0x100, bytes(8), dlc=12)) == b"t1008" + b"00" * 8 + b"\r"


def test_replies():
    assert transmit_reply(FRAMES[0]) == b"z\r" and transmit_reply(FRAMES[3]) == b"Z\r"
    assert status_reply(0x28) == b"F28\r"


@pytest.mark.parametrize("line, command", [
    (b"S4\r", SetBitRate(4)), ("S0", SetBitRate(0)), (b"O\r", Open()), (b"L\r", Open(listen_only=True)),
    (b"C\r", Close()), (b"V\r", Query("V")), (b"N\r", Query("N")), (b"F\r", Query("F")),
    (b"Z1\r", Timestamps(True)), (b"Z0\r", Timestamps(False)), (b"\r", Nothing()), (b"", Nothing()),
])
def test_commands(line, command):
    assert parse_command(line) == command


def test_s_codes_are_lawicels_bit_rates():
    assert SetBitRate(4).bit_rate == 125_000 and SetBitRate(8).bit_rate == 1_000_000
    assert sorted(BIT_RATES) == list(range(9))


@pytest.mark.parametrize("line, complaint", [
    ("S9", "one digit 0..8"), ("Sx", "one digit 0..8"), ("O1", "no argument"), ("Z2", "0 or 1"),
    ("q", "not a command"), ("t10", "too short"), ("t1005010203", "10 hex digits"),
    ("t1009", "0..8"), ("t8000", "does not fit a standard"), ("T200000000", "does not fit an extended"),
    ("r1002AA", "no data"), ("t10G0", "hex digits"), ("t1 10", "hex digits"), ("t1002010", "4 hex digits"),
])
def test_bad_commands_say_what_is_wrong(line, complaint):
    with pytest.raises(SlcanError, match=complaint):
        parse_command(line)


# ------------------------------------------------------------------ the Demo1 firmware as an SLCAN adapter

SOLUTION = Path(__file__).resolve().parent.parent / "solutions" / "demo1_monitor.py"


def station(can_id, received, *, every_ms=20):
    """A node at 125 kbit/s: sends `can_id` every `every_ms` and keeps what it receives."""
    def main():
        CANInitialize(4, 10, 8, 4, 3, CAN_CONFIG_ALL_MSG)
        OpenTimer1(TIMER_INT_OFF & T1_16BIT_RW & T1_SOURCE_INT & T1_PS_1_8 & T1_OSC1EN_OFF & T1_SYNC_EXT_OFF)
        count, elapsed = 0, 0
        while True:
            if PIR1bits.TMR1IF:                 # every 52.4288 ms
                PIR1bits.TMR1IF = 0
                elapsed += 52
                if elapsed >= every_ms:
                    elapsed = 0
                    CANSendMessage(can_id, [count & 0xFF, 0x5A], 2, CAN_TX_PRIORITY_0)
                    count += 1
            if CANIsRxReady():
                received.append(CANReceiveMessage())
    return main


class AdapterRoom:
    """A node sending 0x088, one receiving, and the Demo1 board with DSW2 switch 1 ON (SLCAN)."""

    def __init__(self):
        self.sim = Simulator()
        self.bus = Bus(self.sim)
        self.received = []
        APP023(self.bus, "sender").run(station(0x088, []))
        APP023(self.bus, "receiver").run(station(0x0F0, self.received, every_ms=10**9))
        self.board = APP023(self.bus, "adapter")
        self.board.dsw2.on(1)
        self.board.run(SOLUTION)
        self.replies = bytearray()
        self.board.usb.listeners.append(lambda byte, time_ps: self.replies.append(byte))

    def command(self, text: bytes, seconds: float = 0.02) -> bytes:
        """Send command bytes from the PC side; the adapter's answers meanwhile (frames it reported left out)."""
        return b"".join(line for line in self.lines(text, seconds) if line[:1] not in (b"t", b"T", b"r", b"R"))

    def lines(self, text: bytes, seconds: float) -> list[bytes]:
        """Send command bytes; everything the adapter sent meanwhile, as lines ending in CR or BELL."""
        self.replies.clear()
        self.board.usb.write(text)
        self.run(seconds)
        return re.findall(rb"[^\r\a]*[\r\a]", bytes(self.replies))

    def run(self, seconds: float) -> None:
        self.sim.run(until=self.sim.now + round(seconds * PS_PER_SECOND))
        for process in self.sim.processes:
            assert process.failure is None, f"firmware {process.name} crashed:\n{process.failure_text}"


def test_the_adapter_answers_each_command_as_lawicel_specifies():
    room = AdapterRoom()
    room.run(0.01)
    assert room.command(b"V\r") == b"V1013\r"
    assert room.command(b"N\r") == b"NA023\r"
    assert room.command(b"F\r") == b"\a", "status needs an open channel"
    assert room.command(b"t1230\r") == b"\a", "a closed channel cannot transmit"
    assert room.command(b"C\r") == b"\a", "closing a closed channel"
    assert room.command(b"S0\r") == b"\a", "10 kbit/s is below what the ECAN can do at 40 MHz"
    assert room.command(b"S4\r") == b"\r"
    assert room.command(b"Q\r") == b"\a"
    assert room.command(b"\r") == b"\r"
    assert room.command(b"L\r") == b"\r"
    assert room.board.ecan.opmode.name == "LISTEN_ONLY"
    assert room.command(b"t1230\r") == b"\a", "listen-only cannot transmit"
    assert room.command(b"S5\r") == b"\a", "the bit rate is set while the channel is closed"
    assert room.command(b"C\r") == b"\r" and room.board.ecan.opmode.name == "CONFIGURATION"
    assert room.command(b"O\r") == b"\r" and room.board.ecan.opmode.name == "NORMAL"
    assert room.command(b"F\r").startswith(b"F") and room.command(b"O\r") == b"\a"


def test_the_adapter_reports_the_frames_on_the_bus_and_sends_what_it_is_told():
    room = AdapterRoom()
    room.run(0.01)
    assert room.command(b"O\r") == b"\r"
    heard = room.lines(b"", seconds=0.2)
    sent = [e.frame for e in room.bus.frames() if e.sender == "sender"]
    assert heard == [encode_frame(f) for f in sent] and len(sent) >= 3
    assert room.command(b"T1ABCDE002CAFE\r") == b"Z\r"
    assert room.command(b"r1234\r") == b"z\r"
    wanted = [CanFrame(0x1ABCDE00, b"\xCA\xFE", extended=True), CanFrame(0x123, remote=True, dlc=4)]
    assert [e.frame for e in room.bus.frames() if e.sender == "adapter"] == wanted
    got = [m for m in room.received if m.id != 0x088]
    assert [(m.id, m.length, bool(m.flags & CAN_RX_RTR_FRAME)) for m in got] == [(0x1ABCDE00, 2, False),
                                                                               (0x123, 4, True)]
    assert got[0].data == b"\xCA\xFE"
    assert room.command(b"C\rZ1\rO\r", seconds=0.0) == b""
    replies = room.lines(b"", seconds=0.2)
    assert replies[:3] == [b"\r"] * 3
    time_stamps = [int(line[-5:-1], 16) for line in replies[3:]]
    assert replies[3:] and all(line.startswith(b"t0882") and len(line) == 14 for line in replies[3:])
    assert all(b - a in (52, 53) for a, b in zip(time_stamps, time_stamps[1:])), "ms between 0x088 frames"


def with_python_can(room: AdapterRoom, usb: UsbCdc, pc_program) -> dict:
    """Run `pc_program(results)` in a thread, as a PC program, while the simulation runs paced to the wall
    clock in this thread (firmware greenlets live here). Stops 20 ms after the program ends, or after 10 s."""
    results: dict = {}
    done = threading.Event()

    def pc() -> None:
        try:
            pc_program(results)
        except BaseException as failure:            # re-raised below, in the test's thread
            results["failure"] = failure
        finally:
            done.set()

    clock = WallClock(room.sim)
    clock.add_poller(usb.poll)
    thread = threading.Thread(target=pc)
    thread.start()
    clock.run(10.0, stop=done.is_set)
    thread.join(timeout=5)
    if "failure" in results:
        raise results["failure"]
    assert done.is_set(), "the PC program did not finish within 10 s of simulated time"
    clock.run(0.02)                                 # what it wrote last (python-can's closing C) arrives
    room.run(0)
    return results


@pytest.mark.parametrize("transport", ["pty", "socket"])
def test_python_can_uses_the_board_as_an_slcan_adapter_to_receive_and_to_send(transport):
    room = AdapterRoom()
    room.run(0.01)

    def pc_program(results: dict) -> None:
        with can.Bus(interface="slcan", channel=usb.url, bitrate=125000, sleep_after_open=0) as bus:
            results["version"] = bus.get_version(timeout=2)
            results["serial"] = bus.get_serial_number(timeout=2)
            results["messages"] = [bus.recv(timeout=2) for _ in range(3)]
            bus.send(can.Message(arbitration_id=0x321, data=[1, 2, 3], is_extended_id=False))
            deadline = time.monotonic() + 2
            while not any(m.id == 0x321 for m in room.received) and time.monotonic() < deadline:
                time.sleep(0.01)

    with UsbCdc(room.board, transport=transport) as usb:
        results = with_python_can(room, usb, pc_program)
    assert results["version"] == (10, 13) and results["serial"] == "A023"
    messages = results["messages"]
    assert None not in messages, "python-can received no frame within 2 s"
    from_sender = [e.frame for e in room.bus.frames() if e.sender == "sender"]
    first = from_sender.index(CanFrame(0x088, bytes(messages[0].data)))
    assert [(m.arbitration_id, m.is_extended_id, m.is_remote_frame, bytes(m.data)) for m in messages] == [
        (f.can_id, f.extended, f.remote, f.data) for f in from_sender[first:first + 3]], (
        "python-can got consecutive frames of the bus, none lost, none changed")
    assert [e.frame for e in room.bus.frames() if e.sender == "adapter"] == [CanFrame(0x321, b"\1\2\3")]
    assert [(m.id, m.data) for m in room.received if m.id == 0x321] == [(0x321, b"\1\2\3")]
    assert room.board.ecan.opmode.name == "CONFIGURATION", "python-can's shutdown sends C: the channel closes"


def test_an_adapter_opened_at_another_bit_rate_cannot_read_the_bus_and_disturbs_it():
    room = AdapterRoom()
    room.run(0.01)

    def pc_program(results: dict) -> None:
        with can.Bus(interface="slcan", channel=usb.port, bitrate=250000, sleep_after_open=0) as bus:
            results["message"] = bus.recv(timeout=0.3)

    with UsbCdc(room.board) as usb:
        results = with_python_can(room, usb, pc_program)
    assert results["message"] is None
    destroyed = [e for e in room.bus.trace if e.sender == "sender" and "adapter" in e.error]
    assert destroyed and "bit timing does not match the bus" in destroyed[0].error
