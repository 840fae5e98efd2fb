"""APP023_GLCD.h, the workshop's GLCD library: GLCD_Initial, setcurGLCD, putsGLCD, putrsGLCD, putcGLCD.

Its driver bit-bangs the display module's ports; the board's GLCD (appsim.board.glcd) does that work and takes its time.
"""
from __future__ import annotations

from collections.abc import Sequence
from typing import Any

from appsim.chip.sfr import GLCDPort, current_mcu
from appsim.firmware.runtime import library_call

NO_GLCD = "this MCU has no GLCD: the GLCD functions need firmware running on an APP023 board"


def _display() -> GLCDPort:
    display = current_mcu().glcd
    if display is None:
        raise RuntimeError(NO_GLCD)
    library_call()
    return display


def _codes(text: Any, function: str) -> list[int]:
    """A C string as character codes, up to its NUL: from a str, bytes or a list of ints (0..255)."""
    if isinstance(text, str):
        try:
            codes = list(text.encode("latin-1"))
        except UnicodeEncodeError:
            raise ValueError(f"{function}: the GLCD shows one byte per character (0..255); "
                             f"{text!r} has characters outside that") from None
    elif isinstance(text, (bytes, bytearray)):
        codes = list(text)
    elif isinstance(text, (list, tuple)) and all(isinstance(c, int) and not isinstance(c, bool) for c in text):
        codes = list(text)
        if any(not 0 <= c <= 0xFF for c in codes):
            raise ValueError(f"{function}: a C string holds bytes 0..255; got {text!r}")
    else:
        raise TypeError(f"{function} takes a string (str, bytes, or a list of character codes); got {text!r}")
    return codes[:codes.index(0)] if 0 in codes else codes


def GLCD_Initial() -> None:
    """Set the GLCD up: clear the screen, cursor to line 1 column 1, backlight on."""
    _display().initial()


def setcurGLCD(line: int, column: int) -> None:
    """Put the cursor on `line` (1..8) at `column` (1..21)."""
    if not all(isinstance(v, int) and not isinstance(v, bool) for v in (line, column)):
        raise ValueError(f"setcurGLCD({line!r}, {column!r}): lines are numbered 1..8 and columns "
                         "1..21 on the APP023's 8x21 screen")
    _display().set_cursor(int(line), int(column))


def putsGLCD(text: str | bytes | Sequence[int]) -> None:
    """Write a string (from RAM) at the cursor; it stops at a NUL, and what passes column 21 is cut off."""
    codes = _codes(text, "putsGLCD")
    _display().write(codes)


def putrsGLCD(text: str | bytes | Sequence[int]) -> None:
    """Write a string from program memory (ROM): the same as putsGLCD here."""
    codes = _codes(text, "putrsGLCD")
    _display().write(codes)


def putcGLCD(character: int | str) -> None:
    """Write one character (a code 0..255 or a 1-character str) at the cursor."""
    code = ord(character) if isinstance(character, str) and len(character) == 1 else character
    if not isinstance(code, int) or isinstance(code, bool) or not 0 <= code <= 0xFF:
        raise ValueError(f"putcGLCD takes one character: a code 0..255 or a 1-character string; got {character!r}")
    _display().write([code])


__all__ = ["GLCD_Initial", "putcGLCD", "putrsGLCD", "putsGLCD", "setcurGLCD"]
