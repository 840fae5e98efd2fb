"""Microchip AN738, the PIC18 CAN library of the workshop, in Python: same names, values and quirks.

What AN738 makes a macro (CANIsRxReady(), CANIsTxReady(), CANAbortAll() ...) costs its register accesses only, as in C;
the functions also cost their CALL (`library_call`).

Every function acts only through the ECAN registers of the board it runs on, as the C library does;
where the C library would silently corrupt a frame or hang, this one raises `AN738Error` instead.
"""
from __future__ import annotations

import enum
import operator
from collections.abc import Sequence
from typing import NamedTuple

from appsim.chip.ecan import registers as R
from appsim.chip.ecan.acceptance import pack_id, unpack_id
from appsim.chip.sfr import FirmwareMCU, current_mcu
from appsim.errors import AN738Error
from appsim.firmware.runtime import library_call

macro = current_mcu     # AN738's macros (CANIsRxReady, CANIsTxReady, ...): their register accesses, and no call

TRUE, FALSE = True, False


class CAN_OP_MODE(enum.IntEnum):
    CAN_OP_MODE_BITS = 0b11100000       # mask for the mode bits
    CAN_OP_MODE_NORMAL = 0b00000000
    CAN_OP_MODE_SLEEP = 0b00100000
    CAN_OP_MODE_LOOP = 0b01000000
    CAN_OP_MODE_LISTEN = 0b01100000
    CAN_OP_MODE_CONFIG = 0b10000000


class CAN_CONFIG_FLAGS:
    """Combined with `&`; each field's default is the all-ones value."""

    CAN_CONFIG_DEFAULT = 0b11111111
    CAN_CONFIG_PHSEG2_PRG_BIT = 0b00000001
    CAN_CONFIG_PHSEG2_PRG_ON = 0b11111111
    CAN_CONFIG_PHSEG2_PRG_OFF = 0b11111110
    CAN_CONFIG_LINE_FILTER_BIT = 0b00000010
    CAN_CONFIG_LINE_FILTER_ON = 0b11111111
    CAN_CONFIG_LINE_FILTER_OFF = 0b11111101
    CAN_CONFIG_SAMPLE_BIT = 0b00000100
    CAN_CONFIG_SAMPLE_ONCE = 0b11111111
    CAN_CONFIG_SAMPLE_THRICE = 0b11111011
    CAN_CONFIG_MSG_TYPE_BIT = 0b00001000
    CAN_CONFIG_STD_MSG = 0b11111111
    CAN_CONFIG_XTD_MSG = 0b11110111
    CAN_CONFIG_DBL_BUFFER_BIT = 0b00010000
    CAN_CONFIG_DBL_BUFFER_ON = 0b11111111
    CAN_CONFIG_DBL_BUFFER_OFF = 0b11101111
    CAN_CONFIG_MSG_BITS = 0b01100000
    CAN_CONFIG_ALL_MSG = 0b11111111
    CAN_CONFIG_VALID_XTD_MSG = 0b11011111
    CAN_CONFIG_VALID_STD_MSG = 0b10111111
    CAN_CONFIG_ALL_VALID_MSG = 0b10011111


class CAN_TX_MSG_FLAGS:
    """Combined with `&`; defaults are priority 3, standard identifier, data frame."""

    CAN_TX_PRIORITY_BITS = 0b00000011
    CAN_TX_PRIORITY_0 = 0b11111100
    CAN_TX_PRIORITY_1 = 0b11111101
    CAN_TX_PRIORITY_2 = 0b11111110
    CAN_TX_PRIORITY_3 = 0b11111111
    CAN_TX_FRAME_BIT = 0b00001000
    CAN_TX_STD_FRAME = 0b11111111
    CAN_TX_XTD_FRAME = 0b11110111
    CAN_TX_RTR_BIT = 0b01000000
    CAN_TX_NO_RTR_FRAME = 0b11111111
    CAN_TX_RTR_FRAME = 0b10111111


