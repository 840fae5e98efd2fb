"""MPLAB C18's timers.h for Timer1: OpenTimer1, ReadTimer1, WriteTimer1, CloseTimer1, through T1CON, TMR1H, TMR1L.

Masks are combined with `&`; a field left out keeps its all-ones value (C18's values for this PIC18).
"""
from __future__ import annotations

from appsim.chip.sfr import RD16 as _RD16
from appsim.chip.sfr import TMR1IF
from appsim.chip.sfr import TMR1ON as _TMR1ON
from appsim.firmware.runtime import library_call

TIMER_INT_ON = 0b11111111       # PIE1.TMR1IE = 1: an overflow interrupts (with INTCON.PEIE and GIE set)
TIMER_INT_OFF = 0b01111111
T1_16BIT_RW = 0b11111111        # RD16 = 1
T1_8BIT_RW = 0b10111111         # RD16 = 0
T1_PS_1_1 = 0b11001111
T1_PS_1_2 = 0b11011111
T1_PS_1_4 = 0b11101111
T1_PS_1_8 = 0b11111111
T1_OSC1EN_ON = 0b11111111
T1_OSC1EN_OFF = 0b11110111
T1_SYNC_EXT_ON = 0b11111011     # T1SYNC is active low: 0 = synchronise
T1_SYNC_EXT_OFF = 0b11111111
T1_SOURCE_EXT = 0b11111111      # TMR1CS = 1: does not count on the APP023 (see Timer1)
T1_SOURCE_INT = 0b11111101


def OpenTimer1(config: int) -> None:
    """Configure Timer1, clear it and PIR1.TMR1IF, and start it, as C18's OpenTimer1 does.

    `config`: TIMER_INT_* & T1_*BIT_RW & T1_SOURCE_* & T1_PS_* & T1_OSC1EN_* & T1_SYNC_EXT_*.
    """
    if not isinstance(config, int) or isinstance(config, bool) or not 0 <= config <= 0xFF:
        raise ValueError(f"OpenTimer1 takes one byte of TIMER_INT_... & T1_... masks combined with &; got {config!r}")
    mcu = library_call()
    mcu.write_name("T1CON", config & 0x7E)
    mcu.set_bits("T1CON", _RD16, bool(config & 0x40))
    mcu.write_name("TMR1H", 0)
    mcu.write_name("TMR1L", 0)
    mcu.set_bits("PIR1", 1 << TMR1IF, False)
    mcu.set_bits("PIE1", 1 << TMR1IF, bool(config & 0x80))
    mcu.set_bits("T1CON", _TMR1ON, True)


def ReadTimer1() -> int:
    """TMR1H:TMR1L, reading TMR1L first (so that RD16 = 1 gives a consistent 16-bit value)."""
    mcu = library_call()
    low = mcu.read_name("TMR1L")
    return (mcu.read_name("TMR1H") << 8) | low


def WriteTimer1(value: int) -> None:
    """Load TMR1H:TMR1L with `value` (0..65535), high byte first."""
    if not isinstance(value, int) or isinstance(value, bool) or not 0 <= value <= 0xFFFF:
        raise ValueError(f"Timer1 is a 16-bit counter: WriteTimer1 takes 0..65535; got {value!r}")
    mcu = library_call()
    mcu.write_name("TMR1H", value >> 8)
    mcu.write_name("TMR1L", value & 0xFF)


def CloseTimer1() -> None:
    """Stop Timer1 (TMR1ON = 0) and clear PIE1.TMR1IE."""
    mcu = library_call()
    mcu.set_bits("T1CON", _TMR1ON, False)
    mcu.set_bits("PIE1", 1 << TMR1IF, False)


# What firmware sees (`from appsim.firmware import *`); the chip side is appsim.chip.timer1.Timer1.
__all__ = [
    "T1_8BIT_RW",
    "T1_16BIT_RW",
    "T1_OSC1EN_OFF",
    "T1_OSC1EN_ON",
    "T1_PS_1_1",
    "T1_PS_1_2",
    "T1_PS_1_4",
    "T1_PS_1_8",
    "T1_SOURCE_EXT",
    "T1_SOURCE_INT",
    "T1_SYNC_EXT_OFF",
    "T1_SYNC_EXT_ON",
    "TIMER_INT_OFF",
    "TIMER_INT_ON",
    "CloseTimer1",
    "OpenTimer1",
    "ReadTimer1",
    "WriteTimer1",
]
