"""The PIC18F8680's special function registers as its header p18f8680.h names them, and the MCU firmware runs on now.

Pure data (addresses, bit fields) and one seam, `RUNNING_MCU`: imported alike by the chip's models and by the
firmware library, which runs in the grader's sandbox without the simulator.
"""
from __future__ import annotations

import abc
from collections.abc import Sequence
from contextvars import ContextVar
from typing import Any, Protocol

from appsim.chip.ecan import registers as ecan_registers
from appsim.errors import NotOnABoard

Bitfields = dict[str, dict[str, tuple[int, int]]]       # register -> field -> (shift, width)


# ------------------------------------------------------------------ A/D converter
ADC_REGISTERS: dict[str, int] = {"ADRESH": 0xFC4, "ADRESL": 0xFC3, "ADCON0": 0xFC2, "ADCON1": 0xFC1, "ADCON2": 0xFC0}
ADC_BITFIELDS: Bitfields = {
    "ADCON0": {"ADON": (0, 1), "GO_DONE": (1, 1), "GO": (1, 1), "DONE": (1, 1), "CHS": (2, 4),
               "CHS0": (2, 1), "CHS1": (3, 1), "CHS2": (4, 1), "CHS3": (5, 1)},
    "ADCON1": {"PCFG": (0, 4), "PCFG0": (0, 1), "PCFG1": (1, 1), "PCFG2": (2, 1), "PCFG3": (3, 1),
               "VCFG0": (4, 1), "VCFG1": (5, 1)},
    "ADCON2": {"ADCS": (0, 3), "ADCS0": (0, 1), "ADCS1": (1, 1), "ADCS2": (2, 1),
               "ACQT": (3, 3), "ACQT0": (3, 1), "ACQT1": (4, 1), "ACQT2": (5, 1), "ADFM": (7, 1)},
}
ADON, GO_DONE = 0x01, 0x02                  # ADCON0
ADC_CHANNELS = 16                           # AN0..AN15 (CHS3:0) on the 80-pin part
ADFM = 0x80                                 # ADCON2

# ------------------------------------------------------------------ Timer1
TIMER1_REGISTERS: dict[str, int] = {"TMR1H": 0xFCF, "TMR1L": 0xFCE, "T1CON": 0xFCD}
TIMER1_BITFIELDS: Bitfields = {
    "T1CON": {"TMR1ON": (0, 1), "TMR1CS": (1, 1), "T1SYNC": (2, 1), "NOT_T1SYNC": (2, 1), "T1INSYNC": (2, 1),
              "T1OSCEN": (3, 1), "T1CKPS": (4, 2), "T1CKPS0": (4, 1), "T1CKPS1": (5, 1), "RD16": (7, 1)},
}
RD16, T1OSCEN, T1SYNC, TMR1CS, TMR1ON = 0x80, 0x08, 0x04, 0x02, 0x01     # T1CON
T1CKPS = 0x30

# ------------------------------------------------------------------ EUSART
USART_REGISTERS: dict[str, int] = {"TXSTA": 0xFAC, "RCSTA": 0xFAB, "TXREG": 0xFAD, "RCREG": 0xFAE, "SPBRG": 0xFAF,
                                   "BAUDCON": 0xF7E, "SPBRGH": 0xF7F}
USART_BITFIELDS: Bitfields = {
    "TXSTA": {"TX9D": (0, 1), "TRMT": (1, 1), "BRGH": (2, 1), "SENDB": (3, 1), "SYNC": (4, 1), "TXEN": (5, 1),
              "TX9": (6, 1), "CSRC": (7, 1)},
    "RCSTA": {"RX9D": (0, 1), "OERR": (1, 1), "FERR": (2, 1), "ADDEN": (3, 1), "ADEN": (3, 1), "CREN": (4, 1),
              "SREN": (5, 1), "RX9": (6, 1), "SPEN": (7, 1)},
    "BAUDCON": {"ABDEN": (0, 1), "WUE": (1, 1), "BRG16": (3, 1), "SCKP": (4, 1), "RCIDL": (6, 1)},
}
CSRC, TX9, TXEN, SYNC, SENDB, BRGH, TRMT, TX9D = 0x80, 0x40, 0x20, 0x10, 0x08, 0x04, 0x02, 0x01     # TXSTA
SPEN, RX9, SREN, CREN, ADDEN, FERR, OERR, RX9D = 0x80, 0x40, 0x20, 0x10, 0x08, 0x04, 0x02, 0x01     # RCSTA
RCIDL, SCKP, BRG16, WUE, ABDEN = 0x40, 0x10, 0x08, 0x02, 0x01                                      # BAUDCON