class CAN_RX_MSG_FLAGS:
    """Bits set by CANReceiveMessage, tested with `&`; the low three bits are the filter number."""

    CAN_RX_FILTER_BITS = 0b00000111
    CAN_RX_FILTER_1 = 0
    CAN_RX_FILTER_2 = 1
    CAN_RX_FILTER_3 = 2
    CAN_RX_FILTER_4 = 3
    CAN_RX_FILTER_5 = 4
    CAN_RX_FILTER_6 = 5
    CAN_RX_OVERFLOW = 0b00001000
    CAN_RX_INVALID_MSG = 0b00010000
    CAN_RX_XTD_FRAME = 0b00100000
    CAN_RX_RTR_FRAME = 0b01000000
    CAN_RX_DBL_BUFFERED = 0b10000000


class CAN_MASK(enum.IntEnum):
    CAN_MASK_B1 = 0     # RXM0, the mask of RXB0
    CAN_MASK_B2 = 1     # RXM1, the mask of RXB1


class CAN_FILTER(enum.IntEnum):
    CAN_FILTER_B1_F1 = 0    # RXF0
    CAN_FILTER_B1_F2 = 1    # RXF1
    CAN_FILTER_B2_F1 = 2    # RXF2
    CAN_FILTER_B2_F2 = 3    # RXF3
    CAN_FILTER_B2_F3 = 4    # RXF4
    CAN_FILTER_B2_F4 = 5    # RXF5


# Every enumerator also as a plain name, as C puts them in scope.
globals().update({name: value for group in (CAN_CONFIG_FLAGS, CAN_TX_MSG_FLAGS, CAN_RX_MSG_FLAGS)
                  for name, value in vars(group).items() if name.startswith("CAN_")})
globals().update({m.name: m for group in (CAN_OP_MODE, CAN_MASK, CAN_FILTER) for m in group})

# Register addresses, resolved from the register map once rather than by name on every call.
(_BRGCON1, _BRGCON2, _BRGCON3, _CANCON, _CANSTAT, _COMSTAT, _PIR3, _RXB0CON, _RXB0D0, _RXB0DLC, _RXB0EIDH,
 _RXB0EIDL, _RXB0SIDH, _RXB0SIDL, _RXB1CON, _RXERRCNT, _TXERRCNT) = (R.BY_NAME[name].address for name in (
    "BRGCON1", "BRGCON2", "BRGCON3", "CANCON", "CANSTAT", "COMSTAT", "PIR3", "RXB0CON", "RXB0D0", "RXB0DLC",
    "RXB0EIDH", "RXB0EIDL", "RXB0SIDH", "RXB0SIDL", "RXB1CON", "RXERRCNT", "TXERRCNT"))
_TXB_CON = tuple(R.BY_NAME[buffer + "CON"].address for buffer in R.TX_BUFFERS)        # TXB0CON, TXB1CON, TXB2CON
_TX_WINDOWS = tuple(zip(_TXB_CON, (0b100, 0b011, 0b010), strict=True))               # (TXBnCON, CANCON.WIN)
_RXM_SIDH = tuple(R.BY_NAME[f"RXM{n}SIDH"].address for n in range(2))
_RXF_SIDH = tuple(R.BY_NAME[f"RXF{n}SIDH"].address for n in range(6))
_WIN_RXB1 = 0b101
_DLC_AND_ID = (_RXB0DLC, _RXB0SIDL, _RXB0SIDH, _RXB0EIDH, _RXB0EIDL)   # a received frame's, in the library's order
_DATA = tuple(_RXB0D0 + i for i in range(8))
_MODES = {m.value: m.name for m in CAN_OP_MODE if m is not CAN_OP_MODE.CAN_OP_MODE_BITS}


class CANMessage(NamedTuple):
    """What CANReceiveMessage gives back: unpacks as `id, data, length, flags`.

    It is false when no buffer was full (the C function's FALSE), so `if msg:` works too.
    `length` is the raw DLC, as AN738 returns it (9..15 stay 9..15); `data` has at most 8 bytes.
    """

    id: int
    data: bytes
    length: int
    flags: int

    def __bool__(self) -> bool:
        return self.flags != -1


NO_MESSAGE = CANMessage(0, b"", 0, -1)


def _window(mcu: FirmwareMCU, win: int) -> None:
    """CANCON.WIN = win, by read-modify-write as the library does (`CANCON &= 0b11110001; |= ...`)."""
    mcu.write(_CANCON, (mcu.read(_CANCON) & 0b11110001) | (win << 1))


