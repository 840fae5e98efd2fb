"""Timer1 of the PIC18F8680 at register level (T1CON, TMR1H, TMR1L), counting Fosc/4 on the simulated clock.

The count is computed from simulated time; one event per overflow sets PIR1.TMR1IF. appsim.firmware.timers (C18's
timers.h) drives it.
"""
from __future__ import annotations

from typing import TYPE_CHECKING

from appsim.chip.interrupts import Interrupts
from appsim.chip.sfr import RD16 as _RD16
from appsim.chip.sfr import T1CKPS as _T1CKPS
from appsim.chip.sfr import TIMER1_REGISTERS, TMR1IF
from appsim.chip.sfr import TMR1CS as _TMR1CS
from appsim.chip.sfr import TMR1ON as _TMR1ON
from appsim.sim import Timer

if TYPE_CHECKING:
    from appsim.chip.mcu import PIC18F8680

_TMR1H, _TMR1L, _T1CON = (TIMER1_REGISTERS[name] for name in ("TMR1H", "TMR1L", "T1CON"))
_T1CON_WRITABLE = 0xBF          # bit 6 is unimplemented on the PIC18F8680 and reads 0
COUNTS = 1 << 16

class Timer1:
    """Timer1 of one PIC18F8680, a Peripheral on its SFR bus.

    T1CON: RD16 (7), bit 6 unimplemented (reads 0; MPLAB C18's p18f8680.h names no bit there),
    T1CKPS1:0 (5:4, prescaler 1, 2, 4, 8), T1OSCEN (3), T1SYNC (2), TMR1CS (1), TMR1ON (0). All reset to 0.

    With TMR1ON = 1 and TMR1CS = 0 the 16-bit count TMR1H:TMR1L advances once per prescaler period of
    Fosc/4; rolling over from 0xFFFF to 0x0000 sets PIR1.TMR1IF (the timer keeps counting). At 40 MHz
    with 1:8 that is every 65536 x 8 / 10 MHz = 52.4288 ms exactly. Writing TMR1H or TMR1L clears the
    prescaler, as on the chip.

    Reads and writes follow the data sheet: with RD16 = 1 (16-bit mode) reading TMR1L latches the high
    byte into the TMR1H buffer, which TMR1H then reads, and writing TMR1H fills that buffer, which goes
    into the timer together with the next write of TMR1L. With RD16 = 0 both bytes are read and
    written directly (a read of TMR1L then TMR1H can see a carry in between).

    External clock (TMR1CS = 1): the APP023 has no 32 kHz crystal on T1OSO/T1OSI and nothing drives
    T13CKI, so the timer does not count at all, whatever T1OSCEN and T1SYNC say.
    """

    def __init__(self, mcu: PIC18F8680, interrupts: Interrupts):
        self.mcu = mcu
        self.interrupts = interrupts
        self._t1con = 0
        self._count = 0                 # the count at self._since (ps), when the prescaler was last cleared
        self._since = 0
        self._high_buffer = 0           # the TMR1H buffer of 16-bit mode
        self._overflow: Timer | None = None
        mcu.time_varying.update((_TMR1H, _TMR1L))

    @property
    def counting(self) -> bool:
        """Whether the count advances: TMR1ON = 1 on the internal clock (Fosc/4)."""
        return self._t1con & (_TMR1ON | _TMR1CS) == _TMR1ON

    @property
    def prescaler(self) -> int:
        return 1 << ((self._t1con & _T1CKPS) >> 4)

    def tick_ps(self) -> int:
        """How long one count lasts: the prescaler times the instruction cycle."""
        return self.prescaler * self.mcu.tcy_ps

    def overflow_period_ps(self) -> int:
        """Time between two overflows when counting freely: 65536 counts."""
        return COUNTS * self.tick_ps()

    def value(self) -> int:
        """TMR1H:TMR1L now, as the firmware's clock sees it."""
        return self._now()[0]

    def _now(self) -> tuple[int, int]:
        """The count now, and when it last changed (where the prescaler's present period began)."""
        now = self.mcu.sim.time()
        if not self.counting:
            return self._count, now
        ticks = (now - self._since) // self.tick_ps()
        return (self._count + ticks) % COUNTS, self._since + ticks * self.tick_ps()

    # -------------------------------------------------------------- the SFR bus
    def read(self, address: int) -> int:
        if address == _T1CON:
            return self._t1con
        count = self.value()
        if address == _TMR1L:
            if self._t1con & _RD16:
                self._high_buffer = count >> 8
            return count & 0xFF
        return self._high_buffer if self._t1con & _RD16 else count >> 8

    def write(self, address: int, value: int) -> None:
        if address == _T1CON:           # the prescaler keeps its phase
            count, since = self._now()
            self._t1con = value & _T1CON_WRITABLE
            self._restart(count, since)
            return
        if address == _TMR1H and self._t1con & _RD16:
            self._high_buffer = value
            return
        if address == _TMR1H:
            count = (value << 8) | (self.value() & 0xFF)
        else:
            high = self._high_buffer if self._t1con & _RD16 else self.value() >> 8
            count = (high << 8) | value
        self._restart(count, self.mcu.sim.time())     # writing TMR1 clears the prescaler

    # -------------------------------------------------------------- counting
    def _restart(self, count: int, since: int) -> None:
        """Count on from `count`, reached at `since`; schedule the next overflow."""
        self._count = count
        self._since = since
        if self._overflow is not None:
            self._overflow.cancel()
            self._overflow = None
        if self.counting:
            self._overflow = self.mcu.sim.call_at(
                self._since + (COUNTS - count) * self.tick_ps(), self._overflowed)

    def _overflowed(self) -> None:
        self._overflow = None
        self._restart(0, self.mcu.sim.now)
        self.interrupts.set_flag(TMR1IF)

