"""The functions the kit's headers declare, for C: each takes its arguments as C passes them (integers, pointers into
the firmware's memory) and calls the same library the Python firmware calls, so both spend the same cycles.

Only the board's libraries (AN738, adc, timers, usart, delays, GLCD) cost cycles; sprintf and the string functions,
like Python's own string work, cost none.
"""
from __future__ import annotations

import sys
from collections.abc import Callable
from types import FrameType
from typing import Any

from appsim import firmware
from appsim.chip.sfr import current_mcu
from appsim.errors import CRuntimeError
from appsim.firmware import adc, an738, glcd, timers, usart
from appsim.firmware.c18 import runtime
from appsim.firmware.c18.runtime import Ptr, bytes_at, put_string, string_at
from appsim.firmware.interrupts import MARK


class Restart(BaseException):
    """Reset() ran: the C program starts again from its startup code (see the translated module's main)."""


def _flag(function: Callable[[], object]) -> Callable[[], int]:
    return lambda: 1 if function() else 0


def CANSendMessage(id: int, Data: Ptr | None, DataLen: int, MsgFlags: int) -> int:
    remote = not MsgFlags & an738.CAN_TX_MSG_FLAGS.CAN_TX_RTR_BIT
    data = b"" if Data is None and remote else bytes_at(Data, DataLen, "CANSendMessage")
    return 1 if an738.CANSendMessage(id, data, DataLen, MsgFlags) else 0


def CANReceiveMessage(id: Ptr | None, Data: Ptr | None, DataLen: Ptr | None, MsgFlags: Ptr | None) -> int:
    """AN738's: *MsgFlags = 0 first; FALSE with nothing else written when neither buffer is full."""
    for name, pointer in (("id", id), ("Data", Data), ("DataLen", DataLen), ("MsgFlags", MsgFlags)):
        if pointer is None:
            raise CRuntimeError(f"CANReceiveMessage was given NULL for {name}: it writes there")
    assert id is not None and Data is not None and DataLen is not None and MsgFlags is not None
    MsgFlags.set_integer(0, 0)
    message = an738.CANReceiveMessage()
    if not message:
        return 0
    id.set_integer(0, message.id)
    if Data.i + len(message.data) > Data.hi:
        raise CRuntimeError(f"CANReceiveMessage writes {len(message.data)} data bytes into {Data.name}, which has "
                            f"room for {Data.hi - Data.i}: give it an array of 8 bytes (a frame carries up to 8)")
    for k, byte in enumerate(message.data):
        Data.set_integer(k, byte)             # into a plain char array, 0xFF is the char -1
    DataLen.set_integer(0, message.length)
    MsgFlags.set_integer(0, message.flags)
    return 1


def _string(function: Callable[[list[int]], object], name: str) -> Callable[[Ptr | None], None]:
    def call(text: Ptr | None) -> None:
        function(string_at(text, name))
    return call


def putsUSART(data: Ptr | None) -> None:
    usart.putsUSART(bytes(string_at(data, "putsUSART")))


def putrsUSART(data: Ptr | None) -> None:
    usart.putrsUSART(bytes(string_at(data, "putrsUSART")))


def ClrWdt() -> None:
    current_mcu().spend_cycles(1)


def Reset() -> None:
    """C18's Reset(): the C program starts again from its startup code (globals initialised, then main()). The chip's
    registers are not reset (the kit's PIC18F8680 has no reset of them all, which the RESET instruction does), and in
    an interrupt routine it is refused: there the core's interrupt would stay in service, as it never is on the chip."""
    routine = _running_routine()
    if routine is not None:
        raise CRuntimeError(f"Reset() inside the interrupt routine {routine}(): on the chip the RESET instruction "
                            "resets the core and every register, and the kit restarts only the C program, so the "
                            "interrupt being served would stay in service. Set a flag there and call Reset() from "
                            "main()")
    current_mcu().spend_cycles(1)
    raise Restart


def _running_routine() -> str | None:
    """The name of the interrupt routine (a function its pragma marked) the current call comes from, if any."""
    frame: FrameType | None = sys._getframe(1)
    while frame is not None:
        function = frame.f_globals.get(frame.f_code.co_name)
        if getattr(function, "__code__", None) is frame.f_code and getattr(function, MARK, None) is not None:
            return frame.f_code.co_name
        frame = frame.f_back
    return None


# ------------------------------------------------------------------ string.h, stdlib.h (no cycles: computation)
def strlen(s: Ptr | None) -> int:
    return len(string_at(s, "strlen"))


