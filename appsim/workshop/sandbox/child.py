"""A student's firmware inside the grader's sandbox: it loads the file it is sent, says what it calls itself, and runs
main() with the board across two pipes: a register read the read-ahead cannot answer is a round trip, writes wait.

Only the firmware library is here (AN738, the C18 headers, the GLCD library), as a C build links it in; the simulator
and the checks stay with the grader, so nothing this process does to itself changes anything but its own behaviour.
"""
from __future__ import annotations

import builtins
import importlib
import json
import os
import resource
from collections.abc import Callable, Sequence
from pathlib import Path
from typing import Any

from appsim import errors
from appsim.chip.polling import PollingLoop, firmware_entry, firmware_site
from appsim.chip.sfr import ADDRESSES, HIGH_VECTOR, RUNNING_MCU, SFRNames, missing_routine
from appsim.errors import FirmwareError, NoInterruptRoutine
from appsim.firmware.identity import identity_of
from appsim.firmware.interrupts import routines
from appsim.firmware.loader import crash_message, load_source
from appsim.workshop.sandbox import protocol as wire
from appsim.workshop.sandbox.protocol import Channel

FOLDER = Path("/firmware")          # where the firmware's file would be: only its name is shown


class RemoteMCU(SFRNames):
    """What `current_mcu()` gives the firmware here: the board's PIC18F8680, in the grader, across the pipes.

    The batch is built in place behind room for its length, so a read is one write and one read of the pipes. Each
    read's answer brings a read-ahead (see PIC18F8680.read_ahead): until the firmware writes or spends its budget,
    nothing changes on the board, so a register it offers is read here, as PIC18F8680.read would read it, and the
    grader does that read afterwards, in order (a SERVED item). A write the read-ahead says the outcome of (a byte for
    a busy USART) goes on from there. Only a read that would park a polling loop goes out.

    Interrupts (see the protocol's notes): while the board may take one (`_live`), every write but a foretold one, a
    spend beyond the budget and an empty loop's wait go out and wait; an answer may be preceded by VECTOR, and then the
    firmware's routine runs here, at that point of the firmware, as the board's core would call it there.
    """

    sfr_addresses = ADDRESSES

    def __init__(self, channel: Channel):
        self._channel = channel
        self._pending = bytearray(wire.LENGTH.size) + wire.BATCH
        self._empty = len(self._pending)
        self.glcd = RemoteDisplay(self)
        self.access_ps = self.tcy_ps = 0
        self.routines: dict[int, Callable[[], None]] = {}   # the firmware's interrupt routines by vector
        self._live = False                              # INTCON.GIEH on the board: it may take an interrupt
        self._ahead: dict[int, int] | None = None       # address -> value, while the read-ahead holds
        self._after: dict[int, dict[int, int]] = {}     # written address -> the read-ahead after that write
        self._left_ps = 0                               # what the firmware may still spend before it runs out
        self._seen: set[int] = set()                    # read since the last change (a read again may be polling)
        self._loop = PollingLoop()                      # its sites: the board's, if current (PIC18F8680.loop)
        self._sites_current = False

    def read(self, address: int, site: int | None = None) -> int:
        ahead = self._ahead
        value = ahead.get(address) if ahead is not None else None      # what the read-ahead says it reads
        offered = value is not None and self._left_ps >= self.access_ps
        if offered and address not in self._seen:  # the first read since the change: where it comes from is no matter
            self._seen.add(address)
            return self._served(address, 0, value)  # type: ignore[arg-type]  # offered: not None
        place = firmware_site()
        judged = None                           # what the loop was, if the board may yet say it was no read again
        known = (address, place) in self._loop.sites
        again_here = (ahead is not None and address in self._seen) or known
        if again_here:
            if not self._sites_current:         # a read again: PIC18F8680._read_again's rule, judged here
                self._loop.changed()
                self._sites_current = True
            if not offered:                     # (one it offers, within its budget, is one for certain)
                judged = self._loop.mark()
            turned_on = self._loop.goes_on(address, place)
            if turned_on is not None:           # it turns on: a read that cannot park, at a site new to the board
                if offered:
                    return self._served(address, turned_on, value)  # type: ignore[arg-type]
                place = turned_on
        self._ahead = None                      # a read that would park (or that the read-ahead does not cover)
        self._pending += wire.READ_ITEM.pack(wire.READ, _address(address), place)
        self.flush()
        reply = os.read(self._channel.read_fd, 1 << 16)
        if len(reply) < 6 or reply[4:5] != wire.VALUE or wire.LENGTH.unpack_from(reply)[0] != len(reply) - 4:
            self._channel.push(reply)
            reply = wire.LENGTH.pack(0) + self.answer()
            if reply[4:5] != wire.VALUE:
                raise RuntimeError("the grader answered a register read with something else")
        woken, again = self._read_ahead(reply[6:])
        if judged is not None and not again:
            self._loop.restore(judged)          # the board changed before the read: it was no read again after all
        elif not again_here and again and not known and self._loop.look is not None:
            self._loop.end_look()               # a read again from a new place, as the board saw (PollingLoop.new_site)
        if woken:
            self._loop.woken(address, place)   # it parked, and was woken to see whether it counts
        return reply[5]

    def _read_ahead(self, data: bytes) -> tuple[bool, bool]:
        """Take a read-ahead; whether the read it answers ended a park that a look woke, and was a read again."""
        (self._left_ps, current, self._ahead, self._seen, sites, self._after, woken,
         again) = wire.decode_read_ahead(data)
        self._loop.sites, self._sites_current = sites, current
        return woken, again

    def _served(self, address: int, place: int, value: int) -> int:
        self._left_ps -= self.access_ps
        self._pending += wire.SERVED_ITEM.pack(wire.SERVED, address, place, value)
        if len(self._pending) > wire.BATCH_BYTES:
            self.flush()
        return value

    def write(self, address: int, value: int) -> None:
        address = _address(address)
        after = self._after.get(address) if self._ahead is not None else None
        if after is not None and self._left_ps >= self.access_ps:
            self._left_ps -= self.access_ps     # PIC18F8680.read_ahead: its time, a change, and these values after it
            after.pop(address, None)
            self._ahead, self._after, self._seen, self._sites_current = after, {}, set(), False
        else:
            after = self._ahead = None          # the board changes: what was read ahead no longer holds
        if address == wire.INTCON or (self._live and after is None):
            self._pending += wire.WRITE_ITEM.pack(wire.WRITE_WAIT, address, value & 0xFF)
            self.flush()
            self._go_on()
            return
        self._pending += wire.WRITE_ITEM.pack(wire.WRITE, address, value & 0xFF)
        if len(self._pending) > wire.BATCH_BYTES:
            self.flush()

    def spend_cycles(self, cycles: int) -> None:
        self._spend(cycles, wire.SPEND, wire.SPEND_WAIT)

    def wait_cycles(self, cycles: int) -> None:
        """A delay (PIC18F8680.wait_cycles): spent, and a change for polling, here as on the board: every register
        reads as not seen since, and the polling loop's sites start again (values the read-ahead foretold after a
        write no longer hold: on the board the write would come after a change)."""
        self._seen, self._sites_current, self._after = set(), False, {}
        self._spend(cycles, wire.DELAY, wire.DELAY_WAIT)        # a wait's answer brings a read-ahead after it

    def _spend(self, cycles: int, op: bytes, op_waits: bytes) -> None:
        if not isinstance(cycles, int) or cycles < 0:
            raise ValueError(f"instruction cycles are a whole number >= 0; got {cycles!r}")
        cycles = min(cycles, (1 << 64) - 1)
        if self._live and (self._ahead is None or cycles * self.tcy_ps > self._left_ps):
            self._ahead = None                  # the board may hand over, and vector, meanwhile
            self._pending += wire.SPEND_ITEM.pack(op_waits, cycles)
            self.flush()
            self._go_on()
            return
        if self._ahead is not None:
            self._left_ps -= cycles * self.tcy_ps
            if self._left_ps < 0:               # it reaches the next event: the board may change
                self._ahead = None
        self._pending += wire.SPEND_ITEM.pack(op, cycles)
        if len(self._pending) > wire.BATCH_BYTES:
            self.flush()

    def wait_for_interrupt(self, loop: str) -> None:
        """An empty waiting loop's turn (PIC18F8680.wait_for_interrupt, on the board): until an interrupt is taken."""
        self._ahead = None
        text = loop.encode()[:wire.MAX_LOOP].decode("utf-8", "ignore").encode()     # whole characters
        self._pending += wire.IDLE_HEAD.pack(wire.IDLE, len(text)) + text
        self.flush()
        self._go_on()

    def _go_on(self) -> None:
        """The answer to a WRITE_WAIT, SPEND_WAIT or IDLE: interrupts live or not, and a read-ahead."""
        reply = self.answer()
        if reply[:1] != wire.GO_ON or len(reply) < 2:
            raise RuntimeError("the grader answered a waiting access with something else")
        self._live = bool(reply[1])
        self._read_ahead(reply[2:])

    def _vector(self, reply: bytes) -> None:
        """VECTOR: the board's core takes an interrupt here; the firmware's routine runs, then RETFIE."""
        vector = reply[1]
        self._live = bool(reply[2])
        self._read_ahead(reply[3:])
        routine = self.routines.get(vector)
        if routine is None:
            raise NoInterruptRoutine(missing_routine(vector))
        routine()
        self._ahead = None                      # the answer it waits for next brings a fresh one
        self._pending += wire.RETFIE_ITEM.pack(wire.RETFIE, vector)
        self.flush()
        if vector == HIGH_VECTOR:
            self._live = True                   # RETFIE sets GIE/GIEH again (a low routine's sets GIEL)

    def display(self, item: bytes) -> None:
        self._ahead = None
        self._pending += item
        self.flush()
        self.answer()

    def flush(self) -> None:
        """Send the batch (if it holds anything)."""
        pending = self._pending
        if len(pending) > self._empty:
            wire.LENGTH.pack_into(pending, 0, len(pending) - wire.LENGTH.size)
            try:
                written = os.write(self._channel.write_fd, pending)
                while written < len(pending):
                    written += os.write(self._channel.write_fd, pending[written:])
            except OSError:
                os._exit(0)             # the grader went away
            del pending[self._empty:]

    def report(self, kind: bytes, text: str = "") -> None:
        """Tell the grader how the run ends (after the accesses still waiting in the batch)."""
        self.flush()
        if not self._channel.send(kind + text.encode()[:wire.MAX_TEXT]):
            os._exit(0)

    def answer(self) -> bytes:
        """The grader's answer to the access that ended the batch (an error the board raised, raised here); the
        interrupt routines the board vectors to before it answers run first."""
        while True:
            reply = self._channel.receive()
            if reply is None:
                os._exit(0)             # the grader ended this run
            if reply[:1] == wire.ERROR:
                name, text = json.loads(reply[1:])
                raise _error_class(name)(text)
            if reply[:1] != wire.VECTOR:
                return reply
            self._vector(reply)


