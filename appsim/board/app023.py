"""The APP023 training board: glue around a PIC18F8680 at 40 MHz on a CAN bus, with its off-chip parts.

The potentiometer on AN0, the GLCD, DSW2 (routing the EUSART's pins, read on RJ0/RJ1) and the two serial ends.
"""
from __future__ import annotations

from collections.abc import Callable, Mapping
from pathlib import Path
from types import ModuleType
from typing import Any

from appsim.board.dsw2 import CON9, DSW2, USB
from appsim.board.glcd import GLCD, attach_glcd
from appsim.bus.wire import Bus
from appsim.chip.adc import ADC
from appsim.chip.ecan.controller import ECAN
from appsim.chip.interrupts import Interrupts
from appsim.chip.mcu import PIC18F8680, Routine
from appsim.chip.ports import PortJ
from appsim.chip.timer1 import Timer1
from appsim.chip.usart import USART, SerialEnd
from appsim.firmware.interrupts import routines as interrupt_routines
from appsim.firmware.loader import load_firmware
from appsim.sim import Process


class APP023:
    """One board on a bus. `potentiometer` is the 10-bit value AN0 reads (0..1023)."""

    def __init__(self, bus: Bus, name: str = "station0", *, potentiometer: int = 512):
        self.bus = bus
        self.mcu: PIC18F8680 = bus.attach(PIC18F8680(bus.sim, name))
        self.adc: ADC = self.mcu.adc
        self.adc.potentiometer = potentiometer
        self.interrupts: Interrupts = self.mcu.interrupts
        self.timer1: Timer1 = self.mcu.timer1
        self.usart: USART = self.mcu.usart
        self.portj: PortJ = self.mcu.portj
        self.glcd: GLCD = attach_glcd(self.mcu)
        self.dsw2 = DSW2(self.mcu)                   # 5 6 ON; positions 1 2 drive RJ0 RJ1
        self.portj.levels = self.dsw2.levels
        self.usart.wired_to = lambda: self.dsw2.route
        self.usb = SerialEnd(self.usart, USB, "PIC18F2550 USB-CDC")    # the USB-CDC monitor's end (DSW2 5 6 ON)
        self.con9 = SerialEnd(self.usart, CON9, "CON9 RS-232")         # the RS-232 connector's end (DSW2 3 4 ON)
        self.firmware: ModuleType | None = None

    @property
    def name(self) -> str:
        return self.mcu.name

    @property
    def ecan(self) -> ECAN:
        return self.mcu.ecan

    def run(self, firmware: str | Path | ModuleType | Callable[[], Any],
            routines: Mapping[int, Routine] | None = None) -> Process:
        """Program the board with a firmware file, module or `main` function, and start it: a file's or module's
        interrupt routines are those it marks (@interrupt, @interruptlow); a bare `main` has `routines`, if any."""
        if isinstance(firmware, (str, Path)):
            firmware = load_firmware(firmware)
        if isinstance(firmware, ModuleType):
            self.firmware = firmware
            return self.mcu.run(firmware.main, interrupt_routines(firmware))
        return self.mcu.run(firmware, routines)
