"""One graded run: the student's firmware on its station's board in a seeded classroom, on the simulated clock.

Loading, picking the station, catching crashes and a `main()` that returns; helpers that read the bus and the LCD.
"""
from __future__ import annotations

import random
import re
import traceback
from collections.abc import Callable, Iterable
from dataclasses import dataclass
from pathlib import Path
from types import ModuleType

from appsim.board.app023 import APP023
from appsim.bus.wire import Bus, BusEvent
from appsim.workshop.classroom import STATIONS, Classroom, station_ids
from appsim.chip.ecan.controller import Mode
from appsim.can.frame import CanFrame
from appsim.firmware.loader import FirmwareError, load_firmware
from appsim.chip.mcu import PIC18F8680
from appsim.sim import PS_PER_SECOND, Simulator

KIT = Path(__file__).resolve().parents[3]
MS = PS_PER_SECOND // 1000
BIT_RATE = 125_000
TIMER1_PERIOD_PS = 65536 * 8 * 100_000          # Fosc/4 = 10 MHz with 1:8: 52.4288 ms
STATION_IDS = tuple(station_ids(k)["MESSAGE_ID1"] for k in range(1, STATIONS + 1))
RTR_IDS = tuple(station_ids(k)["RTR_ID"] for k in range(1, STATIONS + 1))
MASTER_ID = 0x088
MODES = {Mode.NORMAL: "Normal", Mode.DISABLE: "Disable", Mode.LOOPBACK: "Loopback",
         Mode.LISTEN_ONLY: "Listen-only", Mode.CONFIGURATION: "Configuration"}


class Fatal(Exception):
    """The firmware cannot be judged: it did not load, crashed, returned, or has no station's ID."""


@dataclass(frozen=True)
class Firmware:
    """What the student handed in: something a board can run, and where its code lives (for line numbers)."""

    runnable: ModuleType | Callable[[], object]
    filename: str | None
    label: str

    @property
    def module(self) -> ModuleType | None:
        return self.runnable if isinstance(self.runnable, ModuleType) else None


def resolve(firmware: str | Path | ModuleType | Callable[[], object]) -> Firmware:
    """The firmware as a runnable thing; a file that does not load is `Fatal`, with its line."""
    if isinstance(firmware, (str, Path)):
        path = Path(firmware)
        try:
            module = load_firmware(path)
        except FirmwareError as error:
            raise Fatal(_load_error(error, path)) from None
        return Firmware(module, str(path), _short(path))
    if isinstance(firmware, ModuleType):
        if not callable(getattr(firmware, "main", None)):
            raise Fatal(f"{firmware.__name__} has no main(): a firmware defines `def main():` that loops "
                        "forever, as main() does in EX1.C")
        filename = getattr(firmware, "__file__", None)
        return Firmware(firmware, filename, _short(Path(filename)) if filename else firmware.__name__)
    if callable(firmware):
        code = getattr(firmware, "__code__", None)
        return Firmware(firmware, code.co_filename if code else None, f"{getattr(firmware, '__name__', 'main')}()")
    raise TypeError(f"firmware is a file path, a loaded firmware module or a main() function; got {firmware!r}")


def _short(path: Path) -> str:
    try:
        return str(path.resolve().relative_to(KIT))
    except ValueError:
        return str(path)


def _load_error(error: FirmwareError, path: Path) -> str:
    text = str(error)
    cause = error.__cause__
    if cause is not None and cause.__traceback__ is not None:
        where = _student_frame(cause.__traceback__, str(path))
        if where is not None:
            text += f"\n(line {where.lineno}: {where.line})"
    return f"the firmware does not load: {text}"


def _student_frame(tb, filename: str | None) -> traceback.FrameSummary | None:
    """The last line of the student's own file in a traceback (none for code of the kit's, such as a proxy)."""
    if filename is None or Path(filename).resolve().is_relative_to(KIT / "appsim"):
        return None
    mine = [frame for frame in traceback.extract_tb(tb) if frame.filename == filename]
    return mine[-1] if mine else None