def _integer(value: object) -> int | None:
    """`value` as C would take an integer argument: an int, an IntEnum member, anything with __index__; else None."""
    try:
        return operator.index(value)        # type: ignore[arg-type]
    except Exception:                       # its __index__ may raise anything
        return None


def _shown(value: object) -> str:
    """A value in a message, the same on every run (no object's address)."""
    return repr(value) if isinstance(value, (int, float, str, bytes, type(None))) else f"a {type(value).__name__}"


def _check_range(name: str, value: int, low: int, high: int, consequence: str) -> int:
    number = _integer(value)
    if number is None or not low <= number <= high:
        raise AN738Error(f"{name} = {_shown(value if number is None else number)} is outside {low}..{high}; "
                         f"{consequence}")
    return number


def _check_id(value: int, extended: bool, what: str) -> int:
    if extended:
        return _check_range(what, value, 0, 0x1FFF_FFFF,
                            "a 29-bit extended identifier ends at 0x1FFFFFFF, and AN738 would drop the upper bits")
    number = _integer(value)
    if number is None or not 0 <= number <= 0x7FF:
        shown = f"0x{number:X}" if number is not None and number >= 0 else _shown(value if number is None else number)
        kept = f" and use 0x{number & 0x7FF:03X}" if number is not None and number >= 0 else ""
        raise AN738Error(
            f"{what} {shown} does not fit an 11-bit standard identifier (0x000..0x7FF): AN738 "
            f"would silently drop the upper bits{kept}. Use a smaller value, or the extended "
            "flag (CAN_TX_XTD_FRAME / CAN_CONFIG_XTD_MSG) for a 29-bit identifier.")
    return number


def _check_mode(mode: int) -> None:
    if mode not in _MODES:
        raise AN738Error(
            f"mode 0x{mode:02X} is not one CAN_OP_MODE value ({', '.join(_MODES.values())}). "
            "CANSetOperationMode writes it to CANCON and waits until CANSTAT shows it, which "
            "would never happen: the firmware would hang there. Pass exactly one mode.")


# ------------------------------------------------------------------ configuration

def CANSetOperationModeNoWait(mode: int) -> None:
    """CANCON = mode: requests the mode (and clears ABAT and WIN); does not wait."""
    _check_mode(mode)
    mcu = macro()
    mcu.write(_CANCON, mode)


def CANSetOperationMode(mode: int) -> None:
    """Request `mode` and wait until CANSTAT.OPMODE shows it (the module waits for the bus to be idle)."""
    _check_mode(mode)
    mcu = library_call()
    mcu.write(_CANCON, mode)
    while (mcu.read(_CANSTAT) & CAN_OP_MODE.CAN_OP_MODE_BITS) != mode:
        pass


def CANGetOperationMode() -> int:
    """The requested mode, CANCON & 0xE0 (not CANSTAT: the mode asked for, not the mode reached)."""
    return macro().read(_CANCON) & CAN_OP_MODE.CAN_OP_MODE_BITS


def CANSetBaudRate(SJW: int, BRP: int, PHSEG1: int, PHSEG2: int, PROPSEG: int,
                   flags: int = CAN_CONFIG_FLAGS.CAN_CONFIG_DEFAULT) -> None:
    """BRGCON1..3 from TQ counts (1-based; the registers get value − 1). Ignored outside Configuration mode."""
    wrap = "AN738 writes value − 1 into a field too small for it and the bit timing comes out wrong"
    SJW, BRP = _check_range("SJW", SJW, 1, 4, wrap), _check_range("BRP", BRP, 1, 64, wrap)
    PHSEG1, PHSEG2 = _check_range("PHSEG1", PHSEG1, 1, 8, wrap), _check_range("PHSEG2", PHSEG2, 1, 8, wrap)
    PROPSEG = _check_range("PROPSEG", PROPSEG, 1, 8, wrap)
    mcu = library_call()
    mcu.write(_BRGCON1, ((SJW - 1) << 6) | (BRP - 1))
    brgcon2 = ((PHSEG1 - 1) << 3) | (PROPSEG - 1)
    if not flags & CAN_CONFIG_FLAGS.CAN_CONFIG_SAMPLE_BIT:
        brgcon2 |= 0x40                                 # SAM: sample three times
    if flags & CAN_CONFIG_FLAGS.CAN_CONFIG_PHSEG2_PRG_BIT:
        brgcon2 |= 0x80                                 # SEG2PHTS: PHSEG2 freely programmable
    mcu.write(_BRGCON2, brgcon2)
    brgcon3 = PHSEG2 - 1
    if flags & CAN_CONFIG_FLAGS.CAN_CONFIG_LINE_FILTER_BIT:
        brgcon3 |= 0x40                                 # WAKFIL
    mcu.write(_BRGCON3, brgcon3)


