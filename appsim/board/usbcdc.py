"""The APP023's PIC18F2550 USB-CDC bridge: the board's USART as a serial port on the PC, one program at a time.

A pseudo-terminal (what `screen`, `miniterm` or pyserial open), or a TCP socket for `serial_for_url`.
"""
from __future__ import annotations

import logging
import os
import select
import socket
import sys
import time
from collections import Counter
from typing import Literal

from appsim.board.app023 import APP023
from appsim.chip.usart import LineReader
from appsim.sim import PS_PER_SECOND, Timer

if sys.platform != "win32":                  # Windows has no pseudo-terminals: it takes the socket transport
    import termios
    import tty

log = logging.getLogger(__name__)

OUT_ENDPOINT_BYTES = 64        # the PIC18F2550's CDC data OUT endpoint: the PC's bytes its UART has not sent yet
SOCKET_RECEIVE_BYTES = 4096    # what the kernel holds for the bridge of the socket program's writes
CR, LF = 0x0D, 0x0A
LINE_ENDS = b"\r\n\a"          # CR LF end a monitor line; CR or BELL end an SLCAN answer
LONGEST_LINE = 256             # bytes: the monitor's lines are under 70; more without an end (a wrong baud rate's
                               # garbage) is not a line
ANSWER_PS = PS_PER_SECOND // 20  # 50 ms: the board answers within this, and pauses no longer inside a line
LINGER_POLL_S = 0.05           # after the run: how often `linger` looks whether the program has closed the port

# Why bytes from the board reached no program.
NOBODY = "no program had the port open"
LEFT = "meant for a program that had left"
FULL = "the program was not reading and its buffer was full"
# Why bytes from the PC never reached the board.
NOT_TAKEN = "the board's USART did not take them (receiver off, or OERR: the firmware did not read RCREG in time)"
UNPLUGGED = "still in the bridge when it was unplugged"


