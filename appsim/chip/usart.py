"""The PIC18F8680's USART in asynchronous mode at register level (TXSTA, RCSTA, SPBRG, TXREG, RCREG, BAUDCON, SPBRGH).

Bytes leave by the TX pin to the serial end the board wires it to, and arrive from it; appsim.firmware.usart (C18's
usart.h) drives it.
"""
from __future__ import annotations

import bisect
import functools
from collections import Counter, deque
from collections.abc import Callable, Iterable, Sequence
from typing import TYPE_CHECKING, NamedTuple

from appsim.chip.interrupts import Interrupts
from appsim.chip.sfr import (
    ABDEN,
    ADDEN,
    BRG16,
    BRGH,
    CREN,
    CSRC,
    FERR,
    INTERRUPT_REGISTERS,
    OERR,
    RCIDL,
    RCIF,
    RX9,
    RX9D,
    SCKP,
    SENDB,
    SPEN,
    SREN,
    SYNC,
    TRMT,
    TX9,
    TX9D,
    TXEN,
    TXIF,
    USART_REGISTERS,
    WUE,
)
from appsim.sim import PS_PER_SECOND, Timer

if TYPE_CHECKING:
    from appsim.chip.mcu import PIC18F8680

_TXSTA, _RCSTA, _TXREG, _RCREG, _SPBRG, _BAUDCON, _SPBRGH = (
    USART_REGISTERS[name] for name in ("TXSTA", "RCSTA", "TXREG", "RCREG", "SPBRG", "BAUDCON", "SPBRGH"))
_CSRC, _TX9, _TXEN, _SYNC, _SENDB, _BRGH, _TRMT, _TX9D = CSRC, TX9, TXEN, SYNC, SENDB, BRGH, TRMT, TX9D
_SPEN, _RX9, _SREN, _CREN, _ADDEN, _FERR, _OERR, _RX9D = SPEN, RX9, SREN, CREN, ADDEN, FERR, OERR, RX9D
_RCIDL, _SCKP, _BRG16, _WUE, _ABDEN = RCIDL, SCKP, BRG16, WUE, ABDEN
_PIR1 = INTERRUPT_REGISTERS["PIR1"]
_TXSTA_WRITABLE = 0xFD                      # all but TRMT
_RCSTA_WRITABLE = 0xF8                      # SPEN RX9 SREN CREN ADDEN; FERR OERR RX9D are read-only
_BAUDCON_WRITABLE = _SCKP | _BRG16 | _WUE | _ABDEN
FIFO_DEPTH = 2
PC_BAUD = 19_200                            # the link's setting on the PC side: 19200 N 8 1

class Received(NamedTuple):
    """A byte in the receive FIFO, with the status bits that go with it."""

    data: int
    ninth: bool
    framing_error: bool


class SerialEnd:
    """A device the board can wire the USART's TX and RX pins to (on the APP023: the PIC18F2550's USB-CDC, or
    CON9's RS-232), seen from the PC; `route` names it among the USART's ends.

    `listeners` are called with (byte, time_ps) when a byte's stop bit leaves the USART, if the pins are
    wired here. `write` sends bytes to the board at `baud` (8N1, back to back), starting at the
    caller's present simulated time; the USART samples each frame at its own baud rate, so a firmware
    with the wrong SPBRG receives garbage and framing errors, as with a real cable. Bytes that find
    the pins wired elsewhere, SPEN or CREN off, or the receiver blocked by an overrun are counted in `lost`.
    """

    def __init__(self, usart: USART, route: str, place: str, *, baud: int = PC_BAUD):
        if route in usart.ends:
            raise ValueError(f"the USART of {usart.mcu.name} already has an end named {route!r}")
        self.usart = usart
        self.route = route
        self.place = place
        self.baud = baud
        self.listeners: list[Callable[[int, int], None]] = []
        self.lost = 0
        self._line_free_ps = 0
        usart.ends[route] = self

    @property
    def connected(self) -> bool:
        """Whether the board wires the USART's pins to this end now."""
        return self.usart.wired_to() == self.route

    def bit_ps(self) -> int:
        return round(PS_PER_SECOND / self.baud)

    def frame_ps(self) -> int:
        """One 8N1 frame on the line: start bit, 8 data bits, stop bit."""
        return 10 * self.bit_ps()

    def write(self, data: bytes | bytearray) -> None:
        """Send `data` from the PC to the board's RX pin, one 8N1 frame after the other."""
        if not isinstance(data, (bytes, bytearray)):
            raise TypeError(f"{self.place}: write takes bytes (b'...'); got {data!r}")
        sim = self.usart.mcu.sim
        start = max(sim.time(), self._line_free_ps)
        for byte in data:
            sim.call_at(start, functools.partial(self.usart.frame_starts, self, byte))
            start += self.frame_ps()
        self._line_free_ps = start

    def __repr__(self) -> str:
        return f"<SerialEnd {self.place}: {'connected' if self.connected else 'not connected'}, lost {self.lost}>"