def strcpy(dest: Ptr | None, src: Ptr | None) -> Ptr | None:
    put_string(dest, string_at(src, "strcpy"), "strcpy")
    return dest


def strncpy(dest: Ptr | None, src: Ptr | None, n: int) -> Ptr | None:
    codes = string_at(src, "strncpy")[:n]
    codes += [0] * (n - len(codes))
    if dest is None or dest.i + n > dest.hi:
        raise CRuntimeError(f"strncpy writes {n} bytes into {getattr(dest, 'name', 'NULL')}, which has less room")
    for k, code in enumerate(codes):
        dest.set_integer(k, code)
    return dest


def strcat(dest: Ptr | None, src: Ptr | None) -> Ptr | None:
    head = string_at(dest, "strcat")
    put_string(dest, head + string_at(src, "strcat"), "strcat")
    return dest


def _compare(a: list[int], b: list[int]) -> int:
    for x, y in zip(a + [0], b + [0], strict=False):
        if x != y:
            return -1 if x < y else 1
    return 0


def strcmp(a: Ptr | None, b: Ptr | None) -> int:
    return _compare(string_at(a, "strcmp"), string_at(b, "strcmp"))


def strncmp(a: Ptr | None, b: Ptr | None, n: int) -> int:
    return _compare(string_at(a, "strncmp")[:n], string_at(b, "strncmp")[:n])


def memcpy(dest: Ptr | None, src: Ptr | None, n: int) -> Ptr | None:
    """`n` bytes: integers as their bytes, lowest first (C18's order: a long into four BYTEs), structs whole."""
    if not n:
        return dest
    if dest is None or src is None:
        raise CRuntimeError("memcpy was given a NULL pointer")
    if dest.element[2] and src.element[2]:
        _put_bytes(dest, _bytes(src, n))
        return dest
    count = _whole_elements(src, n, "memcpy")
    if dest.element != src.element:
        raise CRuntimeError(f"memcpy copies {src.element[3]} from {src.name} into {dest.name}, which holds "
                            f"{dest.element[3]}: the kit's C keeps memory as objects, not bytes, and copies a struct "
                            "only into a struct of its type")
    for k in range(count):
        dest.set(k, runtime.copy(src.get(k)))
    return dest


def memset(dest: Ptr | None, value: int, n: int) -> Ptr | None:
    """`n` bytes set to `value`'s low byte: each byte of an int, a struct's every member (to 0 only)."""
    if not n:
        return dest
    if dest is None:
        raise CRuntimeError("memset was given a NULL pointer")
    if dest.element[2]:
        _put_bytes(dest, bytes([value & 0xFF]) * n)
        return dest
    if value & 0xFF:
        raise CRuntimeError(f"memset sets the bytes of {dest.name} ({dest.element[3]}) to {value & 0xFF}: the kit's C "
                            "keeps a struct as its members, not bytes, so it clears them (0) but sets no other byte")
    for k in range(_whole_elements(dest, n, "memset")):
        dest.set(k, _cleared(dest.get(k)))
    return dest


def memcmp(a: Ptr | None, b: Ptr | None, n: int) -> int:
    if not n:
        return 0
    if a is None or b is None:
        raise CRuntimeError("memcmp was given a NULL pointer")
    for p in (a, b):
        if not p.element[2]:
            raise CRuntimeError(f"memcmp compares the bytes of {p.name} ({p.element[3]}): the kit's C keeps a struct "
                                "as its members, not bytes; compare the members")
    return _compare(list(_bytes(a, n)), list(_bytes(b, n)))


