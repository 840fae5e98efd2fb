"""PIR1, PIE1 and IPR1 of the PIC18F8680: the peripheral interrupt flags that Timer1 and the USART share.

Peripherals set latched flags (TMR1IF) or provide read-only status flags (TXIF, RCIF); firmware polls and clears.
"""
from __future__ import annotations

from collections.abc import Callable
from typing import TYPE_CHECKING

from appsim.chip.sfr import INTERRUPT_REGISTERS, INTERRUPT_SOURCES

if TYPE_CHECKING:
    from appsim.chip.mcu import PIC18F8680

_PIE1, _PIR1, _IPR1 = (INTERRUPT_REGISTERS[name] for name in ("PIE1", "PIR1", "IPR1"))
FLAG_NAMES: dict[int, str] = {bit: f"{source}IF" for bit, source in enumerate(INTERRUPT_SOURCES)}


class PeripheralInterrupts:
    """PIR1/PIE1/IPR1 of one MCU, a Peripheral on its SFR bus.

    Reset values: PIR1 = 0x00, PIE1 = 0x00, IPR1 = 0xFF (all high priority), as the data sheet gives.
    A latched flag (TMR1IF) is set by its peripheral through `set_flag` and stays set until firmware
    writes 0 to it; firmware may also set it by writing 1, as on the chip. ADIF, SSPIF, CCP1IF, TMR2IF
    and PSPIF are latched bits that no simulated peripheral sets (the A/D is polled through GO/DONE). A status flag given
    to `provide` (TXIF = TXREG empty, RCIF = receive FIFO not empty) follows the peripheral's state:
    it reads what the peripheral says and ignores writes.

    No interrupt is taken: PIE1 and IPR1 are plain R/W bits that nothing acts on, and firmware polls
    PIR1 (as the workshop's code does with its TMR1_OVERFLOW flag).
    """

    def __init__(self, mcu: PIC18F8680):
        self.mcu = mcu
        self._latched = 0
        self._status: dict[int, Callable[[], bool]] = {}
        self._enable = 0x00
        self._priority = 0xFF

    def provide(self, bit: int, status: Callable[[], bool]) -> None:
        """Make PIR1 bit `bit` a read-only flag that reads `status()`."""
        if bit in self._status:
            raise ValueError(f"PIR1 bit {bit} ({FLAG_NAMES[bit]}) already has a peripheral behind it")
        self._status[bit] = status

    def set_flag(self, bit: int) -> None:
        """A peripheral event sets latched PIR1 bit `bit` (and wakes a polling firmware)."""
        self._latched |= 1 << bit
        self.mcu.changed()

    def flag(self, bit: int) -> bool:
        """PIR1 bit `bit` as firmware would read it."""
        return bool(self.pir1 >> bit & 1)

    @property
    def pir1(self) -> int:
        value = self._latched
        for bit, status in self._status.items():
            value = value & ~(1 << bit) | (int(bool(status())) << bit)
        return value

    # -------------------------------------------------------------- the SFR bus
    def read(self, address: int) -> int:
        if address == _PIR1:
            return self.pir1
        return self._enable if address == _PIE1 else self._priority

    def write(self, address: int, value: int) -> None:
        if address == _PIR1:
            status_bits = sum(1 << bit for bit in self._status)
            self._latched = value & ~status_bits
        elif address == _PIE1:
            self._enable = value
        else:
            self._priority = value