def station_of(exercise: str, firmware: Firmware, message_id: int | None) -> int:
    """The station (1..6) the student's board takes: `message_id`, else the firmware's MESSAGE_ID1 (Ex5: RTR_ID)."""
    if message_id is not None:
        return _station_by(message_id, "message_id", STATION_IDS, "0x100, 0x110 .. 0x150")
    module = firmware.module
    if module is None:
        return 1
    if exercise == "ex5" and isinstance(getattr(module, "RTR_ID", None), int):
        return _station_by(module.RTR_ID, "RTR_ID", RTR_IDS, "0x81 .. 0x86 (0x100 -> 0x81 ... 0x150 -> 0x86)")
    value = getattr(module, "MESSAGE_ID1", None)
    if isinstance(value, int):
        return _station_by(value, "MESSAGE_ID1", STATION_IDS, "0x100, 0x110 .. 0x150")
    return 1


def _station_by(value: object, name: str, ids: tuple[int, ...], which: str) -> int:
    if isinstance(value, int) and not isinstance(value, bool) and value in ids:
        return ids.index(value) + 1
    shown = f"0x{value:03X}" if isinstance(value, int) else repr(value)
    raise Fatal(f"{name} = {shown} is not a station's: the classroom's stations use {which}, one each. "
                f"Set {name} to the one assigned to you.")


def hex_id(value: int) -> str:
    return f"0x{value:03X}"


def count(n: int, word: str) -> str:
    """`1 frame`, `3 frames`."""
    return f"{n} {word}{'' if n == 1 else 's'}"


def ms(time_ps: int) -> str:
    return f"{time_ps / MS:.1f} ms"


def payload(potentiometer: int) -> bytes:
    """01 02 03 ADRESH ADRESL for a 10-bit A/D result, right-justified."""
    return bytes([1, 2, 3, potentiometer >> 8, potentiometer & 0xFF])


def describe(frame: CanFrame) -> str:
    """A frame as the CAN monitor would list it: `0x100 DATA 01 02 03 01 2C` or `0x081 RTR DLC 0`."""
    if frame.remote:
        return f"{hex_id(frame.can_id)} RTR DLC {frame.dlc}"
    return f"{hex_id(frame.can_id)} DATA {frame.data.hex(' ').upper()}".rstrip()


def hex_values(text: str) -> list[int]:
    """Hexadecimal numbers on an LCD line: `0x100`, or a bare hex word with a digit in it (`100`, `08A`)."""
    return [int(token.removeprefix("0x").removeprefix("0X"), 16)
            for token in re.findall(r"\b(?:0[xX][0-9A-Fa-f]+|(?=[A-Fa-f]*\d)[0-9A-Fa-f]+)\b", text)]


def decimal_values(text: str) -> list[int]:
    return [int(token) for token in re.findall(r"\b\d+\b", text)]