def _write_id(mcu: FirmwareMCU, base: int, value: int, extended: bool) -> None:
    """CANIDToRegs: the ID into SIDH (at `base`), SIDL (and EIDH, EIDL when extended)."""
    sidh, sidl, eidh, eidl = pack_id(value, extended)
    mcu.write(base, sidh)
    mcu.write(base + 1, sidl)
    if extended:
        mcu.write(base + 2, eidh)
        mcu.write(base + 3, eidl)


def CANSetMask(code: int, val: int, type: int) -> None:
    """Mask of RXB0 (CAN_MASK_B1) or RXB1 (CAN_MASK_B2). Bit 1 = compare, 0 = don't care.

    Works only in Configuration mode: anywhere else the hardware ignores the writes, silently.
    """
    if code not in (0, 1):
        raise AN738Error(f"mask code {code!r} is not CAN_MASK_B1 or CAN_MASK_B2")
    extended = not type & CAN_CONFIG_FLAGS.CAN_CONFIG_MSG_TYPE_BIT
    _write_id(library_call(), _RXM_SIDH[code], _check_id(val, extended, "mask"), extended)


def CANSetFilter(code: int, val: int, type: int) -> None:
    """Filter RXF0..RXF5 (CAN_FILTER_B1_F1 .. CAN_FILTER_B2_F4); `type` STD or XTD sets EXIDEN.

    Works only in Configuration mode: anywhere else the hardware ignores the writes, silently.
    """
    if code not in range(6):
        raise AN738Error(f"filter code {code!r} is not one CAN_FILTER value (CAN_FILTER_B1_F1 .. CAN_FILTER_B2_F4)")
    extended = not type & CAN_CONFIG_FLAGS.CAN_CONFIG_MSG_TYPE_BIT
    _write_id(library_call(), _RXF_SIDH[code], _check_id(val, extended, "filter"), extended)


def CANInitialize(SJW: int, BRP: int, PHSEG1: int, PHSEG2: int, PROPSEG: int,
                  config: int = CAN_CONFIG_FLAGS.CAN_CONFIG_DEFAULT) -> None:
    """Configuration mode, bit timing, RXM of both buffers, masks 0, filters 0 — and back to NORMAL mode.

    Faithful to the library: it returns in Normal mode (request Loopback or Listen-only after it),
    leaves both masks at 0 (accept everything), and never sets RXB0DBEN (its double-buffer test
    compares 0x10 with 0xFF).
    """
    CANSetOperationMode(CAN_OP_MODE.CAN_OP_MODE_CONFIG)
    CANSetBaudRate(SJW, BRP, PHSEG1, PHSEG2, PROPSEG, config)
    mcu = library_call()
    rxbcon = config & CAN_CONFIG_FLAGS.CAN_CONFIG_MSG_BITS
    mcu.write(_RXB0CON, rxbcon)
    if (config & CAN_CONFIG_FLAGS.CAN_CONFIG_DBL_BUFFER_BIT) == CAN_CONFIG_FLAGS.CAN_CONFIG_DBL_BUFFER_ON:
        mcu.write(_RXB0CON, mcu.read(_RXB0CON) | R.RXB0DBEN)   # never true (0x10 != 0xFF)
    mcu.write(_RXB1CON, mcu.read(_RXB0CON))
    CANSetMask(CAN_MASK.CAN_MASK_B1, 0, CAN_CONFIG_FLAGS.CAN_CONFIG_XTD_MSG)
    CANSetMask(CAN_MASK.CAN_MASK_B2, 0, CAN_CONFIG_FLAGS.CAN_CONFIG_XTD_MSG)
    msg_type = (config & CAN_CONFIG_FLAGS.CAN_CONFIG_MSG_BITS) | (~CAN_CONFIG_FLAGS.CAN_CONFIG_MSG_BITS & 0xFF)
    if msg_type == CAN_CONFIG_FLAGS.CAN_CONFIG_VALID_XTD_MSG:
        type1 = type2 = CAN_CONFIG_FLAGS.CAN_CONFIG_XTD_MSG
    elif msg_type == CAN_CONFIG_FLAGS.CAN_CONFIG_VALID_STD_MSG:
        type1 = type2 = CAN_CONFIG_FLAGS.CAN_CONFIG_STD_MSG
    else:
        type1, type2 = CAN_CONFIG_FLAGS.CAN_CONFIG_STD_MSG, CAN_CONFIG_FLAGS.CAN_CONFIG_XTD_MSG
    for code in CAN_FILTER:
        CANSetFilter(code, 0, type1 if code < 2 else type2)
    CANSetOperationMode(CAN_OP_MODE.CAN_OP_MODE_NORMAL)


