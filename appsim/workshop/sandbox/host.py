"""The grader's side of a sandboxed firmware: a child loads the file, the board runs its main(), each access crosses.

Every wait has a deadline; the grader's CPU time for it and the time it sleeps count against its limits (`usage`);
every message is decoded strictly; whatever the child does, it ends as a `Fault` of its own exercise and nothing else.
"""
from __future__ import annotations

import signal
import time

from appsim.chip.mcu import PIC18F8680
from appsim.chip.sfr import current_mcu
from appsim.errors import SandboxUnavailable
from appsim.firmware.glcd import NO_GLCD
from appsim.workshop.checks.trial import Fatal, Firmware
from appsim.workshop.faults import EXITED, RETURNED, Fault, FirmwareFault, stalled
from appsim.workshop.sandbox import protocol as wire
from appsim.workshop.sandbox.children import DEFAULT_LIMITS, Child, Limits, Sandbox
from appsim.workshop.sandbox.protocol import Access, ProtocolError
from appsim.workshop.sandbox.usage import Usage

__all__ = ["DEFAULT_LIMITS", "Limits", "Sandbox", "SandboxedFirmware"]

LONG_WAIT_S = 0.05                # a wait for the firmware this long is followed by a look at what it used
READ_AHEAD_REGISTERS = 16         # a read-ahead offers the registers read last, at most this many (Ex2 reads 10)
WRITE_AHEAD_REGISTERS = 4         # and what they read after a write of a register written last, for at most this many


# ====================================================================== a firmware file, run in a child

