"""The PIC18F8680 10-bit A/D converter at register level (ADRESH, ADRESL, ADCON0..2), with the potentiometer on AN0.

A conversion takes the programmed acquisition time (ADCON2.ACQT) and 11 TAD on the simulated clock, then sets
PIR1.ADIF; appsim.firmware.adc (C18's adc.h) drives it.
"""
from __future__ import annotations

import numbers
from typing import TYPE_CHECKING, TypeGuard

from appsim.chip.sfr import ADC_CHANNELS, ADC_REGISTERS, ADIF
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
ACQUISITION_TAD = (0, 2, 4, 6, 8, 12, 16, 20)   # ACQT2:0 -> the acquisition time the A/D adds after GO, in TAD
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
    ADCON2: ADFM (7), ACQT2:0 (5:3), ADCS2:0 (2:0). All reset to 0; unimplemented bits read 0.

    Setting GO/DONE with ADON = 1 begins the acquisition time ACQT2:0 selects (0, 2, 4, 6, 8, 12, 16 or 20 TAD;
    ACQT = 000 is manual acquisition: the conversion begins at once), then samples the selected input and ends the
    conversion 11 TAD later (TAD from ADCS2:0: 2, 4, 8, 16, 32 or 64 Tosc, or the RC oscillator's typical 4 µs):
    ADRESH:ADRESL get the code (right-justified if ADFM = 1, left-justified if 0), GO/DONE clears and PIR1.ADIF
    sets, whatever PIE1.ADIE says (DS30491: "when the conversion is completed, the GO/DONE bit is cleared, the ADIF
    flag is set"). GO/DONE with ADON = 0 does nothing; clearing GO/DONE or ADON mid-conversion aborts it, leaving
    ADRESH:ADRESL as they were and ADIF clear (as on the chip).

    Simplifications, where the kit's firmware never looks:
    - The acquisition or conversion begins at the GO write, not at the A/D clock's next edge: DS30491's timing
      diagrams show up to one TAD more (TCY..TAD) before the first TAD.
    - The minimum TAD and acquisition time are not checked: a too-fast ADCS or a too-short ACQT still converts
      exactly (the input is a code, with no source impedance to settle).
    - Inputs are given as codes (VREF+ = VDD, VREF- = VSS), so VCFG1:0 and PCFG3:0 are plain R/W bits:
      a channel converts regardless of PCFG.
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
        """How long a conversion takes with the present ADCON2, from GO to DONE: the acquisition time ACQT2:0 selects
        and 11 TAD (TAD from ADCS2:0)."""
        adcon2 = self._registers[_ADCON2]
        tosc = _TAD_TOSC.get(adcon2 & 0x07)
        tad_ps = RC_TAD_PS if tosc is None else tosc * PS_PER_SECOND // self.mcu.fosc
        return (ACQUISITION_TAD[(adcon2 >> 3) & 0x07] + CONVERSION_TAD) * tad_ps

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
        """Sample the selected input now and schedule the end of the conversion (the chip holds the input at the end
        of the acquisition time; inputs here change between runs, not within one's few microseconds)."""
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
        self.mcu.interrupts.set_flag(ADIF)      # and the firmware sees the change (or is interrupted)

