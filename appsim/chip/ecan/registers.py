"""The PIC18F8680 ECAN special function registers in legacy Mode 0: name, address, reset value, access.

Data only, as the DS39500 register map and bit tables give it; `appsim.chip.ecan.controller` gives it behaviour.
"""
from __future__ import annotations

from dataclasses import dataclass


@dataclass(frozen=True, slots=True)
class Register:
    """One 8-bit SFR.

    `writable` bits take the value written; `clear_only` bits (R/C) are cleared by writing 0 and
    ignore a 1; every other bit is read-only or unimplemented (U-0). `protected` registers can be
    written only in Configuration mode and read as 0 in every other mode; `locked` ones can be written only
    in Configuration mode and read as they are in every mode.
    """

    name: str
    address: int
    reset: int = 0x00
    writable: int = 0xFF
    clear_only: int = 0x00
    protected: bool = False
    locked: bool = False


# Offsets of a message buffer block (TXBn, RXBn): CON, SIDH, SIDL, EIDH, EIDL, DLC, D0..D7.
BUFFER_FIELDS = ("CON", "SIDH", "SIDL", "EIDH", "EIDL", "DLC") + tuple(f"D{m}" for m in range(8))
BUFFER_BASE = {"RXB0": 0xF60, "RXB1": 0xF50, "TXB0": 0xF40, "TXB1": 0xF30, "TXB2": 0xF20}
TX_BUFFERS = ("TXB0", "TXB1", "TXB2")
RX_BUFFERS = ("RXB0", "RXB1")

# CANCON.WIN<2:0> (and the matching CANSTAT.ICODE<2:0>) -> buffer mapped onto F60h..F6Dh.
WINDOW = {0b000: "RXB0", 0b001: "RXB0", 0b010: "TXB2", 0b011: "TXB1",
          0b100: "TXB0", 0b101: "RXB1", 0b110: "RXB0", 0b111: "RXB0"}
WINDOW_FIRST, WINDOW_LAST = 0xF60, 0xF6D

# Access of the buffer registers after the CON byte, by field (DS39500 §9.2).
_TX_FIELD_ACCESS = {"SIDL": 0xEB, "DLC": 0x4F}          # SID2:0, EXIDE, EID17:16 / TXRTR, DLC3:0
# An RX buffer's identifier, DLC and data are read-only: only a received frame writes them (DS39500 gives R/W-x,
# the PIC18F8680 data sheet R-x).
_RX_FIELD_WRITABLE = 0x00


def _buffer_registers() -> list[Register]:
    registers = []
    for buffer, base in BUFFER_BASE.items():
        is_tx = buffer.startswith("TX")
        for offset, field in enumerate(BUFFER_FIELDS):
            if field == "CON":
                if is_tx:   # TXABT TXLARB TXERR read-only; TXREQ, TXPRI1:0 R/W
                    registers.append(Register(f"{buffer}CON", base, writable=0x0B))
                elif buffer == "RXB0":   # RXFUL R/C; RXM1:0, RXB0DBEN R/W; RXRTRRO JTOFF FILHIT0 R
                    registers.append(Register("RXB0CON", base, writable=0x64, clear_only=0x80))
                else:                    # RXFUL R/C; RXM1:0 R/W; RXRTRRO FILHIT2:0 R
                    registers.append(Register("RXB1CON", base, writable=0x60, clear_only=0x80))
            else:
                registers.append(Register(f"{buffer}{field}", base + offset,
                                          writable=_TX_FIELD_ACCESS.get(field, 0xFF) if is_tx
                                          else _RX_FIELD_WRITABLE))
    return registers


def _acceptance_registers() -> list[Register]:
    registers = []
    for n in range(6):
        for offset, field in enumerate(("SIDH", "SIDL", "EIDH", "EIDL")):
            registers.append(Register(f"RXF{n}{field}", 0xF00 + 4 * n + offset, protected=True,
                                      writable=0xEB if field == "SIDL" else 0xFF))
    for n in range(2):   # a mask has no EXIDEN: RXMnSIDL<4:2> are unimplemented
        for offset, field in enumerate(("SIDH", "SIDL", "EIDH", "EIDL")):
            registers.append(Register(f"RXM{n}{field}", 0xF18 + 4 * n + offset, protected=True,
                                      writable=0xE3 if field == "SIDL" else 0xFF))
    return registers


REGISTERS: tuple[Register, ...] = tuple(
    _acceptance_registers()
    + _buffer_registers()
    + [
        Register("CANSTATRO4", 0xF2E, reset=0x80, writable=0x00),
        Register("CANSTATRO3", 0xF3E, reset=0x80, writable=0x00),
        Register("CANSTATRO2", 0xF4E, reset=0x80, writable=0x00),
        Register("CANSTATRO1", 0xF5E, reset=0x80, writable=0x00),
        Register("CANSTAT", 0xF6E, reset=0x80, writable=0x00),
        Register("CANCON", 0xF6F, reset=0x80, writable=0xFE),
        Register("BRGCON1", 0xF70, protected=True),
        Register("BRGCON2", 0xF71, protected=True),
        Register("BRGCON3", 0xF72, writable=0xC7, protected=True),   # WAKDIS, WAKFIL, SEG2PH2:0
        # ENDRHI, CANCAP (PIC18F8680). DS39500 names no register list for "all control registers" that
        # Configuration mode locks; DS30475A's reading, that CIOCON is one of them, is taken (it reads in any mode).
        Register("CIOCON", 0xF73, writable=0x30, locked=True),
        Register("COMSTAT", 0xF74, writable=0x00, clear_only=0xC0),  # RXB0OVFL, RXB1OVFL are R/C
        Register("RXERRCNT", 0xF75, writable=0x00),
        Register("TXERRCNT", 0xF76, writable=0x00),
        Register("ECANCON", 0xF77),
        Register("PIE3", 0xFA3),
        Register("PIR3", 0xFA4),
        Register("IPR3", 0xFA5, reset=0xFF),
    ]
)

