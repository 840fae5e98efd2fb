"""The PIC18F8680 10-bit A/D converter at register level (ADRESH, ADRESL, ADCON0..2), with the potentiometer on AN0.

Conversions take 11 TAD on the simulated clock; MPLAB C18's adc.h functions (OpenADC, ConvertADC, ...) drive it.
"""
from __future__ import annotations

import numbers
from typing import TypeGuard

from appsim.chip.mcu import PIC18F8680, library_call
from appsim.sim import PS_PER_SECOND, Timer

_ADRESH, _ADRESL, _ADCON0, _ADCON1, _ADCON2 = 0xFC4, 0xFC3, 0xFC2, 0xFC1, 0xFC0
REGISTERS: tuple[tuple[str, int], ...] = (
    ("ADRESH", _ADRESH), ("ADRESL", _ADRESL), ("ADCON0", _ADCON0), ("ADCON1", _ADCON1), ("ADCON2", _ADCON2))
_WRITABLE = {_ADRESH: 0xFF, _ADRESL: 0xFF, _ADCON0: 0x3F, _ADCON1: 0x3F, _ADCON2: 0xBF}   # U-0 bits read 0

_GO_DONE, _ADON = 0x02, 0x01                # ADCON0
_ADFM = 0x80                                # ADCON2

CHANNELS = 16                               # AN0..AN15 (CHS3:0) on the 80-pin part
FULL_SCALE = 1023                           # a 10-bit code
CONVERSION_TAD = 11                         # TAD per 10-bit conversion
_TAD_TOSC = {0b000: 2, 0b100: 4, 0b001: 8, 0b101: 16, 0b010: 32, 0b110: 64}   # ADCS2:0 -> TAD in Tosc
RC_TAD_PS = 4_000_000                       # ADCS2:0 = x11, the A/D RC oscillator: TAD typically 4 µs

# Bits and fields for C18-style structs (`ADCON0bits.GO`): register -> field -> (shift, width).
BITFIELDS: dict[str, dict[str, tuple[int, int]]] = {
    "ADCON0": {"ADON": (0, 1), "GO_DONE": (1, 1), "GO": (1, 1), "DONE": (1, 1), "CHS": (2, 4),
               "CHS0": (2, 1), "CHS1": (3, 1), "CHS2": (4, 1), "CHS3": (5, 1)},
    "ADCON1": {"PCFG": (0, 4), "PCFG0": (0, 1), "PCFG1": (1, 1), "PCFG2": (2, 1), "PCFG3": (3, 1),
               "VCFG0": (4, 1), "VCFG1": (5, 1)},
    "ADCON2": {"ADCS": (0, 3), "ADCS0": (0, 1), "ADCS1": (1, 1), "ADCS2": (2, 1),
               "ACQT": (3, 3), "ACQT0": (3, 1), "ACQT1": (4, 1), "ACQT2": (5, 1), "ADFM": (7, 1)},
}


def _is_int(value: object) -> TypeGuard[int]:
    return isinstance(value, numbers.Integral) and not isinstance(value, bool)


def _code(channel: int, value: object) -> int:
    what = "the potentiometer on AN0" if channel == 0 else f"AN{channel}"
    if not _is_int(value) or not 0 <= value <= FULL_SCALE:
        raise ValueError(f"{what} gives 0..{FULL_SCALE} (10 bits); got {value!r}")
    return int(value)


def _channel(channel: object) -> int:
    if not _is_int(channel) or not 0 <= channel < CHANNELS:
        raise IndexError(f"the PIC18F8680 has analog inputs AN0..AN{CHANNELS - 1}; got {channel!r}")
    return int(channel)


class AnalogInputs:
    """What AN0..AN15 present to the converter, as the 10-bit code each converts to (0 unless set)."""

    def __init__(self) -> None:
        self._codes = [0] * CHANNELS

    def __getitem__(self, channel: int) -> int:
        return self._codes[_channel(channel)]

    def __setitem__(self, channel: int, code: int) -> None:
        channel = _channel(channel)
        self._codes[channel] = _code(channel, code)

    def __len__(self) -> int:
        return CHANNELS