class USART:
    """The USART (EUSART) of one PIC18F8680 in asynchronous mode, a Peripheral on its SFR bus.

    Baud rate from SPBRG (SPBRGH:SPBRG when BAUDCON.BRG16 = 1) and BRGH, by the data sheet's formulas:
    Fosc / (64 (n + 1)), Fosc / (16 (n + 1)) with BRGH or BRG16, Fosc / (4 (n + 1)) with both. At 40 MHz,
    BRGH = 1 and SPBRG = 129 give 19230.8 baud: a frame (start, 8 data, stop) takes 520 µs.

    Transmit: a byte written to TXREG moves to the shift register (TSR) as soon as it is empty with
    SPEN = TXEN = 1; PIR1.TXIF reads 1 while TXEN = 1 and TXREG is empty, TXSTA.TRMT while the TSR is
    empty. TX9 = 1 makes frames 11 bits (the ends receive the 8 data bits). Clearing TXEN or SPEN aborts
    the byte being sent and empties TXREG.

    Receive (CREN = 1, SPEN = 1): a 2-byte FIFO behind the receive shift register. PIR1.RCIF reads 1
    while the FIFO holds a byte; RCSTA.FERR and RX9D belong to the byte at the top of the FIFO and
    reading RCREG pops it. A byte completing while the FIFO is full sets OERR and is lost; while OERR
    is set nothing more is received, until firmware clears CREN (which clears OERR), as on the chip.
    SREN has no effect in asynchronous mode, so a receiver opened with USART_SINGLE_RX receives nothing.

    Not simulated: synchronous mode (SYNC = 1 is refused with an error), address detection (ADDEN),
    break characters (SENDB), auto-baud (ABDEN), wake-up (WUE); BAUDCON.RCIDL always reads 1. TXIF and RCIF
    interrupt as the flags they are (appsim.chip.interrupts): TXIF while TXREG is empty, RCIF while a byte waits.
    """

    def __init__(self, mcu: PIC18F8680, interrupts: Interrupts):
        self.mcu = mcu
        self.ends: dict[str, SerialEnd] = {}
        # Which end the board wires TX and RX to now (its `route`), None for nowhere: the board sets it (DSW2).
        self.wired_to: Callable[[], str | None] = lambda: None
        self._txsta = 0
        self._rcsta = 0
        self._baudcon = 0
        self._spbrg = self._spbrgh = 0
        self._baud_rate_set()
        self._txreg: int | None = None          # a byte waiting in TXREG
        self._sending: Timer | None = None      # the TSR's byte, until its stop bit ends
        self._sending_since = 0                 # and when its start bit began
        self._fifo: deque[Received] = deque()
        self._last_read = 0
        self._overrun = False
        interrupts.provide(TXIF, lambda: bool(self._txsta & _TXEN) and self._txreg is None)
        interrupts.provide(RCIF, lambda: bool(self._fifo))
        self._interrupts = interrupts
        mcu.read_side_effects.add(_RCREG)
        mcu.quiet_writes[_TXREG] = self._fills_txreg

    # -------------------------------------------------------------- timing
    def bit_ps(self) -> int:
        """One bit at the baud rate SPBRG/SPBRGH, BRGH and BRG16 give (worked out when one of them is written)."""
        return self._bit_ps

    def _baud_rate_set(self) -> None:
        brg16, brgh = bool(self._baudcon & _BRG16), bool(self._txsta & _BRGH)
        divisor = 4 if brg16 and brgh else 16 if brg16 or brgh else 64
        n = (self._spbrgh << 8 | self._spbrg) if brg16 else self._spbrg
        self._bit_ps = divisor * (n + 1) * PS_PER_SECOND // self.mcu.fosc

    @property
    def baud(self) -> float:
        return PS_PER_SECOND / self.bit_ps()

    def frame_ps(self) -> int:
        """One transmitted frame: start, 8 (or 9) data bits, stop."""
        return (11 if self._txsta & _TX9 else 10) * self.bit_ps()

    # -------------------------------------------------------------- the SFR bus
    def read(self, address: int) -> int:
        if address == _TXSTA:
            return self._txsta | (0 if self._sending else _TRMT)
        if address == _RCSTA:
            top = self._fifo[0] if self._fifo else None
            return (self._rcsta | (_OERR if self._overrun else 0)
                    | (_FERR if top and top.framing_error else 0) | (_RX9D if top and top.ninth else 0))
        if address == _RCREG:
            if self._fifo:
                self._last_read = self._fifo.popleft().data
                self.mcu.changed()
            return self._last_read
        if address == _TXREG:
            return self._txreg or 0
        if address == _BAUDCON:
            return self._baudcon | _RCIDL
        return self._spbrg if address == _SPBRG else self._spbrgh

    def write(self, address: int, value: int) -> None:
        if address == _TXSTA:
            if value & _SYNC:
                raise ValueError("TXSTA.SYNC = 1 selects synchronous mode, which the APP023's link does not use "
                                 "and the simulator does not model: use USART_ASYNCH_MODE (19200 N 8 1)")
            self._txsta = value & _TXSTA_WRITABLE
            if not value & _TXEN:
                self._abort_transmit()
        elif address == _RCSTA:
            self._rcsta = value & _RCSTA_WRITABLE
            if not value & _CREN:
                self._overrun = False
            if not value & _SPEN:                   # the whole USART resets
                self._abort_transmit()
                self._fifo.clear()
                self._overrun = False
        elif address == _TXREG:
            self._txreg = value
        elif address == _BAUDCON:
            self._baudcon = value & _BAUDCON_WRITABLE
        elif address == _SPBRG:
            self._spbrg = value
        elif address == _SPBRGH:
            self._spbrgh = value
        if address in (_TXSTA, _BAUDCON, _SPBRG, _SPBRGH):
            self._baud_rate_set()
        self._load_shift_register()

    # -------------------------------------------------------------- transmit
    def sending_since(self) -> int | None:
        """When the frame leaving the TX pin now began (None: none is, TRMT): the line is known up to then."""
        return None if self._sending is None else self._sending_since

    def _fills_txreg(self) -> dict[int, int] | None:
        """What a write of TXREG changes, when the TSR is busy shifting a byte out: the byte only waits in TXREG, so
        PIR1.TXIF reads 0 and nothing else moves (PIC18F8680.quiet_writes). None when the TSR is empty: the byte
        would start a frame."""
        if self._sending is None:
            return None
        return {_PIR1: self._interrupts.pir1 & ~(1 << TXIF)}

    def _abort_transmit(self) -> None:
        if self._sending is not None:
            self._sending.cancel()
            self._sending = None
        self._txreg = None

    def _load_shift_register(self) -> None:
        """TXREG -> TSR when the TSR is empty and the transmitter enabled: the frame starts now."""
        enabled = self._txsta & _TXEN and self._rcsta & _SPEN
        if self._txreg is None or self._sending is not None or not enabled:
            return
        byte, self._txreg = self._txreg, None
        self._sending_since = self.mcu.sim.time()
        self._sending = self.mcu.sim.call_after(self.frame_ps(), lambda: self._sent(byte))
        self.mcu.changed()

    def _sent(self, byte: int) -> None:
        self._sending = None
        end = self.ends.get(self.wired_to() or "")
        if end is not None:
            for listener in list(end.listeners):
                listener(byte, self.mcu.sim.now)
        self._load_shift_register()
        self.mcu.changed()

    # -------------------------------------------------------------- receive
    def frame_starts(self, end: SerialEnd, byte: int) -> None:
        """A frame's start bit from `end` reaches RX now: sample it at the USART's own baud rate."""
        if not end.connected:
            end.lost += 1
            return
        ninth = bool(self._rcsta & _RX9)
        sampled = sample_frame(byte, end.bit_ps(), self.bit_ps(), 9 if ninth else 8)
        if sampled is None:                       # no start bit where the receiver looks for it
            end.lost += 1
            return
        data, last_data_bit, stop = sampled
        done = self.bit_ps() * (3 + 2 * (9 if ninth else 8)) // 2       # the middle of the stop bit
        received = Received(data & 0xFF, ninth and bool(last_data_bit), not stop)
        self.mcu.sim.call_after(done, lambda: self._received(end, received))

    def _received(self, end: SerialEnd, received: Received) -> None:
        if not (self._rcsta & _SPEN and self._rcsta & _CREN) or self._overrun:
            end.lost += 1
            return
        if len(self._fifo) == FIFO_DEPTH:
            self._overrun = True
            end.lost += 1
        else:
            self._fifo.append(received)
        self.mcu.changed()


