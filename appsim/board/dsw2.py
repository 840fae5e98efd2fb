"""DSW2, the APP023's 8-position DIP switch: where the USART goes (5 6 -> PIC18F2550 USB, 3 4 -> CON9 RS-232), and
PORTJ.

Positions 1 and 2 are read by firmware on RJ0/RJ1 (ON reads 0, pulled up): the switch drives those PORTJ pins.
"""
from __future__ import annotations

from collections.abc import Iterable

from appsim.chip.mcu import PIC18F8680

POSITIONS = range(1, 9)
USB, CON9 = "usb", "con9"
_PAIRS = {USB: (5, 6), CON9: (3, 4)}
_PLACES = {USB: "PIC18F2550 USB", CON9: "CON9 RS-232"}


class DSW2:
    """The switch bank. Default as the workshop needs it: 5 and 6 ON (USART to the USB-CDC monitor), others OFF.

    The USART reaches the PIC18F2550 when 5 and 6 are ON and 3 and 4 OFF, and CON9 when 3 and 4 are ON
    and 5 and 6 OFF. Any other setting of 3..6 (both pairs, half a pair, none) connects it to nothing
    usable: bytes sent go nowhere and nothing is received (the kit's convention; the workshop only says
    which pair to set). `routing` says so in words. Positions 7 and 8 are not connected.
    """

    def __init__(self, mcu: PIC18F8680, on: Iterable[int] = (5, 6)):
        self.mcu = mcu
        self._on: frozenset[int] = frozenset()
        self._route: str | None = None      # where the USART goes with `_on` (looked at for every byte sent)
        self.set(on)

    def on(self, *positions: int) -> None:
        """Switch `positions` ON."""
        self._switched(self._on | frozenset(_checked(positions)))

    def off(self, *positions: int) -> None:
        """Switch `positions` OFF."""
        self._switched(self._on - frozenset(_checked(positions)))

    def set(self, on: Iterable[int]) -> None:
        """Switch exactly the positions in `on` ON and the others OFF."""
        self._switched(frozenset(_checked(tuple(on))))

    def _switched(self, on: frozenset[int]) -> None:
        self._on = on
        self._route = next((route for route, pair in _PAIRS.items()
                            if set(pair) <= on and not set(_PAIRS[CON9 if route == USB else USB]) & on), None)
        self.mcu.changed()

    def is_on(self, position: int) -> bool:
        return _checked((position,))[0] in self._on

    def levels(self) -> int:
        """What positions 1 and 2 put on RJ0 and RJ1 (pulled up: OFF reads 1), the other PORTJ pins 0."""
        return sum((not self.is_on(position)) << (position - 1) for position in (1, 2))

    @property
    def route(self) -> str | None:
        """Where the USART goes: "usb", "con9", or None (nowhere)."""
        return self._route

    @property
    def routing(self) -> str:
        """The USART's routing in words, with what to change when it goes nowhere."""
        route = self.route
        if route is not None:
            return f"USART -> {_PLACES[route]}"
        usb, con9 = (set(_PAIRS[r]) & self._on for r in (USB, CON9))
        if usb and con9:
            problem = "switches of both pairs are ON, mixing the PIC18F2550 and CON9 paths"
        elif usb or con9:
            half = sorted(usb or con9)
            problem = f"{' '.join(map(str, half))} ON alone: a path needs both switches of its pair"
        else:
            problem = "3 4 and 5 6 are all OFF"
        return (f"USART -> nowhere ({problem}); set 5 6 ON and 3 4 OFF for the USB monitor, "
                f"or 3 4 ON and 5 6 OFF for CON9 RS-232")

    def __str__(self) -> str:
        on = " ".join(str(p) for p in sorted(self._on)) + " ON" if self._on else "all OFF"
        return f"DSW2: {on} ({self.routing})"


def _checked(positions: tuple[int, ...]) -> tuple[int, ...]:
    for position in positions:
        if not isinstance(position, int) or isinstance(position, bool) or position not in POSITIONS:
            raise ValueError(f"DSW2 has positions 1..8; got {position!r}")
    return positions
