"""MPLAB C18's adc.h: OpenADC, ConvertADC, BusyADC, ReadADC ... acting on the A/D only through its registers.

Masks are combined with `&`, as in C; a field left out keeps its all-ones value.
"""
from __future__ import annotations

import numbers
from typing import TypeGuard

from appsim.chip.sfr import ADC_CHANNELS, ADIF, PEIE
from appsim.chip.sfr import ADFM as _ADFM
from appsim.chip.sfr import ADON as _ADON
from appsim.chip.sfr import GO_DONE as _GO_DONE
from appsim.firmware.runtime import library_call


def _is_int(value: object) -> TypeGuard[int]:
    return isinstance(value, numbers.Integral) and not isinstance(value, bool)


ADC_FOSC_2 = 0b10001111
ADC_FOSC_4 = 0b11001111
ADC_FOSC_8 = 0b10011111
ADC_FOSC_16 = 0b11011111
ADC_FOSC_32 = 0b10101111
ADC_FOSC_64 = 0b11101111
ADC_FOSC_RC = 0b11111111

ADC_0_TAD = 0b11110001      # acquisition time (ADCON2.ACQT, three-argument OpenADC): 0 TAD, manual acquisition
ADC_2_TAD = 0b11110011
ADC_4_TAD = 0b11110101
ADC_6_TAD = 0b11110111
ADC_8_TAD = 0b11111001
ADC_12_TAD = 0b11111011
ADC_16_TAD = 0b11111101
ADC_20_TAD = 0b11111111

ADC_RIGHT_JUST = 0b11111111
ADC_LEFT_JUST = 0b01111111

ADC_0ANA = 0b11111111       # all digital
ADC_1ANA = 0b11111110       # AN0 analog
ADC_2ANA = 0b11111101       # AN0..AN1
ADC_3ANA = 0b11111100
ADC_4ANA = 0b11111011
ADC_5ANA = 0b11111010
ADC_6ANA = 0b11111001
ADC_7ANA = 0b11111000
ADC_8ANA = 0b11110111
ADC_9ANA = 0b11110110
ADC_10ANA = 0b11110101
ADC_11ANA = 0b11110100
ADC_12ANA = 0b11110011
ADC_13ANA = 0b11110010
ADC_14ANA = 0b11110001      # AN0..AN13
ADC_16ANA = 0b11110000      # all analog

ADC_INT_ON = 0b11111111     # PIR1.ADIF = 0, PIE1.ADIE = 1, INTCON.PEIE = 1
ADC_INT_OFF = 0b01111111

ADC_VREFPLUS_VDD = 0b11111110
ADC_VREFPLUS_EXT = 0b11111111
ADC_VREFMINUS_VSS = 0b11111101
ADC_VREFMINUS_EXT = 0b11111111

ADC_CH0 = 0b10000111
ADC_CH1 = 0b10001111
ADC_CH2 = 0b10010111
ADC_CH3 = 0b10011111
ADC_CH4 = 0b10100111
ADC_CH5 = 0b10101111
ADC_CH6 = 0b10110111
ADC_CH7 = 0b10111111
ADC_CH8 = 0b11000111
ADC_CH9 = 0b11001111
ADC_CH10 = 0b11010111
ADC_CH11 = 0b11011111
ADC_CH12 = 0b11100111
ADC_CH13 = 0b11101111
ADC_CH14 = 0b11110111
ADC_CH15 = 0b11111111

_CHANNEL_MASKS = frozenset(0b10000111 | (n << 3) for n in range(ADC_CHANNELS))


def _byte(name: str, value: int) -> int:
    if not _is_int(value) or not 0 <= value <= 0xFF:
        raise ValueError(f"{name} is one byte of ADC_... masks combined with &; got {value!r}")
    return int(value)