class UsbCdc:
    """What the PC sees of `board.usb`: the board's USART bytes come out of `port` (or `url`), and what a PC
    program writes there goes to the USART's receiver at 19200 baud, as `poll()` takes it in.

    `transport="pty"` (Linux, macOS) gives `port`, a path such as `/dev/pts/7`; `transport="socket"`
    listens on 127.0.0.1 (a free port) and gives `url` = `socket://127.0.0.1:PORT` for pyserial's
    `serial.serial_for_url`.

    Like the PIC18F2550, the bridge holds at most one USB packet (64 bytes) of what the PC wrote and
    sends it to the board at 19200 baud; until it has room it takes nothing more (a USB device NAKs),
    so a PC that writes faster waits in its `write()`, and memory stays bounded whatever it writes.
    The board's link has no flow control: bytes the board's USART does not take (receiver off, or
    OERR because the firmware did not read RCREG in time) are lost, and `lost_to_board` counts them.

    Its UART (19200 8N1) reads the board's TX line as a whole, as it comes (`appsim.chip.usart.LineReader`, the rule
    the notebook's terminal decodes a run's line by): the board's bytes as sent when its USART runs at 19200 baud; at
    another rate what a real receiver reads there, garbage, framing errors and bytes running into each other, and
    `misread` counts the board's bytes it did not read as sent.

    One program at a time. It gets whole lines from the board, from the first line start after it came
    (a line is over at CR, LF or BELL, when the board has been silent for `ANSWER_PS`, or after `LONGEST_LINE` bytes);
    when its port
    is full, the rest of the line is dropped too. When it leaves, what it wrote still reaches the board
    (as a closing serial port drains), what it did not read is dropped, and the next program is served
    from the first line the board starts 50 ms (`ANSWER_PS`) after the last of those bytes: the answers
    were not for it. On the socket, programs that connect meanwhile wait their turn. (On the pty, two
    programs that have it open at once, or one that opens it as another closes it between two polls,
    share it, as they would share a real /dev/ttyACM0: the kernel cannot tell them apart.)
    Bytes from the board that no program got are lost: `lost_to_pc` counts them, `why_lost` says why.

    Call `poll()` between slices of simulated time (`WallClock.add_poller(usb.poll)`): the simulation
    must not run in another thread while it does.
    """

    def __init__(self, board: APP023, *, transport: Literal["pty", "socket"] = "pty"):
        if transport not in ("pty", "socket"):
            raise ValueError(f"transport is 'pty' (a serial port path) or 'socket' (socket://127.0.0.1:PORT), "
                             f"not {transport!r}")
        if transport == "pty" and sys.platform == "win32":
            raise OSError("Windows has no pseudo-terminals: use UsbCdc(board, transport='socket') and open its url")
        self.end = board.usb
        self.sim = board.mcu.sim
        self.transport = transport
        self._port: _Pty | _Socket = _Pty() if transport == "pty" else _Socket()
        self.port = self._port.port
        self.url = self._port.url
        self.to_pc = 0                         # bytes from the board that a PC program got
        self.why_lost: Counter[str] = Counter()  # bytes from the board that no program got, by reason
        self.to_board = 0                      # bytes from the PC the bridge took
        self._reader = LineReader(self.end.baud)   # the bridge's UART on the board's TX line
        self._reading: Timer | None = None     # when the line it is reading a byte from is known far enough
        self.closed = False
        self._unsent = 0                       # bytes from the PC still in the OUT endpoint when it was unplugged
        self._out = bytearray()                # the OUT endpoint
        self._uart: Timer | None = None        # the bridge's UART, sending the OUT endpoint's next byte to the board
        self._serving = False                  # a program is being served
        self._draining = False                 # it left: what it wrote is still being taken in
        self._skipping: str | None = None      # why the rest of the board's line goes to no program
        self._last = LF                        # the board's last byte: plugged in, it is taken to be between lines
        self._last_ps = self.sim.now           # and when it came
        self._line_bytes = 0                   # bytes since the last line end
        self._handover_ps = 0                  # no program is served before this (answers to the last one)
        self.end.listeners.append(self._from_board)

    @property
    def lost_to_pc(self) -> int:
        """Bytes the board sent that no PC program got (`why_lost` says why)."""
        return sum(self.why_lost.values())

    @property
    def misread(self) -> Counter[int]:
        """Bytes from the board its UART did not read as sent, by the board's baud rate."""
        return self._reader.misread

    @property
    def lost_to_board(self) -> int:
        """Bytes a PC program wrote that the board never received."""
        return self.end.lost + self._unsent

    # ------------------------------------------------------------------ board -> PC
    def _between_lines(self, time_ps: int) -> bool:
        """Whether the board's last line is over: it ended, or the board has been silent for ANSWER_PS."""
        return (self._last in LINE_ENDS or time_ps >= self._last_ps + ANSWER_PS
                or self._line_bytes >= LONGEST_LINE)

    def _from_board(self, sent: int, time_ps: int) -> None:
        """A byte's stop bit left the board's USART: the line is known up to now."""
        usart = self.end.usart
        self._reader.send((time_ps - usart.frame_ps(), sent, usart.bit_ps()))
        self._read(time_ps)

    def _read(self, until_ps: int) -> None:
        """What the bridge's UART has read of the board's TX line as known up to `until_ps` (`LineReader`: the line as
        a whole, as the terminal decodes it); it looks again when the byte it is reading is over, if the board is
        silent by then (else the board's next byte tells it)."""
        for read_ps, received in self._reader.read(until_ps):
            self._to_pc(received.data, read_ps)
        wants = self._reader.wants_ps
        if wants is not None and self._reading is None:
            self._reading = self.sim.call_at(wants + 1, self._look_again)

    def _look_again(self) -> None:
        self._reading = None
        usart = self.end.usart
        if usart.sending_since() is None or not self.end.connected:
            self._read(self.sim.now)
        else:                                   # its end tells; unless aborted (TXEN cleared): look after it anyway
            self._reading = self.sim.call_after(usart.frame_ps(), self._look_again)

    def _to_pc(self, byte: int, time_ps: int) -> None:
        starts_line = self._between_lines(time_ps) and not (self._last == CR and byte == LF)
        self._line_bytes = 0 if starts_line else self._line_bytes + 1
        self._last, self._last_ps = byte, time_ps
        if starts_line:
            if not (self._serving or self._draining):
                self._serve_next()
            self._skipping = None
        why: str | None
        if not self._serving:
            why = LEFT if self._draining or time_ps < self._handover_ps else NOBODY
        elif self._skipping:
            why = self._skipping
        else:
            why = self._port.write(byte)
            if why is None:
                self.to_pc += 1
                return
            if why == LEFT:
                self._serving, self._draining = False, True
            self._skipping = why               # the rest of the line is lost too: a program gets whole lines only
        self._lose(why, time_ps)

    def _lose(self, why: str, time_ps: int) -> None:
        if not self.why_lost[why]:
            log.log(logging.WARNING if why == FULL else logging.INFO,       # the others come and go as programs do
                    "USB-CDC bridge: bytes from the board lost from %.6f s (simulated): %s. why_lost counts them.",
                    time_ps / PS_PER_SECOND, why)
        self.why_lost[why] += 1

    # ------------------------------------------------------------------ PC -> board
    def poll(self) -> None:
        """Take in what the PC wrote, as far as the OUT endpoint has room; serve the next program in its turn."""
        if self.closed:
            return
        if self._serving or self._draining:
            room = OUT_ENDPOINT_BYTES - len(self._out)
            if room:
                data = self._port.read(room)
                if data:
                    self._take(data)
                elif self._draining or data is None:
                    self._left()
        if not (self._serving or self._draining) and self._between_lines(self.sim.now):
            self._serve_next()

    def _take(self, data: bytes) -> None:
        self._out += data
        self.to_board += len(data)
        if self._uart is None:
            self._send_to_board()

    def _send_to_board(self) -> None:
        """The bridge's UART: the OUT endpoint's next byte onto the board's RX line, the one after a frame later."""
        if not self._out:
            self._uart = None
            return
        self.end.write(self._out[:1])
        del self._out[0]
        frame = self.end.frame_ps()
        if not self._serving:                  # written by a program that left: what the board answers is its
            self._handover_ps = max(self._handover_ps, self.sim.now + frame + ANSWER_PS)
        self._uart = self.sim.call_after(frame, self._send_to_board)

    # ------------------------------------------------------------------ programs in turn
    def _serve_next(self) -> None:
        if self.sim.now >= self._handover_ps and self._port.take():
            self._serving = True
            self._skipping = NOBODY            # the line in progress began before the program came

    def _left(self) -> None:
        """The program left, and all it wrote is taken in: drop what it did not read; the next waits for its answers."""
        self._serving = self._draining = False
        self._port.drop()
        self._handover_ps = max(self._handover_ps, self.sim.now + ANSWER_PS)

    # ------------------------------------------------------------------ life cycle
    def in_use(self) -> bool:
        """Whether a program has the port open (on the socket: is connected and served)."""
        return not self.closed and self._port.in_use()

    def linger(self, notice: str = "") -> int:
        """The run is over: send `notice` to the program that has the port open, and keep the port until it closes it,
        as a bridge left plugged in would. Closing our end under it instead hangs the port up, and pyserial raises
        there (miniterm dies with a traceback). What the program writes meanwhile reaches nothing: the count of those
        bytes. Returns at once when no program has the port; Ctrl-C ends the wait."""
        if not self.in_use():
            return 0
        if notice and self._last != LF:
            notice = "\r\n" + notice          # after the line the board was sending
        for byte in notice.encode():
            if self._port.write(byte) is not None:
                break
        ignored = 0
        while (data := self._port.read(SOCKET_RECEIVE_BYTES)) is not None:
            ignored += len(data)
            if not data:
                time.sleep(LINGER_POLL_S)
        return ignored

    def report(self) -> str:
        """What crossed the bridge each way, and what was lost on the way, with why."""
        to_board = {NOT_TAKEN: self.end.lost, UNPLUGGED: self._unsent}
        misread = "".join(f"\n  {count:,} bytes from the board came at {baud:,} baud: the bridge's UART at "
                          f"{self.end.baud:,} baud misread them" for baud, count in self.misread.items())
        return (f"USB-CDC port {self.url}\n"
                f"  board -> PC: {_count(self.to_pc + self.lost_to_pc, self.why_lost)}\n"
                f"  PC -> board: {_count(self.to_board, to_board)}{misread}")

    def close(self) -> None:
        """Unplug the bridge: the port or socket goes away; the board's bytes go nowhere."""
        if self.closed:
            return
        self.closed = True
        self.end.listeners.remove(self._from_board)
        for timer in (self._uart, self._reading):
            if timer is not None:
                timer.cancel()
        self._unsent = len(self._out)
        self._out.clear()
        self._port.close()
        log.info("USB-CDC bridge closed. %s", self.report())

    def __enter__(self) -> UsbCdc:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()

    def __repr__(self) -> str:
        return f"UsbCdc({self.url}, lost_to_pc={self.lost_to_pc}, lost_to_board={self.lost_to_board})"


