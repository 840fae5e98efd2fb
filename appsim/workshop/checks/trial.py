"""One graded run: the student's firmware on its station's board in a seeded classroom, on the simulated clock.

Loading, picking the station, catching crashes and a `main()` that returns; helpers that read the bus and the LCD.
"""
from __future__ import annotations

import random
import re
from collections.abc import Callable, Iterable, Mapping, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from types import ModuleType
from typing import Protocol

from appsim.board.app023 import APP023
from appsim.bus.trace import Trace
from appsim.bus.wire import Bus, BusEvent
from appsim.can.frame import STANDARD_ID_MAX, CanFrame
from appsim.chip.ecan.acceptance import raw29
from appsim.chip.ecan.controller import ECAN
from appsim.chip.mcu import PIC18F8680
from appsim.errors import AppsimError, FirmwareError
from appsim.firmware.identity import identity_of, shown
from appsim.firmware.interrupts import in_c18_words
from appsim.firmware.interrupts import routines as interrupt_routines
from appsim.firmware.loader import is_c, load_firmware, load_source, read_firmware
from appsim.sim import PS_PER_SECOND, Simulator
from appsim.workshop.classroom import Classroom
from appsim.workshop.course import CLASSROOM_BIT_RATE, MASTER_ID, RTR_IDS, STATION_IDS, STATIONS
from appsim.workshop.faults import Fault, fault_of

MS = PS_PER_SECOND // 1000
TIMER1_PERIOD_PS = 65536 * 8 * 100_000          # Fosc/4 = 10 MHz with 1:8: 52.4288 ms
__all__ = ["MASTER_ID"]


class Fatal(AppsimError):
    """The firmware cannot be judged: `fault` says why (it did not load, crashed, returned, has no station's ID...)."""

    def __init__(self, fault: Fault):
        super().__init__(fault.message)
        self.fault = fault


@dataclass(frozen=True)
class Firmware:
    """What the student handed in, loaded: what a board runs, what it calls itself, where its code lives.

    `identity` holds the integers the loaded firmware gives MESSAGE_ID1 and RTR_ID (missing if not integers): the
    firmware's own word, which is safe to take, since the verdict comes from what it then does on the bus. `routines`
    are its interrupt routines by vector, as the board's core calls them.
    """

    runnable: Callable[[], object]
    filename: str | None
    label: str
    identity: Mapping[str, int] = field(default_factory=dict)
    routines: Mapping[int, Callable[[], object]] = field(default_factory=dict)
    language: str = "python"        # or "c": the language its messages quote code in

    def says(self, python: str, c: str) -> str:
        """A piece of code as the firmware's own language writes it."""
        return c if self.language == "c" else python

    def worded(self, fault: Fault) -> Fault:
        """A fault of this firmware's run in its own language's words (C's `#pragma interrupt` for `@interrupt`)."""
        return Fault(fault.kind, in_c18_words(fault.message)) if self.language == "c" else fault


class Loadable(Protocol):
    """Firmware that loads itself elsewhere (the grader's sandbox): `load()` gives it, or raises `Fatal`."""

    def load(self) -> Firmware: ...


def loaded(load: Callable[[], ModuleType], filename: str, label: str) -> Firmware:
    """The firmware module `load()` gives (its code from `filename`, called `label`); one that does not load is
    `Fatal`, with the loader's words."""
    try:
        module = load()
    except FirmwareError as error:
        raise Fatal(Fault("load", f"the firmware does not load: {error}")) from None
    return Firmware(module.main, filename, label, identity_of(module), interrupt_routines(module),
                    language_of(module))


def language_of(module: ModuleType) -> str:
    return "c" if getattr(module, "__c18__", False) else "python"


def notebook_firmware(path: Path) -> tuple[str | None, str, bytes]:
    """The exercise a notebook names, and the file its firmware cells make (ex1.py, or ex1.c: the language its
    FIRMWARE cell chooses) with their code, read as `appsim grade` reads it (IPython magics made comments, so its
    lines are the cells'); FirmwareError if it has none or is no notebook."""
    from appsim.workshop.grading.submissions import firmware_from_notebook

    exercise, firmware = firmware_from_notebook(path.name, read_firmware(path))
    if isinstance(firmware, Fault):
        raise FirmwareError(firmware.message)
    return exercise, *firmware


