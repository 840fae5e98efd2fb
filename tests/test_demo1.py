"""Demo1, the CAN monitor: what a PC reading the USB-CDC port sees, against what was on the bus."""
from __future__ import annotations

import os
import pty
import re
import subprocess
import sys
import threading
from pathlib import Path

import pytest
import serial

from appsim.board.app023 import APP023
from appsim.board.usbcdc import UsbCdc
from appsim.bus.wire import Bus
from appsim.chip.mcu import PIC18F8680
from appsim.chip.sfr import current_mcu
from appsim.firmware import *
from appsim.firmware.runtime import CALL_CYCLES
from appsim.sim import PS_PER_SECOND, Simulator

KIT = Path(__file__).resolve().parent.parent
SOLUTION = KIT / "solutions" / "demo1_monitor.py"
STARTER = KIT / "exercises" / "demo1_monitor.py"
CLASSROOM = (4, 10, 8, 4, 3)

# The documented line format (docs/monitor-format.md).
FRAME_LINE = re.compile(r"^ *(\d+\.\d{6})  0x([0-9A-F]{3}|[0-9A-F]{8})  (STD|XTD)  (DATA|RTR )  DLC (\d+)"
                        r"((?:  [0-9A-F]{2}(?: [0-9A-F]{2})*)?)$")
LOST_LINE = re.compile(r"^# lost (\d+) frames? \(queue full\)$")



def wait_tenths_of_ms(units: int) -> None:
    """What Delay1KTCYx(units) waits, for any count: C18's takes 1..255 (0 means 256), these waits are longer."""
    current_mcu().spend_cycles(CALL_CYCLES + 1_000 * units)

def sender(frames, *, start_ms: float, gap_ms: float):
    """Firmware sending `frames` (id, flags, data) one after the other, `gap_ms` apart."""
    def main():
        CANInitialize(*CLASSROOM, CAN_CONFIG_ALL_MSG)
        wait_tenths_of_ms(round(start_ms * 10))
        for can_id, flags, data in frames:
            while not CANSendMessage(can_id, data, len(data), flags):
                pass
            wait_tenths_of_ms(round(gap_ms * 10))
        while True:
            if CANIsRxReady():
                CANReceiveMessage()
    return main


class Classroom:
    """A bus at 125 kbit/s, senders, and the monitor board running Demo1 with its bridge."""

    def __init__(self, transport="pty", firmware=SOLUTION):
        self.sim = Simulator()
        self.bus = Bus(self.sim)
        self.board = APP023(self.bus, "monitor")
        self.board.run(firmware)
        self.usb = UsbCdc(self.board, transport=transport)

    def node(self, name, main):
        self.bus.attach(PIC18F8680(self.sim, name)).run(main)

    def run(self, seconds):
        self.sim.run_for(seconds)
        for process in self.sim.processes:
            assert process.failure is None, f"firmware {process.name} crashed:\n{process.failure_text}"


def read_while_running(classroom, port, seconds):
    """Run the simulation while a thread reads from the PC side, as a terminal would; the lines read."""
    received, done = bytearray(), threading.Event()

    def reader():
        while not done.is_set():
            received.extend(port.read(max(1, port.in_waiting)))

    thread = threading.Thread(target=reader)
    thread.start()
    try:
        classroom.run(seconds)
    finally:
        done.set()
        thread.join(timeout=5)
    # The kernel hands the pty's last bytes to the reading side a little later (a loaded machine: many ms later),
    # so read on until all the bridge passed has come, as a terminal left open would show it.
    passed = classroom.usb.to_pc
    port.timeout = 10
    received.extend(port.read(passed - len(received)))
    assert len(received) == passed, f"the bridge passed {passed} bytes, the port gave {len(received)}"
    text = received.decode("ascii")
    assert text.endswith("\r\n"), "each line ends in CR LF"
    return text.removesuffix("\r\n").split("\r\n")


