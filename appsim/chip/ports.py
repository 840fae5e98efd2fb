"""PORTJ of the PIC18F8680 (PORTJ, LATJ, TRISJ): eight pins that read the board's levels as inputs, LATJ as outputs.

Only PORTJ is modelled, for the APP023's DSW2 switches on RJ0 and RJ1; the board drives the input levels.
"""
from __future__ import annotations

from collections.abc import Callable

from appsim.chip.sfr import PORTJ_REGISTERS

_PORTJ, _LATJ, _TRISJ = (PORTJ_REGISTERS[name] for name in ("PORTJ", "LATJ", "TRISJ"))


class PortJ:
    """PORTJ, LATJ and TRISJ: a Peripheral on the SFR bus.

    TRISJ resets to 0xFF (all inputs). An input pin reads the level the board puts on it (`levels`; a pin
    nothing drives reads 0). An output pin reads back its LATJ bit; writing PORTJ writes LATJ, as on the chip.
    """

    def __init__(self) -> None:
        self._latch = 0
        self._tris = 0xFF
        self.levels: Callable[[], int] = lambda: 0     # RJ7..RJ0 as the board drives them

    def read(self, address: int) -> int:
        if address == _PORTJ:
            return (self.levels() & self._tris) | (self._latch & ~self._tris & 0xFF)
        return self._latch if address == _LATJ else self._tris

    def write(self, address: int, value: int) -> None:
        if address == _TRISJ:
            self._tris = value
        else:
            self._latch = value