def _bytes(p: Ptr, n: int) -> bytes:
    """The `n` bytes of memory from `p`, its integers each as its size's bytes, lowest first."""
    size = p.element[0]
    data = b"".join((p.get(k) & ((1 << 8 * size) - 1)).to_bytes(size, "little") for k in range(-(-n // size)))
    return data[:n]


def _put_bytes(p: Ptr, data: bytes) -> None:
    """Bytes into the memory at `p`, integer by integer (one written in part keeps its other bytes)."""
    size = p.element[0]
    for k in range(0, len(data), size):
        part = data[k:k + size]
        if len(part) < size:
            part += _bytes(p.add(k // size), size)[len(part):]
        p.set_integer(k // size, int.from_bytes(part, "little"))


def _whole_elements(p: Ptr, n: int, function: str) -> int:
    size = p.element[0]
    if not size or n % size:
        raise CRuntimeError(f"{function} of {n} bytes covers part of a {p.element[3]} ({size} bytes) in {p.name}: "
                            "the kit's C keeps memory as objects, not bytes; give it a whole number of them "
                            f"(sizeof({p.element[3]}) each)")
    return n // size


def _cleared(value: Any) -> Any:
    """A struct's (or array's, or pointer's) value with every byte 0: its integers 0, its pointers NULL."""
    if isinstance(value, list):
        return [_cleared(item) for item in value]
    return None if value is None or isinstance(value, Ptr) else 0


def atoi(s: Ptr | None) -> int:
    text = bytes(string_at(s, "atoi")).decode("latin-1").strip()
    digits = ""
    for k, c in enumerate(text):
        if c.isdigit() or (k == 0 and c in "+-"):
            digits += c
        else:
            break
    try:
        return int(digits)
    except ValueError:
        return 0


def itoa(value: int, string: Ptr | None) -> Ptr | None:
    put_string(string, list(str(value).encode()), "itoa")
    return string


def ultoa(value: int, string: Ptr | None) -> Ptr | None:
    put_string(string, list(str(value & 0xFFFF_FFFF).encode()), "ultoa")
    return string


BINDINGS: dict[str, Callable[..., Any]] = {
    # CAN18XX8.h
    "CANInitialize": an738.CANInitialize, "CANSetOperationMode": an738.CANSetOperationMode,
    "CANSetBaudRate": an738.CANSetBaudRate, "CANSetMask": an738.CANSetMask, "CANSetFilter": an738.CANSetFilter,
    "CANSendMessage": CANSendMessage, "CANReceiveMessage": CANReceiveMessage,
    # adc.h
    "OpenADC": adc.OpenADC, "SetChanADC": adc.SetChanADC, "ConvertADC": adc.ConvertADC,
    "BusyADC": _flag(adc.BusyADC), "ReadADC": adc.ReadADC, "CloseADC": adc.CloseADC,
    # timers.h
    "OpenTimer1": timers.OpenTimer1, "ReadTimer1": timers.ReadTimer1, "WriteTimer1": timers.WriteTimer1,
    "CloseTimer1": timers.CloseTimer1,
    # usart.h
    "OpenUSART": usart.OpenUSART, "BusyUSART": _flag(usart.BusyUSART),
    "WriteUSART": lambda data: usart.WriteUSART(data & 0xFF), "DataRdyUSART": _flag(usart.DataRdyUSART),
    "ReadUSART": usart.ReadUSART, "putsUSART": putsUSART, "putrsUSART": putrsUSART, "CloseUSART": usart.CloseUSART,
    # delays.h, p18f8680.h
    "Delay10TCYx": firmware.Delay10TCYx, "Delay100TCYx": firmware.Delay100TCYx,
    "Delay1KTCYx": firmware.Delay1KTCYx, "Delay10KTCYx": firmware.Delay10KTCYx,
    "Nop": firmware.Nop, "ClrWdt": ClrWdt, "Reset": Reset,
    # APP023_GLCD.h
    "GLCD_Initial": glcd.GLCD_Initial, "setcurGLCD": glcd.setcurGLCD,
    "putsGLCD": _string(glcd.putsGLCD, "putsGLCD"), "putrsGLCD": _string(glcd.putrsGLCD, "putrsGLCD"),
    "putcGLCD": glcd.putcGLCD,
    # stdio.h, string.h, stdlib.h
    "sprintf": runtime.sprintf,
    "strlen": strlen, "strcpy": strcpy, "strncpy": strncpy, "strcat": strcat, "strcmp": strcmp, "strncmp": strncmp,
    "memcpy": memcpy, "memset": memset, "memcmp": memcmp,
    "strcpypgm2ram": strcpy, "strcmppgm2ram": strcmp, "strlenpgm": strlen,
    "atoi": atoi, "itoa": itoa, "ultoa": ultoa, "abs": abs,
}

# What each integer-valued function returns, where narrower than its C type says: its result needs no wrapping.
RESULTS: dict[str, tuple[int, int]] = {
    "CANSendMessage": (0, 1), "CANReceiveMessage": (0, 1), "BusyADC": (0, 1), "BusyUSART": (0, 1),
    "DataRdyUSART": (0, 1), "ReadADC": (0, 1023), "ReadTimer1": (0, 0xFFFF), "sprintf": (0, 0x7FFF),
    "strlen": (0, 0x7FFF), "strlenpgm": (0, 0x7FFF), "strcmp": (-1, 1), "strncmp": (-1, 1), "memcmp": (-1, 1),
    "strcmppgm2ram": (-1, 1),
}
