"""The PIC18F2550 USB-CDC bridge: the board's USART as a pty or a socket that pyserial opens."""
from __future__ import annotations

import logging
import os
import re
import socket
import threading
import time

import pytest
import serial

from appsim.board.app023 import APP023
from appsim.board.usbcdc import LEFT, NOBODY, UsbCdc
from appsim.bus.wire import Bus
from appsim.chip import usart
from appsim.firmware import *
from appsim.sim import PS_PER_SECOND, Simulator, ps

LINK_19200 = (USART_TX_INT_OFF & USART_RX_INT_OFF & USART_ASYNCH_MODE & USART_EIGHT_BIT
              & USART_CONT_RX & USART_BRGH_HIGH, 129)
LINE = re.compile(rb"\d{8}\n")       # chatter's lines


def shouting_echo():
    """Firmware: every byte received goes back in upper case."""
    OpenUSART(*LINK_19200)
    while True:
        if DataRdyUSART():
            byte = ReadUSART()
            while BusyUSART():
                pass
            WriteUSART(ord(chr(byte).upper()))


def chatter():
    """Firmware: sends numbered lines forever, as fast as 19200 baud allows."""
    OpenUSART(*LINK_19200)
    number = 0
    while True:
        for byte in f"{number:08d}\n".encode():
            while BusyUSART():
                pass
            WriteUSART(byte)
        number += 1