def parse(line):
    match = FRAME_LINE.match(line)
    assert match, f"not a frame line in the documented format: {line!r}"
    time, ident, kind, what, dlc, data = match.groups()
    return (float(time), int(ident, 16), kind == "XTD", what == "RTR ", int(dlc),
            bytes.fromhex(data.replace(" ", "")))


def on_the_bus(event):
    frame = event.frame
    return frame.can_id, frame.extended, frame.remote, frame.dlc, frame.data


MIXED = [
    (0x088, CAN_TX_PRIORITY_0 & CAN_TX_STD_FRAME, [1, 2, 3, 2, 0x9A]),
    (0x1ABCDE00, CAN_TX_PRIORITY_0 & CAN_TX_XTD_FRAME, [0xAA]),
    (0x081, CAN_TX_PRIORITY_0 & CAN_TX_RTR_FRAME, [0] * 5),
    (0x7FF, CAN_TX_PRIORITY_0, []),
    (0x100, CAN_TX_PRIORITY_0, list(range(8))),
]


def test_the_monitor_prints_exactly_the_frames_on_the_bus_in_order_with_their_times():
    room = Classroom()
    room.node("a", sender(MIXED, start_ms=2, gap_ms=40))
    room.node("b", sender([(0x110 + k, CAN_TX_PRIORITY_0, [k, 0x55]) for k in range(5)], start_ms=3, gap_ms=35))
    with room.usb, serial.Serial(room.usb.port, timeout=0.05) as port:
        lines = read_while_running(room, port, 0.5)
    assert lines[0].startswith("# APP023 CAN monitor (Demo1)")
    printed = [parse(line) for line in lines[1:]]
    frames = room.bus.frames()
    assert len(frames) == 10 and len(room.bus.trace) == 10
    assert [p[1:] for p in printed] == [on_the_bus(e) for e in frames]
    # The monitor's clock is Timer1: its gaps between lines are the gaps between the frames' ends.
    for (time, *_), event in zip(printed, frames, strict=True):
        gap_monitor = time - printed[0][0]
        gap_bus = (event.end_ps - frames[0].end_ps) / PS_PER_SECOND
        assert abs(gap_monitor - gap_bus) < 50e-6
    # Listen-only: the monitor never ACKed anything.
    assert all("monitor" not in e.acked_by for e in frames)


def test_a_busy_bus_outruns_the_usart_and_the_monitor_says_how_many_frames_it_lost():
    room = Classroom()
    for n, base in enumerate((0x200, 0x300, 0x400)):      # three nodes sending back to back for ~40 ms
        room.node(f"busy{n}", sender([(base + k, CAN_TX_PRIORITY_0, [k] * 8) for k in range(16)],
                                     start_ms=2, gap_ms=0))
    with room.usb, serial.Serial(room.usb.port, timeout=0.05) as port:
        lines = read_while_running(room, port, 1.5)       # 48 frames; 17 lines take ~0.5 s at 19200 baud
    frames = [on_the_bus(e) for e in room.bus.frames()]
    assert len(frames) == 48
    # Walk the bus trace: each printed frame is the next one on the bus, after skipping exactly as
    # many as the preceding "# lost N frames" line says.
    position, lost_total = 0, 0
    for line in lines[1:]:
        lost = LOST_LINE.match(line)
        if lost:
            position += int(lost.group(1))
            lost_total += int(lost.group(1))
            continue
        assert parse(line)[1:] == frames[position], f"line {line!r} is not bus frame #{position}"
        position += 1
    assert position == len(frames), "printed frames + lost counts add up to every frame on the bus"
    assert lost_total > 0
    assert room.usb.lost_to_pc == room.usb.lost_to_board == 0


