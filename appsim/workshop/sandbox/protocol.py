"""The wire between the grader and a sandboxed firmware: length-prefixed messages on two pipes, decoded strictly.

The grader trusts nothing it reads here: `decode` turns a child's message into plain values or raises ProtocolError.
"""
from __future__ import annotations

import functools
import json
import os
import struct

from appsim.chip.sfr import HIGH_VECTOR, INTERRUPT_REGISTERS, LOW_VECTOR
from appsim.firmware.identity import LIMIT as identity_limit

LENGTH = struct.Struct("<I")
MAX_FROM_CHILD = 64 << 10           # a batch is flushed at BATCH_BYTES; texts are cut at MAX_TEXT
MAX_FROM_GRADER = 1 << 20           # the firmware's source, at most MAX_SOURCE
MAX_SOURCE = 512 << 10
BATCH_BYTES = 4096                  # writes and spends wait at most this long for the next read
MAX_TEXT = 8000                     # bytes of a message the child words itself (a traceback, a load error)
MAX_IDENTITY = 512

# Child to grader. Alone: HELLO (booted, waiting for its firmware), LOADED + JSON identity, LOAD_FAILED + text,
# RETURNED, RAISED + text, OUT_OF_MEMORY, EXITED. Or a BATCH of accesses: WRITE address:u16 value:u8, SPEND
# cycles:u64, DELAY cycles:u64 (time the firmware lets pass on purpose: PIC18F8680.wait_cycles, a change for polling)
# and SERVED address:u16 site:i64 value:u8 (a read the child answered from its read-ahead) items, ended by
# at most one item that waits for its answer, READ address:u16 site:i64 or DISPLAY op:u8 (INITIAL; CURSOR line:i64
# column:i64; TEXT length:u32 count:u16 codes:u8*count, the first `count` of the `length` codes written, count =
# min(length, TEXT_SHOWN): the screen shows at most 21 of them, the rest only moves the cursor on); or, where the
# board may take an interrupt (see Interrupts below), WRITE_WAIT address:u16 value:u8, SPEND_WAIT or DELAY_WAIT
# cycles:u64, IDLE
# length:u16 loop:utf-8 (an empty waiting loop, by its line: PIC18F8680.wait_for_interrupt), or RETFIE vector:u8
# (the routine the grader vectored to returns).
HELLO, LOADED, LOAD_FAILED, RETURNED, RAISED, OUT_OF_MEMORY, EXITED, BATCH = (
    b"H", b"L", b"F", b"E", b"X", b"M", b"Q", b"B")
WRITE, SPEND, DELAY, SERVED, READ, DISPLAY = b"W", b"S", b"Y", b"r", b"R", b"D"
WRITE_WAIT, SPEND_WAIT, DELAY_WAIT, IDLE, RETFIE = b"w", b"s", b"y", b"I", b"T"
INITIAL, CURSOR, TEXT = 0, 1, 2
# Grader to child: SOURCE name-length:u16 name source; GO access_ps:u64 tcy_ps:u64; VALUE value:u8 and a read-ahead
# (READ_AHEAD: budget_ps:u64 flags:u8 (CURRENT, WOKEN, JUDGED) entries:u16 sites:u16 writes:u8, then the entries'
# addresses (u16 each), their values (u8 each) and whether each was seen (u8 each), then sites x (address:u16 site:i64),
# then writes x (address:u16 and the entries' values after a write there, u8 each); see PIC18F8680.read_ahead); DONE
# (display); ERROR + JSON [class, text]; GO_ON live:u8 and a read-ahead (a WRITE_WAIT, SPEND_WAIT or IDLE done); VECTOR
# vector:u8 live:u8 and a read-ahead (run the routine at that vector now, then say RETFIE; the answer to the waiting
# access comes after).
SOURCE, GO, VALUE, DONE, ERROR, GO_ON, VECTOR = b"S", b"G", b"V", b"K", b"Z", b"O", b"J"

# Interrupts. `live` is INTCON.GIEH as the board has it: while it is 0 the board takes no interrupt, and only a write
# of INTCON (which waits: WRITE_WAIT) can change that, so the child batches as it always does. While it is 1, the
# board may vector wherever it hands over to events or a write changes it, so the child waits for the answer to each
# write (but one the read-ahead foretells), to a spend beyond its budget, and to its empty waiting loops; a served read
# and a spend within the budget cannot be interrupted. The child knows `live` from GO_ON and VECTOR, and from RETFIE:
# a high-priority routine's (or any, with RCON.IPEN = 0) sets GIEH again; a low-priority routine's leaves it as it is.
INTCON = INTERRUPT_REGISTERS["INTCON"]
VECTORS = (HIGH_VECTOR, LOW_VECTOR)
MAX_LOOP = 1024                     # bytes of an IDLE item's loop ("line 12 of ex6.py (`while not done:`)")