class RemoteDisplay:
    """The board's GLCD as the GLCD library reaches it, across the socket (see appsim.chip.sfr.GLCDPort)."""

    def __init__(self, mcu: RemoteMCU):
        self._mcu = mcu

    def initial(self) -> None:
        self._mcu.display(wire.DISPLAY + bytes([wire.INITIAL]))

    def set_cursor(self, line: int, column: int) -> None:
        clamp = (1 << 63) - 1
        self._mcu.display(wire.CURSOR_ITEM.pack(wire.DISPLAY, wire.CURSOR, max(-clamp, min(line, clamp)),
                                                max(-clamp, min(column, clamp))))

    def write(self, codes: list[int]) -> None:
        shown = codes[:wire.TEXT_SHOWN]     # the screen shows 21 of them at most; the rest only moves the cursor on
        self._mcu.display(wire.TEXT_HEAD.pack(wire.DISPLAY, wire.TEXT, min(len(codes), wire.TEXT_LENGTH_MAX),
                                              len(shown)) + bytes(shown))


def _address(address: int) -> int:
    if not isinstance(address, int) or address not in wire.ADDRESSES:
        raise ValueError(f"the PIC18F8680's data memory has addresses 0x000..0xFFF; got {address!r}")
    return address


def _error_class(name: str) -> type[Exception]:
    found = errors.by_name(name) or getattr(builtins, name, None)
    return found if isinstance(found, type) and issubclass(found, Exception) else RuntimeError


