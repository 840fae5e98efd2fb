"""The APP023's PIC18F2550 USB-CDC bridge: the board's USART as a serial port on the PC.

A pseudo-terminal (what `screen`, `miniterm` or pyserial open), or a TCP socket for `serial_for_url`.
"""
from __future__ import annotations

import logging
import os
import socket
import sys
from typing import Literal

from appsim.board.app023 import APP023
from appsim.sim import PS_PER_SECOND

log = logging.getLogger(__name__)

READ_CHUNK = 4096


class UsbCdc:
    """What the PC sees of `board.usb`: every byte the USART sends comes out of `port` (or `url`),
    and every byte the PC writes there goes to the USART's receiver when `poll()` runs.

    `transport="pty"` (Linux, macOS) gives `port`, a path such as `/dev/pts/7`; `transport="socket"`
    listens on 127.0.0.1 (a free port) and gives `url` = `socket://127.0.0.1:PORT` for pyserial's
    `serial.serial_for_url`. One PC program at a time; it may come and go.

    Call `poll()` between slices of simulated time (`WallClock.add_poller(usb.poll)`): the simulation
    must not run in another thread while it does. Bytes the PC does not read pile up in the kernel; when
    that buffer is full (or, on the socket, while no program is connected) they are lost, as behind a
    real bridge whose PC stopped reading: `lost_bytes` counts them and a warning says so.
    """

    def __init__(self, board: APP023, *, transport: Literal["pty", "socket"] = "pty"):
        if transport not in ("pty", "socket"):
            raise ValueError(f"transport is 'pty' (a serial port path) or 'socket' (socket://127.0.0.1:PORT), "
                             f"not {transport!r}")
        if transport == "pty" and sys.platform == "win32":
            raise OSError("Windows has no pseudo-terminals: use UsbCdc(board, transport='socket') and open its url")
        self.end = board.usb
        self.transport = transport
        self.lost_bytes = 0
        self.closed = False
        self._warned = False
        self.port: str | None = None
        if transport == "pty":
            self._master, self._slave = os.openpty()
            import tty                           # POSIX only: Windows takes the socket transport
            tty.setraw(self._slave)              # bytes pass untouched: no echo, no CR/LF translation
            os.set_blocking(self._master, False)
            self.port = os.ttyname(self._slave)
            self.url = self.port
        else:
            self._listener = socket.create_server(("127.0.0.1", 0))
            self._listener.setblocking(False)
            self._connection: socket.socket | None = None
            self.url = f"socket://127.0.0.1:{self._listener.getsockname()[1]}"
        self.end.listeners.append(self._from_board)

    # ------------------------------------------------------------------ board -> PC
    def _from_board(self, byte: int, time_ps: int) -> None:
        if self.closed:
            return
        if self.transport == "pty":
            try:
                os.write(self._master, bytes((byte,)))
            except BlockingIOError:
                self._lose(time_ps, "the PC is not reading the serial port and its buffer is full")
            return
        connection = self._connected()
        if connection is None:
            self._lose(time_ps, "no program is connected to the socket")
            return
        try:
            connection.send(bytes((byte,)))
        except BlockingIOError:
            self._lose(time_ps, "the program on the socket is not reading and its buffer is full")
        except OSError:
            self._hang_up()
            self._lose(time_ps, "the program on the socket went away")

    def _lose(self, time_ps: int, reason: str) -> None:
        self.lost_bytes += 1
        if not self._warned:
            self._warned = True
            log.warning("USB-CDC bridge: bytes from the board lost from %.6f s (simulated): %s. "
                        "lost_bytes counts them.", time_ps / PS_PER_SECOND, reason)

    # ------------------------------------------------------------------ PC -> board
    def poll(self) -> None:
        """Pass what the PC wrote since the last poll to the board's USART (one byte per byte time)."""
        if self.closed:
            return
        data = b""
        if self.transport == "pty":
            try:
                data = os.read(self._master, READ_CHUNK)
            except BlockingIOError:
                pass
        else:
            connection = self._connected()
            if connection is not None:
                try:
                    data = connection.recv(READ_CHUNK)
                    if not data:
                        self._hang_up()
                except BlockingIOError:
                    pass
                except OSError:
                    self._hang_up()
        if data:
            self.end.write(data)

    # ------------------------------------------------------------------ socket connections
    def _connected(self) -> socket.socket | None:
        """The PC program on the socket, accepting one that is waiting if none is connected."""
        if self._connection is None:
            try:
                self._connection, _ = self._listener.accept()
            except BlockingIOError:
                return None
            self._connection.setblocking(False)
            self._connection.setsockopt(socket.IPPROTO_TCP, socket.TCP_NODELAY, 1)
        return self._connection

    def _hang_up(self) -> None:
        if self._connection is not None:
            self._connection.close()
            self._connection = None

    # ------------------------------------------------------------------ life cycle
    def close(self) -> None:
        """Unplug the bridge: the port or socket goes away; the board's bytes go nowhere."""
        if self.closed:
            return
        self.closed = True
        self.end.listeners.remove(self._from_board)
        if self.transport == "pty":
            os.close(self._master)
            os.close(self._slave)
        else:
            self._hang_up()
            self._listener.close()
        if self.lost_bytes:
            log.warning("USB-CDC bridge closed; %d bytes from the board were lost", self.lost_bytes)

    def __enter__(self) -> UsbCdc:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()

    def __repr__(self) -> str:
        return f"UsbCdc({self.url}, lost_bytes={self.lost_bytes})"