# A sandbox's zygote and the grader, on its control socket (one message a packet): FORK with the child's two pipe ends
# (SCM_RIGHTS), answered FORKED pid:i32 (as the sandbox numbers it); ENDED pid:i32 status:i32 cpu_s:f64 when a child
# ended (a signal as a negative status). HELLO once booted.
FORK, FORKED, ENDED = b"F", b"K", b"E"
FORK_C = b"C"       # FORK for a C firmware: the zygote loads the C translator and the kit's headers first, once
FORKED_MESSAGE = struct.Struct("<ci")
ENDED_MESSAGE = struct.Struct("<ciid")
MAX_CONTROL = 32
MAX_STATE = 16 << 20                # the kit headers' state a zygote may be handed at boot (about 50 kB)

WRITE_ITEM = struct.Struct("<cHB")
SERVED_ITEM = struct.Struct("<cHqB")
GO_TIMES = struct.Struct("<QQ")
READ_AHEAD = struct.Struct("<QBHHB")
# A read-ahead's flags: its sites are this change's; the read it answers ended a park that a look woke
# (PIC18F8680._park_polling: does the loop count?); that read was a read again with nothing changed on the board
# (PIC18F8680._read_again judged it), as the child took it to be, or else it undoes what it judged (PollingLoop.mark).
CURRENT, WOKEN, JUDGED = 1, 2, 4
READ_AHEAD_SITE = struct.Struct("<Hq")
WRITE_AHEAD = struct.Struct("<H")
SPEND_ITEM = struct.Struct("<cQ")
READ_ITEM = struct.Struct("<cHq")
IDLE_HEAD = struct.Struct("<cH")
RETFIE_ITEM = struct.Struct("<cB")
CURSOR_ITEM = struct.Struct("<cBqq")
LONE_READ = BATCH + READ            # how a batch of one READ begins, the most common message by far
LONE_READ_SIZE = 1 + READ_ITEM.size
TEXT_HEAD = struct.Struct("<cBIH")
TEXT_SHOWN = 64                     # codes of a text sent: appsim.board.glcd shows at most COLUMNS (21) of them
TEXT_LENGTH_MAX = (1 << 32) - 1
NAME_LENGTH = struct.Struct("<H")
ADDRESSES = range(0x1000)           # the PIC18F8680's data memory: 0x000..0xFFF


class ProtocolError(Exception):
    """A child's message that is not of this protocol (the grader's own words say so; the bytes are not shown)."""


# ====================================================================== framing, with a deadline on every wait

class Channel:
    """One end of a pair of pipes: whole messages out, whole messages in. Reads block: the grader puts a deadline on
    a child by ending it (see host.Watchdog), which closes the pipe and so ends the wait."""

    def __init__(self, read_fd: int, write_fd: int, limit: int):
        self.read_fd = read_fd
        self.write_fd = write_fd
        self.limit = limit
        self._buffer = bytearray()

    def send(self, message: bytes) -> bool:
        """False if the other end has gone."""
        data = LENGTH.pack(len(message)) + message
        try:
            written = os.write(self.write_fd, data)
            while written < len(data):
                data = data[written:]
                written = os.write(self.write_fd, data)
        except (BrokenPipeError, ConnectionResetError):
            return False
        return True

    def receive(self) -> bytes | None:
        """The next message; None once the other end closed. A length of 0 or over the limit is a ProtocolError."""
        buffer = self._buffer
        while True:
            if len(buffer) >= 4:
                (length,) = LENGTH.unpack_from(buffer)
                if not 0 < length <= self.limit:
                    raise ProtocolError(f"a message of {length} bytes (at most {self.limit} are allowed)")
                if len(buffer) >= 4 + length:
                    message = bytes(buffer[4:4 + length])
                    del buffer[:4 + length]
                    return message
            chunk = os.read(self.read_fd, 1 << 16)
            if not chunk:
                return None
            if not buffer and len(chunk) > 4 and len(chunk) == 4 + LENGTH.unpack_from(chunk)[0]:
                if len(chunk) - 4 > self.limit:         # the common case: one whole message in one read
                    raise ProtocolError(f"a message of {len(chunk) - 4} bytes (at most {self.limit} are allowed)")
                return chunk[4:]
            buffer += chunk

    def push(self, data: bytes) -> None:
        """Bytes already read from the pipe, to be taken before what comes next."""
        self._buffer[:0] = data

    def close(self) -> None:
        for fd in (self.read_fd, self.write_fd):
            try:
                os.close(fd)
            except OSError:
                pass


# ====================================================================== what a child may say