BY_NAME: dict[str, Register] = {r.name: r for r in REGISTERS}
BY_ADDRESS: dict[int, Register] = {r.address: r for r in REGISTERS}

# Bits, by the datasheet's names.
REQOP_MASK = 0xE0       # CANCON<7:5>, CANSTAT.OPMODE<7:5>
ABAT = 0x10
WIN_MASK = 0x0E
ICODE_MASK = 0x0E
TXABT, TXLARB, TXERR, TXREQ, TXPRI_MASK = 0x40, 0x20, 0x10, 0x08, 0x03
RXFUL, RXM_MASK, RXRTRRO, RXB0DBEN, JTOFF = 0x80, 0x60, 0x08, 0x04, 0x02
EXIDE = 0x08            # TXBnSIDL<3>; RXFnSIDL.EXIDEN and RXBnSIDL.EXID sit on the same bit
SRR = 0x10              # RXBnSIDL<4>
TXRTR = RXRTR = 0x40    # TXBnDLC<6>, RXBnDLC<6>
RXB0OVFL, RXB1OVFL, TXBO, TXBP, RXBP, TXWARN, RXWARN, EWARN = (0x80, 0x40, 0x20, 0x10,
                                                              0x08, 0x04, 0x02, 0x01)
IRXIF, WAKIF, ERRIF, TXB2IF, TXB1IF, TXB0IF, RXB1IF, RXB0IF = (0x80, 0x40, 0x20, 0x10,
                                                              0x08, 0x04, 0x02, 0x01)
TXBIF = {"TXB0": TXB0IF, "TXB1": TXB1IF, "TXB2": TXB2IF}
RXBIF = {"RXB0": RXB0IF, "RXB1": RXB1IF}
MDSEL_MASK = 0xC0       # ECANCON<7:6>

# Bit fields as the C18 header names them (`RXB0CONbits.RXFUL`): field -> (shift, width).
_SIDL = {"SID": (5, 3), "SID2": (7, 1), "SID1": (6, 1), "SID0": (5, 1), "EID17": (1, 1), "EID16": (0, 1)}
_INTERRUPTS = ("IRX", "WAK", "ERR", "TXB2", "TXB1", "TXB0", "RXB1", "RXB0")


def _single_bits(*names: str) -> dict[str, tuple[int, int]]:
    """Names of bits 7..0, '' for an unimplemented bit."""
    return {name: (7 - i, 1) for i, name in enumerate(names) if name}


def _field(name: str, shift: int, width: int) -> dict[str, tuple[int, int]]:
    """A multi-bit field and its single bits (REQOP, REQOP2, REQOP1, REQOP0)."""
    return {name: (shift, width)} | {f"{name}{b}": (shift + b, 1) for b in range(width)}


BITFIELDS: dict[str, dict[str, tuple[int, int]]] = {
    "CANCON": _field("REQOP", 5, 3) | {"ABAT": (4, 1)} | _field("WIN", 1, 3),
    "CANSTAT": _field("OPMODE", 5, 3) | _field("ICODE", 1, 3),
    "COMSTAT": _single_bits("RXB0OVFL", "RXB1OVFL", "TXBO", "TXBP", "RXBP", "TXWARN", "RXWARN", "EWARN"),
    "RXB0CON": _single_bits("RXFUL", "", "", "", "RXRTRRO", "RXB0DBEN", "JTOFF", "FILHIT0")
    | _field("RXM", 5, 2),
    "RXB1CON": _single_bits("RXFUL", "", "", "", "RXRTRRO") | _field("RXM", 5, 2) | _field("FILHIT", 0, 3),
    "BRGCON1": _field("SJW", 6, 2) | _field("BRP", 0, 6),
    "BRGCON2": _single_bits("SEG2PHTS", "SAM") | _field("SEG1PH", 3, 3) | _field("PRSEG", 0, 3),
    "BRGCON3": _single_bits("WAKDIS", "WAKFIL") | _field("SEG2PH", 0, 3),
    "CIOCON": _single_bits("", "", "ENDRHI", "CANCAP"),
    "ECANCON": _field("MDSEL", 6, 2) | {"FIFOWM": (5, 1)} | _field("EWIN", 0, 5),
    "PIR3": _single_bits(*(f"{n}IF" for n in _INTERRUPTS)),
    "PIE3": _single_bits(*(f"{n}IE" for n in _INTERRUPTS)),
    "IPR3": _single_bits(*(f"{n}IP" for n in _INTERRUPTS)),
}
for _n in range(3):
    BITFIELDS[f"TXB{_n}CON"] = _single_bits("", "TXABT", "TXLARB", "TXERR", "TXREQ") | _field("TXPRI", 0, 2)
    BITFIELDS[f"TXB{_n}SIDL"] = _SIDL | {"EXIDE": (3, 1)}
    BITFIELDS[f"TXB{_n}DLC"] = {"TXRTR": (6, 1)} | _field("DLC", 0, 4)
for _n in range(2):
    BITFIELDS[f"RXB{_n}SIDL"] = _SIDL | {"SRR": (4, 1), "EXID": (3, 1)}
    BITFIELDS[f"RXB{_n}DLC"] = _single_bits("", "RXRTR", "RB1", "RB0") | _field("DLC", 0, 4)
    BITFIELDS[f"RXM{_n}SIDL"] = dict(_SIDL)
for _n in range(6):
    BITFIELDS[f"RXF{_n}SIDL"] = _SIDL | {"EXIDEN": (3, 1)}