def resolve(firmware: str | Path | ModuleType | Callable[[], object] | Loadable,
            c_options: Sequence[str] = ()) -> Firmware:
    """The firmware as a runnable thing (a notebook's firmware cell for a .ipynb file); one that does not load is
    `Fatal`, with its line. `c_options` are C18's options for a .c file (or a notebook's C cell)."""
    if isinstance(firmware, (str, Path)):
        path = Path(firmware)
        if path.suffix.lower() == ".ipynb":
            def from_notebook() -> ModuleType:
                _, graded, source = notebook_firmware(path)
                return load_source(path, source, language="c" if is_c(graded) else "python", c_options=c_options)
            return loaded(from_notebook, str(path), str(path))
        return loaded(lambda: load_firmware(path, c_options=c_options), str(path), str(path))
    if isinstance(firmware, ModuleType):
        if not callable(getattr(firmware, "main", None)):
            raise Fatal(Fault("load", f"{firmware.__name__} has no main(): a firmware defines `def main():` that "
                                      "loops forever, as main() does in EX1.C"))
        filename = getattr(firmware, "__file__", None)
        label = Path(filename).name if filename else firmware.__name__
        try:
            routines = interrupt_routines(firmware)
        except FirmwareError as error:
            raise Fatal(Fault("load", f"the firmware does not load: {error}")) from None
        return Firmware(firmware.main, filename, label, identity_of(firmware), routines, language_of(firmware))
    load = getattr(firmware, "load", None)
    if callable(load):
        return load()               # it loads itself, with its own options
    if callable(firmware):
        code = getattr(firmware, "__code__", None)
        return Firmware(firmware, code.co_filename if code else None, f"{getattr(firmware, '__name__', 'main')}()")
    raise TypeError(f"firmware is a file path, a loaded firmware module or a main() function; got {firmware!r}")


@dataclass(frozen=True)
class Placement:
    """Where the student's board goes in the classroom: the station (1..6) whose place it takes, the identifiers it
    sends (MESSAGE_ID1, and Ex5's RTR_ID), and, if one is no station's, why (in the student's names): the checks that
    depend on the station fail with it, everything else is judged all the same."""

    station: int
    own_id: int
    rtr_id: int
    problem: str | None = None


STATIONS_SAY = {"MESSAGE_ID1": "0x100, 0x110 ... 0x150", "RTR_ID": "0x81 ... 0x86 (0x100 -> 0x81 ... 0x150 -> 0x86)"}


def placement(exercise: str, firmware: Firmware, message_id: int | None = None) -> Placement:
    """The student's board's place, from `message_id` if given, else from the firmware as loaded: its MESSAGE_ID1
    (Ex5: its RTR_ID names the station); without one, station 1. Ex1 runs off the bus in Loopback mode, so any standard
    identifier will do there (the workshop's own fix sets MESSAGE_ID1 to the filter's 0x088); on the bus an
    identifier that is no station's takes station 1's place, and the checks say what is wrong with it."""
    own = firmware.identity.get("MESSAGE_ID1") if message_id is None else message_id
    rtr_id = firmware.identity.get("RTR_ID")
    if exercise == "ex5" and rtr_id is not None and message_id is None:
        if rtr_id in RTR_IDS:
            station = RTR_IDS.index(rtr_id) + 1
            return Placement(station, STATION_IDS[station - 1], rtr_id)
        return Placement(1, STATION_IDS[0], rtr_id, _no_station("RTR_ID", rtr_id))
    if own is None:
        return Placement(1, STATION_IDS[0], RTR_IDS[0])
    if own in STATION_IDS:
        station = STATION_IDS.index(own) + 1
        return Placement(station, own, RTR_IDS[station - 1])
    if exercise == "ex1" and 0 <= own <= STANDARD_ID_MAX:
        return Placement(1, own, RTR_IDS[0])
    problem = (f"MESSAGE_ID1 = {shown(own)} is not a standard identifier: CAN's 11-bit identifiers are 0x000 .. "
               f"0x{STANDARD_ID_MAX:03X}." if exercise == "ex1" else _no_station("MESSAGE_ID1", own))
    return Placement(1, own, RTR_IDS[0], problem)


def _no_station(name: str, value: int) -> str:
    return (f"{name} = {shown(value)} is not a station's identifier: the classroom's stations use "
            f"{STATIONS_SAY[name]}, one each. Set {name} to the one assigned to you.")


def quoted(text: str, most: int = 80) -> str:
    """Text the firmware produced, quoted for a message: its first `most` characters, and how long it was."""
    return repr(text) if len(text) <= most else f"{text[:most]!r}... ({len(text):,} characters)"


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


class _TraceFull(Exception):
    """A trace of the check's passed its window: the run stops at that event (a flood would otherwise run on to the
    end of the check, in the grader's time, only to be judged a memory fault there)."""


