"""Interrupt routines as MPLAB C18 writes them: `@interrupt` for `#pragma interrupt` (vector 0x08), `@interruptlow` for
`#pragma interruptlow` (0x18); the cycles C18's entry and exit code costs; and the wait an empty loop becomes.

A decorator only marks its function; `routines(module)` finds the marked ones, as the linker finds the pragmas' names.
"""
from __future__ import annotations

from collections.abc import Callable, Mapping
from types import FunctionType, ModuleType
from typing import Any, TypeVar

from appsim.chip.sfr import HIGH_VECTOR, LOW_VECTOR, VECTOR_NAMES, current_mcu, missing_routine
from appsim.errors import FirmwareError

# C18's code around a routine, in instruction cycles. High priority (`#pragma interrupt`, RETFIE FAST: the core's
# shadow registers keep WREG, STATUS and BSR): the GOTO at 0x08, saving and restoring FSR2 and the compiler's
# temporaries. Low priority (`#pragma interruptlow`): the same from 0x18, and WREG, STATUS and BSR saved in software.
C18_ENTRY_CYCLES = {HIGH_VECTOR: 10, LOW_VECTOR: 16}
C18_EXIT_CYCLES = {HIGH_VECTOR: 8, LOW_VECTOR: 14}
MARK = "__c18_interrupt__"          # the attribute a decorator sets: the routine's vector
PRAGMAS = {HIGH_VECTOR: "@interrupt", LOW_VECTOR: "@interruptlow"}
PLAIN = (int, bool, float, str, bytes, type(None))      # values whose truth and comparisons run no Python code

F = TypeVar("F", bound=Callable[[], Any])


def _mark(function: F, vector: int) -> F:
    if not isinstance(function, FunctionType):
        raise TypeError(f"{PRAGMAS[vector]} marks a function defined with `def`, as `#pragma` names a C function; "
                        f"got {function!r}")
    if getattr(function, MARK, vector) != vector:
        raise FirmwareError(f"{function.__name__}() is marked both @interrupt and @interruptlow: a routine has one "
                            "vector (0x08 or 0x18)")
    setattr(function, MARK, vector)
    return function


def interrupt(function: F) -> F:
    """Mark `function` as the high-priority interrupt routine, as C18's `#pragma interrupt NAME` does: the core calls
    it at vector 0x08 (every interrupt with RCON.IPEN = 0, the high-priority ones with IPEN = 1). The routine returns
    with RETFIE FAST; it must clear the flag of the source it served, or it is entered again at once."""
    return _mark(function, HIGH_VECTOR)


def interruptlow(function: F) -> F:
    """Mark `function` as the low-priority interrupt routine, as C18's `#pragma interruptlow NAME` does: the core calls
    it at vector 0x18 for an enabled source whose IPR bit is 0, with RCON.IPEN = 1 and INTCON.GIEH and GIEL set. A
    high-priority interrupt may pre-empt it."""
    return _mark(function, LOW_VECTOR)


def routines(module: ModuleType | Mapping[str, object]) -> dict[int, Callable[[], None]]:
    """The interrupt routines a loaded firmware marks (at most one per vector, taking no arguments), by vector, each
    as the core calls it: with C18's entry and exit code around it. FirmwareError for two at one vector."""
    namespace = vars(module) if isinstance(module, ModuleType) else module
    found: dict[int, FunctionType] = {}
    for value in namespace.values():
        vector = getattr(value, MARK, None) if isinstance(value, FunctionType) else None
        if vector not in PRAGMAS:
            continue
        assert isinstance(value, FunctionType)
        other = found.setdefault(vector, value)
        if other is not value:
            raise FirmwareError(f"{other.__name__}() and {value.__name__}() are both marked {PRAGMAS[vector]}: the "
                                f"PIC18 has one routine at vector 0x{vector:02X}; serve every source there in one")
        code = value.__code__
        if code.co_argcount - len(value.__defaults__ or ()) > 0 or code.co_kwonlyargcount - len(
                value.__kwdefaults__ or {}) > 0:
            raise FirmwareError(f"{value.__name__}() is an interrupt routine, which the core calls with no arguments "
                                f"(`void {value.__name__}(void)` in C): give it none")
    return {vector: _as_c18_builds_it(function, vector) for vector, function in found.items()}


def _as_c18_builds_it(function: FunctionType, vector: int) -> Callable[[], None]:
    entry, exit_ = C18_ENTRY_CYCLES[vector], C18_EXIT_CYCLES[vector]

    def routine() -> None:
        mcu = current_mcu()
        mcu.spend_cycles(entry)
        function()
        mcu.spend_cycles(exit_)

    routine.__qualname__ = routine.__name__ = function.__name__
    return routine


def in_c18_words(text: str) -> str:
    """A message of the kit's about interrupt routines (the core's, the watchdog's, a crash's) as a C firmware's
    author reads it: `#pragma interrupt` where Python's words say `@interrupt`, and for a vector with no routine, C18's
    pragma and the vector's GOTO to write."""
    for vector, decorator in PRAGMAS.items():
        pragma = f"#pragma {decorator[1:]}"
        python = missing_routine(vector)
        sections = {HIGH_VECTOR: "high_vector", LOW_VECTOR: "low_vector"}
        c = (python.replace(f"has no {decorator} routine", f"has no {pragma} routine")
             .replace(f"Mark the function that serves it with {decorator} (as `{pragma} NAME` does in C18)",
                      f"Name the function that serves it with {pragma} NAME, and put C18's vector at 0x{vector:02X}: "
                      f"#pragma code {sections[vector]}=0x{vector:02X}, a function holding only "
                      f"`_asm GOTO NAME _endasm`, then #pragma code"))
        text = text.replace(python, c).replace(VECTOR_NAMES[vector], VECTOR_NAMES[vector].replace(decorator, pragma))
    return text


def idle(loop: str, values: tuple[object, ...], calls: tuple[object, ...]) -> None:
    """One turn of an empty waiting loop, as the loader rewrites it (appsim.firmware.loader): when the loop's condition
    reads only plain values (`values`, the names it reads, as they are now) and its body calls only `Nop` (`calls`),
    nothing but an interrupt routine can change the condition, so it waits until the next interrupt is taken. Else it
    does nothing, and the loop spins as written."""
    from appsim.firmware import Nop

    if all(type(value) in PLAIN for value in values) and all(call is Nop for call in calls):
        current_mcu().wait_for_interrupt(loop)


__all__ = ["interrupt", "interruptlow"]
