"""What a CAN controller offers the wire, and what the wire tells it: the one interface between the bus and a chip.

The bus drives any controller of this shape (the PIC18F8680's ECAN is one) and imports no chip; a controller raises
its own changes to whatever runs on it.
"""
from __future__ import annotations

import enum
from typing import Protocol

from appsim.bus.bitlevel import Assembled
from appsim.can.bittiming import BitTiming
from appsim.can.frame import CanFrame


class Mode(enum.IntEnum):
    """A controller's operating mode, numbered as the ECAN's OPMODE<2:0> / REQOP<2:0> (CANSTAT<7:5>, CANCON<7:5>)."""

    NORMAL = 0b000
    DISABLE = 0b001
    LOOPBACK = 0b010
    LISTEN_ONLY = 0b011
    CONFIGURATION = 0b100

    @property
    def words(self) -> str:
        """The mode as the workshop writes it: "Normal", "Listen-only", ..."""
        return self.name.capitalize().replace("_", "-")


class ErrorCounters:
    """A controller's fault confinement, read from its transmit and receive error counters as ISO 11898-1 says:
    bus-off with TEC above 255, else error-passive with TEC or REC above 127, else error-active."""

    tec: int
    rec: int

    @property
    def bus_off(self) -> bool:
        return self.tec > 255

    @property
    def error_passive(self) -> bool:
        return self.tec <= 255 and (self.tec > 127 or self.rec > 127)


class Wire(Protocol):
    """What a controller tells the wire it is attached to."""

    def mode_requested(self, controller: Controller) -> None:
        """The firmware asked for another mode: it takes effect when the bus lets it (11 recessive bits)."""

    def transmit_requested(self, controller: Controller) -> None:
        """A transmit buffer has a frame to send."""


class Controller(Protocol):
    """A CAN controller as the wire sees it: its mode and error state, its next frame, and the events of the bus
    (a frame it sent went through or failed, it lost arbitration, a frame or an error reached it).

    The events change what its firmware can see; the controller raises those changes itself.
    """

    name: str                       # the node's name in the bus trace
    fosc: int                       # its oscillator: with its bit timing, its own bit rate
    wire: Wire | None
    opmode: Mode
    tec: int                        # transmit and receive error counters (fault confinement)
    rec: int
    on_wire: str | None             # the transmit buffer whose frame is on the bus now

    @property
    def bus_off(self) -> bool: ...
    @property
    def error_passive(self) -> bool: ...
    def bit_timing(self) -> BitTiming: ...
    def enter_requested_mode(self) -> None: ...
    def next_transmission(self) -> str | None: ...
    def frame_in(self, buffer: str) -> CanFrame: ...
    def transmission_started(self, buffer: str) -> None: ...
    def transmission_succeeded(self, buffer: str) -> None: ...
    def arbitration_lost(self, buffer: str) -> None: ...
    def transmission_failed(self, buffer: str, *, tec_increment: int = 8) -> None: ...
    def frame_received(self, frame: CanFrame) -> object:
        """A valid frame for its acceptance logic; what that did with it, as the trace shows it (`str`)."""
    def receive_error(self, *, rec_increment: int = 1, assembled: Assembled | None = None,
                      acknowledged: bool = False) -> None:
        """It detected an error as a receiver (or a silent listener); `assembled`: what it had read up to it;
        `acknowledged`: it had received the frame without error up to the ACK slot and sent its ACK, so REC counts
        down first (rule 8, `appsim.bus.bitlevel.rule_8`), then up by `rec_increment`."""
    def bus_activity(self) -> None:
        """A start of frame on the bus (wakes a sleeping controller)."""
    def bus_off_recovery(self, sequences: int) -> None: ...


class Node(Protocol):
    """What sits on the bus: anything with a name and a controller (a PIC18F8680)."""

    name: str

    @property
    def controller(self) -> Controller: ...
