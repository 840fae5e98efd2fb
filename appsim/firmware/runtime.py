"""The C runtime a library function of the firmware runs in: the MCU it acts on, and what its CALL costs.

Every AN738 and C18 function starts with `library_call()`; it reaches the board only through that MCU's registers.
"""
from __future__ import annotations

from appsim.chip.sfr import FirmwareMCU, current_mcu

CALL_CYCLES = 10                # CALL/RETURN and argument passing of a C18 library function


def library_call() -> FirmwareMCU:
    """The MCU a C18 or AN738 library function acts on, after the CALL/RETURN and argument passing it costs."""
    mcu = current_mcu()
    mcu.spend_cycles(CALL_CYCLES)
    return mcu