def test_the_socket_fallback_serves_the_same_lines_to_serial_for_url():
    room = Classroom(transport="socket")
    room.node("a", sender(MIXED, start_ms=2, gap_ms=30))
    room.node("b", sender([], start_ms=0, gap_ms=0))      # someone must ACK: the monitor never does
    assert room.usb.url.startswith("socket://127.0.0.1:") and room.usb.port is None
    with room.usb, serial.serial_for_url(room.usb.url, timeout=0.05) as port:
        lines = read_while_running(room, port, 0.3)
    assert [parse(line)[1:] for line in lines[1:]] == [on_the_bus(e) for e in room.bus.frames()]
    assert len(lines) == 1 + len(MIXED)


def test_the_starter_prints_frames_but_still_has_its_todos():
    """Unchanged, the starter runs its USART at 2.5 Mbaud (SPBRG 0) and ACKs frames (Normal mode)."""
    room = Classroom(firmware=STARTER)
    room.node("a", sender(MIXED[:2], start_ms=2, gap_ms=30))
    room.node("b", sender([], start_ms=0, gap_ms=0))
    room.run(0.2)
    assert room.board.usart.baud > 2_000_000
    assert room.bus.frames() and all("monitor" in e.acked_by for e in room.bus.frames()), (
        "without TODO 2 the monitor is in Normal mode and ACKs: it takes part in the bus it watches")
    room.usb.close()


def test_appsim_monitor_counts_the_bytes_lost_each_way_and_says_why():
    """The command a student runs: a PC program types at the monitor (which never reads its USART: all but the
    FIFO's two bytes are lost), reads a line, and leaves while lines keep coming (lost: no program to go to)."""
    command = subprocess.Popen([sys.executable, "-m", "appsim", "monitor", "--seconds", "2", "--transport", "socket"],
                               stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True,
                               env={**os.environ, "PYTHONUNBUFFERED": "1"})
    try:
        url = re.search(r"socket://127\.0\.0\.1:\d+", command.stdout.readline()).group()
        with serial.serial_for_url(url, timeout=5) as port:
            port.write(b"hello\r" * 10)
            line = port.read_until(b"\r\n").decode()
            assert line.endswith("\r\n") and (line.startswith("# ") or FRAME_LINE.match(line[:-2])), line
        out, err = command.communicate(timeout=30)
    finally:
        command.kill()
    assert command.returncode == 0 and "Traceback" not in err
    to_pc = re.search(r"board -> PC: (\d+) bytes, (\d+) of them lost \((.*)\)", out)
    assert to_pc and int(to_pc[2]) > 0 and "no program had the port open" in to_pc[3], out
    assert "PC -> board: 60 bytes, 58 of them lost (58: the board's USART did not take them" in out


def monitor(*argv: str, **popen) -> subprocess.Popen:
    return subprocess.Popen([sys.executable, "-m", "appsim", "monitor", *argv], stdout=subprocess.PIPE, text=True,
                            env={**os.environ, "PYTHONUNBUFFERED": "1"}, **popen)


