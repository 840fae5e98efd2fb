"""The grader's side of a sandboxed firmware: a child loads the file, the board runs its main(), each access crosses.

Every wait has a deadline; the grader's CPU time for it and the time it sleeps count against its limits (`usage`);
every message is decoded strictly; whatever the child does, it ends as a `Fault` of its own exercise and nothing else.
Where the board's core takes an interrupt, it calls the child's routine: VECTOR, and the child's accesses are served
from inside the core's call until the child's RETFIE.
"""
from __future__ import annotations

import functools
import signal
import time

from appsim.board.glcd import GLCD
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


class _Ended(BaseException):
    """The run ends inside an interrupt routine (the child ended there, or broke the protocol): out through the board's
    core to `_serve`. A BaseException, so that no `except Exception` of the board's takes it for a board's error."""

    def __init__(self, fault: Fault):
        super().__init__(fault.message)
        self.fault = fault


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
        self._took_version = -1         # the board's version right after that write
        # Interrupts: the child's routines running (their vectors, innermost last); whether the access being done waits
        # for its answer (only there may the board vector), which one it is and when it began; what the child was told
        # of INTCON.GIEH, and up to which time of the board's its last read-ahead lets it go on without a word.
        self._serving: list[int] = []
        self._waiting = False
        self._item: tuple[bytes, int] = (wire.READ, 0)
        self._item_from = 0
        self._child_live = False
        self._offered_end: int | None = None
        self._returned = False

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
                routines = {vector: functools.partial(self._routine, vector) for vector in wire.VECTORS}
                return Firmware(self._main, None, self.name, wire.decode_identity(data), routines,
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
        try:
            fault = self._serve_loop(mcu, self._usage)
        except _Ended as ended:
            return ended.fault
        assert fault is not None, "a RETFIE with no routine running is refused"
        return fault

    def _serve_loop(self, mcu: PIC18F8680, usage: Usage) -> Fault | None:
        """The hot path, a lone register read, is done inline: one read and one write of the pipes, and the board.
        What the firmware used is looked at every 64 messages, and after each long wait for one. None: the routine
        this loop serves returned (RETFIE)."""
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
                    self._waiting = True
                    mcu.parking.judged = False      # (the read-ahead says whether this read was a read again)
                    try:
                        value = mcu.read(address, site)
                    except Exception as error:       # the firmware sees it raised, as on a local board
                        self._error = error
                    if self._error is None:         # (a routine the read was interrupted by may have met one)
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
            if self._returned:
                self._returned = False
                return None
            if reply is not None:
                self.round_trips += 1
                if not channel.send(reply):
                    return self._gone()

    def _perform(self, mcu: PIC18F8680, accesses: list[Access], codes: bytes) -> bytes | None:
        """Do a batch on the board; the answer when it ends with an access that waits for one. An access the board
        refuses (an error from a peripheral) skips the rest of the batch and is raised in the child at its answer."""
        value = 0
        process = mcu.process
        assert process is not None
        for op, first, second, third in accesses:
            self._waiting = op in wire.WAITING
            self._item, self._item_from = (op, first), process.local_time
            if op is wire.SERVED:
                if self._error is None:
                    self._replay(mcu, first, second, third)
                continue
            if op is wire.RETFIE:
                self._return_from(first)
                return None
            if self._error is None:
                try:
                    if op is wire.READ:
                        mcu.parking.judged = False
                        value = mcu.read(first, second)
                        self._recent(first)
                    elif op is wire.WRITE or op is wire.WRITE_WAIT:
                        self._took = self._taken(mcu, first)
                        mcu.write(first, second)
                        self._took_version = mcu.version
                    elif op is wire.SPEND or op is wire.SPEND_WAIT:
                        mcu.spend_cycles(first)
                    elif op is wire.DELAY or op is wire.DELAY_WAIT:
                        mcu.wait_cycles(first)
                    elif op is wire.IDLE:
                        mcu.wait_for_interrupt(codes.decode())
                    else:
                        _display(mcu, op, first, second, codes)
                except Exception as error:       # the firmware sees it raised, as on a local board
                    self._error = error
            if self._waiting:
                if self._error is not None:
                    reply, self._error, self._offered_end = wire.error_message(self._error), None, None
                    return reply
                if op is wire.READ:
                    return self._answer(mcu, value)
                if op[:1] == wire.DISPLAY:
                    self._offered_end = None
                    return wire.DONE
                live = self._child_live = mcu.interrupts.armed
                return wire.go_on_message(live, self._read_ahead(mcu))
        return None

    # -------------------------------------------------------------- interrupts
    def _routine(self, vector: int) -> None:
        """The board's core vectors (the firmware's routine at `vector`, as PIC18F8680 calls it, in the board's
        process): the child runs its routine where it waits, and its accesses are served from here until its RETFIE."""
        if not self._waiting:
            raise _Ended(self._unwaited())
        mcu = current_mcu()
        assert isinstance(mcu, PIC18F8680) and self._child is not None and self._usage is not None
        self._serving.append(vector)
        live = self._child_live = mcu.interrupts.armed
        if not self._child.channel.send(wire.vector_message(vector, live, self._read_ahead(mcu))):
            raise _Ended(self._gone())
        fault = self._serve_loop(mcu, self._usage)
        if fault is not None:
            raise _Ended(fault)
        self._waiting = True                # back in the access it interrupted, which waits for its answer

    def _return_from(self, vector: int) -> None:
        """The child's RETFIE: of the routine running, else a ProtocolError. The core's own RETFIE follows."""
        if not self._serving:
            raise ProtocolError("a RETFIE where no interrupt routine runs")
        if self._serving[-1] != vector:
            raise ProtocolError(f"a RETFIE from vector 0x{vector:02X}, where the routine at 0x{self._serving[-1]:02X} "
                                "runs")
        self._serving.pop()
        if vector == wire.HIGH_VECTOR:
            self._child_live = True         # as the child has it: RETFIE sets GIE/GIEH again
        self._returned = True

    def _unwaited(self) -> Fault:
        """The board vectors during an access the child did not wait at: the student's doing if an honest child waits
        there (by what it was told), else a mistake of the grader's, which cannot judge the exercise then."""
        op, first = self._item
        mcu = current_mcu()
        assert isinstance(mcu, PIC18F8680)
        spends = op is wire.SPEND or op is wire.DELAY
        cost = first * mcu.tcy_ps if spends else mcu.access_ps
        beyond = self._offered_end is None or self._item_from + cost > self._offered_end
        if ((op is wire.WRITE and (first == wire.INTCON or (self._child_live and self._took is None)))
                or (op is wire.SERVED and beyond) or (spends and self._child_live and beyond)):
            return _protocol(ProtocolError("an access where the board may take an interrupt did not wait for its "
                                           "answer"))
        return Fault("grader", "the board took an interrupt during an access the firmware's process had been told it "
                               "need not wait at (a mistake of the simulator's, not the firmware's): this exercise "
                               "cannot be judged sandboxed; grade it again after updating the kit, or report it")

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
        return wire.VALUE + bytes((value & 0xFF,)) + self._read_ahead(mcu)

    def _read_ahead(self, mcu: PIC18F8680) -> bytes:
        """What the firmware may read next without asking, and how long it may go on (see PIC18F8680.read_ahead)."""
        ahead = mcu.read_ahead(self._offered(), self._writes)
        self._after, self._after_addresses = dict(ahead.after_writes), ahead.addresses
        self._after_version, self._took = mcu.version, None
        process = mcu.process
        assert process is not None
        self._offered_end = process.local_time + ahead.budget_ps
        return wire.read_ahead_message(*ahead)

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
        served read that does is not one (a ProtocolError); checks and grade agreeing is tested on every solution.
        Only a value the read-ahead foretold after a write, read with nothing changed on the board since that write,
        can be the grader's mistake: a child that spent past its budget, or read on after another access, broke the
        protocol, whatever value it claims."""
        process = mcu.process
        assert process is not None
        expected = process.local_time + mcu.access_ps
        version = mcu.version
        value = mcu.read(address, site)
        self._recent(address)
        if value != used or process.local_time != expected:
            if (self._took is not None and self._took.get(address) == used and version == self._took_version
                    and process.local_time == expected):
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
    elif isinstance(display, GLCD):
        display.write(list(codes), length=first)    # the first codes of `first`: all the screen can show
    else:
        display.write(list(codes))