def _limit(settings: dict[str, int]) -> None:
    with open("/proc/self/statm") as statm:
        size = int(statm.read().split()[0]) * os.sysconf("SC_PAGE_SIZE")
    cpu = settings["cpu_s"]
    for limit, value in ((resource.RLIMIT_AS, size + (settings["memory_mb"] << 20)),
                         (resource.RLIMIT_CPU, cpu), (resource.RLIMIT_NPROC, 0), (resource.RLIMIT_CORE, 0),
                         (resource.RLIMIT_FSIZE, settings["file_mb"] << 20), (resource.RLIMIT_NOFILE, 32),
                         (resource.RLIMIT_MEMLOCK, 0)):
        hard = value + 1 if limit == resource.RLIMIT_CPU else value     # SIGXCPU first, then SIGKILL
        try:
            resource.setrlimit(limit, (value, hard))
        except (ValueError, OSError):
            resource.setrlimit(limit, (min(value, resource.getrlimit(limit)[1]),) * 2)


def boot() -> None:
    """Load what every firmware imports (and what Demo1's imports), once, before any firmware is seen."""
    importlib.import_module("appsim.firmware")
    importlib.import_module("appsim.can.slcan")


def boot_c(options: Sequence[str] = (), state: bytes | None = None) -> bool:
    """Load the C translator and know the kit's headers (from `state`, which the grader made from them, else parsed
    here), once, before the first C firmware is forked: a submission in C pays for them once, one in Python never.
    Whether it loaded them now."""
    global _c_booted
    if _c_booted:
        return False
    c18 = importlib.import_module("appsim.firmware.c18")
    if state is not None:
        c18.adopt(state)
    c18.warm(options)                   # with the state: nothing left to do
    _c_booted = True
    return True