def _count(sent: int, lost: dict[str, int]) -> str:
    """`sent` bytes, how many of them were lost, and why."""
    reasons = "; ".join(f"{count}: {why}" for why, count in lost.items() if count)
    return f"{sent} bytes, {sum(lost.values())} of them lost" + (f" ({reasons})" if reasons else "")


class _Pty:
    """A pseudo-terminal: programs open `port`; POLLHUP on the master end says that none has it open."""

    def __init__(self) -> None:
        self._master, slave = os.openpty()
        tty.setraw(slave)                      # bytes pass untouched: no echo, no CR/LF translation
        self.port: str = os.ttyname(slave)
        self.url = self.port
        os.close(slave)                        # no end of ours stays open, so POLLHUP means no program
        os.set_blocking(self._master, False)
        self._poll = select.poll()
        self._poll.register(self._master, select.POLLIN)

    def _events(self) -> int:
        ready = self._poll.poll(0)
        return ready[0][1] if ready else 0

    def take(self) -> bool:
        """Whether there is a program to serve: one has the port open, or one left what it wrote."""
        events = self._events()
        return not events & select.POLLHUP or bool(events & select.POLLIN)

    def in_use(self) -> bool:
        """Whether a program has the port open."""
        return not self._events() & select.POLLHUP

    def read(self, size: int) -> bytes | None:
        """Up to `size` bytes the program wrote; None when none has the port open and nothing is left."""
        try:
            return os.read(self._master, size)
        except BlockingIOError:
            return b""
        except OSError:                        # EIO: no program has the port open and nothing is left to read
            return None

    def write(self, byte: int) -> str | None:
        """Pass one byte to the program: None if done, else why it was lost (LEFT: it has gone)."""
        if self._events() & select.POLLHUP:
            return LEFT
        try:
            os.write(self._master, bytes((byte,)))
        except BlockingIOError:
            return FULL
        return None

    def drop(self) -> None:
        """The program left: what it did not read is not for the next one (flushed on the port's side: the
        master's TCOFLUSH would leave what the line discipline already holds)."""
        try:
            slave = os.open(self.port, os.O_RDWR | os.O_NOCTTY | os.O_NONBLOCK)
        except OSError:                        # a program locked the port (TIOCEXCL): none other can open it
            return
        try:
            termios.tcflush(slave, termios.TCIFLUSH)
        finally:
            os.close(slave)

    def close(self) -> None:
        os.close(self._master)


