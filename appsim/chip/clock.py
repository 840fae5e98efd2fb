"""The APP023's PIC18F8680 clock: Fosc from a 10 MHz crystal through the 4x PLL, one instruction cycle per 4 Fosc.

The one home of Fosc: the MCU, its ECAN (bit timing) and the command line's defaults take it from here.
"""
from __future__ import annotations

FOSC_HZ = 40_000_000            # 10 MHz crystal with the 4x PLL (HSPLL)
