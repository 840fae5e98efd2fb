"""The PIC18F8680 as firmware sees it: its peripherals on one SFR bus (by address and name), time in cycles, and the
core taking interrupts between two instructions.

Each SFR access costs instruction cycles at Fosc/4. A read that polls (the same register, read again
from the same place in the firmware, with nothing changed since, not even a delay of its own, a timer it reads or its
own variables: `appsim.chip.polling`) parks the firmware until a peripheral event changes something it reads: a
busy-wait costs one loop turn per event, not per cycle.
"""
from __future__ import annotations

import contextvars
from collections.abc import Callable, Iterable, Mapping, Sequence
from typing import Any, NamedTuple, Protocol

import greenlet

from appsim.chip.adc import ADC
from appsim.chip.clock import FOSC_HZ
from appsim.chip.ecan import registers as ecan_registers
from appsim.chip.ecan.controller import ECAN
from appsim.chip.interrupts import INTERRUPT_LATENCY_CYCLES, RETFIE_CYCLES, Interrupts
from appsim.chip.polling import (
    LOOK_PASSES,
    POLLING_SITES,
    PollingLoop,
    firmware_entry,
    firmware_site,
    forget_firmware_code,
)
from appsim.chip.ports import PortJ
from appsim.chip.sfr import (
    ADC_REGISTERS,
    INTERRUPT_REGISTERS,
    PORTJ_REGISTERS,
    RUNNING_MCU,
    TIMER1_REGISTERS,
    USART_REGISTERS,
    VECTOR_NAMES,
    GLCDPort,
    SFRNames,
    missing_routine,
)
from appsim.chip.timer1 import Timer1
from appsim.chip.usart import USART
from appsim.errors import FirmwareHung, NoInterruptRoutine
from appsim.sim import PS_PER_SECOND, Process, Simulator, Timer

SFR_ACCESS_CYCLES = 2           # a C statement touching an SFR: MOVFF / MOVF + MOVWF, with banking
REENTRIES_AT_ONCE = 10_000      # a routine entered again at once this often in a row never clears its source
Routine = Callable[[], object]  # an interrupt routine, as the core calls it

_getcurrent = greenlet.getcurrent


class Peripheral(Protocol):
    """Anything on the SFR bus: reads and writes bytes at its addresses."""

    def read(self, address: int) -> int: ...
    def write(self, address: int, value: int) -> None: ...


READ_AHEAD_MAX_PS = 1 << 62           # a horizon with no event ahead
LOOK_FIRST_PS = PS_PER_SECOND // 1000   # a loop parked this long is woken once, nothing changed, to see if it counts;
LOOK_LAST_PS = PS_PER_SECOND            # each time it does not, the next look there comes twice as late, up to this
LOOK_COUNTING_PS = 8 * LOOK_FIRST_PS    # and one that did comes again after this: a loop that counts turns on


def _reads_zero(address: int) -> int:
    """An address with nothing behind it reads 0."""
    return 0


class ReadAhead(NamedTuple):
    """See `PIC18F8680.read_ahead`: the time the firmware may spend, whether `sites` (address, call site) are the
    polling loop's at this change, the registers it may read without asking (their addresses; their values, and
    whether each was read since the last change, both as bytes), those sites, and what the registers read after a
    write of one of `written` (its address, and their values then, as bytes), where the board can tell; whether the
    read it comes after ended a park a look woke (`PIC18F8680._park_polling`), and whether that read was a read again
    with nothing changed (`PIC18F8680._read_again` judged it)."""

    budget_ps: int
    current: bool
    addresses: tuple[int, ...]
    values: bytes
    seen: bytes
    sites: list[tuple[int, int]]
    after_writes: list[tuple[int, bytes]]
    woken: bool
    judged: bool