class _Socket:
    """A TCP socket on 127.0.0.1 for pyserial's `socket://` URLs: one connection served, the others wait their turn."""

    def __init__(self) -> None:
        self._listener = socket.create_server(("127.0.0.1", 0))
        self._listener.setsockopt(socket.SOL_SOCKET, socket.SO_RCVBUF, SOCKET_RECEIVE_BYTES)  # connections inherit it
        self._listener.setblocking(False)
        self._connection: socket.socket | None = None
        self.port: str | None = None
        self.url = f"socket://127.0.0.1:{self._listener.getsockname()[1]}"

    def take(self) -> bool:
        """Whether there is a program to serve: the next connection waiting, accepted now."""
        try:
            self._connection, _ = self._listener.accept()
        except OSError:                        # none waiting (or it gave up before it was accepted)
            return False
        self._connection.setblocking(False)
        self._connection.setsockopt(socket.IPPROTO_TCP, socket.TCP_NODELAY, 1)
        return True

    def in_use(self) -> bool:
        """Whether a program is connected and served (those waiting their turn were never served)."""
        return self._connection is not None

    def read(self, size: int) -> bytes | None:
        """Up to `size` bytes the program wrote; None when it has gone and nothing is left."""
        assert self._connection is not None
        try:
            return self._connection.recv(size) or None
        except BlockingIOError:
            return b""
        except OSError:
            return None

    def write(self, byte: int) -> str | None:
        """Pass one byte to the program: None if done, else why it was lost (LEFT: it has gone)."""
        assert self._connection is not None
        try:
            self._connection.send(bytes((byte,)))
        except BlockingIOError:
            return FULL
        except OSError:
            return LEFT
        return None

    def drop(self) -> None:
        """The program left: close its connection (what it did not read goes with it)."""
        if self._connection is not None:
            self._connection.close()
            self._connection = None

    def close(self) -> None:
        self.drop()
        self._listener.close()