_c_booted = False


def main(settings: dict[str, Any], read_fd: int, write_fd: int) -> None:
    """One firmware's life in a fresh process: walled in, it says hello, receives its firmware, loads it, says what
    it calls itself, and runs main() when told. `settings` holds the limits and the seccomp filter (if any)."""
    channel = Channel(read_fd, write_fd, wire.MAX_FROM_GRADER)
    if settings.get("seccomp"):
        install_filter(bytes.fromhex(settings["seccomp"]))
    if not channel.send(wire.HELLO):
        return
    message = channel.receive()
    if message is None or message[:1] != wire.SOURCE:
        return
    (length,) = wire.NAME_LENGTH.unpack_from(message, 1)
    path = FOLDER / message[3:3 + length].decode()
    source = message[3 + length:]
    _limit(settings)
    mcu = RemoteMCU(channel)
    RUNNING_MCU.set(mcu)
    try:
        module = load_source(path, source, c_options=settings.get("c_options", ()))
    except FirmwareError as error:
        mcu.report(wire.LOAD_FAILED, str(error))
        return
    try:
        identity = identity_of(module)                  # what it calls itself, read as `appsim check` reads it
    except BaseException as error:                      # its module's own __getattr__ ran, and raised
        mcu.report(wire.LOAD_FAILED, crash_message(error, str(path)))
        return
    mcu.routines = routines(module)
    mcu.report(wire.LOADED, json.dumps(identity))
    go = channel.receive()
    if go is None or go[:1] != wire.GO:
        return
    mcu.access_ps, mcu.tcy_ps = wire.GO_TIMES.unpack_from(go, 1)
    try:
        module.main()
    except MemoryError:
        mcu.report(wire.OUT_OF_MEMORY)
    except SystemExit:
        mcu.report(wire.EXITED)
    except BaseException as error:      # KeyboardInterrupt too: it stops this firmware only
        mcu.report(wire.RAISED, crash_message(error, str(path)))
    else:
        mcu.report(wire.RETURNED)


def install_filter(program: bytes) -> None:
    """Refuse this process (and anything it starts) the system calls of `program` (isolation.seccomp_program), for
    good: PR_SET_NO_NEW_PRIVS, then PR_SET_SECCOMP. OSError if the kernel refuses."""
    import ctypes

    class SockFprog(ctypes.Structure):
        _fields_ = [("len", ctypes.c_ushort), ("filter", ctypes.c_void_p)]

    libc = ctypes.CDLL(None, use_errno=True)
    buffer = ctypes.create_string_buffer(program, len(program))
    fprog = SockFprog(len(program) // 8, ctypes.addressof(buffer))
    for call in ((PR_SET_NO_NEW_PRIVS, 1, 0, 0, 0),
                 (PR_SET_SECCOMP, SECCOMP_MODE_FILTER, ctypes.addressof(fprog), 0, 0)):
        if libc.prctl(*(ctypes.c_ulong(arg) for arg in call)) != 0:
            error = ctypes.get_errno()
            raise OSError(error, f"the kernel refused the sandbox's seccomp filter: {os.strerror(error)}")


PR_SET_NO_NEW_PRIVS, PR_SET_SECCOMP, SECCOMP_MODE_FILTER = 38, 22, 2


firmware_entry(main)                # it runs the firmware's main(), as a board's process does
