"""SLCAN (Lawicel): the protocol as pure functions, and python-can's own slcan bus on the simulated board."""
from __future__ import annotations

import re
import sys
import threading
import time
from pathlib import Path

import can
import pytest
import serial
from hypothesis import given, settings
from hypothesis import strategies as st

from appsim.board.app023 import APP023
from appsim.board.usbcdc import UsbCdc
from appsim.bus.realtime import WallClock
from appsim.bus.wire import Bus
from appsim.can.frame import CanFrame
from appsim.can.slcan import (
    BIT_RATES,
    Close,
    Nothing,
    Open,
    Query,
    SetBitRate,
    SlcanError,
    Timestamps,
    Transmit,
    encode_frame,
    parse_command,
    status_reply,
    transmit_reply,
)
from appsim.firmware import *
from appsim.sim import PS_PER_SECOND, Simulator

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
    ("S\u0664", "one digit 0..8"), ("t100\u0661AA", "hex digits"),            # SLCAN is ASCII: Arabic-Indic digits
])
def test_bad_commands_say_what_is_wrong(line, complaint):
    with pytest.raises(SlcanError, match=complaint):
        parse_command(line)


@settings(max_examples=2000)
@given(st.one_of(st.binary(max_size=40), st.from_regex(rb"\A[tTrRSZ][0-9A-Fa-f]{0,12}[0-9]?[0-9A-F ]{0,20}\Z")))
def test_any_line_is_a_command_or_an_error_that_says_what_is_wrong(line):
    try:
        command = parse_command(line)
    except SlcanError as error:
        assert str(error)
    else:
        assert isinstance(command, (SetBitRate, Open, Close, Query, Timestamps, Transmit, Nothing))


# ------------------------------------------------------------------ the Demo1 firmware as an SLCAN adapter

SOLUTION = Path(__file__).resolve().parent.parent / "solutions" / "demo1_monitor.py"


@pytest.fixture(params=["demo1_monitor.py", "demo1_monitor.c"])
def in_both_languages(request, monkeypatch):
    """The adapter as the Python solution and as its C twin (solutions/demo1_monitor.c)."""
    monkeypatch.setattr(sys.modules[__name__], "SOLUTION", SOLUTION.with_name(request.param))


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


def busy_sender(can_id):
    """A node at 125 kbit/s sending 8-byte frames (1.1 ms each) 0.5 ms apart: the bus is busy 2/3 of the time."""
    def main():
        CANInitialize(4, 10, 8, 4, 3, CAN_CONFIG_ALL_MSG)
        count = 0
        while True:
            if CANSendMessage(can_id, [count & 0xFF] * 8, 8, CAN_TX_PRIORITY_0):
                count += 1
            Delay1KTCYx(5)
    return main


class AdapterRoom:
    """A node sending 0x088, one receiving, and the Demo1 board with DSW2 switch 1 ON (SLCAN); with `busy`,
    a node that keeps the bus busy most of the time (opening the channel waits for the bus to be idle)."""

    def __init__(self, *, busy: bool = False):
        self.sim = Simulator()
        self.bus = Bus(self.sim)
        self.received = []
        APP023(self.bus, "sender").run(station(0x088, []))
        APP023(self.bus, "receiver").run(station(0x0F0, self.received, every_ms=10**9))
        if busy:
            APP023(self.bus, "busy").run(busy_sender(0x0AA))
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


@pytest.mark.usefixtures("in_both_languages")
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


@pytest.mark.usefixtures("in_both_languages")
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
    assert all(b - a in (52, 53) for a, b in zip(time_stamps, time_stamps[1:], strict=False)), "ms between 0x088 frames"


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
@pytest.mark.usefixtures("in_both_languages")
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


