"""The PIC18F8680 10-bit A/D converter at register level (ADRESH, ADRESL, ADCON0..2), with the potentiometer on AN0.

Conversions take 11 TAD on the simulated clock; appsim.firmware.adc (C18's adc.h) drives it.
"""
from __future__ import annotations

import numbers
from typing import TYPE_CHECKING, TypeGuard

from appsim.chip.sfr import ADC_CHANNELS, ADC_REGISTERS
from appsim.chip.sfr import ADFM as _ADFM
from appsim.chip.sfr import ADON as _ADON
from appsim.chip.sfr import GO_DONE as _GO_DONE
from appsim.sim import PS_PER_SECOND, Timer

if TYPE_CHECKING:
    from appsim.chip.mcu import PIC18F8680

_ADRESH, _ADRESL, _ADCON0, _ADCON1, _ADCON2 = (ADC_REGISTERS[name]
                                               for name in ("ADRESH", "ADRESL", "ADCON0", "ADCON1", "ADCON2"))
_WRITABLE = {_ADRESH: 0xFF, _ADRESL: 0xFF, _ADCON0: 0x3F, _ADCON1: 0x3F, _ADCON2: 0xBF}   # U-0 bits read 0

CHANNELS = ADC_CHANNELS
FULL_SCALE = 1023                           # a 10-bit code
CONVERSION_TAD = 11                         # TAD per 10-bit conversion
_TAD_TOSC = {0b000: 2, 0b100: 4, 0b001: 8, 0b101: 16, 0b010: 32, 0b110: 64}   # ADCS2:0 -> TAD in Tosc
RC_TAD_PS = 4_000_000                       # ADCS2:0 = x11, the A/D RC oscillator: TAD typically 4 µs


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
        self._registers = {address: 0 for address in ADC_REGISTERS.values()}
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