def test_appsim_monitor_runs_your_own_demo1_and_its_summary_says_what_became_of_every_frame(tmp_path):
    """The summary separates frames lost on the CAN side from bytes lost on USB; a firmware that drops frames without
    a '# lost' line shows as frames neither listed nor said lost."""
    silent = tmp_path / "my_demo1.py"
    silent.write_text(SOLUTION.read_text().replace("        lost += 1\n", ""))
    runs = {}
    for name, argv in (("solution", ()), ("silent", ("--firmware", str(silent)))):
        command = monitor("--seconds", "3", "--transport", "socket", *argv, stderr=subprocess.PIPE)
        out, err = command.communicate(timeout=60)
        assert command.returncode == 0 and "Traceback" not in err, err
        runs[name] = out
    start = "the classroom (exercise 2) runs in real time for 3 s, then stops (--seconds to change; Ctrl-C stops"
    assert "Demo1 CAN monitor (the solution, demo1_monitor.py)" in runs["solution"] and start in runs["solution"]
    assert f"Demo1 CAN monitor ({silent})" in runs["silent"]
    summary = re.compile(r"(\d+) frames on the bus\n"
                         r"  (\d+) \(\d+%\) listed by the monitor on its serial port\n"
                         r"  (\d+) \(\d+%\) lost on the CAN side: (\d+) when its RAM queue was full \(its '# lost' "
                         r"lines\), (\d+) when RXB0 and RXB1 were full\n"
                         r"(    why: .*\n)?"
                         r"(?:  (\d+) \(\d+%\) neither listed nor said lost.*\n)?"
                         r"USB-CDC port socket")
    summaries = {name: summary.search(out) for name, out in runs.items()}
    frames, listed, lost, queue, ecan, why, neither = summaries["solution"].groups()
    assert int(frames) == 401 and int(listed) > 90 and int(lost) == int(queue) > 250 and ecan == "0"
    assert int(neither or 0) < 20
    assert re.fullmatch(r"    why: a frame's line is about \d+ bytes and the USART sends 1,923 bytes a second \(19,231 "
                        r"baud, 8N1\), so the monitor can list about 3\d frames a second, while the bus carried 13\d a "
                        r"second: its RAM queue fills, and it says '# lost N'\. That is the APP023's own limit, as on "
                        r"the real board, not a fault of the firmware \(docs/monitor-format\.md\)\n", why), why
    frames, listed, lost, queue, ecan, why, neither = summaries["silent"].groups()
    assert int(frames) == 401 and lost == "0" and int(neither) > 250, "dropped without a word: the summary says so"
    assert why is None, "nothing said lost, nothing to explain"


def test_appsim_monitor_shows_its_progress_on_a_terminal():
    main_end, terminal = os.openpty()
    command = monitor("--seconds", "2.5", "--transport", "socket", stderr=terminal)
    os.close(terminal)
    shown = bytearray()
    while True:
        try:
            chunk = os.read(main_end, 4096)
        except OSError:                        # EIO: the command has closed its end
            break
        if not chunk:
            break
        shown += chunk
    os.close(main_end)
    command.communicate(timeout=30)
    updates = re.findall(rb"\r +([\d.]+) / 2.5 s  ([\d,]+) frames on the bus: ([\d,]+) listed, ([\d,]+) lost on the "
                         rb"CAN side; USB: ([\d,]+) bytes lost", bytes(shown))
    assert len(updates) >= 2 and float(updates[-1][0]) >= 1.0 and int(updates[-1][2]) > 0, shown
    assert bytes(shown).endswith(b"\r\n"), "the line ends when the run does"


@pytest.mark.skipif(sys.platform == "win32", reason="a pty")
def test_miniterm_on_the_monitors_port_ends_without_a_traceback_when_the_monitor_ends():
    """The run ends while miniterm has the port open: the port stays, miniterm shows the notice, its user leaves with
    Ctrl-] (exit status 0), and only then does the monitor close the port."""
    command = monitor("--seconds", "2", stderr=subprocess.PIPE)
    port = re.search(r"/dev/pts/\d+", command.stdout.readline()).group()
    child, terminal = pty.fork()
    if child == 0:                                                     # miniterm needs a terminal of its own
        os.execv(sys.executable, [sys.executable, "-m", "serial.tools.miniterm", port, "19200"])
    shown, said = bytearray(), ""
    try:
        while "stays open until the program using it closes it" not in said:
            said += command.stdout.readline()
            assert command.poll() is None, said
        while b"# appsim monitor: the run ended at 2.0 s, nothing more comes" not in shown:
            shown += os.read(terminal, 4096)
        os.write(terminal, b"\x1d")                                    # Ctrl-]
        while True:
            try:
                chunk = os.read(terminal, 4096)
            except OSError:
                break
            if not chunk:
                break
            shown += chunk
        _, status = os.waitpid(child, 0)
        out, err = command.communicate(timeout=30)
    finally:
        command.kill()
        os.close(terminal)
    text = shown.decode(errors="replace")
    assert os.waitstatus_to_exitcode(status) == 0 and "Traceback" not in text and "--- exit ---" in text, text
    assert command.returncode == 0 and "Traceback" not in err