@pytest.mark.parametrize("transport", ["pty", "socket"])
@pytest.mark.usefixtures("in_both_languages")
def test_python_can_uses_the_adapter_after_a_program_flooded_it_at_full_speed_and_left(transport):
    room = AdapterRoom(busy=True)
    room.run(0.01)

    def pc_program(results: dict) -> None:
        with can.Bus(interface="slcan", channel=usb.url, bitrate=125000, sleep_after_open=0) as bus:
            results["version"] = bus.get_version(timeout=2)
            results["message"] = bus.recv(timeout=2)

    with UsbCdc(room.board, transport=transport) as usb:
        with serial.serial_for_url(usb.url) as flood:
            flood.write(b"O\rC\r" * 30 + bytes(range(256)))
        clock = WallClock(room.sim)            # the flooding program has left before python-can comes, as in a lab:
        clock.add_poller(usb.poll)             # on a pty, a program that opens the port as another closes it shares
        clock.run(0.5)                         # its stream (the kernel cannot tell them apart)
        results = with_python_can(room, usb, pc_program)
    assert results["version"] == (10, 13), "python-can got the adapter's version"
    assert results["message"] is not None and results["message"].arbitration_id in (0x088, 0x0AA)


@pytest.mark.usefixtures("in_both_languages")
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


# ------------------------------------------------------------------ whatever the PC writes, the adapter answers again

FRAME_LINE = rb"[tTrR][0-9A-F]{4,}\r"                         # a received frame (with or without a time stamp)
ANSWER = rb"\r|\a|[zZ]\r|V1013\r|NA023\r|F[0-9A-F]{2}\r"     # every answer the adapter gives


def answers(stream: bytes) -> list[bytes]:
    """The adapter's answers in what it sent, frame lines left out; everything it sent must be one or the other."""
    assert re.fullmatch(rb"(?:%s|%s)*" % (FRAME_LINE, ANSWER), stream), f"a torn or unknown line in {stream!r}"
    return [token for token in re.findall(rb"%s|%s" % (FRAME_LINE, ANSWER), stream)
            if not re.fullmatch(FRAME_LINE, token)]


