"""The APP023 training board: a PIC18F8680 at 40 MHz with its ECAN on a CAN bus and the A/D on a potentiometer.

The board's other parts (Timer1, GLCD, USART to the USB-CDC monitor) plug into the same SFR bus.
"""
from __future__ import annotations

from collections.abc import Callable
from pathlib import Path
from types import ModuleType
from typing import Any

from appsim.chip.adc import ADC, attach_adc
from appsim.bus.wire import Bus
from appsim.board.dsw2 import attach_dsw2
from appsim.board.glcd import GLCD, attach_glcd
from appsim.chip.interrupts import PeripheralInterrupts, attach_interrupts
from appsim.firmware.loader import load_firmware
from appsim.chip.mcu import PIC18F8680
from appsim.sim import Process
from appsim.chip.timer1 import Timer1, attach_timer1
from appsim.chip.usart import USART, SerialEnd, attach_usart


class APP023:
    """One board on a bus. `potentiometer` is the 10-bit value AN0 reads (0..1023)."""

    def __init__(self, bus: Bus, name: str = "station0", *, potentiometer: int = 512):
        self.bus = bus
        self.mcu: PIC18F8680 = bus.attach(PIC18F8680(bus.sim, name))
        self.adc: ADC = attach_adc(self.mcu)
        self.adc.potentiometer = potentiometer
        self.interrupts: PeripheralInterrupts = attach_interrupts(self.mcu)
        self.timer1: Timer1 = attach_timer1(self.mcu, self.interrupts)
        self.glcd: GLCD = attach_glcd(self.mcu)
        self.dsw2, self.portj = attach_dsw2(self.mcu)      # DSW2 5 6 ON; positions 1 2 on RJ0 RJ1
        self.usart: USART = attach_usart(self.mcu, self.interrupts, self.dsw2)
        self.usb: SerialEnd = self.usart.usb         # the PIC18F2550 USB-CDC monitor's end (DSW2 5 6 ON)
        self.con9: SerialEnd = self.usart.con9       # the RS-232 connector's end (DSW2 3 4 ON)
        self.firmware: ModuleType | None = None

    @property
    def name(self) -> str:
        return self.mcu.name

    @property
    def ecan(self):
        return self.mcu.ecan

    def run(self, firmware: str | Path | ModuleType | Callable[[], Any]) -> Process:
        """Program the board with a firmware file, module or `main` function, and start it."""
        if isinstance(firmware, (str, Path)):
            firmware = load_firmware(firmware)
        if isinstance(firmware, ModuleType):
            self.firmware = firmware
            firmware = firmware.main
        return self.mcu.run(firmware)