# ------------------------------------------------------------------ transmit

def CANIsTxReady() -> bool:
    """TRUE if at least one of TXB0..TXB2 has TXREQ = 0."""
    mcu = macro()
    for con in _TXB_CON:
        if not mcu.read(con) & R.TXREQ:
            return True
    return False


def CANSendMessage(id: int, Data: Sequence[int] | bytes | None, DataLen: int,
                   MsgFlags: int = CAN_TX_MSG_FLAGS.CAN_TX_PRIORITY_3) -> bool:
    """Queue a frame in the first free buffer, TXB0 → TXB1 → TXB2; FALSE if all three are pending.

    The buffer is written through the RXB0 window (CANCON.WIN), as the C library does. For a remote
    frame (CAN_TX_RTR_FRAME) DataLen is the DLC sent, and Data may be None.
    """
    extended = not MsgFlags & CAN_TX_MSG_FLAGS.CAN_TX_FRAME_BIT
    id = _check_id(id, extended, "identifier")
    remote = not MsgFlags & CAN_TX_MSG_FLAGS.CAN_TX_RTR_BIT
    DataLen = _check_range("DataLen", DataLen, 0, 8,
                 "a CAN frame carries at most 8 data bytes; AN738 would write that DLC and copy "
                 "the extra bytes past TXBnD7 into the next registers")
    data = bytes(Data or b"")
    if len(data) < DataLen and not remote:
        raise AN738Error(f"DataLen is {DataLen} but only {len(data)} data bytes were given: the C "
                         "library would send whatever memory follows your array")
    mcu = library_call()
    win = next((w for con, w in _TX_WINDOWS if not mcu.read(con) & R.TXREQ), None)   # the first free TXBn
    if win is None:
        return False
    _window(mcu, win)
    mcu.write(_RXB0CON, MsgFlags & CAN_TX_MSG_FLAGS.CAN_TX_PRIORITY_BITS)   # TXBnCON.TXPRI
    _write_id(mcu, _RXB0SIDH, id, extended)
    mcu.write(_RXB0DLC, DataLen | (R.TXRTR if remote else 0))
    for i in range(min(DataLen, len(data))):
        mcu.write(_RXB0D0 + i, data[i])
    mcu.write(_RXB0CON, mcu.read(_RXB0CON) | R.TXREQ)
    _window(mcu, 0b000)
    return True


def CANAbortAll() -> None:
    """CANCON.ABAT = 1: abort every pending transmission."""
    mcu = macro()
    mcu.write(_CANCON, mcu.read(_CANCON) | R.ABAT)


# ------------------------------------------------------------------ receive

def CANIsRxReady() -> bool:
    """TRUE if RXB0 or RXB1 holds a message (RXFUL): one that passed the masks and filters."""
    mcu = macro()
    return bool(mcu.read(_RXB0CON) & R.RXFUL or mcu.read(_RXB1CON) & R.RXFUL)