def bridged(main, transport="pty"):
    """A board with its USB-CDC bridge plugged in, running `main` for 1 ms (its USART is open before the PC sends
    anything), and a list that gets every byte its USART sends."""
    sim = Simulator()
    board = APP023(Bus(sim), "board")
    sent = bytearray()
    board.usb.listeners.append(lambda byte, time_ps: sent.append(byte))
    usb = UsbCdc(board, transport=transport)
    board.run(main)
    sim.run(until=PS_PER_SECOND // 1000)
    return sim, board, usb, sent


def run(sim, seconds, poll=None):
    """Run in 1 ms slices, polling the bridge between them (what WallClock does, minus the pacing)."""
    end = sim.now + ps(seconds)
    while sim.now < end:
        if poll is not None:
            poll()
        sim.run(until=min(end, sim.now + PS_PER_SECOND // 1000))


def numbers(received: bytes) -> list[int]:
    """chatter's line numbers in what a program received: whole lines from the first byte, the last one perhaps
    still coming (the board was sending it when the run stopped)."""
    assert re.fullmatch(rb"(?:\d{8}\n)*\d{0,8}", received), f"a torn line in {received!r}"
    return [int(line) for line in LINE.findall(received)]


class RawProgram:
    """A PC program on the port through the kernel's own interface, never blocking (pyserial's write spins when the
    port is full): `write` says how much the port took."""

    def __init__(self, usb: UsbCdc):
        if usb.port is not None:
            self.fd = os.open(usb.port, os.O_RDWR | os.O_NOCTTY | os.O_NONBLOCK)
            self.socket = None
        else:
            self.socket = socket.socket()
            self.socket.setsockopt(socket.SOL_SOCKET, socket.SO_RCVBUF, 4096)    # a small buffer fills soon
            self.socket.connect(("127.0.0.1", int(usb.url.rsplit(":", 1)[1])))
            self.socket.setblocking(False)

    def write(self, data: bytes | memoryview) -> int:
        try:
            return os.write(self.fd, data) if self.socket is None else self.socket.send(data)
        except BlockingIOError:
            return 0

    def read(self) -> bytes:
        try:
            return os.read(self.fd, 100_000) if self.socket is None else self.socket.recv(100_000)
        except BlockingIOError:
            return b""

    def read_all(self, count: int) -> bytes:
        """The `count` bytes the bridge passed to this program: the kernel hands a pty's bytes to its reading side a
        little after the bridge wrote them (on a loaded machine, many ms), so this waits for them, 10 s at most."""
        got, ends = b"", time.monotonic() + 10
        while len(got) < count and time.monotonic() < ends:
            new = self.read()
            got += new
            if not new:
                time.sleep(0.001)
        assert len(got) == count, f"the bridge passed {count} bytes to the program, it read {len(got)}"
        return got

    def close(self) -> None:
        if self.socket is None:
            os.close(self.fd)
        else:
            self.socket.close()


@pytest.mark.parametrize("transport", ["pty", "socket"])
def test_what_the_pc_writes_reaches_the_firmware_and_its_answer_comes_back(transport):
    sim, board, usb, _ = bridged(shouting_echo, transport)
    with usb, serial.serial_for_url(usb.url, timeout=1) as port:
        port.write(b"hello, app023\r")
        port.flush()
        run(sim, 0.05, usb.poll)        # 14 bytes there and back at 19200 baud: 7.3 ms each way
        assert port.read(14) == b"HELLO, APP023\r"
        assert usb.lost_to_pc == usb.lost_to_board == 0


def test_the_pty_is_a_serial_port_in_raw_mode_under_dev():
    sim, board, usb, _ = bridged(shouting_echo)
    with usb:
        assert usb.port.startswith("/dev/") and usb.url == usb.port and os.path.exists(usb.port)
        with serial.Serial(usb.port, 115200, timeout=1) as port:   # the baud rate a PC sets is ignored
            port.write(b"\r\n\x03\x7f")                # CR, LF, Ctrl-C, DEL: passed on untouched
            run(sim, 0.01, usb.poll)
            assert port.read(4) == b"\r\n\x03\x7f"


def resident_bytes() -> int:
    """This process's memory in RAM now (Linux: /proc/self/statm)."""
    with open("/proc/self/statm") as statm:
        return int(statm.read().split()[1]) * os.sysconf("SC_PAGE_SIZE")


@pytest.mark.parametrize("transport", ["pty", "socket"])
def test_a_pc_writing_10_mb_and_never_reading_waits_and_memory_stays_bounded(transport):
    """Like a USB device that NAKs, the bridge takes the PC's bytes only as fast as 19200 baud carries them
    to the board: the PC's writes are held back, nothing piles up in the simulator. This board never reads
    them (its USART overruns: counted); the PC never reads the board's lines (counted when lost)."""
    sim, board, usb, sent = bridged(chatter, transport)
    data = memoryview(bytes(range(256)) * (10 * 2**20 // 256))        # 10 MB
    before, most = resident_bytes(), 0
    with usb:
        pc = RawProgram(usb)
        written = 0
        for ms in range(15_000):                                      # 15 s of simulated time
            written += pc.write(data[written:written + 65536])
            usb.poll()
            sim.run(until=sim.now + PS_PER_SECOND // 1000)
            if ms % 500 == 0:
                most = max(most, resident_bytes())
        pc.close()
    assert most - before < 10 * 2**20, f"the simulator's memory grew by {(most - before) / 2**20:.1f} MB"
    assert written < len(data) // 2, f"the PC wrote {written} bytes: its writes were not held back"
    assert usb.to_board > 15 * 1800 and usb.lost_to_board > usb.to_board - 100, (
        "the bridge passed what 19200 baud carries, and the board's USART, never read, lost nearly all of it")
    assert usb.to_pc + usb.lost_to_pc == len(sent), "every byte from the board reached the PC or was counted"


def test_bytes_the_pc_does_not_read_are_lost_counted_and_reported_never_silently(caplog):
    sim, board, usb, sent = bridged(chatter)
    with caplog.at_level(logging.WARNING, logger="appsim.board.usbcdc"), usb, \
            serial.Serial(usb.port, timeout=0.2) as port:
        run(sim, 12.0)                   # 23 kB at 19200 baud, the PC busy elsewhere: the kernel keeps ~20 kB
        port.timeout = 10                # the kernel hands the last of them to this side a little later
        kept = port.read(usb.to_pc)
        port.timeout = 0.2
        kept += port.read(1)             # and nothing more than the bridge says it passed
    assert usb.lost_to_pc > 0 and len(kept) == usb.to_pc and usb.to_pc + usb.lost_to_pc == len(sent)
    before = usb.why_lost[NOBODY]                  # sent before the PC opened the port
    assert kept == bytes(sent[before:before + len(kept)]), "then the oldest bytes, in order, with no hole"
    assert "not reading" in caplog.text and "lost" in caplog.text


@pytest.mark.parametrize("transport", ["pty", "socket"])
def test_while_no_program_has_the_port_open_bytes_are_lost_and_a_program_that_comes_gets_whole_lines(transport):
    sim, board, usb, sent = bridged(chatter, transport)
    with usb:
        run(sim, 0.1, usb.poll)
        assert usb.why_lost[NOBODY] == len(sent) > 0 and usb.to_pc == 0
        with serial.serial_for_url(usb.url, timeout=1) as port:
            run(sim, 0.1, usb.poll)
            got = numbers(port.read(usb.to_pc))                       # all the bridge passed to it
            assert got and got == list(range(got[0], got[-1] + 1)), "whole lines, none missing"


def test_two_programs_in_turn_on_the_socket_never_tear_a_line_nor_hand_over_its_tail():
    """One program at a time: the second waits while the first is served. When the first leaves in the middle
    of a line, the rest of that line is for nobody; the second gets whole lines the board began after."""
    sim, board, usb, sent = bridged(chatter, "socket")
    with usb:
        first = serial.serial_for_url(usb.url, timeout=0)
        second = serial.serial_for_url(usb.url, timeout=0)            # connected, waiting its turn
        run(sim, 0.1, usb.poll)
        seen = numbers(first.read(10_000))
        assert seen and second.read(10_000) == b"", "the second program gets nothing while the first is served"
        while sent.endswith(b"\n"):                                   # on until the board is in a line
            run(sim, 0.001, usb.poll)
        unfinished = sent.count(b"\n")                                # its number
        first.close()
        run(sim, 0.2, usb.poll)
        got = numbers(second.read(10_000))
        second.close()
    assert got and got[0] > unfinished and got == list(range(got[0], got[-1] + 1))
    assert usb.why_lost[LEFT] > 0, "the tail of the first program's line is counted as lost"


def test_an_answer_to_a_program_that_left_is_not_handed_to_the_next():
    sim, board, usb, sent = bridged(shouting_echo, "socket")
    with usb:
        with serial.serial_for_url(usb.url) as first:                 # writes and leaves without waiting
            first.write(b"first\r")
        with serial.serial_for_url(usb.url, timeout=0) as second:
            second.write(b"second\r")
            run(sim, 0.2, usb.poll)
            assert second.read(100) == b"SECOND\r"
    assert bytes(sent) == b"FIRST\rSECOND\r", "what the first wrote reached the board"
    assert usb.why_lost[LEFT] == 6, "its answer went to no program, and is counted"


def test_on_the_pty_a_program_never_gets_what_the_last_one_left_unread():
    sim, board, usb, sent = bridged(chatter)
    starts = []                                                        # (time, number) of each line the board began
    board.usb.listeners.append(lambda byte, time_ps: starts.append((time_ps, len(starts))) if byte == 0x0A else None)
    with usb:
        with serial.Serial(usb.port, timeout=0) as first:
            run(sim, 0.1, usb.poll)
            first.read(20)                                             # reads a little, leaves the rest unread
        run(sim, 0.1, usb.poll)
        opened = sim.now
        second = RawProgram(usb)                                       # (pyserial would flush the port on opening)
        passed = usb.to_pc
        run(sim, 0.1, usb.poll)
        got = numbers(second.read_all(usb.to_pc - passed))
        second.close()
    first_new_line = next(number + 1 for time_ps, number in starts if time_ps >= opened)
    assert got and got[0] >= first_new_line, "only lines the board began after the second program opened the port"


def test_what_a_program_writes_just_before_it_closes_the_port_still_reaches_the_board():
    sim, board, usb, sent = bridged(shouting_echo)
    with usb:
        with serial.Serial(usb.port) as port:                          # echo -e 'abc\r' > /dev/pts/N
            port.write(b"abc\r")
        run(sim, 0.05, usb.poll)
    assert bytes(sent) == b"ABC\r" and usb.why_lost[LEFT] == 4, "the answer had no program to go to"


def test_close_unplugs_the_bridge():
    sim, board, usb, sent = bridged(chatter)
    usb.close()
    before = len(sent), usb.to_pc, usb.lost_to_pc
    run(sim, 0.01)
    assert not os.path.exists(usb.port) and len(board.usb.listeners) == 1, "only the test's own listener is left"
    assert len(sent) > before[0] and (usb.to_pc, usb.lost_to_pc) == before[1:], "the board's bytes go nowhere"
    usb.close()                          # twice is harmless


def test_a_transport_that_does_not_exist_is_refused_with_the_choices():
    with pytest.raises(ValueError, match="'pty'.*'socket'"):
        UsbCdc(APP023(Bus(Simulator())), transport="usb")


@pytest.mark.parametrize("transport", ["pty", "socket"])
def test_after_the_run_the_port_lingers_until_its_program_closes_it_so_the_program_sees_no_error(transport):
    """What `appsim monitor` does when its run ends: closing our end under a program hangs the port up, and pyserial
    raises there (miniterm dies with a traceback); lingering, the program reads the notice and leaves in its time."""
    sim, board, usb, sent = bridged(chatter, transport)
    with usb:
        assert usb.linger("# over\r\n") == 0, "no program: nothing to wait for"
        port = serial.serial_for_url(usb.url, timeout=5)
        run(sim, 0.05, usb.poll)
        assert usb.in_use()
        read: list[bytes] = []

        def program():
            read.append(port.read_until(b"# over\r\n"))
            port.write(b"bye")                                         # after the run: reaches nothing
            port.flush()
            port.close()

        thread = threading.Thread(target=program)
        thread.start()
        assert usb.linger("# over\r\n") == 3
        thread.join(timeout=5)
    board_bytes = read[0].removesuffix(b"# over\r\n")
    assert board_bytes != read[0] and board_bytes.endswith(b"\n"), "the notice on a line of its own, at the end"
    assert numbers(board_bytes.removesuffix(b"\r\n")), "after the board's lines (the last one cut by the end)"


# ------------------------------------------------------------------ its UART reads the line as the terminal does

def sending(text: bytes, config: int, spbrg: int, gap_ms: int = 0):
    """Firmware: after 5 ms, sends `text` with its USART at `config`/`spbrg`, back to back or `gap_ms` apart."""
    def main():
        OpenUSART(config, spbrg)
        Delay10KTCYx(5)
        for byte in text:
            while BusyUSART():
                pass
            WriteUSART(byte)
            if gap_ms:
                Delay1KTCYx(10 * gap_ms)
        while True:
            Delay10KTCYx(100)
    return main


def through_the_bridge(main, seconds: float = 0.3) -> tuple[bytes, list[usart.Received], UsbCdc]:
    """What a program on the bridge's port reads of `main`'s output, what the notebook's terminal decodes of the same
    TX line (`usart.decode`, as `station.terminal()` does: bytes and framing errors), and the bridge."""
    sim = Simulator()
    board = APP023(Bus(sim), "board")
    line = []
    board.usb.listeners.append(lambda byte, time_ps: line.append(
        (time_ps - board.usart.frame_ps(), byte, board.usart.bit_ps())))
    usb = UsbCdc(board, transport="socket")
    with usb, serial.serial_for_url(usb.url, timeout=0.5) as port:
        run(sim, 0.001, usb.poll)               # the program is served before the board sends
        board.run(main)
        run(sim, seconds, usb.poll)
        got = port.read(usb.to_pc) if usb.to_pc else b""
    return got, usart.decode(line), usb


def shown(decoded: list[usart.Received]) -> bytes:
    return bytes(received.data for received in decoded)


FAST = (LINK_19200[0], 64)                                  # 38,462 baud: twice as fast as the bridge reads
SLOW = (LINK_19200[0] & USART_BRGH_LOW, 64)                 # 9,615 baud: half as fast
SLOWEST = (LINK_19200[0] & USART_BRGH_LOW, 255)             # 2,441 baud: a NUL holds the line low 3.7 ms, a break


def test_a_line_split_across_a_slow_firmwares_writes_reaches_the_program_whole_as_the_terminal_shows_it():
    text = b"0x088 DLC 5 01 02 03 01 FF\r\n"
    got, terminal, usb = through_the_bridge(sending(text, *LINK_19200, gap_ms=7))
    assert got == shown(terminal) == text and not usb.misread and usb.lost_to_pc == 0


@pytest.mark.parametrize("gap_ms", [0, 2])
def test_at_another_baud_rate_the_program_reads_the_garbage_the_terminal_shows(gap_ms):
    """At 38,462 baud the bridge's UART at 19,200 reads each frame over two of the board's: back to back, a byte's
    bits run into the next one's; 2 ms apart, the idle line does. The program gets what the terminal shows, either
    way, and the bridge counts every byte as misread."""
    text = b"APP023 CAN monitor\r\n"
    got, terminal, usb = through_the_bridge(sending(text, *FAST, gap_ms=gap_ms))
    assert got == shown(terminal) and got != text, (got, terminal)
    assert usb.misread == {38_462: len(text)}


def test_back_to_back_bytes_at_another_rate_run_into_each_other_on_the_port_too():
    """The same text, back to back and 2 ms apart, reads differently at 38,462 baud: the line as a whole decides
    (read byte by byte, each from its own start bit, both would read the same)."""
    text = b"APP023 CAN monitor\r\n"
    back_to_back, _, _ = through_the_bridge(sending(text, *FAST))
    apart, _, _ = through_the_bridge(sending(text, *FAST, gap_ms=2))
    assert back_to_back != apart


def test_at_half_the_rate_a_data_bit_is_taken_for_a_start_bit_on_the_port_as_in_the_terminal():
    """At 9,615 baud each of the board's bits lasts two of the bridge's: it reads a byte in the first half of the
    board's frame, and a falling edge among that frame's own data bits starts the next, so the program gets more
    bytes than the board sent, with framing errors, as the terminal shows."""
    text = b"\x55\x33\x0f"
    got, terminal, usb = through_the_bridge(sending(text, *SLOW, gap_ms=2))
    assert got == shown(terminal) and len(got) > len(text), (got, terminal)
    assert any(received.framing_error for received in terminal)
    assert usb.misread == {9_615: len(text)}


def test_a_break_a_nul_at_2441_baud_is_one_nul_with_a_framing_error_on_the_port_as_in_the_terminal():
    """The NUL holds the line low for 3.7 ms, 71 of the bridge's bits: it reads one 0x00 with its stop bit low (a
    framing error), then waits for the line to rise and fall again. The 'A' 5 ms later (0x41: start, 1, five 0s, 1,
    0) is two bytes of its own: 0x80 (its start bit, then bit 0 high), 0x00 with a framing error (bits 1..5, 2 ms
    low), 0x80 again (bit 7 low, then the stop bit)."""
    got, terminal, usb = through_the_bridge(sending(b"\x00A", *SLOWEST, gap_ms=5))
    assert got == shown(terminal) == b"\x00\x80\x00\x80", (got, terminal)
    assert [received.framing_error for received in terminal] == [True, False, True, False]
    assert usb.misread == {2_441: 2}
