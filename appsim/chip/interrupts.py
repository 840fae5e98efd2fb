"""The PIC18F8680's interrupt logic: INTCON, INTCON2, INTCON3, RCON.IPEN and PIR1/PIE1/IPR1 (PIR3/PIE3/IPR3 live in the
ECAN), deciding which vector the core takes, and the global enables it clears on entry and RETFIE sets again.

Peripherals set latched flags (TMR1IF, ADIF) or provide status flags (TXIF, RCIF); the core (appsim.chip.mcu) vectors.
"""
from __future__ import annotations

from collections.abc import Callable, Mapping
from typing import TYPE_CHECKING

from appsim.chip.ecan import registers as ecan_registers
from appsim.chip.sfr import (
    GIEH,
    GIEL,
    HIGH_VECTOR,
    INTERRUPT_BITFIELDS,
    INTERRUPT_REGISTERS,
    INTERRUPT_SOURCES,
    IPEN,
    LOW_VECTOR,
)

if TYPE_CHECKING:
    from appsim.chip.mcu import PIC18F8680

_PIE1, _PIR1, _IPR1, _RCON, _INTCON3, _INTCON2, _INTCON = (
    INTERRUPT_REGISTERS[name] for name in ("PIE1", "PIR1", "IPR1", "RCON", "INTCON3", "INTCON2", "INTCON"))
FLAG_NAMES: dict[int, str] = {bit: f"{source}IF" for bit, source in enumerate(INTERRUPT_SOURCES)}
INTERRUPT_LATENCY_CYCLES = 3        # from the flag to the first instruction at the vector, for an internal source
RETFIE_CYCLES = 2
RESETS = {_PIE1: 0x00, _IPR1: 0xFF, _RCON: 0x1C, _INTCON3: 0xC0, _INTCON2: 0xFF, _INTCON: 0x00}
_RCON_WRITABLE = 0x93               # IPEN, RI, POR, BOR; TO and PD are read-only, bits 6:5 unimplemented

# The core's own sources, as (name, flag, enable, priority): each a (register, bit); INT0 has no priority bit (high).
_CORE = (("RB", (_INTCON, 0), (_INTCON, 3), (_INTCON2, 0)), ("INT0", (_INTCON, 1), (_INTCON, 4), None),
         ("TMR0", (_INTCON, 2), (_INTCON, 5), (_INTCON2, 2)), ("INT1", (_INTCON3, 0), (_INTCON3, 3), (_INTCON3, 6)),
         ("INT2", (_INTCON3, 1), (_INTCON3, 4), (_INTCON3, 7)), ("INT3", (_INTCON3, 2), (_INTCON3, 5), (_INTCON2, 1)))
_ECAN_SOURCES = tuple(name[:-2] for name, _ in sorted(ecan_registers.BITFIELDS["PIR3"].items(),
                                                      key=lambda item: item[1][0]))    # bit 0..7: RXB0 .. IRX


def _bit_name(register: str, field_bit: int, suffix: str) -> str:
    """`PIE1bits.TMR1IE`: the C18 name of bit `field_bit` of PIR1/PIE1/IPR1-style `register`."""
    sources = INTERRUPT_SOURCES if register[-1] == "1" else _ECAN_SOURCES
    return f"{register}bits.{sources[field_bit]}{suffix}"


def _core_name(register: int, bit: int) -> str:
    name = next(n for n, a in INTERRUPT_REGISTERS.items() if a == register)
    field = next(f for f, (shift, _) in INTERRUPT_BITFIELDS[name].items() if shift == bit)
    return f"{name}bits.{field}"