Sent = tuple[int, int, int]
"""One 8N1 frame on a line: (start_ps, byte, bit_ps), the time its start bit begins, its byte, the sender's bit time."""


def _level(frames: Sequence[Sent], t: int) -> int:
    """The level of a line carrying `frames` (in time order, none overlapping) at `t`: high (1) when idle."""
    index = bisect.bisect_right(frames, (t, 256, 0)) - 1
    if index < 0:
        return 1
    start, byte, bit_ps = frames[index]
    bit = (t - start) // bit_ps
    return 0 if bit == 0 else (byte >> (bit - 1)) & 1 if bit <= 8 else 1


def _read_frame(level: Callable[[int], int], start: int, bit_ps: int, data_bits: int) -> tuple[int, int, int] | None:
    """A receiver at `bit_ps` reads a frame whose start bit's falling edge is at `start`: (data bits as a number, the
    last data bit, the stop bit), or None if the start bit is not low at its middle (a glitch, not a start)."""
    if level(start + bit_ps // 2):
        return None
    bits = [level(start + bit_ps // 2 + (i + 1) * bit_ps) for i in range(data_bits)]
    return (sum(bit << i for i, bit in enumerate(bits)), bits[-1],
            level(start + bit_ps // 2 + (data_bits + 1) * bit_ps))


def sample_frame(byte: int, sent_bit_ps: int, bit_ps: int, data_bits: int) -> tuple[int, int, int] | None:
    """What a receiver at `bit_ps` reads from one 8N1 frame sent at `sent_bit_ps` (line idle after it).

    Returns (data bits as a number, the last data bit, the stop bit), or None if the start bit is not
    seen low at its middle. At matching rates this is (byte, bit 7, 1).
    """
    return _read_frame(functools.partial(_level, [(0, byte, sent_bit_ps)]), 0, bit_ps, data_bits)


class LineReader:
    """A UART receiver at `baud` (8N1) reading a line as it is sent, as the PIC18F2550's reads the board's TX pin: from
    each falling edge once it is ready, it samples the bits at their middles; a stop bit read low is a framing error
    (the byte is kept, FERR set). At the sender's own rate that is every byte as sent; at another rate, garbage: a data
    bit of one byte may be taken for the start bit of the next, and back-to-back bytes run into each other.

    `send` gives it each frame the line carried, in time order; `read(until_ps)` what it has read of the line as known
    up to `until_ps` (nothing more began before then), with when it read each byte (its stop bit's middle).
    `wants_ps` is the time the line must be known past for the byte it is reading; `misread` counts the frames it did
    not read as sent (from their start bit, the byte, a stop bit), by the sender's baud rate. Memory: the frames not
    read yet, a few.
    """

    def __init__(self, baud: int = PC_BAUD):
        self.bit_ps = round(PS_PER_SECOND / baud)
        self.misread: Counter[int] = Counter()
        self._frames: list[Sent] = []               # not read yet, in time order, none overlapping
        self._edges: deque[tuple[int, int]] = deque()   # (time, frame) where the line may fall; frame -1: no start
        self._ready = 0                             # the receiver looks for a start edge from then on
        self._first = 0                             # the number of the first frame in `_frames`
        self._level = functools.partial(_level, self._frames)

    def send(self, frame: Sent) -> None:
        start, _, step = frame
        number = self._first + len(self._frames)
        self._frames.append(frame)
        self._edges.append((start, number))
        self._edges.extend((start + n * step, -1) for n in range(1, 9))

    @property
    def wants_ps(self) -> int | None:
        return self._edges[0][0] + self.bit_ps // 2 + 9 * self.bit_ps if self._edges else None

    def read(self, until_ps: int) -> list[tuple[int, Received]]:
        bit_ps, level, edges = self.bit_ps, self._level, self._edges
        received = []
        while edges:
            edge, number = edges[0]
            last = edge + bit_ps // 2 + 9 * bit_ps          # the stop bit's middle, its last sample
            if edge >= self._ready and last >= until_ps:
                break                                       # the line is not known that far yet
            edges.popleft()
            read = None
            frame = _read_frame(level, edge, bit_ps, 8) if edge >= self._ready and level(edge - 1) > level(edge) \
                else None                                   # a falling edge, and low at the start bit's middle
            if frame is not None:
                data, _, stop = frame
                read = Received(data, False, not stop)
                received.append((last, read))
                self._ready = edge + bit_ps * 19 // 2       # the middle of the stop bit
            if number >= 0:
                _, byte, step = self._frames[number - self._first]
                if read is None or read.data != byte or read.framing_error:
                    self.misread[round(PS_PER_SECOND / step)] += 1
        self._forget()
        return received

    def _forget(self) -> None:
        """Drop the frames the line's levels no longer need: those over before the next edge to look at."""
        frames = self._frames
        before = self._edges[0][0] - 1 if self._edges else None
        done = 0
        while done < len(frames) and (before is None or frames[done][0] + 9 * frames[done][2] <= before):
            done += 1
        if done:
            del frames[:done]
            self._first += done


def decode(frames: Iterable[Sent], baud: int = PC_BAUD) -> list[Received]:
    """What a UART receiver at `baud` (8N1) reads from a line that carried `frames` (none overlapping), as the
    PIC18F2550's reads the board's TX pin (`LineReader`, the whole line known)."""
    reader = LineReader(baud)
    for frame in sorted(frames):
        reader.send(frame)
    return [byte for _, byte in reader.read(1 << 62)]
