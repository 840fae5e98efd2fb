"""The PIC18F2550 USB-CDC bridge: the board's USART as a pty or a socket that pyserial opens."""
from __future__ import annotations

import logging
import os

import pytest
import serial

from appsim.board.app023 import APP023
from appsim.bus.wire import Bus
from appsim.firmware import *  # noqa: F403
from appsim.sim import PS_PER_SECOND, Simulator
from appsim.board.usbcdc import UsbCdc

LINK_19200 = (USART_TX_INT_OFF & USART_RX_INT_OFF & USART_ASYNCH_MODE & USART_EIGHT_BIT
              & USART_CONT_RX & USART_BRGH_HIGH, 129)


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


def board_running(main):
    """A board whose firmware has started (its USART is open before the PC sends anything)."""
    sim = Simulator()
    board = APP023(Bus(sim), "board")
    board.run(main)
    sim.run(until=PS_PER_SECOND // 1000)
    return sim, board


def run(sim, seconds, poll=None):
    """Run in 1 ms slices, polling the bridge between them (what WallClock does, minus the pacing)."""
    end = sim.now + round(seconds * PS_PER_SECOND)
    while sim.now < end:
        if poll is not None:
            poll()
        sim.run(until=min(end, sim.now + PS_PER_SECOND // 1000))


@pytest.mark.parametrize("transport", ["pty", "socket"])
def test_what_the_pc_writes_reaches_the_firmware_and_its_answer_comes_back(transport):
    sim, board = board_running(shouting_echo)
    with UsbCdc(board, transport=transport) as usb, serial.serial_for_url(usb.url, timeout=1) as port:
        port.write(b"hello, app023\r")
        port.flush()
        run(sim, 0.05, usb.poll)        # 14 bytes there and back at 19200 baud: 7.3 ms each way
        assert port.read(14) == b"HELLO, APP023\r"
        assert usb.lost_bytes == 0 and board.usb.lost == 0


def test_the_pty_is_a_serial_port_in_raw_mode_under_dev():
    sim, board = board_running(shouting_echo)
    with UsbCdc(board) as usb:
        assert usb.port.startswith("/dev/") and usb.url == usb.port and os.path.exists(usb.port)
        with serial.Serial(usb.port, 115200, timeout=1) as port:   # the baud rate a PC sets is ignored
            port.write(b"\r\n\x03\x7f")                # CR, LF, Ctrl-C, DEL: passed on untouched
            run(sim, 0.01, usb.poll)
            assert port.read(4) == b"\r\n\x03\x7f"


def test_bytes_the_pc_does_not_read_are_lost_counted_and_reported_never_silently(caplog):
    sim, board = board_running(chatter)
    sent = bytearray()
    board.usb.listeners.append(lambda byte, time_ps: sent.append(byte))
    with caplog.at_level(logging.WARNING, logger="appsim.board.usbcdc"), UsbCdc(board) as usb, \
            serial.Serial(usb.port, timeout=0.2) as port:
        run(sim, 12.0)                   # 23 kB at 19200 baud, the PC busy elsewhere: the kernel keeps ~20 kB
        kept = port.read(len(sent))
    assert usb.lost_bytes > 0 and len(kept) + usb.lost_bytes == len(sent)
    assert bytes(sent).startswith(kept), "what the PC gets is the oldest bytes, in order, with no hole"
    assert "not reading" in caplog.text and "lost" in caplog.text


def test_on_the_socket_bytes_are_lost_while_no_program_is_connected(caplog):
    sim, board = board_running(chatter)
    sent = []
    board.usb.listeners.append(lambda byte, time_ps: sent.append(byte))
    with caplog.at_level(logging.WARNING, logger="appsim.board.usbcdc"), UsbCdc(board, transport="socket") as usb:
        run(sim, 0.1)
        assert usb.lost_bytes == len(sent) > 0
        assert "no program is connected" in caplog.text
        with serial.serial_for_url(usb.url, timeout=1) as port:
            start = len(sent)
            run(sim, 0.05)
            assert port.read(len(sent) - start) == bytes(sent[start:]) and usb.lost_bytes == start
        run(sim, 0.01, usb.poll)         # the program left: the bridge notices, later bytes are lost again
        before = usb.lost_bytes
        run(sim, 0.01)
        assert usb.lost_bytes > before


def test_close_unplugs_the_bridge():
    sim, board = board_running(chatter)
    usb = UsbCdc(board)
    port = usb.port
    usb.close()
    run(sim, 0.01)
    assert not os.path.exists(port) and usb.lost_bytes == 0 and board.usb.listeners == []
    usb.close()                          # twice is harmless


def test_a_transport_that_does_not_exist_is_refused_with_the_choices():
    sim, board = board_running(chatter)
    with pytest.raises(ValueError, match="'pty'.*'socket'"):
        UsbCdc(board, transport="usb")