def OpenADC(config: int, config2: int, portconfig: int | None = None) -> None:
    """Configure and switch on the A/D (ADCON0..2), aborting a conversion in progress, as C18's adc.h does for the
    PIC18F8680: `OpenADC(config, config2, portconfig)`.

    `config`: ADC_FOSC_* & ADC_*_JUST & ADC_n_TAD (the acquisition time, ADCON2.ACQT); `config2`: ADC_CH* & ADC_INT_*
    & ADC_VREF*; `portconfig`: ADC_*ANA. ADC_INT_ON also clears PIR1.ADIF and sets PIE1.ADIE and INTCON.PEIE.

    The two-argument form `OpenADC(config, config2)` is C18's for parts without ACQT (the PIC18F8720 family), with
    the port configuration in `config` (ADC_FOSC_* & ADC_*_JUST & ADC_*ANA) and no acquisition time (ACQT = 000):
    C18 for the PIC18F8680 does not have it, and the kit takes it so that firmware written that way still runs.
    """
    config, config2 = _byte("config", config), _byte("config2", config2)
    if portconfig is None:
        pcfg, acquisition = config & 0x0F, 0
    else:
        pcfg, acquisition = _byte("portconfig", portconfig) & 0x0F, (config << 2) & 0b00111000
    channel = (config2 >> 1) & 0b00111100
    mcu = library_call()
    mcu.write_name("ADCON0", channel)
    mcu.write_name("ADCON1", ((config2 & 0b11) << 4) | pcfg)
    mcu.write_name("ADCON2", (config & _ADFM) | acquisition | ((config >> 4) & 0x07))
    if config2 & 0x80:
        mcu.set_bits("PIR1", 1 << ADIF, False)
        mcu.set_bits("PIE1", 1 << ADIF, True)
        mcu.set_bits("INTCON", PEIE, True)
    mcu.write_name("ADCON0", channel | _ADON)


def SetChanADC(channel: int) -> None:
    """Select the input to convert: `channel` is one of ADC_CH0..ADC_CH15."""
    if not _is_int(channel) or channel not in _CHANNEL_MASKS:
        raise ValueError(f"SetChanADC takes ADC_CH0..ADC_CH15 (C18's masks), not a channel number; got {channel!r}")
    mcu = library_call()
    mcu.write_name("ADCON0", (mcu.read_name("ADCON0") & 0b11000011) | ((channel >> 1) & 0b00111100))


def ConvertADC() -> None:
    """Start a conversion: ADCON0bits.GO = 1."""
    mcu = library_call()
    mcu.write_name("ADCON0", mcu.read_name("ADCON0") | _GO_DONE)


def BusyADC() -> bool:
    """Whether a conversion is in progress (ADCON0bits.GO_DONE)."""
    return bool(library_call().read_name("ADCON0") & _GO_DONE)


def ReadADC() -> int:
    """The result as ADRESH:ADRESL (0..1023 when right-justified)."""
    mcu = library_call()
    return (mcu.read_name("ADRESH") << 8) | mcu.read_name("ADRESL")


def CloseADC() -> None:
    """Switch the A/D off (ADCON0bits.ADON = 0), aborting a conversion in progress."""
    mcu = library_call()
    mcu.write_name("ADCON0", mcu.read_name("ADCON0") & ~_ADON)


# What firmware sees (`from appsim.firmware import *`); the chip side is appsim.chip.adc.ADC.
__all__ = (
    ["OpenADC", "SetChanADC", "ConvertADC", "BusyADC", "ReadADC", "CloseADC",
     "ADC_FOSC_2", "ADC_FOSC_4", "ADC_FOSC_8", "ADC_FOSC_16", "ADC_FOSC_32", "ADC_FOSC_64", "ADC_FOSC_RC",
     "ADC_RIGHT_JUST", "ADC_LEFT_JUST", "ADC_INT_ON", "ADC_INT_OFF",
     *(f"ADC_{n}_TAD" for n in (0, 2, 4, 6, 8, 12, 16, 20)),
     "ADC_VREFPLUS_VDD", "ADC_VREFPLUS_EXT", "ADC_VREFMINUS_VSS", "ADC_VREFMINUS_EXT"]
    + [f"ADC_{n}ANA" for n in (*range(15), 16)]
    + [f"ADC_CH{n}" for n in range(ADC_CHANNELS)]
)