class Trial:
    """The classroom for one check run: seeded potentiometers, the student's board, the simulated clock."""

    def __init__(self, exercise: str, firmware: Firmware, station: int, seed: int):
        self.exercise = exercise
        self.firmware = firmware
        self.station = station
        self.own_id = STATION_IDS[station - 1]
        self.rtr_id = RTR_IDS[station - 1]
        draw = random.Random(seed)
        values = draw.sample(range(1024), STATIONS + 3)       # distinct, so no value can stand in for another
        self.potentiometers = values[:STATIONS]
        self.master_potentiometers = values[STATIONS:]
        self.bus = Bus(Simulator(), BIT_RATE)
        self._room: Classroom | None = None
        self._board: APP023 | None = None

    @property
    def room(self) -> Classroom:
        if self._room is None:
            raise RuntimeError("set the classroom up first: Trial.classroom(...)")
        return self._room

    @property
    def board(self) -> APP023:
        """The board running the student's firmware."""
        if self._board is None:
            raise RuntimeError("set the classroom up first: Trial.classroom(...)")
        return self._board

    # -------------------------------------------------------------- setting up
    def classroom(self, exercise: int, stations: int, *, own_board: str | None = None) -> Classroom:
        """The master, the PC monitor interface and stations 1..n (n >= the student's), the student's firmware on
        its station's board; or, with `own_board`, on a board of its own by that name (Demo1's monitor)."""
        stations = max(stations, self.station)
        room = self._room = Classroom(self.bus, exercise, stations=stations,
                                      potentiometers=self.potentiometers[:stations],
                                      master_potentiometer=self.master_potentiometers[0])
        board = self._board = (room.station(self.station) if own_board is None
                               else APP023(self.bus, own_board, potentiometer=self.potentiometers[-1]))
        board.run(self.firmware.runnable)
        return room

    def node(self, name: str, main: Callable[[], object]) -> PIC18F8680:
        """A test node of the check's own (a PIC18F8680 at 125 kbit/s running `main`)."""
        mcu = self.bus.attach(PIC18F8680(self.bus.sim, name))
        mcu.run(main)
        return mcu

    # -------------------------------------------------------------- running
    def run(self, seconds: float) -> None:
        """Run the simulated clock; the student's firmware crashing or returning is `Fatal`."""
        sim = self.bus.sim
        sim.run(until=sim.now + round(seconds * PS_PER_SECOND))
        process = self.board.mcu.process
        assert process is not None, "the student's firmware was started in Trial.classroom"
        if process.failure is not None:
            where = _student_frame(process.failure.__traceback__, self.firmware.filename)
            place = f" at line {where.lineno} of {Path(where.filename).name} (`{where.line}`)" if where else ""
            raise Fatal(f"main() crashed{place}: {process.failure_text.strip().splitlines()[-1]}\n"
                        "The board stopped there, so nothing after it can be judged.")
        if process.finished:
            raise Fatal(f"main() returned (by {ms(self.now)}): firmware has nowhere to return to, so main() must "
                        "loop forever (`while True:` around the work, as `while(1)` in EX1.C's main()).")
        for board in self.bus.boards():
            other = board.process
            if board is not self.board.mcu and other is not None and other.failure is not None:
                raise RuntimeError(f"the classroom's own firmware on {board.name} crashed:\n{other.failure_text}")

    # -------------------------------------------------------------- reading what happened
    @property
    def name(self) -> str:
        return self.board.name

    @property
    def now(self) -> int:
        return self.bus.sim.now

    def sent(self, *, ok_only: bool = False) -> list[BusEvent]:
        """The student's frames on the bus (with the ones that ended in errors unless `ok_only`)."""
        return [e for e in self.bus.trace if e.sender == self.name and (e.ok or not ok_only)]

    def reception(self, event: BusEvent) -> str:
        """What the student's acceptance logic did with a frame ("" if the node did not take part)."""
        return dict(event.received).get(self.name, "")

    def mode(self) -> str:
        return MODES[self.board.ecan.opmode]

    def acceptance(self, buffer: str) -> str:
        """RXB0's (or RXB1's) mask, filters and RXM as the registers hold them now, in the workshop's words."""
        ecan = self.board.ecan
        rxm = (ecan.get(f"{buffer}CON") >> 5) & 0b11
        mask, filters = ("RXM0", ("RXF0", "RXF1")) if buffer == "RXB0" else ("RXM1", ("RXF2", "RXF3", "RXF4", "RXF5"))
        values = ", ".join(f"{f} = {hex_id(sid(ecan, f))}" for f in filters)
        if rxm == 0b11:
            return f"{buffer}CON.RXM = 11: {buffer} takes every frame, masks and filters are not used"
        return f"{mask} = {hex_id(sid(ecan, mask))}, {values}, {buffer}CON.RXM = {rxm:02b}"

    def lcd(self, line: int) -> str:
        return self.board.glcd.line(line)


def sid(ecan, register: str) -> int:
    """The 11-bit standard identifier in a filter or mask (RXFnSIDH/SIDL, RXMnSIDH/SIDL)."""
    return (ecan.get(f"{register}SIDH") << 3) | (ecan.get(f"{register}SIDL") >> 5)


def took(reception: str) -> bool:
    """The acceptance logic put the frame in a receive buffer."""
    return reception.startswith("RXB")


def listing(events: Iterable[BusEvent], limit: int = 3) -> str:
    """A few events as `0x110 DATA .. from station2 at 103.2 ms`, and how many more."""
    events = list(events)
    shown = "; ".join(f"{describe(e.frame)} from {e.sender} at {ms(e.start_ps)}" for e in events[:limit])
    return shown + (f" (and {len(events) - limit} more)" if len(events) > limit else "")
