"""Frames read through a CAN database (a DBC file, read by cantools): each frame's message name and signal values, for
the trace table, the timeline and the terminal's trace.
"""
from __future__ import annotations

from pathlib import Path
from typing import Any

from appsim.bus.wire import BusEvent
from appsim.can.frame import CanFrame
from appsim.errors import AppsimError


class DbcError(AppsimError, ValueError):
    """A CAN database file that cannot be read, with what is wrong."""


class Signals:
    """The messages of the DBC at `path`, to name frames and their signals. A frame the DBC does not describe reads
    as "" (the trace shows it as before)."""

    def __init__(self, path: str | Path):
        import cantools

        self.path = Path(path)
        try:
            database = cantools.database.load_file(str(self.path), database_format="dbc")
        except FileNotFoundError:
            raise DbcError(f"there is no CAN database {self.path}: give the path of a .dbc file (--dbc alone reads "
                           "the workshop's)") from None
        except (OSError, UnicodeDecodeError) as error:
            raise DbcError(f"cannot read {self.path}: {getattr(error, 'strerror', None) or error}") from None
        except Exception as error:      # cantools' parse errors have no common base
            words = "".join(c if c.isprintable() else "?" for c in (str(error).splitlines() or [""])[0])
            raise DbcError(f"{self.path} is not a DBC file cantools can read: {words[:200]}") from None
        if not isinstance(database, cantools.database.can.Database):
            raise DbcError(f"{self.path} is not a CAN database")
        self.database = database
        self._by_id: dict[tuple[int, bool], Any] = {(message.frame_id, bool(message.is_extended_frame)): message
                                                    for message in database.messages}

    def describe(self, frame: CanFrame) -> str:
        """"MASTER_BROADCAST: TxData0=1 TxData1=2 TxData2=3 ADRES=666 counts", or why the data do not fit."""
        message = self._by_id.get((frame.can_id, frame.extended))
        if message is None:
            return ""
        if frame.remote:
            return f"remote request (RTR) for {message.name}"
        if len(frame.data) != message.length:
            return f"{message.name}: {len(frame.data)} data bytes where the DBC says {message.length}"
        values = message.decode(frame.data, decode_choices=True)
        assert isinstance(values, dict)         # a message without containers decodes to its signals
        units = {signal.name: signal.unit for signal in message.signals}
        shown = [f"{name}={_value(value)}" + (f" {units[name]}" if units.get(name) else "")
                 for name, value in values.items()]
        return f"{message.name}: {' '.join(shown)}"

    def __call__(self, event: BusEvent) -> str:
        """What the trace shows for an event: its frame's signals (nothing for an error frame)."""
        return "" if event.error else self.describe(event.frame)


def _value(value: object) -> str:
    return f"{value:g}" if isinstance(value, float) else str(value)