class Parking:
    """A parked firmware as the board keeps it: what it read (what wakes it), and for a polling loop the looks at it
    that tell whether it counts (`PIC18F8680._park_polling`): where it parked and since when, the look ahead, when each
    place is due to be looked at again, and what the last look saw."""

    __slots__ = ("after", "event", "judged", "looked", "parked_at", "parked_on", "parked_since", "woken_read",
                 "looking")

    def __init__(self) -> None:
        self.parked_on: dict[int, int] | None = None        # what a parked loop read (None: wake on any change)
        self.parked_at: tuple[int, int] | None = None     # where the loop parked: (address, site)
        self.parked_since = 0
        self.event: Timer | None = None
        self.after: dict[tuple[int, int], int] = {}        # place -> how long after it parks there it is looked at
        self.looking = False
        self.looked: tuple[tuple[int, int], int] | None = None     # where a look woke the loop, and when
        self.woken_read = False        # the read just done ended a park a look woke (the sandbox's loop judges)
        self.judged = False             # the sandbox's read just done was a read again (the grader clears it before)


class PIC18F8680(SFRNames):
    """One microcontroller on the simulated clock, built whole: the ECAN module (F00h..F77h, FA3h..FA5h), the A/D,
    Timer1, the EUSART, the interrupt logic (INTCON.., RCON, PIR1/PIE1/IPR1) and PORTJ on its SFR bus. A board wires
    its pins (`usart.wired_to`, `portj.levels`) and may give it a display (`glcd`).

    Interrupts: the core takes one between two register accesses (this model's instructions) once its flag, its
    enable and the global enables say so (`Interrupts.request`), `INTERRUPT_LATENCY_CYCLES` after the access that saw
    it, by calling the firmware's routine for that vector in the firmware's own process; RETFIE follows the routine's
    return. With interrupts enabled (INTCON.GIE), spent time (a delay, a library's work) is interruptible at any
    cycle, and a polling loop parked on its registers wakes to take one. While GIE is 0 nothing of this costs."""

    def __init__(self, sim: Simulator, name: str = "node", *, fosc: int = FOSC_HZ):
        # 29 attributes: CPython 3.11 keeps up to 29 of an object's attributes inline, where they are fastest to reach;
        # a 30th cost every register access about 3 %. New state goes to the peripherals (see Interrupts).
        self.sim = sim
        self.name = name
        self.fosc = fosc
        self.tcy_ps = 4 * PS_PER_SECOND // fosc
        self.access_ps = SFR_ACCESS_CYCLES * self.tcy_ps
        self.ecan = ECAN(name, fosc, changed=self.changed)
        self.sfr_addresses: dict[str, int] = {}
        self._devices: dict[int, Peripheral] = {}
        self._readers: dict[int, Callable[[int], int]] = {}     # address -> its peripheral's read
        self.map(self.ecan, ((r.name, r.address) for r in ecan_registers.REGISTERS))
        self.version = 0
        self._seen: dict[int, int] = {}                 # address -> `version` when the firmware last read it
        # What a polling loop reads again at `_polled_version`: values, where from (`loop`), and whether they tell all
        # (no register whose read has a side effect).
        self._polled_version = -1
        self._polled: dict[int, int] = {}
        self.loop = PollingLoop()
        self._polled_pure = True
        self.parking = Parking()                            # what a parked firmware read, the looks at its loop
        self.time_varying: set[int] = set()
        # The registers a read-ahead offered last, and how each is read (see `read_ahead`).
        self._offered: tuple[int, ...] | None = None
        self._offered_addresses: tuple[int, ...] = ()
        self._offered_readers: list[tuple[int, Callable[[int], int]]] = []
        self.read_side_effects: set[int] = set()            # reading changes them (RCREG pops its FIFO)
        self.quiet_writes: dict[int, Callable[[], dict[int, int] | None]] = {}     # see `read_ahead`
        self.process: Process | None = None
        self.glcd: GLCDPort | None = None                   # the board's display, if it has one
        self.interrupts = Interrupts(self)
        self.map(self.interrupts, INTERRUPT_REGISTERS.items())
        self.adc = ADC(self)
        self.map(self.adc, ADC_REGISTERS.items())
        self.timer1 = Timer1(self, self.interrupts)
        self.map(self.timer1, TIMER1_REGISTERS.items())
        self.usart = USART(self, self.interrupts)
        self.map(self.usart, USART_REGISTERS.items())
        self.portj = PortJ()
        self.map(self.portj, PORTJ_REGISTERS.items())

    @property
    def controller(self) -> ECAN:
        """Its CAN controller, as the wire sees it (`appsim.bus.controller.Controller`)."""
        return self.ecan

    def map(self, device: Peripheral, registers: Iterable[tuple[str, int]]) -> None:
        """Put a peripheral's registers (name, address) on the SFR bus."""
        for name, address in registers:
            self.sfr_addresses[name] = address
            self._devices[address] = device
            self._readers[address] = device.read

    # -------------------------------------------------------------- firmware access
    def read(self, address: int, site: int | None = None) -> int:
        """The register's value; `site` names the firmware's call site when it runs elsewhere (a sandbox).

        An interrupt requested meanwhile (while the firmware handed over, or while its polling loop was parked) is
        taken after the read, before the firmware uses the value: between this instruction and the next."""
        process = self.process
        if process is None or _getcurrent() is not process:
            return self._readers.get(address, _reads_zero)(address)
        local_time = process.local_time = process.local_time + self.access_ps   # process.spend, its common case
        late = local_time > process.horizon
        if late:
            process.spend(0)
        seen, version = self._seen, self.version    # after spend: other firmware and events may have run
        if seen.get(address) == version:
            self._read_again(process, address, site)
            seen[address] = self.version
            value = self._polled[address] = self._readers.get(address, _reads_zero)(address)  # what the loop saw
            if self.interrupts.requested:
                self._interrupt(process)
            return value
        seen[address] = version
        value = self._readers.get(address, _reads_zero)(address)
        if late and self.interrupts.requested:
            self._interrupt(process)
        return value

    def read_each(self, addresses: Sequence[int]) -> list[int]:
        """The registers read one after the other, each as `read` reads it; while that changes nothing (the reads fit
        before the firmware's horizon, so nothing else runs meanwhile, and the register is not one read again since the
        last change nor one time changes: no polling loop, no interrupt taken between them), without its call."""
        process = self.process
        if (process is None or _getcurrent() is not process
                or process.local_time + len(addresses) * self.access_ps > process.horizon):
            return [self.read(address) for address in addresses]
        seen, version, access_ps = self._seen, self.version, self.access_ps
        readers, time_varying = self._readers, self.time_varying
        values: list[int] = []
        for k, address in enumerate(addresses):
            if seen.get(address) == version or address in time_varying:
                return values + [self.read(address) for address in addresses[k:]]
            process.local_time += access_ps
            seen[address] = version
            values.append(readers.get(address, _reads_zero)(address))
        return values

    def _read_again(self, process: Process, address: int, site: int | None) -> None:
        """A register read again with nothing changed since: from the same place in the firmware, with the firmware's
        own variables as they were (`PollingLoop`), that is a polling loop, parked until a change that it would see. A
        loop that counts its turns (a timeout, `TxData[k] = ADRESH` for k = 0..4) turns on as on the chip. A loop that
        reads a register time changes (Timer1) sees time pass by itself, as one that waits (`wait_cycles`): that read
        is a change, the loop never parks. A `site` given comes from a sandbox, whose firmware judges counting there."""
        if address in self.time_varying:
            self.version += 1
            return
        self.parking.judged = True
        loop = self.loop
        if self._polled_version != self.version:
            self._polled_version = self.version
            self._polled, self._polled_pure = {}, True
            loop.changed()
        here = site is None
        place = firmware_site(3) if site is None else site         # from read's caller
        if address in self.read_side_effects:
            self._polled_pure = here = False    # a read that changes the board: its loop is judged by place alone
        sites, key = loop.sites, (address, place)
        if key not in sites:                    # PollingLoop.new_site, here: every polling loop's path
            if len(sites) < POLLING_SITES:
                sites.add(key)
            if loop.look is not None:
                loop.end_look()
            return
        if loop.from_known_place(address, place, judged=here) is not None:
            return
        self.parking.parked_on = self._polled if self._polled_pure else None
        self._park_polling(process, key, here)

    def _park_polling(self, process: Process, parked_at: tuple[int, int], here: bool) -> None:
        """Park a polling loop. One that stays parked LOOK_FIRST_PS is woken once with nothing changed that it reads
        (`_look`): the loop it is in may count after all, which its variables at its next read again tell
        (`PollingLoop.woken`, here or in the sandbox). Each look at one place comes twice as late as the one before,
        up to LOOK_LAST_PS; unless the loop ran on after the last look there for longer than LOOK_PASSES reads take
        (it counts, or counted to its end): then the next comes after LOOK_COUNTING_PS. A loop that counts (a
        timeout) so turns COUNTED_TURNS reads per change on the board, and as many every LOOK_COUNTING_PS at least: a
        free-running counter costs about 128,000 reads a simulated second, not the chip's millions."""
        parking = self.parking
        if parking.looked is not None:
            looked_at, woke_at = parking.looked
            parking.looked = None
            if process.local_time - woke_at > LOOK_PASSES * self.access_ps:
                parking.after[looked_at] = LOOK_COUNTING_PS        # it turned on: more than a turn's reads
        parking.parked_at, parking.parked_since = parked_at, process.local_time
        due = process.local_time + parking.after.get(parked_at, LOOK_FIRST_PS)
        event = parking.event
        if event is None or event.time > due:       # one look ahead at a time; `_look` puts it off if it may
            if event is not None:
                event.cancel()
            parking.event = self.sim.call_at(due, self._look)
        process.park()
        parking.parked_at = None
        if parking.looking:
            parking.looking = False
            if self.version == self._polled_version:        # nothing it reads changed since the look woke it
                self.loop.woken(*parked_at, judged=here)
                parking.woken_read = not here

    def _look(self) -> None:
        """Wake the parked polling loop to look whether it counts, if it is time: changes it does not read (Timer1
        overflowing) may have come meanwhile, and it reads as it did, so its places still hold."""
        parking = self.parking
        parking.event = None
        parked_at, process, parked_on = parking.parked_at, self.process, parking.parked_on
        if parked_at is None or process is None or not process.parked or parked_on is None:
            return
        after = parking.after.get(parked_at, LOOK_FIRST_PS)
        due = parking.parked_since + after
        if due > self.sim.now:
            parking.event = self.sim.call_at(due, self._look)
            return
        if len(parking.after) >= POLLING_SITES:
            parking.after.clear()
        parking.after[parked_at] = min(2 * after, LOOK_LAST_PS)
        if self.version != self._polled_version:
            self._polled_version = version = self.version
            for address in parked_on:
                self._seen[address] = version
        parking.looking = True
        parking.looked = parked_at, max(process.local_time, self.sim.now)
        process.wake()

    def read_ahead(self, addresses: tuple[int, ...], written: Iterable[int] = ()) -> ReadAhead:
        """What firmware that runs elsewhere (the grader's sandbox) may read without asking, right now.

        Nothing else runs until the firmware writes a register or has spent `budget_ps` (then it reaches the horizon
        and hands over), so until then the registers among `addresses` whose reading changes nothing keep the values
        given here. With whether each was read since the last change, and the polling loop's sites at this change,
        the firmware can apply `_read_again`'s rule itself and ask only for a read that would park. The same
        `addresses` (one tuple) asked again reuse what was looked up for them.

        A write changes the board, but some writes change it in a way known beforehand: a peripheral says so in
        `quiet_writes` (address -> the new values of the other registers the write changes, None when it would do
        more, such as start a timer). For those among `written`, the values the registers read after the write
        come too: it takes the access's time, nothing else runs, and every register reads as not seen since.
        """
        process = self.process
        assert process is not None
        if addresses is not self._offered:
            self._offered = addresses
            mapped = self._readers
            offered = [a for a in addresses if a not in self.time_varying and a not in self.read_side_effects]
            self._offered_readers = [(a, mapped.get(a, _reads_zero)) for a in offered]
            self._offered_addresses = tuple(offered)
        budget = process.horizon - process.local_time
        seen, version = self._seen, self.version
        readers = self._offered_readers
        current = self._polled_version == version
        parking = self.parking
        woken, parking.woken_read = parking.woken_read, False
        judged, parking.judged = parking.judged, False
        values = [read(a) for a, read in readers]
        after_writes = []
        for address in written:
            changes = self.quiet_writes[address]()
            if changes is not None:
                after_writes.append((address, bytes([changes.get(a, value) for a, value in zip(
                    self._offered_addresses, values, strict=True)])))
        return ReadAhead(min(int(budget), READ_AHEAD_MAX_PS) if budget > 0 else 0, current, self._offered_addresses,
                         bytes(values), bytes([seen.get(a) == version for a, _ in readers]),
                         list(self.loop.sites) if current else [], after_writes, woken, judged)

    def write(self, address: int, value: int) -> None:
        """Write the register; an interrupt this write (or an event while it waited) makes pending is taken after it."""
        process = self.process
        if process is not None and _getcurrent() is process:
            process.spend(self.access_ps)
        else:
            process = None                  # not the firmware's own write: nothing to interrupt here
        self.version += 1
        device = self._devices.get(address)
        if device is not None:
            device.write(address, value & 0xFF)
        interrupts = self.interrupts
        if interrupts.armed or interrupts.requested:
            self._update_request()
            if interrupts.requested and process is not None:
                self._interrupt(process)

    def spend_cycles(self, cycles: int) -> None:
        """Time the firmware spends computing (instruction cycles at Fosc/4): interruptible, cycle by cycle, while
        interrupts are enabled (INTCON.GIE)."""
        process = self.process
        if process is not None and _getcurrent() is process:
            if self.interrupts.armed:
                self._spend_interruptibly(process, cycles * self.tcy_ps)
            else:
                process.spend(cycles * self.tcy_ps)

    def wait_cycles(self, cycles: int) -> None:
        """Time the firmware lets pass on purpose (C18's delays), spent as `spend_cycles`. A loop that waits so between
        its reads sees time pass (its timeout comes), so a wait counts as a change: the reads after it are a new
        look, never a polling loop's read again (`_read_again`), and the loop turns as it would on the chip."""
        self.spend_cycles(cycles)
        if self.process is not None and _getcurrent() is self.process:
            self.version += 1

    # -------------------------------------------------------------- interrupts
    def _update_request(self) -> None:
        """Whether the core has an interrupt to take now; a parked firmware wakes to take it."""
        interrupts = self.interrupts
        interrupts.requested = interrupts.armed and interrupts.request() != 0
        process = self.process
        if interrupts.requested and process is not None and process.parked:
            process.wake()

    def _interrupt(self, process: Process) -> None:
        """Take the interrupt requested, between two instructions of the firmware: after the latency, its routine runs
        in the firmware's own process, from here; then RETFIE, and at once the next one if one is pending (the same
        routine again, if it left its flag set)."""
        interrupts = self.interrupts
        interrupted, taken = process.routine, 0
        while interrupts.requested:
            vector = interrupts.request()
            if not vector:
                interrupts.requested = False
                return
            if taken == REENTRIES_AT_ONCE:
                self._hang(f"{VECTOR_NAMES[vector]} was entered {taken:,} times in a row: each time it returned "
                           f"(RETFIE), {interrupts.pending()} was still pending, and the core takes a pending "
                           f"interrupt again right after RETFIE, so {interrupted} has not run one instruction since "
                           "the first. Clear the source's flag in the routine (`PIR1bits.TMR1IF = 0` for Timer1's), or "
                           "disable the source (its enable bit: PIE1bits.TXIE for a transmit routine with nothing "
                           "left to send)")
            taken += 1
            interrupts.enter(vector)
            self.version += 1                   # the routine may change what the interrupted loop reads
            process.routine = VECTOR_NAMES[vector]
            process.spend(INTERRUPT_LATENCY_CYCLES * self.tcy_ps)
            self._update_request()
            if interrupts.requested:
                self._interrupt(process)        # a high-priority source pre-empts a low-priority routine at once
            routine = interrupts.routines.get(vector)
            if routine is None:
                raise NoInterruptRoutine(missing_routine(vector))
            routine()
            process.routine = interrupted
            interrupts.retfie()
            process.spend(RETFIE_CYCLES * self.tcy_ps)
            self.version += 1
            self._update_request()

    def _spend_interruptibly(self, process: Process, time_ps: int) -> None:
        """Spend `time_ps` (a delay loop, a library's work) where any cycle may be interrupted: up to the next event
        at once, else parked until the time is over or an interrupt is requested. A routine's time does not count."""
        left = time_ps
        while True:
            if self.interrupts.requested:
                self._interrupt(process)
            if left <= process.horizon - process.local_time:
                process.local_time += left
                return
            started = process.local_time
            over = self.sim.call_at(started + left, process.wake)
            self.parking.parked_on = {}     # nothing read: only the end of the time or an interrupt wakes it
            process.park()
            over.cancel()
            left -= process.local_time - started

    def wait_for_interrupt(self, loop: str) -> None:
        """The firmware waits in `loop` (an empty loop the loader found: only an interrupt routine can end it, such as
        `while not flag: pass`) until an interrupt is taken. One that none can ever come to stops the firmware with
        the watchdog's `FirmwareHung`, saying why."""
        process = self.process
        assert process is not None and _getcurrent() is process, "firmware waits in its own process"
        while not self.interrupts.requested:
            why = self.interrupts.why_none_can_come()
            if why is not None:
                self._hang(f"{process.routine} waits in an empty loop at {loop}, which only an interrupt routine can "
                           f"end, and no interrupt can come: {why}. The board would spin there for ever")
            self.parking.parked_on = {}
            process.park()
        self._interrupt(process)

    def _hang(self, message: str) -> None:
        """Stop the firmware as the watchdog does (one that caught the last one and went on is frozen)."""
        process = self.process
        assert process is not None
        if process.failure is not None:
            process.freeze()
        process.failure = FirmwareHung(message)
        raise process.failure

    # -------------------------------------------------------------- hardware side
    def changed(self) -> None:
        """A peripheral changed state the firmware can see: wake a parked firmware (or interrupt it)."""
        self.version += 1
        interrupts = self.interrupts
        if interrupts.armed or interrupts.requested:
            self._update_request()
        process = self.process
        if process is not None and process.parked and self._loop_would_see_a_change():
            process.wake()

    def _loop_would_see_a_change(self) -> bool:
        parked_on = self.parking.parked_on
        if parked_on is None:
            return True
        readers = self._readers
        for address, value in parked_on.items():     # (a loop, not any(): at each event of the bus, for each board)
            if readers.get(address, _reads_zero)(address) != value:
                return True
        return False

    def run(self, main: Callable[[], Any], routines: Mapping[int, Routine] | None = None) -> Process:
        """Start firmware `main` on this MCU (after a reset, as programming the chip would), with its interrupt
        routines by vector (HIGH_VECTOR, LOW_VECTOR): the core calls them in the firmware's process."""
        if self.process is not None and not self.process.dead:
            self.process.stop()
        forget_firmware_code()          # new firmware brings new code objects (a grader loads thousands)
        self.loop, self.parking = PollingLoop(), Parking()
        self.interrupts.reset(routines or {})
        context = contextvars.Context()
        context.run(RUNNING_MCU.set, self)                  # what `current_mcu()` gives its firmware
        self.process = self.sim.start(self.name, main, context=context)
        return self.process


firmware_entry(Process._body)       # a process runs its firmware's main() from there
