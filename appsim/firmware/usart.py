"""MPLAB C18's usart.h: OpenUSART, WriteUSART, ReadUSART, putsUSART ... through TXSTA, RCSTA, SPBRG, TXREG, RCREG.

Masks are combined with `&`; a field left out keeps its all-ones value (C18's values).
"""
from __future__ import annotations

from appsim.chip.sfr import BRGH as _BRGH
from appsim.chip.sfr import CREN as _CREN
from appsim.chip.sfr import CSRC as _CSRC
from appsim.chip.sfr import RCIF, TXIF
from appsim.chip.sfr import RX9 as _RX9
from appsim.chip.sfr import SPEN as _SPEN
from appsim.chip.sfr import SREN as _SREN
from appsim.chip.sfr import SYNC as _SYNC
from appsim.chip.sfr import TRMT as _TRMT
from appsim.chip.sfr import TX9 as _TX9
from appsim.chip.sfr import TXEN as _TXEN
from appsim.firmware.runtime import library_call

USART_TX_INT_ON = 0b11111111
USART_TX_INT_OFF = 0b01111111
USART_RX_INT_ON = 0b11111111
USART_RX_INT_OFF = 0b10111111
USART_BRGH_HIGH = 0b11111111
USART_BRGH_LOW = 0b11101111
USART_CONT_RX = 0b11111111
USART_SINGLE_RX = 0b11110111
USART_SYNC_MASTER = 0b11111111
USART_SYNC_SLAVE = 0b11111011
USART_NINE_BIT = 0b11111111
USART_EIGHT_BIT = 0b11111101
USART_SYNCH_MODE = 0b11111111
USART_ASYNCH_MODE = 0b11111110


def _byte(function: str, value: int | str) -> int:
    code = ord(value) if isinstance(value, str) and len(value) == 1 else value
    if not isinstance(code, int) or isinstance(code, bool) or not 0 <= code <= 0xFF:
        raise ValueError(f"{function} sends one byte: 0..255 or a 1-character string; got {value!r}")
    return code


def OpenUSART(config: int, spbrg: int) -> None:
    """Reset and configure the USART, then enable it (TXEN, SPEN), as C18's OpenUSART does.

    `config`: USART_TX_INT_* & USART_RX_INT_* & USART_ASYNCH_MODE & USART_EIGHT_BIT/NINE_BIT &
    USART_CONT_RX/SINGLE_RX & USART_BRGH_*; `spbrg`: the baud rate value (129 with BRGH_HIGH: 19200
    at 40 MHz). SPBRGH gets spbrg >> 8, used only if BAUDCON.BRG16 is set.
    """
    if not isinstance(config, int) or isinstance(config, bool) or not 0 <= config <= 0xFF:
        raise ValueError(f"OpenUSART's config is one byte of USART_... masks combined with &; got {config!r}")
    if not isinstance(spbrg, int) or isinstance(spbrg, bool) or not 0 <= spbrg <= 0xFFFF:
        raise ValueError(f"OpenUSART's spbrg is the baud rate generator value, 0..65535; got {spbrg!r} "
                         "(129 with USART_BRGH_HIGH gives 19200 baud at 40 MHz)")
    mcu = library_call()
    mcu.write_name("TXSTA", 0)
    mcu.write_name("RCSTA", 0)
    if config & 0x01:
        mcu.set_bits("TXSTA", _SYNC, True)
    if config & 0x02:
        mcu.set_bits("TXSTA", _TX9, True)
        mcu.set_bits("RCSTA", _RX9, True)
    if config & 0x04:
        mcu.set_bits("TXSTA", _CSRC, True)
    mcu.set_bits("RCSTA", _CREN if config & 0x08 else _SREN, True)
    mcu.set_bits("TXSTA", _BRGH, bool(config & 0x10))
    mcu.set_bits("PIR1", 1 << TXIF, False)
    mcu.set_bits("PIE1", 1 << RCIF, bool(config & 0x40))
    mcu.set_bits("PIR1", 1 << RCIF, False)
    mcu.set_bits("PIE1", 1 << TXIF, bool(config & 0x80))
    mcu.write_name("SPBRG", spbrg & 0xFF)
    mcu.write_name("SPBRGH", spbrg >> 8)
    mcu.set_bits("TXSTA", _TXEN, True)
    mcu.set_bits("RCSTA", _SPEN, True)


def BusyUSART() -> bool:
    """Whether the transmitter is still shifting a byte out (TXSTA.TRMT = 0), as C18 tests it."""
    return not library_call().read_name("TXSTA") & _TRMT


def WriteUSART(data: int | str) -> None:
    """Put one byte in TXREG (without waiting: call BusyUSART first, as putsUSART does)."""
    code = _byte("WriteUSART", data)
    library_call().write_name("TXREG", code)


putcUSART = WriteUSART


def DataRdyUSART() -> bool:
    """Whether a received byte is waiting (PIR1.RCIF)."""
    return bool(library_call().read_name("PIR1") & (1 << RCIF))


def ReadUSART() -> int:
    """The next received byte from RCREG (C18 also notes FERR/OERR in USART_Status; read RCSTAbits for them)."""
    mcu = library_call()
    mcu.read_name("RCSTA")
    return mcu.read_name("RCREG")


getcUSART = ReadUSART


def _put_string(function: str, text: str | bytes) -> None:
    if isinstance(text, str):
        try:
            codes = text.encode("latin-1")
        except UnicodeEncodeError:
            raise ValueError(f"{function} sends one byte per character (0..255); {text!r} has others") from None
    elif isinstance(text, (bytes, bytearray)):
        codes = bytes(text)
    else:
        raise TypeError(f"{function} takes a string (str or bytes); got {text!r}")
    codes = codes[:codes.index(0)] if 0 in codes else codes
    for code in codes + b"\0":          # C18's loop sends the terminating NUL too
        while BusyUSART():
            pass
        putcUSART(code)


def putsUSART(text: str | bytes) -> None:
    """Send a string from RAM, waiting for the transmitter before each byte; C18 sends its NUL as well."""
    _put_string("putsUSART", text)


def putrsUSART(text: str | bytes) -> None:
    """Send a string from program memory (ROM): the same as putsUSART here, NUL included."""
    _put_string("putrsUSART", text)


def CloseUSART() -> None:
    """Disable the receiver and the transmitter and their interrupt enables, as C18's CloseUSART does."""
    mcu = library_call()
    mcu.write_name("RCSTA", mcu.read_name("RCSTA") & 0b01001111)
    mcu.set_bits("TXSTA", _TXEN, False)
    mcu.write_name("PIE1", mcu.read_name("PIE1") & 0b11001111)


__all__ = [
    "USART_ASYNCH_MODE",
    "USART_BRGH_HIGH",
    "USART_BRGH_LOW",
    "USART_CONT_RX",
    "USART_EIGHT_BIT",
    "USART_NINE_BIT",
    "USART_RX_INT_OFF",
    "USART_RX_INT_ON",
    "USART_SINGLE_RX",
    "USART_SYNCH_MODE",
    "USART_SYNC_MASTER",
    "USART_SYNC_SLAVE",
    "USART_TX_INT_OFF",
    "USART_TX_INT_ON",
    "BusyUSART",
    "CloseUSART",
    "DataRdyUSART",
    "OpenUSART",
    "ReadUSART",
    "WriteUSART",
    "getcUSART",
    "putcUSART",
    "putrsUSART",
    "putsUSART",
]