def CANReceiveMessage() -> CANMessage:
    """Read RXB0, else RXB1, through the window: clears RXBnIF and the overflow flag, RXFUL last.

    Returns `CANMessage(id, data, length, flags)`, false when neither buffer was full.
    Quirks kept from the library: for RXB0 the filter number is reported only when RXB0DBEN is set,
    and then `&= 0x01` also wipes CAN_RX_OVERFLOW; `length` is the raw DLC.
    """
    mcu = library_call()
    flags = 0
    if mcu.read(_RXB0CON) & R.RXFUL:
        con_address = _RXB0CON
        _window(mcu, 0b000)
        mcu.write(_PIR3, mcu.read(_PIR3) & ~R.RXB0IF)
        if mcu.read(_COMSTAT) & R.RXB0OVFL:
            flags |= CAN_RX_MSG_FLAGS.CAN_RX_OVERFLOW
            mcu.write(_COMSTAT, mcu.read(_COMSTAT) & ~R.RXB0OVFL)
        con = mcu.read(_RXB0CON)
        if con & R.RXB0DBEN:
            flags |= con & CAN_RX_MSG_FLAGS.CAN_RX_FILTER_BITS
            flags &= 0x01
    elif mcu.read(_RXB1CON) & R.RXFUL:
        con_address = _RXB1CON
        _window(mcu, _WIN_RXB1)
        mcu.write(_PIR3, mcu.read(_PIR3) & ~R.RXB1IF)
        if mcu.read(_COMSTAT) & R.RXB1OVFL:
            flags |= CAN_RX_MSG_FLAGS.CAN_RX_OVERFLOW
            mcu.write(_COMSTAT, mcu.read(_COMSTAT) & ~R.RXB1OVFL)
        flags |= mcu.read(_RXB1CON) & CAN_RX_MSG_FLAGS.CAN_RX_FILTER_BITS
        if flags < 0x02:
            flags |= CAN_RX_MSG_FLAGS.CAN_RX_DBL_BUFFERED
    else:
        return NO_MESSAGE
    dlc_register, sidl, sidh, eidh, eidl = mcu.read_each(_DLC_AND_ID)
    length = dlc_register & 0x0F
    if dlc_register & R.RXRTR:
        flags |= CAN_RX_MSG_FLAGS.CAN_RX_RTR_FRAME
    if sidl & R.EXIDE:
        flags |= CAN_RX_MSG_FLAGS.CAN_RX_XTD_FRAME
    rx_id, _ = unpack_id(sidh, sidl, eidh, eidl)
    data = bytes(mcu.read_each(_DATA[:min(length, 8)]))
    _window(mcu, 0b000)
    if mcu.read(_PIR3) & R.IRXIF:
        flags |= CAN_RX_MSG_FLAGS.CAN_RX_INVALID_MSG
        mcu.write(_PIR3, mcu.read(_PIR3) & ~R.IRXIF)
    mcu.write(con_address, mcu.read(con_address) & ~R.RXFUL)
    return CANMessage(rx_id, data, length, flags)


# ------------------------------------------------------------------ status

def CANIsBusOff() -> bool:
    """COMSTAT.TXBO: the transmit error counter passed 255."""
    return bool(macro().read(_COMSTAT) & R.TXBO)


def CANIsTxPassive() -> bool:
    """COMSTAT.TXBP: the transmit error counter passed 127."""
    return bool(macro().read(_COMSTAT) & R.TXBP)


def CANIsRxPassive() -> bool:
    """COMSTAT.RXBP: the receive error counter passed 127."""
    return bool(macro().read(_COMSTAT) & R.RXBP)


def CANGetTxErrorCount() -> int:
    return macro().read(_TXERRCNT)


def CANGetRxErrorCount() -> int:
    return macro().read(_RXERRCNT)


__all__ = (
    ["TRUE", "FALSE", "AN738Error", "CANMessage", "CAN_OP_MODE", "CAN_CONFIG_FLAGS", "CAN_TX_MSG_FLAGS",
     "CAN_RX_MSG_FLAGS", "CAN_MASK", "CAN_FILTER",
     "CANInitialize", "CANSetOperationMode", "CANSetOperationModeNoWait", "CANGetOperationMode",
     "CANSetBaudRate", "CANSetMask", "CANSetFilter", "CANSendMessage", "CANIsTxReady", "CANAbortAll",
     "CANIsRxReady", "CANReceiveMessage", "CANIsBusOff", "CANIsTxPassive", "CANIsRxPassive",
     "CANGetTxErrorCount", "CANGetRxErrorCount"]
    + [n for g in (CAN_CONFIG_FLAGS, CAN_TX_MSG_FLAGS, CAN_RX_MSG_FLAGS) for n in vars(g) if n.startswith("CAN_")]
    + [m.name for g in (CAN_OP_MODE, CAN_MASK, CAN_FILTER) for m in g]
)