class ADC:
    """The A/D module of one PIC18F8680, a Peripheral on its SFR bus.

    ADCON0: CHS3:0 (bits 5:2), GO/DONE (1), ADON (0). ADCON1: VCFG1:0 (5:4), PCFG3:0 (3:0).
    ADCON2: ADFM (7), bits 5:3, ADCS2:0 (2:0). All reset to 0; unimplemented bits read 0.

    Setting GO/DONE with ADON = 1 samples the selected input and ends the conversion 11 TAD later
    (TAD from ADCS2:0: 2, 4, 8, 16, 32 or 64 Tosc, or the RC oscillator's typical 4 µs): ADRESH:ADRESL
    get the code (right-justified if ADFM = 1, left-justified if 0) and GO/DONE clears. GO/DONE with
    ADON = 0 does nothing; clearing GO/DONE or ADON mid-conversion aborts it, leaving ADRESH:ADRESL as
    they were (as on the chip).

    Simplifications, where the kit's firmware never looks:
    - Acquisition is manual: DS30491's ADCON2 is taken to hold only ADFM and ADCS2:0, as on the
      PIC18F8720 family (an assumption, not checked against the data sheet). Bits 5:3
      (ACQT2:0 on later PIC18s) are kept as plain R/W bits and add no acquisition time. The minimum
      TAD is not checked: a too-fast ADCS still converts exactly.
    - Inputs are given as codes (VREF+ = VDD, VREF- = VSS), so VCFG1:0 and PCFG3:0 are plain R/W bits:
      a channel converts regardless of PCFG.
    - No PIR1.ADIF / PIE1.ADIE (PIR1 is shared with Timer1 and no interrupts are simulated): firmware
      polls GO/DONE, as the workshop's does with BusyADC().
    """

    def __init__(self, mcu: PIC18F8680):
        self.mcu = mcu
        self.inputs = AnalogInputs()
        self._registers = {address: 0 for _, address in REGISTERS}
        self._conversion: Timer | None = None

    @property
    def potentiometer(self) -> int:
        """The APP023 potentiometer on AN0, as the 10-bit code it converts to (0..1023)."""
        return self.inputs[0]

    @potentiometer.setter
    def potentiometer(self, code: int) -> None:
        self.inputs[0] = code

    def conversion_ps(self) -> int:
        """How long a conversion takes with the present ADCS2:0: 11 TAD."""
        tosc = _TAD_TOSC.get(self._registers[_ADCON2] & 0x07)
        tad_ps = RC_TAD_PS if tosc is None else tosc * PS_PER_SECOND // self.mcu.fosc
        return CONVERSION_TAD * tad_ps

    # -------------------------------------------------------------- the SFR bus
    def read(self, address: int) -> int:
        return self._registers[address]

    def write(self, address: int, value: int) -> None:
        self._registers[address] = value & _WRITABLE[address]
        if address == _ADCON0:
            self._adcon0_written()

    # -------------------------------------------------------------- conversions
    def _adcon0_written(self) -> None:
        if not self._registers[_ADCON0] & _ADON:
            self._registers[_ADCON0] &= ~_GO_DONE
        if not self._registers[_ADCON0] & _GO_DONE:
            if self._conversion is not None:
                self._conversion.cancel()
                self._conversion = None
        elif self._conversion is None:
            self._start()

    def _start(self) -> None:
        """Sample the selected input now and schedule the end of the conversion."""
        sample = self.inputs[(self._registers[_ADCON0] >> 2) & 0x0F]
        self._conversion = self.mcu.sim.call_after(self.conversion_ps(), lambda: self._finish(sample))

    def _finish(self, code: int) -> None:
        self._conversion = None
        if self._registers[_ADCON2] & _ADFM:
            high, low = code >> 8, code & 0xFF
        else:
            high, low = code >> 2, (code & 0x03) << 6
        self._registers[_ADRESH] = high
        self._registers[_ADRESL] = low
        self._registers[_ADCON0] &= ~_GO_DONE
        self.mcu.changed()


def attach_adc(mcu: PIC18F8680) -> ADC:
    """Give `mcu` its A/D module: ADRESH, ADRESL, ADCON0..2 on its SFR bus."""
    if "ADCON0" in mcu.sfr_addresses:
        raise ValueError(f"{mcu.name} already has its A/D module")
    adc = ADC(mcu)
    mcu.map(adc, REGISTERS)
    return adc


# ------------------------------------------------------------------ MPLAB C18 adc.h
# Masks combined with `&`; a field left out keeps its all-ones value. OpenADC(config, config2):
# config = clock & justification & port configuration, config2 = channel & interrupt & references.
ADC_FOSC_2 = 0b10001111
ADC_FOSC_4 = 0b11001111
ADC_FOSC_8 = 0b10011111
ADC_FOSC_16 = 0b11011111
ADC_FOSC_32 = 0b10101111
ADC_FOSC_64 = 0b11101111
ADC_FOSC_RC = 0b11111111

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

ADC_INT_ON = 0b11111111     # ignored: interrupts are not simulated (see OpenADC)
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

_CHANNEL_MASKS = frozenset(0b10000111 | (n << 3) for n in range(CHANNELS))


def _byte(name: str, value: int) -> int:
    if not _is_int(value) or not 0 <= value <= 0xFF:
        raise ValueError(f"{name} is one byte of ADC_... masks combined with &; got {value!r}")
    return int(value)


def OpenADC(config: int, config2: int) -> None:
    """Configure and switch on the A/D (ADCON0..2), aborting a conversion in progress.

    `config`: ADC_FOSC_* & ADC_*_JUST & ADC_*ANA; `config2`: ADC_CH* & ADC_INT_* & ADC_VREF*. C18 also
    sets PIE1.ADIE and INTCON.PEIE for ADC_INT_ON; interrupts are not simulated, so that bit is ignored.
    """
    config, config2 = _byte("config", config), _byte("config2", config2)
    channel = (config2 >> 1) & 0b00111100
    mcu = library_call()
    mcu.write_name("ADCON0", channel)
    mcu.write_name("ADCON1", ((config2 & 0b11) << 4) | (config & 0x0F))
    mcu.write_name("ADCON2", (config & _ADFM) | ((config >> 4) & 0x07))
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


# What firmware sees (`from appsim.firmware import *`); the board side is ADC and attach_adc.
__all__ = (
    ["OpenADC", "SetChanADC", "ConvertADC", "BusyADC", "ReadADC", "CloseADC",
     "ADC_FOSC_2", "ADC_FOSC_4", "ADC_FOSC_8", "ADC_FOSC_16", "ADC_FOSC_32", "ADC_FOSC_64", "ADC_FOSC_RC",
     "ADC_RIGHT_JUST", "ADC_LEFT_JUST", "ADC_INT_ON", "ADC_INT_OFF",
     "ADC_VREFPLUS_VDD", "ADC_VREFPLUS_EXT", "ADC_VREFMINUS_VSS", "ADC_VREFMINUS_EXT"]
    + [f"ADC_{n}ANA" for n in (*range(15), 16)]
    + [f"ADC_CH{n}" for n in range(CHANNELS)]
)