# ------------------------------------------------------------------ interrupts
# The core's INTCON, INTCON2, INTCON3 and RCON, and the peripheral flags PIR1/PIE1/IPR1 (PIR3/PIE3/IPR3, the ECAN's,
# are in the ECAN's register map).
INTERRUPT_REGISTERS: dict[str, int] = {"PIE1": 0xF9D, "PIR1": 0xF9E, "IPR1": 0xF9F, "RCON": 0xFD0,
                                       "INTCON3": 0xFF0, "INTCON2": 0xFF1, "INTCON": 0xFF2}
PSPIF, ADIF, RCIF, TXIF, SSPIF, CCP1IF, TMR2IF, TMR1IF = 7, 6, 5, 4, 3, 2, 1, 0          # PIR1 bit numbers
INTERRUPT_SOURCES = ("TMR1", "TMR2", "CCP1", "SSP", "TX", "RC", "AD", "PSP")             # bit 0..7
GIEH, GIEL = 0x80, 0x40                     # INTCON: GIE/GIEH, PEIE/GIEL
GIE, PEIE = GIEH, GIEL
IPEN = 0x80                                 # RCON
HIGH_VECTOR, LOW_VECTOR = 0x08, 0x18        # where the core jumps: high priority (or every source with IPEN = 0), low
VECTOR_NAMES = {HIGH_VECTOR: "the high-priority interrupt routine (@interrupt, vector 0x08)",
                LOW_VECTOR: "the low-priority interrupt routine (@interruptlow, vector 0x18)"}
INTERRUPT_BITFIELDS: Bitfields = {
    **{register: {f"{source}{suffix}": (bit, 1) for bit, source in enumerate(INTERRUPT_SOURCES)}
       for register, suffix in (("PIR1", "IF"), ("PIE1", "IE"), ("IPR1", "IP"))},
    # Each bit under every name MPLAB C18's p18f8680.h gives it (INTCONbits.GIE and INTCONbits.GIEH are one bit).
    "INTCON": {"RBIF": (0, 1), "INT0IF": (1, 1), "INT0F": (1, 1), "TMR0IF": (2, 1), "T0IF": (2, 1), "RBIE": (3, 1),
               "INT0IE": (4, 1), "INT0E": (4, 1), "TMR0IE": (5, 1), "T0IE": (5, 1), "PEIE": (6, 1), "GIEL": (6, 1),
               "GIE": (7, 1), "GIEH": (7, 1)},
    "INTCON2": {"RBIP": (0, 1), "INT3IP": (1, 1), "INT3P": (1, 1), "TMR0IP": (2, 1), "T0IP": (2, 1),
                "INTEDG3": (3, 1), "INTEDG2": (4, 1), "INTEDG1": (5, 1), "INTEDG0": (6, 1), "RBPU": (7, 1),
                "NOT_RBPU": (7, 1)},
    "INTCON3": {"INT1IF": (0, 1), "INT1F": (0, 1), "INT2IF": (1, 1), "INT2F": (1, 1), "INT3IF": (2, 1),
                "INT3F": (2, 1), "INT1IE": (3, 1), "INT1E": (3, 1), "INT2IE": (4, 1), "INT2E": (4, 1),
                "INT3IE": (5, 1), "INT3E": (5, 1), "INT1IP": (6, 1), "INT1P": (6, 1), "INT2IP": (7, 1),
                "INT2P": (7, 1)},
    "RCON": {"BOR": (0, 1), "NOT_BOR": (0, 1), "POR": (1, 1), "NOT_POR": (1, 1), "PD": (2, 1), "NOT_PD": (2, 1),
             "TO": (3, 1), "NOT_TO": (3, 1), "RI": (4, 1), "NOT_RI": (4, 1), "IPEN": (7, 1)},
}

# ------------------------------------------------------------------ PORTJ
PORTJ_REGISTERS: dict[str, int] = {"PORTJ": 0xF88, "LATJ": 0xF91, "TRISJ": 0xF9A}
PORTJ_BITFIELDS: Bitfields = {
    "PORTJ": {f"RJ{n}": (n, 1) for n in range(8)},
    "LATJ": {f"LATJ{n}": (n, 1) for n in range(8)},
    "TRISJ": {f"TRISJ{n}": (n, 1) for n in range(8)},
}