class PcOnThePort:
    """The busy room's adapter on its USB-CDC pty, opened with pyserial; the simulation runs in this thread."""

    def __init__(self):
        self.room = AdapterRoom(busy=True)
        self.room.run(0.01)
        self.usb = UsbCdc(self.room.board)
        self.port = serial.Serial(self.usb.port, timeout=1)
        self.unfinished = b""                           # the line the adapter was sending when the run stopped
        self.received = 0

    def send(self, data: bytes, seconds: float) -> bytes:
        """Write `data` at once (the PC at full speed), run `seconds` past the time 19200 baud needs for it,
        polling the bridge every 1 ms as WallClock does; the lines the adapter finished meanwhile."""
        self.port.write(data)                           # at most a few kB: the pty takes them at once
        sim = self.room.sim
        end = sim.now + round((len(data) / 1920 + seconds) * PS_PER_SECOND)
        while sim.now < end:
            self.usb.poll()
            self.room.run(min(end - sim.now, PS_PER_SECOND // 1000) / PS_PER_SECOND)
        new = self.port.read(self.usb.to_pc - self.received)        # all the bridge passed on
        self.received += len(new)
        lines, self.unfinished = re.fullmatch(rb"(.*[\r\a])?(.*)", self.unfinished + new, re.DOTALL).groups(b"")
        return lines

    def __enter__(self) -> PcOnThePort:
        return self

    def __exit__(self, *exc: object) -> None:
        self.port.close()
        self.usb.close()


@pytest.mark.usefixtures("in_both_languages")
def test_the_adapter_answers_again_after_the_pc_wrote_while_it_opened_the_channel():
    """Opening and closing wait for the bus to be idle (1 to 3 ms here): L CR C CR takes the adapter longer than
    the 2 ms the PC takes to write it, so what waits fills the adapter's 32 bytes of RAM, then the USART's 2-byte
    FIFO, and the next byte overruns it (OERR). The adapter clears CREN and sets it, counts it, and refuses the
    spoiled command."""
    with PcOnThePort() as pc:
        sent = answers(pc.send(b"L\rC\r" * 30, seconds=0.1))
        firmware = pc.room.board.firmware
        assert firmware.usart_overruns > 0 and pc.usb.lost_to_board > 0, "the PC wrote faster than the adapter read"
        assert len(sent) < 60 and b"\a" in sent, "commands that lost bytes are refused with BELL, the rest answered"
        assert answers(pc.send(b"V\r", seconds=0.05)) == [b"V1013\r"]


# What can.Bus(interface="slcan", bitrate=125000) writes: set_bitrate() closes, sets the bit rate and no data bit
# rate, opens; then __init__ opens again. It reads none of the answers.
PYTHON_CAN_OPENS = b"C\rS4\r\rO\rO\r"


@pytest.mark.usefixtures("in_both_languages")
def test_what_python_can_writes_as_it_opens_the_channel_and_right_after_is_all_answered_on_a_busy_bus():
    """python-can writes its commands without reading the answers: it opens and asks for the version (or sends
    a frame) at once. Opening or closing waits for the busy bus to be idle, up to 3 ms, longer than the USART's
    FIFO holds (1 ms): the adapter moves what the USART receives into RAM meanwhile, so that no byte is lost
    wherever the bus is in its frames (1.1 ms) and gaps (0.5 ms) when the commands come."""
    with PcOnThePort() as pc:
        for start_us in range(0, 2000, 100):
            pc.room.run(start_us / 1_000_000)
            sent = answers(pc.send(PYTHON_CAN_OPENS + b"V\r", seconds=0.05))
            closing = b"\a" if start_us == 0 else b"\r"          # the first C finds the channel closed
            assert sent == [closing, b"\r", b"\r", b"\r", b"\a", b"V1013\r"], f"{start_us} us later"
        assert pc.room.board.firmware.usart_overruns == 0 and pc.usb.lost_to_board == 0


SLOW = ["O", "L", "C", "C\rO", "C\rL"]   # opening waits for the bus to be idle (about 1 to 3 ms here)
COMMANDS = st.one_of(
    st.sampled_from(SLOW),
    st.sampled_from(["V", "N", "F", "Z0", "Z1", "", "O1", "Z", "q"] + [f"S{n}" for n in range(10)]),
    st.builds(lambda i, data: f"t{i:03X}{len(data)}{data.hex().upper()}", st.integers(0, 0x7FF), st.binary(max_size=8)),
    st.builds(lambda i, data: f"T{i:08X}{len(data)}{data.hex().upper()}", st.integers(0, 0x1FFFFFFF),
              st.binary(max_size=8)),
    st.builds(lambda i, dlc: f"r{i:03X}{dlc}", st.integers(0, 0x7FF), st.integers(0, 8)),
    st.text("0123456789ABCDEFtTrRSOLCVNFZ\a\n \x00\xff", max_size=40),       # junk, and lines too long
)
# Bytes of any value, with the slow commands among them (random bytes alone rarely spell "O\r").
BYTES = st.lists(st.one_of(st.binary(max_size=8), st.sampled_from([f"{c}\r".encode() for c in SLOW])),
                 max_size=60).map(b"".join)


@settings(max_examples=25, deadline=None)
@given(st.lists(COMMANDS, max_size=40))
def test_every_command_is_answered_once_unless_its_bytes_were_lost_and_then_it_is_counted(commands):
    with PcOnThePort() as pc:
        written = b"".join(command.encode("latin-1") + b"\r" for command in commands)
        sent = answers(pc.send(written, seconds=0.3))
        overruns = pc.room.board.firmware.usart_overruns
        assert (pc.usb.lost_to_board > 0) == (overruns > 0), "bytes lost exactly when the firmware saw OERR"
        if overruns:
            assert len(sent) <= written.count(b"\r")
        else:
            assert len(sent) == written.count(b"\r"), "nothing lost: one answer per command"
        assert answers(pc.send(b"V\r", seconds=0.05)) == [b"V1013\r"]


@settings(max_examples=25, deadline=None)
@given(BYTES)
def test_after_any_bytes_at_full_speed_the_adapter_answers_a_well_formed_command(junk):
    with PcOnThePort() as pc:
        pc.send(junk, seconds=0.3)
        pc.send(b"\r", seconds=0.05)                  # ends whatever line the junk left open, as hosts do
        assert answers(pc.send(b"V\r", seconds=0.05)) == [b"V1013\r"]
        assert answers(pc.send(b"N\r", seconds=0.05)) == [b"NA023\r"]
