"""Why a firmware run earns nothing for an exercise: one word for the gradebook, and a message in the workshop's words.

The same faults come from a run in the notebook (`check`) and from the grader's sandbox (`appsim grade`).
"""
from __future__ import annotations

from dataclasses import dataclass
from typing import TYPE_CHECKING

from appsim.errors import FirmwareHung

if TYPE_CHECKING:
    from appsim.sim import Process

# The kinds, as the gradebook's `fault` column names them (docs/grading.md explains each).
KINDS = ("missing", "symlink", "unreadable", "ambiguous", "load", "exception", "returned", "exited", "stalled",
         "time", "memory", "forbidden", "protocol", "grader")


@dataclass(frozen=True)
class Fault:
    """Why a firmware run earns nothing: `kind` is one word of `KINDS`, `message` says what happened and what to do."""

    kind: str
    message: str

    def __post_init__(self) -> None:
        if self.kind not in KINDS:
            raise ValueError(f"no fault kind {self.kind!r}; the kinds are {', '.join(KINDS)}")


class FirmwareFault(RuntimeError):
    """Raised in a board's process when its (sandboxed) firmware ended with `fault`; the board stops there."""

    def __init__(self, fault: Fault):
        super().__init__(fault.message)
        self.fault = fault


RETURNED = Fault("returned", "main() returned: firmware has nowhere to return to, so main() must loop forever "
                             "(`while True:` around the work, as `while(1)` in EX1.C's main()).")
EXITED = Fault("exited", "the firmware exited (sys.exit, os._exit, or its process ended) while the board was running "
                         "it: firmware never exits; main() loops forever, as main() does in EX1.C")


def stalled(seconds: float) -> Fault:
    return Fault("stalled", f"the firmware stopped answering: {seconds:g} s of wall time went by without it touching "
                            "a register (an endless loop that reads nothing, such as `while True: pass`, or a sleep)")


def fault_of(failure: BaseException, filename: str | None) -> Fault:
    """The fault for what a board's firmware process raised (it ran in this process, or in the sandbox)."""
    if isinstance(failure, FirmwareFault):
        return failure.fault
    if isinstance(failure, SystemExit):
        return EXITED
    if isinstance(failure, FirmwareHung):
        return Fault("stalled", str(failure))
    if isinstance(failure, MemoryError):
        return Fault("memory", "the firmware ran out of memory (MemoryError): a list or string that grows "
                               "without end in the main loop?")
    # the firmware loader, only where a firmware ran (not in the grader's coordinator, which starts its workers first)
    from appsim.firmware.loader import crash_message
    return Fault("exception", crash_message(failure, filename))


def board_fault(process: Process) -> Fault | None:
    """Why a board's firmware is no longer running, if it is not: what it raised (see `fault_of`), or it returned."""
    if process.failure is not None:
        return fault_of(process.failure, process.filename)
    return RETURNED if process.finished else None