class SandboxedFirmware:
    """A firmware file's source, for `check()`: `load()` forks a child in its submission's sandbox that loads it, and
    the board runs its main() there. The first fault ends the run; `fault` keeps it. Call `close()` when the check is
    done."""

    def __init__(self, sandbox: Sandbox, name: str, source: bytes, limits: Limits = DEFAULT_LIMITS, *,
                 owner: object = None, spare: bool = False):
        self.sandbox = sandbox
        self.owner = owner              # the submission it belongs to: its exercises share a sandbox
        self.spare = spare              # whether to boot the next submission's sandbox meanwhile
        self.name = name
        self.source = source
        self.limits = limits
        self.deadline = time.monotonic() + limits.wall_s
        self.fault: Fault | None = None
        self.round_trips = 0
        self._child: Child | None = None
        self._usage: Usage | None = None
        self._error: Exception | None = None
        # The registers the firmware read last, most recent last: those a read-ahead offers (a polling loop's).
        self._reads: dict[int, None] = {}
        self._offer: tuple[int, ...] | None = None
        # The registers written last whose writes the board can tell the outcome of (PIC18F8680.quiet_writes); what
        # the last read-ahead said of them, at which board version; and what the child took from it at its write.
        self._writes: dict[int, None] = {}
        self._after: dict[int, bytes] = {}
        self._after_addresses: tuple[int, ...] = ()
        self._after_version = -1
        self._took: dict[int, int] | None = None

    # -------------------------------------------------------------- loading (checks.trial.Loadable)
    def load(self) -> Firmware:
        try:
            child = self._child = self.sandbox.take(self.deadline, self.owner, spare=self.spare,
                                                    c=self.name.lower().endswith(".c"))
        except SandboxUnavailable as error:
            raise Fatal(self._ends(Fault("grader", str(error)))) from None
        child.channel.send(wire.source_message(self.name, self.source))
        message = self._receive()
        if isinstance(message, Fault):
            raise Fatal(self._ends(message))
        kind, data = message[:1], message[1:]
        try:
            if kind == wire.LOADED:
                return Firmware(self._main, None, self.name, wire.decode_identity(data),
                                "c" if self.name.lower().endswith(".c") else "python")
            if kind == wire.LOAD_FAILED:
                raise Fatal(self._ends(Fault("load", f"the firmware does not load: {wire.decode_text(data)}")))
            ended = self._ending(kind, data)
            if ended is None:
                raise ProtocolError(f"a message of kind {kind!r} while loading")
            raise Fatal(self._ends(ended))
        except ProtocolError as error:
            raise Fatal(self._ends(_protocol(error))) from None

    def close(self) -> None:
        """End the child, wherever it is (a check that finished while the firmware waited for an answer)."""
        if self._child is not None:
            self._child.kill()
            self._child = None
        if self._usage is not None:
            self._usage.close()
            self._usage = None

    # -------------------------------------------------------------- running: the board's firmware process
    def _main(self) -> None:
        mcu = current_mcu()
        assert isinstance(mcu, PIC18F8680)
        process = mcu.process
        assert process is not None and self._child is not None
        process.watched = False         # the sandbox's own limits (stall_s, time_s) govern it, not the watchdog
        try:
            self._child.channel.send(wire.GO + wire.GO_TIMES.pack(mcu.access_ps, mcu.tcy_ps))
            fault = self._serve(mcu)
        except Exception as error:      # a fault of the grader's own, never the student's
            fault = Fault("grader", f"the grader failed while running this firmware: {type(error).__name__}: {error}")
        finally:
            self.close()
        raise FirmwareFault(self._ends(fault))

    def _serve(self, mcu: PIC18F8680) -> Fault:
        """Perform the child's accesses on `mcu` until it ends, or goes over a limit; how it ended."""
        assert self._child is not None
        self._usage = Usage(self._child.firmware_pid())
        return self._serve_loop(mcu, self._usage)

    def _serve_loop(self, mcu: PIC18F8680, usage: Usage) -> Fault:
        """The hot path, a lone register read, is done inline: one read and one write of the pipes, and the board.
        What the firmware used is looked at every 64 messages, and after each long wait for one."""
        child = self._child
        assert child is not None
        channel = child.channel
        monotonic = time.monotonic
        turns, now = 0, monotonic()
        while True:
            turns += 1
            if not turns & 0x3F or monotonic() - now > LONG_WAIT_S:
                fault = self._over(usage)
                if fault is not None:
                    return fault
            now = monotonic()
            message = self._receive(now)
            if isinstance(message, Fault):
                return message
            if len(message) == wire.LONE_READ_SIZE and message.startswith(wire.LONE_READ) and self._error is None:
                _, address, site = wire.READ_ITEM.unpack_from(message, 1)
                if address in wire.ADDRESSES:
                    try:
                        value = mcu.read(address, site)
                    except Exception as error:       # the firmware sees it raised, as on a local board
                        self._error = error
                    else:
                        self.round_trips += 1
                        self._recent(address)
                        if not channel.send(self._answer(mcu, value)):
                            return self._gone()
                        continue
            if message[:1] != wire.BATCH:
                try:
                    return self._ending(message[:1], message[1:]) or _protocol(
                        ProtocolError(f"a message of kind {message[:1]!r} while running"))
                except ProtocolError as error:
                    return _protocol(error)
            try:
                accesses, codes = wire.decode_batch(message)
            except ProtocolError as error:
                return _protocol(error)
            try:
                reply = self._perform(mcu, accesses, codes)
            except ProtocolError as error:
                return _protocol(error)
            if reply is not None:
                self.round_trips += 1
                if not channel.send(reply):
                    return self._gone()

    def _perform(self, mcu: PIC18F8680, accesses: list[Access], codes: bytes) -> bytes | None:
        """Do a batch on the board; the answer when it ends with an access that waits for one. An access the board
        refuses (an error from a peripheral) skips the rest of the batch and is raised in the child at its answer."""
        value = 0
        for op, first, second, third in accesses:
            if op is wire.SERVED:
                if self._error is None:
                    self._replay(mcu, first, second, third)
                continue
            if self._error is None:
                try:
                    if op is wire.READ:
                        value = mcu.read(first, second)
                        self._recent(first)
                    elif op is wire.WRITE:
                        self._took = self._taken(mcu, first)
                        mcu.write(first, second)
                    elif op is wire.SPEND:
                        mcu.spend_cycles(first)
                    else:
                        _display(mcu, op, first, second, codes)
                except Exception as error:       # the firmware sees it raised, as on a local board
                    self._error = error
            if op is wire.READ or op[:1] == wire.DISPLAY:
                if self._error is not None:
                    reply, self._error = wire.error_message(self._error), None
                    return reply
                return self._answer(mcu, value) if op is wire.READ else wire.DONE
        return None

    def _recent(self, address: int) -> None:
        if _remember(self._reads, address, READ_AHEAD_REGISTERS):
            self._offer = None

    def _offered(self) -> tuple[int, ...]:
        """The registers a read-ahead offers: one tuple while they stay the same (see PIC18F8680.read_ahead)."""
        if self._offer is None:
            self._offer = tuple(self._reads)
        return self._offer

    def _answer(self, mcu: PIC18F8680, value: int) -> bytes:
        """A read's answer, with what the firmware may read next without asking (see PIC18F8680.read_ahead)."""
        ahead = mcu.read_ahead(self._offered(), self._writes)
        self._after, self._after_addresses = dict(ahead.after_writes), ahead.addresses
        self._after_version, self._took = mcu.version, None
        return wire.VALUE + bytes((value & 0xFF,)) + wire.read_ahead_message(*ahead)

    def _taken(self, mcu: PIC18F8680, address: int) -> dict[int, int] | None:
        """Before a write of `address`: the values the child may go on with after it, if the last read-ahead told them
        and the board has not changed since (for `_replay` to tell the grader's mistake from the child's)."""
        if address in mcu.quiet_writes:
            _remember(self._writes, address, WRITE_AHEAD_REGISTERS)
        after = self._after.pop(address, None) if self._after_version == mcu.version else None
        self._after = {}
        return None if after is None else dict(zip(self._after_addresses, after, strict=True))

    def _replay(self, mcu: PIC18F8680, address: int, site: int, used: int) -> None:
        """A read the child answered from its read-ahead, done on the board as it would have been asked: it must
        neither park nor hand over, and must give what the child used. The read-ahead allows nothing else, so a
        served read that does is not one (a ProtocolError); checks and grade agreeing is tested on every solution."""
        process = mcu.process
        assert process is not None
        expected = process.local_time + mcu.access_ps
        value = mcu.read(address, site)
        self._recent(address)
        if value != used or process.local_time != expected:
            if self._took is not None and self._took.get(address) == used:
                raise RuntimeError(f"its read-ahead said register 0x{address:03X} would read {used} after a write, "
                                   f"where the board reads {value} (a mistake of the simulator's, not the firmware's)")
            raise ProtocolError(f"a read of register 0x{address:03X} it answered itself with {used}, where the "
                                f"board reads {value}" + ("" if process.local_time == expected else
                                                          ", at a time the board had moved on from"))

    # -------------------------------------------------------------- endings
    def _receive(self, now: float | None = None) -> bytes | Fault:
        """The child's next message, or the fault that came instead (time, stall, its end, a broken message); `now` is
        time.monotonic() if the caller has just read it."""
        child = self._child
        assert child is not None
        child.expires_at = min(self.deadline, (time.monotonic() if now is None else now) + self.limits.stall_s)
        try:
            message = child.channel.receive()
        except ProtocolError as error:
            return _protocol(error)
        if message is not None:
            return message
        if child.expired:
            return self._time() if time.monotonic() >= self.deadline else stalled(self.limits.stall_s)
        return self._gone()

    def _ending(self, kind: bytes, data: bytes) -> Fault | None:
        """The fault a child's closing message says (ProtocolError if it is not one), or None if it is none."""
        if kind == wire.RETURNED:
            return RETURNED
        if kind == wire.RAISED:
            return Fault("exception", wire.decode_text(data))
        if kind == wire.OUT_OF_MEMORY:
            return Fault("memory", f"memory limit: the firmware needed more than {self.limits.memory_mb} MB")
        if kind == wire.EXITED:
            return EXITED
        return None

    def _gone(self) -> Fault:
        """The child's end closed without saying why: it exited, a limit stopped it, or it closed its pipes."""
        child = self._child
        assert child is not None
        ended = child.ended(1.0)
        if ended is None:                   # it closed its pipes and lives on: its run is over all the same
            child.kill()
            return Fault("exited", "the firmware's process closed its link to the board: firmware never does that; "
                                   "main() loops forever, as main() does in EX1.C")
        status, cpu_s = ended
        if status in (-signal.SIGXCPU, -signal.SIGKILL) and cpu_s >= child.cpu_limit_s - 1:
            return Fault("time", f"CPU time limit: the firmware computed for more than {self.limits.time_s:g} s "
                                 "in its own process")
        if status == -signal.SIGSYS:
            return Fault("forbidden", "the firmware made a system call of another ABI (32-bit or x32), which the "
                                      "sandbox stops at once")
        return EXITED

    def _over(self, usage: Usage) -> Fault | None:
        """The limit the firmware has gone over, if any: the grader's CPU time, or its time asleep in all."""
        used = usage.used()
        if used.grader_cpu > self.limits.time_s:
            return self._cpu_time()
        if used.idle is not None and used.idle > self.limits.stall_s:
            return Fault("stalled", f"the firmware slept: more than {self.limits.stall_s:g} s in all went by with "
                                    "the board waiting for it while it neither computed nor touched a register")
        return None

    def _time(self) -> Fault:
        return Fault("time", f"time limit: the exercise took more than {self.limits.wall_s:g} s of wall time, loading "
                             "and running; firmware this slow would not keep up with the bus")

    def _cpu_time(self) -> Fault:
        return Fault("time", f"CPU time limit: simulating the board for this firmware took the grader more than "
                             f"{self.limits.time_s:g} s of CPU (a firmware that reads and writes registers without "
                             "end, never waiting for the bus)")

    def _ends(self, fault: Fault) -> Fault:
        self.close()
        if self.fault is None:
            self.fault = fault
        return self.fault


def _remember(recent: dict[int, None], address: int, most: int) -> bool:
    """Put `address` last in `recent` (oldest first, at most `most`); whether it is new there."""
    if address in recent:
        del recent[address]
        recent[address] = None
        return False
    if len(recent) == most:
        del recent[next(iter(recent))]
    recent[address] = None
    return True


def _protocol(error: ProtocolError) -> Fault:
    return Fault("protocol", f"the firmware's process broke the grader's protocol ({error}): the firmware library in "
                             "its own process was tampered with; the run ends here")


def _display(mcu: PIC18F8680, op: bytes, first: int, second: int, codes: bytes) -> None:
    display = mcu.glcd
    if display is None:
        raise RuntimeError(NO_GLCD)
    if op == wire.DISPLAY_INITIAL:
        display.initial()
    elif op == wire.DISPLAY_CURSOR:
        display.set_cursor(first, second)
    else:
        display.write(list(codes))