def _stop_when_full(trace: Trace) -> Callable[[BusEvent], None]:
    """A trace listener that stops the run at the first event its window cannot keep."""
    def listener(event: BusEvent) -> None:
        if trace.window is not None and trace.total > trace.window:
            raise _TraceFull
    return listener


class Trial:
    """The classroom for one check run: seeded potentiometers, the student's board, the simulated clock."""

    def __init__(self, exercise: str, firmware: Firmware, station: int | Placement, seed: int):
        self.exercise = exercise
        self.firmware = firmware
        place = station if isinstance(station, Placement) else Placement(station, STATION_IDS[station - 1],
                                                                          RTR_IDS[station - 1])
        self.station = place.station
        self.own_id = place.own_id
        self.rtr_id = place.rtr_id
        self.identity_problem = place.problem     # MESSAGE_ID1 (Ex5: RTR_ID) is no station's: why, in its names
        draw = random.Random(seed)
        values = draw.sample(range(1024), STATIONS + 3)       # distinct, so no value can stand in for another
        self.potentiometers = values[:STATIONS]
        self.master_potentiometers = values[STATIONS:]
        self.bus = Bus(Simulator(), CLASSROOM_BIT_RATE)
        for trace in (self.bus.trace, self.bus.loopback_trace):
            trace.listeners.append(_stop_when_full(trace))
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
        board.run(self.firmware.runnable, self.firmware.routines)
        return room

    def node(self, name: str, main: Callable[[], object]) -> PIC18F8680:
        """A test node of the check's own (a PIC18F8680 at 125 kbit/s running `main`)."""
        mcu = self.bus.attach(PIC18F8680(self.bus.sim, name))
        mcu.run(main)
        return mcu

    # -------------------------------------------------------------- running
    def run(self, seconds: float) -> None:
        """Run the simulated clock; the student's firmware crashing, hanging or returning is `Fatal`."""
        sim = self.bus.sim
        try:
            sim.run_for(seconds)
        except _TraceFull:          # the run ends there: what went by since can no longer be judged (below)
            pass
        process = self.board.mcu.process
        assert process is not None, "the student's firmware was started in Trial.classroom"
        if process.failure is not None:
            raise Fatal(self.firmware.worded(fault_of(process.failure, self.firmware.filename)))
        if process.finished:
            raise Fatal(Fault("returned", f"main() returned (by {ms(self.now)}): firmware has nowhere to return to, "
                                          "so main() must loop forever (`while True:` around the work, as "
                                          "`while(1)` in EX1.C's main())."))
        for trace, what in ((self.bus.trace, "frames and error frames on the bus"),
                            (self.bus.loopback_trace, "frames sent in Loopback mode")):
            if trace.dropped:
                raise Fatal(Fault("memory", f"memory limit: a check keeps the last {trace.window:,} {what}, and "
                                            f"{trace.total:,} went by in {ms(self.now)}, so the check cannot see what "
                                            "the firmware did: a loop that sends without waiting (CANSendMessage "
                                            "on every turn, at a bit rate far above the workshop's 125 kbit/s?)"))
        for board in self.bus.boards():
            if not isinstance(board, PIC18F8680):
                continue
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

    def acked(self) -> list[BusEvent]:
        """The frames on the bus the student's node ACKed (a node in Normal mode ACKs every correct frame)."""
        return [e for e in self.bus.trace if self.name in e.acked_by]

    def reception(self, event: BusEvent) -> str:
        """What the student's acceptance logic did with a frame ("" if the node did not take part)."""
        return dict(event.received).get(self.name, "")

    def mode(self) -> str:
        return self.board.ecan.opmode.words

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


def sid(ecan: ECAN, register: str) -> int:
    """The 11-bit standard identifier in a filter or mask (RXFnSIDH/SIDL, RXMnSIDH/SIDL): its top 11 of 29 bits."""
    return raw29(*(ecan.get(register + part) for part in ("SIDH", "SIDL", "EIDH", "EIDL"))) >> 18


def took(reception: str) -> bool:
    """The acceptance logic put the frame in a receive buffer."""
    return reception.startswith("RXB")


def took_part(sent: list[BusEvent], acked: list[BusEvent]) -> str:
    """What a node that was to keep off the bus did there: `sent ...`, else `ACKed ...`."""
    return f"sent {listing(sent)}" if sent else f"ACKed {listing(acked)}"


def listing(events: Iterable[BusEvent], limit: int = 3) -> str:
    """A few events as `0x110 DATA .. from station2 at 103.2 ms`, and how many more."""
    events = list(events)
    shown = "; ".join(f"{describe(e.frame)} from {e.sender} at {ms(e.start_ps)}" for e in events[:limit])
    return shown + (f" (and {len(events) - limit} more)" if len(events) > limit else "")