Access = tuple[bytes, int, int, int]     # (op, first, second, third argument), decoded
# Decoded display items carry their operation in the op: INITIAL, CURSOR (line, column), TEXT (length; the codes apart).
DISPLAY_INITIAL, DISPLAY_CURSOR, DISPLAY_TEXT = b"Di", b"Dc", b"Dt"
WAITING = frozenset((READ, WRITE_WAIT, SPEND_WAIT, DELAY_WAIT, IDLE, DISPLAY_INITIAL, DISPLAY_CURSOR, DISPLAY_TEXT))


def decode_batch(message: bytes) -> tuple[list[Access], bytes]:
    """A BATCH message's items, and the bytes that come with the item that ends it (a display TEXT's codes, an IDLE's
    loop). Only the last item may wait for an answer (READ, WRITE_WAIT, SPEND_WAIT, DELAY_WAIT, IDLE, a display item)
    or end a routine (RETFIE). ProtocolError if anything is off."""
    if len(message) == LONE_READ_SIZE and message.startswith(LONE_READ):
        _, address, site = READ_ITEM.unpack_from(message, 1)
        return [(READ, _address(address), site, 0)], b""
    items: list[Access] = []
    position, end = 1, len(message)
    try:
        while position < end:
            op = message[position:position + 1]
            if op == WRITE:
                _, address, value = WRITE_ITEM.unpack_from(message, position)
                if address == INTCON:
                    raise ProtocolError("a write of INTCON that did not wait for its answer")
                items.append((WRITE, _address(address), value, 0))
                position += WRITE_ITEM.size
            elif op == SPEND or op == DELAY:
                _, cycles = SPEND_ITEM.unpack_from(message, position)
                items.append((SPEND if op == SPEND else DELAY, cycles, 0, 0))
                position += SPEND_ITEM.size
            elif op == SERVED:
                _, address, site, value = SERVED_ITEM.unpack_from(message, position)
                items.append((SERVED, _address(address), site, value))
                position += SERVED_ITEM.size
            elif op == READ:
                _, address, site = READ_ITEM.unpack_from(message, position)
                items.append((READ, _address(address), site, 0))
                position += READ_ITEM.size
                break
            elif op == WRITE_WAIT:
                _, address, value = WRITE_ITEM.unpack_from(message, position)
                items.append((WRITE_WAIT, _address(address), value, 0))
                position += WRITE_ITEM.size
                break
            elif op == SPEND_WAIT or op == DELAY_WAIT:
                _, cycles = SPEND_ITEM.unpack_from(message, position)
                items.append((SPEND_WAIT if op == SPEND_WAIT else DELAY_WAIT, cycles, 0, 0))
                position += SPEND_ITEM.size
                break
            elif op == RETFIE:
                _, vector = RETFIE_ITEM.unpack_from(message, position)
                if vector not in VECTORS:
                    raise ProtocolError(f"a RETFIE from vector 0x{vector:02X}, where the PIC18 has no routine")
                items.append((RETFIE, vector, 0, 0))
                position += RETFIE_ITEM.size
                break
            elif op == IDLE:
                return [*items, (IDLE, 0, 0, 0)], _loop(message, position)
            elif op == DISPLAY:
                item, codes = _display(message, position)
                return [*items, item], codes
            else:
                raise ProtocolError(f"no access of kind {op!r}")
    except struct.error:
        raise ProtocolError("an access cut short") from None
    if position != end:
        raise ProtocolError("an access after one that waits for its answer")
    return items, b""


def _display(message: bytes, position: int) -> tuple[Access, bytes]:
    """A display item, which ends its batch, and the codes of a TEXT."""
    kind = message[position + 1] if position + 1 < len(message) else -1
    rest = len(message) - position
    if kind == INITIAL and rest == 2:
        return (DISPLAY_INITIAL, 0, 0, 0), b""
    if kind == CURSOR and rest == CURSOR_ITEM.size:
        _, _, line, column = CURSOR_ITEM.unpack_from(message, position)
        return (DISPLAY_CURSOR, line, column, 0), b""
    if kind == TEXT and rest >= TEXT_HEAD.size:
        _, _, length, count = TEXT_HEAD.unpack_from(message, position)
        if rest - TEXT_HEAD.size == count == min(length, TEXT_SHOWN):
            return (DISPLAY_TEXT, length, 0, 0), message[position + TEXT_HEAD.size:]
    raise ProtocolError("a display operation that is not one")