# ------------------------------------------------------------------ the whole chip
ADDRESSES: dict[str, int] = ({r.name: r.address for r in ecan_registers.REGISTERS} | ADC_REGISTERS
                             | TIMER1_REGISTERS | USART_REGISTERS | INTERRUPT_REGISTERS | PORTJ_REGISTERS)
BITFIELDS: Bitfields = (ecan_registers.BITFIELDS | ADC_BITFIELDS | TIMER1_BITFIELDS | USART_BITFIELDS
                        | INTERRUPT_BITFIELDS | PORTJ_BITFIELDS)


class SFRNames(abc.ABC):
    """Registers by their data sheet names, on top of `read` and `write` by address."""

    sfr_addresses: dict[str, int]

    @abc.abstractmethod
    def read(self, address: int, site: int | None = None) -> int: ...
    @abc.abstractmethod
    def write(self, address: int, value: int) -> None: ...

    def read_each(self, addresses: Sequence[int]) -> list[int]:
        """The registers read one after the other, as that many MOVF instructions would (a library's block of reads)."""
        return [self.read(address) for address in addresses]

    def address_of(self, name: str) -> int:
        try:
            return self.sfr_addresses[name]
        except KeyError:
            raise KeyError(f"the PIC18F8680 has no special function register named {name!r}") from None

    def read_name(self, name: str) -> int:
        return self.read(self.address_of(name))

    def write_name(self, name: str, value: int) -> None:
        self.write(self.address_of(name), value)

    def set_bits(self, name: str, mask: int, on: bool) -> None:
        """Set (or clear) the `mask` bits of a register, read-modify-write, as `BSF`/`BCF` on it would."""
        value = self.read_name(name)
        self.write_name(name, value | mask if on else value & ~mask)


class GLCDPort(Protocol):
    """How the GLCD library reaches the board's display module (its driver bit-bangs ports; see board.glcd)."""

    def initial(self) -> None: ...
    def set_cursor(self, line: int, column: int) -> None: ...
    def write(self, codes: list[int]) -> None: ...


class FirmwareMCU(Protocol):
    """The MCU as firmware and its libraries see it: registers (see `SFRNames`), instruction cycles, the display."""

    sfr_addresses: dict[str, int]
    glcd: GLCDPort | None

    def read(self, address: int, site: int | None = None) -> int: ...
    def write(self, address: int, value: int) -> None: ...
    def read_each(self, addresses: Sequence[int]) -> list[int]: ...
    def spend_cycles(self, cycles: int) -> None: ...
    def wait_cycles(self, cycles: int) -> None: ...
    def address_of(self, name: str) -> int: ...
    def read_name(self, name: str) -> int: ...
    def write_name(self, name: str, value: int) -> None: ...
    def set_bits(self, name: str, mask: int, on: bool) -> None: ...
    def wait_for_interrupt(self, loop: str) -> None: ...


RUNNING_MCU: ContextVar[Any] = ContextVar("appsim_running_mcu")


def missing_routine(vector: int) -> str:
    """What a firmware without a routine at `vector` is told when the core vectors there (on a board or sandboxed)."""
    decorator, pragma, why = (("@interrupt", "interrupt", "with INTCONbits.GIE set, every enabled source whose flag "
                               "is set vectors to 0x08 (with RCON.IPEN = 1, those whose IPR bit is 1)")
                              if vector == HIGH_VECTOR else
                              ("@interruptlow", "interruptlow", "with RCON.IPEN = 1, an enabled source whose IPR bit "
                               "is 0 vectors to 0x18 when INTCONbits.GIEH and GIEL are set"))
    return (f"an interrupt was taken at vector 0x{vector:02X}, but the firmware has no {decorator} routine: {why}. "
            f"Mark the function that serves it with {decorator} (as `#pragma {pragma} NAME` does in C18), or leave "
            "that source disabled")


def current_mcu() -> FirmwareMCU:
    """The MCU whose firmware is running now (what `CANSendMessage` and friends act on)."""
    mcu = RUNNING_MCU.get(None)
    if mcu is None:
        raise NotOnABoard(
            "this is firmware: it runs on a simulated board, from main(). "
            "Start it with a board's run(main) (or `appsim board FILE`), not by calling it directly.")
    return mcu