class Interrupts:
    """The interrupt logic of one MCU, a Peripheral on its SFR bus (INTCON, INTCON2, INTCON3, RCON, PIR1/PIE1/IPR1).

    Reset values as the data sheet gives them: INTCON = 0x00, INTCON2 = 0xFF, INTCON3 = 0xC0, RCON = 0x1C (RI, TO, PD
    set after a power-on reset), PIR1 = PIE1 = 0x00, IPR1 = 0xFF (all high priority). A latched flag (TMR1IF, ADIF) is
    set by its peripheral through `set_flag` and stays set until firmware writes 0 to it; firmware may also set it by
    writing 1, and then it interrupts as the peripheral's would. A status flag given to `provide` (TXIF = TXREG empty,
    RCIF = receive FIFO not empty) follows the peripheral's state: it reads what the peripheral says and ignores writes.
    INTCON's, INTCON2's and INTCON3's bits are plain R/W bits; nothing on the APP023 drives INT0..INT3 or PORTB's
    change interrupt, and the kit models no Timer0, so their flags are set only by firmware that writes them.

    `request()` is the vector the core takes: with RCON.IPEN = 0 (compatibility mode) every source goes to 0x08,
    INTCON.GIE enabling all of them and INTCON.PEIE the peripherals' too; with IPEN = 1, a source whose priority bit
    is set goes to 0x08 when GIEH is set, the others to 0x18 when GIEH and GIEL are. Entering a routine clears GIE (or
    GIEH, or GIEL for a low-priority one) and RETFIE sets it again: a routine is never entered again while it runs,
    nor pre-empted by one of its own or a lower priority, but a high-priority source pre-empts a low-priority routine.
    """

    def __init__(self, mcu: PIC18F8680):
        self.mcu = mcu
        self._latched = 0
        self._status: dict[int, Callable[[], bool]] = {}
        self._registers = dict(RESETS)
        self.armed = False              # INTCON.GIE/GIEH: whether any interrupt can be taken now
        self.requested = False          # an interrupt the core takes before its next instruction (see PIC18F8680)
        self.routines: dict[int, Callable[[], object]] = {}     # vector -> the firmware's routine there
        self.in_service: list[int] = []     # the vectors of the routines running, the innermost last

    def provide(self, bit: int, status: Callable[[], bool]) -> None:
        """Make PIR1 bit `bit` a read-only flag that reads `status()`."""
        if bit in self._status:
            raise ValueError(f"PIR1 bit {bit} ({FLAG_NAMES[bit]}) already has a peripheral behind it")
        self._status[bit] = status

    def set_flag(self, bit: int) -> None:
        """A peripheral event sets latched PIR1 bit `bit` (and wakes a polling firmware, or interrupts it)."""
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
        return self._registers[address]

    def write(self, address: int, value: int) -> None:
        if address == _PIR1:
            status_bits = sum(1 << bit for bit in self._status)
            self._latched = value & ~status_bits
            return
        if address == _RCON:
            value = (self._registers[_RCON] & ~_RCON_WRITABLE) | (value & _RCON_WRITABLE)
        self._registers[address] = value
        if address == _INTCON:
            self.armed = bool(value & GIEH)

    # -------------------------------------------------------------- what the core does with them
    def _groups(self) -> tuple[int, int, int, int]:
        """The pending sources (flag and enable set) as (core, core priorities, peripheral, peripheral priorities):
        bit masks whose high parts stand for PIR3's and INTCON3's sources."""
        registers = self._registers
        core = core_priority = 0
        for index, (_, (flag_at, flag), (enable_at, enable), priority) in enumerate(_CORE):
            if registers[flag_at] >> flag & registers[enable_at] >> enable & 1:
                core |= 1 << index
                if priority is None or registers[priority[0]] >> priority[1] & 1:
                    core_priority |= 1 << index
        pir3, pie3, ipr3 = self.mcu.ecan.interrupt_registers()
        peripheral = (self.pir1 & registers[_PIE1]) | (pir3 & pie3) << 8
        return core, core_priority, peripheral, registers[_IPR1] | ipr3 << 8

    def request(self) -> int:
        """The vector the core takes before its next instruction (HIGH_VECTOR, LOW_VECTOR), or 0 for none."""
        intcon = self._registers[_INTCON]
        if not intcon & GIEH:
            return 0
        core, core_priority, peripheral, peripheral_priority = self._groups()
        if not self._registers[_RCON] & IPEN:
            return HIGH_VECTOR if core or (peripheral and intcon & GIEL) else 0
        if core & core_priority or peripheral & peripheral_priority:
            return HIGH_VECTOR
        if intcon & GIEL and (core & ~core_priority or peripheral & ~peripheral_priority):
            return LOW_VECTOR
        return 0

    def enter(self, vector: int) -> None:
        """The core vectors: GIE (compatibility mode), GIEH (a high-priority source) or GIEL (a low one) clears."""
        self._registers[_INTCON] &= ~(GIEL if vector == LOW_VECTOR else GIEH)
        self.armed = bool(self._registers[_INTCON] & GIEH)
        self.in_service.append(vector)

    def retfie(self) -> int:
        """RETFIE of the innermost routine: it sets the enable its entry cleared; the vector it returns from."""
        vector = self.in_service.pop()
        self._registers[_INTCON] |= GIEL if vector == LOW_VECTOR else GIEH
        self.armed = bool(self._registers[_INTCON] & GIEH)
        return vector

    def reset(self, routines: Mapping[int, Callable[[], object]]) -> None:
        """A new firmware starts, with these routines: none is running, none requested."""
        self.routines = dict(routines)
        self.in_service.clear()
        self.requested = False

    # -------------------------------------------------------------- in the workshop's words
    def pending(self) -> str:
        """The sources pending now (flag and enable set), by their C18 names: `PIR1bits.TMR1IF`."""
        registers = self._registers
        names = [_core_name(flag_at, flag) for _, (flag_at, flag), (enable_at, enable), _ in _CORE
                 if registers[flag_at] >> flag & registers[enable_at] >> enable & 1]
        pir3, pie3, _ = self.mcu.ecan.interrupt_registers()
        for register, flags in (("PIR1", self.pir1 & registers[_PIE1]), ("PIR3", pir3 & pie3)):
            names += [_bit_name(register, bit, "IF") for bit in range(8) if flags >> bit & 1]
        return ", ".join(names) or "nothing"

    def why_none_can_come(self) -> str | None:
        """Why no interrupt can ever be taken as things stand (no global enable, no source enabled), in the firmware's
        words; None if one can."""
        registers = self._registers
        intcon, ipen = registers[_INTCON], bool(registers[_RCON] & IPEN)
        if not intcon & GIEH:
            if self.in_service:
                return ("INTCONbits.GIE is cleared while an interrupt routine runs (the core cleared it on entry; "
                        "RETFIE sets it again when the routine returns), so nothing can interrupt it")
            return f"INTCONbits.{'GIEH' if ipen else 'GIE'} is 0: no interrupt is taken at all"
        core = [(_core_name(enable_at, enable), priority is None or registers[priority[0]] >> priority[1] & 1)
                for _, _, (enable_at, enable), priority in _CORE if registers[enable_at] >> enable & 1]
        _, pie3, ipr3 = self.mcu.ecan.interrupt_registers()
        peripheral = [(_bit_name(register, bit, "IE"), priorities >> bit & 1)
                      for register, enables, priorities in (("PIE1", registers[_PIE1], registers[_IPR1]),
                                                            ("PIE3", pie3, ipr3))
                      for bit in range(8) if enables >> bit & 1]
        if not core and not peripheral:
            return ("no interrupt source is enabled: PIE1, PIE3 and INTCON's, INTCON3's enable bits are all 0 (set "
                    "PIE1bits.TMR1IE, PIE3bits.RXB0IE ... for the sources the routine serves)")
        if not ipen:
            if core or intcon & GIEL:
                return None
            return (f"{', '.join(name for name, _ in peripheral)} {'is' if len(peripheral) == 1 else 'are'} set, but "
                    "INTCONbits.PEIE is 0: with RCON.IPEN = 0 a peripheral's interrupt needs GIE and PEIE")
        if any(high for _, high in core + peripheral) or intcon & GIEL:
            return None
        return (f"only low-priority sources are enabled ({', '.join(name for name, _ in core + peripheral)}, their "
                "IPR bits 0) and INTCONbits.GIEL is 0")