def _loop(message: bytes, position: int) -> bytes:
    """An IDLE item's loop, which ends its batch: as the loader words it, printable UTF-8 of at most MAX_LOOP bytes."""
    if len(message) - position < IDLE_HEAD.size:
        raise ProtocolError("an empty loop's wait cut short")
    _, length = IDLE_HEAD.unpack_from(message, position)
    loop = message[position + IDLE_HEAD.size:]
    if len(loop) != length or not 0 < length <= MAX_LOOP:
        raise ProtocolError("an empty loop's wait whose loop is not the length it says, or too long to be one")
    try:
        text = loop.decode("utf-8")
    except UnicodeDecodeError:
        raise ProtocolError("an empty loop's wait whose loop is not text") from None
    if not text.isprintable():
        raise ProtocolError("an empty loop's wait whose loop is not printable")
    return loop


def _address(address: int) -> int:
    if address not in ADDRESSES:
        raise ProtocolError(f"address 0x{address:X} is outside the PIC18F8680's data memory")
    return address


def decode_identity(data: bytes) -> dict[str, int]:
    """The LOADED message's identity: a JSON object of at most MESSAGE_ID1 and RTR_ID, small integers only."""
    if len(data) > MAX_IDENTITY:
        raise ProtocolError("an identity too long to be one")
    try:
        identity = json.loads(data)
    except (ValueError, RecursionError):
        raise ProtocolError("an identity that is not JSON") from None
    if not isinstance(identity, dict) or not set(identity) <= {"MESSAGE_ID1", "RTR_ID"}:
        raise ProtocolError("an identity with other names than MESSAGE_ID1 and RTR_ID")
    for value in identity.values():
        if type(value) is not int or not -identity_limit <= value <= identity_limit:
            raise ProtocolError("an identity whose values are not integers")
    return identity


def decode_text(data: bytes) -> str:
    """A text the child worded (a traceback, a load error): at most MAX_TEXT bytes, printable, as the grader quotes."""
    if len(data) > MAX_TEXT:
        raise ProtocolError(f"a text of {len(data)} bytes (at most {MAX_TEXT})")
    text = data.decode("utf-8", "replace")
    return "".join(c if c.isprintable() or c in "\n\t" else "\N{REPLACEMENT CHARACTER}" for c in text)


# ====================================================================== what the grader says

def source_message(name: str, source: bytes) -> bytes:
    encoded = name.encode()
    return SOURCE + NAME_LENGTH.pack(len(encoded)) + encoded + source


def vector_message(vector: int, live: bool, read_ahead: bytes) -> bytes:
    return VECTOR + bytes((vector, live)) + read_ahead


def go_on_message(live: bool, read_ahead: bytes) -> bytes:
    return GO_ON + bytes((live,)) + read_ahead


def read_ahead_message(budget_ps: int, current: bool, addresses: tuple[int, ...], values: bytes, seen: bytes,
                       sites: list[tuple[int, int]], after_writes: list[tuple[int, bytes]], woken: bool,
                       judged: bool) -> bytes:
    flags = (CURRENT if current else 0) | (WOKEN if woken else 0) | (JUDGED if judged else 0)
    return b"".join([READ_AHEAD.pack(budget_ps, flags, len(addresses), len(sites), len(after_writes)),
                     _addresses(len(addresses)).pack(*addresses), values, seen,
                     *(READ_AHEAD_SITE.pack(a, s) for a, s in sites),
                     *(WRITE_AHEAD.pack(a) + after for a, after in after_writes)])


def decode_read_ahead(data: bytes) -> tuple[int, bool, dict[int, int], set[int], set[tuple[int, int]],
                                            dict[int, dict[int, int]], bool, bool]:
    """The child's side: budget, current, {address: value}, the addresses read since the last change, the sites,
    {written address: {address: value}} after a write there, woken and judged."""
    budget, flags, count, site_count, write_count = READ_AHEAD.unpack_from(data)
    position = READ_AHEAD.size
    addresses = _addresses(count).unpack_from(data, position)
    position += 2 * count
    values = dict(zip(addresses, data[position:position + count], strict=True))
    seen = {a for a, was_seen in zip(addresses, data[position + count:position + 2 * count], strict=True) if was_seen}
    position += 2 * count
    sites = set(READ_AHEAD_SITE.iter_unpack(data[position:position + READ_AHEAD_SITE.size * site_count]))
    position += READ_AHEAD_SITE.size * site_count
    after_writes = {}
    for _ in range(write_count):
        (written,) = WRITE_AHEAD.unpack_from(data, position)
        position += WRITE_AHEAD.size
        after_writes[written] = dict(zip(addresses, data[position:position + count], strict=True))
        position += count
    return (budget, bool(flags & CURRENT), values, seen, sites, after_writes, bool(flags & WOKEN),
            bool(flags & JUDGED))


@functools.cache
def _addresses(count: int) -> struct.Struct:
    return struct.Struct(f"<{count}H")


def error_message(error: Exception) -> bytes:
    return ERROR + json.dumps([type(error).__name__, str(error)]).encode()
