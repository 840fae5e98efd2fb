"""Every error the kit raises, as one tree under `AppsimError`; each is also the fitting builtin (as python-can's are).
One stands apart: the watchdog's `FirmwareHung`, a BaseException (see there).

One module, imported by the firmware library too, so an error raised on the board crosses the grading sandbox intact.
"""
from __future__ import annotations


class AppsimError(Exception):
    """Anything the kit refuses or reports as an error; the message says what is wrong and what to do."""


# ------------------------------------------------------------------ CAN
class FrameError(AppsimError, ValueError):
    """A frame that CAN cannot carry, with what to change."""


class BitTimingError(AppsimError, ValueError):
    """A bit-timing setting that cannot be programmed or breaks a datasheet rule; the message says which."""


class WireError(AppsimError, ValueError):
    """A bit sequence a CAN controller would reject; `position` is the wire bit (SOF = 0) where it sees it."""

    def __init__(self, position: int, message: str) -> None:
        super().__init__(message)
        self.position = position


class StuffError(WireError):
    """Six equal bits in a row between SOF and the end of the CRC sequence."""


class CrcError(WireError):
    """The received CRC sequence differs from the CRC of the received SOF..data bits."""

    def __init__(self, position: int, message: str, received: int, computed: int) -> None:
        super().__init__(position, message)
        self.received = received
        self.computed = computed


class FormError(WireError):
    """A fixed-form bit (CRC delimiter, ACK delimiter, EOF) is dominant, or the sequence ends early."""


class InjectionError(AppsimError, ValueError):
    """An error to inject that could never happen on the bus (a bit past every frame, a kind at a bit where it cannot
    be, an identifier no frame can have), with why and what would."""


class SlcanError(AppsimError, ValueError):
    """A line that is not an SLCAN command, with what is wrong; the adapter answers it with BELL."""


# ------------------------------------------------------------------ the chip and the board
class UnsupportedMode(AppsimError, ValueError):
    """ECANCON selects an ECAN mode the kit does not model."""


class NotOnABoard(AppsimError, RuntimeError):
    """A firmware function was called outside firmware running on a simulated board."""


class NotInitialised(AppsimError, RuntimeError):
    """A GLCD function was called before GLCD_Initial()."""


class NoInterruptRoutine(AppsimError, RuntimeError):
    """The core took an interrupt at a vector where the firmware has no routine (@interrupt, @interruptlow)."""


# ------------------------------------------------------------------ firmware
class FirmwareError(AppsimError):
    """A firmware file that cannot run, with what to do about it."""


class CCompileError(FirmwareError):
    """A C firmware file the kit's C18 will not translate: at its line and column, what is wrong and what to do."""

    def __init__(self, message: str, filename: str = "", line: int = 0, column: int = 0) -> None:
        # the file's name, as the loader names a Python file: the same in `appsim check` and in the grader's sandbox
        where = ":".join(str(part) for part in (filename.replace("\\", "/").rsplit("/", 1)[-1], line, column) if part)
        super().__init__(f"{where}: {message}" if where else message)
        self.filename, self.line, self.column, self.reason = filename, line, column, message


class CRuntimeError(AppsimError, RuntimeError):
    """A C firmware did what C18 lets through and the board would get wrong (an index past an array's end, a char
    where sprintf reads an int): the message says what, in C's words; the traceback's last line of the .c file says
    where."""


class AN738Error(AppsimError, ValueError):
    """A call the C library would accept and silently get wrong (or hang on)."""


class FirmwareHung(BaseException):
    """The watchdog stopped a firmware that ran for seconds without reading or writing a register (an endless loop,
    a sleep, a recursion that does not end); the message says which, and where.

    A BaseException, as KeyboardInterrupt is, and so outside `AppsimError`: the firmware's own `except Exception:`
    around its loop must not catch the watchdog (a firmware that catches it anyway is frozen where it is)."""


# ------------------------------------------------------------------ the workshop
class OutputError(AppsimError, OSError):
    """A file the kit was asked to write that it cannot write (a missing directory, a read-only place, an unknown
    format, a full disk), with what to do."""


class GradeError(AppsimError):
    """Input the grader cannot use (a path, a results file, an option), with what to do."""


class SandboxUnavailable(AppsimError, OSError):
    """This machine cannot isolate student firmware (no Linux namespaces, no bubblewrap), with what to do."""


def by_name(name: str) -> type[Exception] | None:
    """The kit's error class called `name` (for an error that crossed the grading sandbox), else None."""
    found = globals().get(name)
    return found if isinstance(found, type) and issubclass(found, AppsimError) else None
