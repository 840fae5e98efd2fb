"""What a firmware file imports: `from appsim.firmware import *`, as EX1.C includes CAN18XX8.h and p18f8680.h.

The AN738 library, every SFR by name (`SFR.CANCON = 0x80`), C18-style bit structs (`RXB0CONbits.RXFUL`) and interrupt
routines marked as C18's pragmas mark them (`@interrupt`, `@interruptlow`).
It acts only through the chip's SFR bus: may import appsim.chip, appsim.can, appsim.sim and appsim.errors.
"""
from __future__ import annotations

from collections.abc import Callable

from appsim.chip.sfr import BITFIELDS, current_mcu
from appsim.firmware import adc, an738, glcd, interrupts, timers, usart
from appsim.firmware.adc import *
from appsim.firmware.an738 import *
from appsim.firmware.glcd import *
from appsim.firmware.interrupts import *
from appsim.firmware.runtime import CALL_CYCLES
from appsim.firmware.timers import *
from appsim.firmware.usart import *


class _SFRs:
    """Every special function register of the board by its datasheet name: `SFR.CANSTAT`, `SFR.CANCON = 0x80`."""

    def __getattr__(self, name: str) -> int:
        return current_mcu().read_name(name)

    def __setattr__(self, name: str, value: int) -> None:
        current_mcu().write_name(name, value)


class _Bits:
    """One register's bits and fields, read and written like C18's `RXB0CONbits.RXFUL = 0` (read-modify-write)."""

    _register: str
    _fields: dict[str, tuple[int, int]]

    def __init__(self, register: str, fields: dict[str, tuple[int, int]]):
        object.__setattr__(self, "_register", register)
        object.__setattr__(self, "_fields", fields)

    def _field(self, name: str) -> tuple[int, int]:
        try:
            return self._fields[name]
        except KeyError:
            raise AttributeError(f"{self._register} has no bit or field named {name!r}; "
                                 f"it has {', '.join(self._fields)}") from None

    def __getattr__(self, name: str) -> int:
        shift, width = self._field(name)
        return (current_mcu().read_name(self._register) >> shift) & ((1 << width) - 1)

    def __setattr__(self, name: str, value: int) -> None:
        shift, width = self._field(name)
        mask = ((1 << width) - 1) << shift
        mcu = current_mcu()
        mcu.write_name(self._register, (mcu.read_name(self._register) & ~mask) | ((value << shift) & mask))


def Nop() -> None:
    """One instruction cycle doing nothing (C18's Nop())."""
    current_mcu().spend_cycles(1)


def _units(function: str, unit: int) -> int:
    """C18's delays take an unsigned char: 1..255 units, and 0 means 256 (its loop counts down before it tests)."""
    if not isinstance(unit, int) or isinstance(unit, bool) or not 0 <= unit <= 0xFF:
        wrapped = f": C18 would wait {unit % 256 or 256} units (it keeps the low byte)" if isinstance(unit, int) else ""
        raise ValueError(f"{function} takes an unsigned char, 0..255 units (0 means 256); got {unit!r}{wrapped}. "
                         f"Call it again for longer waits")
    return unit or 256


def _counted_delay(name: str, cycles: int, per_unit: str) -> Callable[[int], None]:
    """One of C18's counted delays: `cycles` x its unit count (an unsigned char, 0 means 256), after its call."""
    def delay(unit: int) -> None:
        current_mcu().wait_cycles(CALL_CYCLES + cycles * _units(name, unit))
    delay.__name__ = delay.__qualname__ = name
    delay.__doc__ = (f"Wait {cycles:,} x `unit` instruction cycles, as C18's delays.h does ({per_unit} per unit at "
                     "40 MHz); 0 means 256.")
    return delay


Delay10TCYx = _counted_delay("Delay10TCYx", 10, "1 us")
Delay100TCYx = _counted_delay("Delay100TCYx", 100, "10 us")
Delay1KTCYx = _counted_delay("Delay1KTCYx", 1_000, "0.1 ms")
Delay10KTCYx = _counted_delay("Delay10KTCYx", 10_000, "1 ms")


def Delay1TCY() -> None:
    """One instruction cycle (C18's delays.h: a macro for Nop())."""
    Nop()


def Delay10TCY() -> None:
    """Ten instruction cycles (C18's delays.h: a macro for Delay10TCYx(1))."""
    Delay10TCYx(1)


DELAYS = (Delay1TCY, Delay10TCY, Delay10TCYx, Delay100TCYx, Delay1KTCYx, Delay10KTCYx)   # C18's delays.h, all of it


SFR = _SFRs()
globals().update({f"{register}bits": _Bits(register, fields) for register, fields in BITFIELDS.items()})

__all__ = [*an738.__all__, *adc.__all__, *timers.__all__, *glcd.__all__, *usart.__all__, *interrupts.__all__,
           "SFR", "Nop", *(delay.__name__ for delay in DELAYS), *(f"{r}bits" for r in BITFIELDS)]
