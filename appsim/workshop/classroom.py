"""The workshop's classroom on one bus: the master console, six student stations running one exercise, the PC's monitor.

Station k (1..6) has MESSAGE_ID1 = 0x100 + 0x10 (k - 1) and RTR ID 0x81 + (k - 1); your own board can take a
station's place.
"""
from __future__ import annotations

import random
from collections.abc import Collection, Mapping, Sequence
from pathlib import Path
from types import ModuleType

from appsim.board.app023 import APP023
from appsim.bus.wire import Bus
from appsim.chip.mcu import PIC18F8680
from appsim.firmware.an738 import (
    CAN_CONFIG_FLAGS,
    CANInitialize,
    CANIsRxReady,
    CANReceiveMessage,
)
from appsim.firmware.loader import FirmwareError, constants, load_firmware
from appsim.workshop import course
from appsim.workshop.course import CLASSROOM_EXERCISES, STATIONS, station_ids

DEFAULT_POTENTIOMETERS = (100, 250, 400, 550, 700, 850)


def station_defines(names: Collection[str], station: int) -> dict[str, int]:
    """Station k's IDs (see `station_ids`) for a firmware file that assigns `names` at top level."""
    return {name: value for name, value in station_ids(station).items() if name in names}


def pc_monitor_interface() -> None:
    """Firmware of the PC monitor's CAN interface (CANKing on a PICDEM CAN-LIN 3, a PIC18F8680).

    It is on the bus in Normal mode at 125 kbit/s, so it ACKs every frame, and takes every frame in.
    The workshop needs it: in Ex4 every student starts in Listen-only mode, which never ACKs, so
    without it nobody would acknowledge the master's 0x088.
    """
    CANInitialize(4, 10, 8, 4, 3, CAN_CONFIG_FLAGS.CAN_CONFIG_ALL_MSG)
    while True:
        if CANIsRxReady():
            CANReceiveMessage()     # CANKing lists it; here, read `bus.trace`


def _check_station(station: int, stations: int) -> None:
    if not isinstance(station, int) or isinstance(station, bool) or not 1 <= station <= stations:
        raise ValueError(f"station {station!r} is not in this classroom: stations are numbered 1..{stations}")


class Classroom:
    """The master console and `stations` student boards on `bus`, each station running `ex{exercise}.py`.

    The stations' files come from `firmware_dir` (the solutions by default), `ex{exercise}.py` or with `language`
    "c" `ex{exercise}.c`, each loaded with its station's MESSAGE_ID1 and RTR_ID (those the file assigns or
    #defines), as six students each edit their copy.
    Potentiometers: `potentiometers` (one per station), else drawn from `random.Random(seed)` when a
    seed is given, else fixed distinct values. `monitor` puts the PC's CAN monitor on the bus (it ACKs
    every frame, see `pc_monitor_interface`). Nothing runs until the bus's simulator runs.
    """

    def __init__(self, bus: Bus, exercise: int, *, stations: int = STATIONS,
                 potentiometers: Sequence[int] | None = None, master_potentiometer: int = 512,
                 firmware_dir: str | Path | None = None, seed: int | None = None, monitor: bool = True,
                 language: str = "python"):
        if exercise not in CLASSROOM_EXERCISES:
            raise ValueError(f"exercise {exercise!r} does not exist: the workshop has EX1.C .. EX6.C (1..6)")
        if not isinstance(stations, int) or not 1 <= stations <= STATIONS:
            raise ValueError(f"the classroom has 1..{STATIONS} student stations (0x100 .. 0x150); got {stations!r}")
        if potentiometers is None:
            draw = random.Random(seed)
            potentiometers = ([draw.randrange(1024) for _ in range(stations)] if seed is not None
                              else DEFAULT_POTENTIOMETERS[:stations])
        if len(potentiometers) != stations:
            raise ValueError(f"give one potentiometer value per station: {stations} stations, "
                             f"{len(potentiometers)} values")
        self.bus = bus
        self.exercise = exercise
        if language not in ("python", "c"):
            raise ValueError(f"the stations' firmware is in 'python' (exN.py) or 'c' (exN.c); got {language!r}")
        self.firmware = (Path(course.SOLUTIONS if firmware_dir is None else firmware_dir)
                         / f"ex{exercise}.{'c' if language == 'c' else 'py'}")
        self.master = APP023(bus, "master", potentiometer=master_potentiometer)
        self.master.run(load_firmware(course.MASTER_FIRMWARE))
        self.stations: dict[int, APP023] = {}
        names = constants(self.firmware)
        for k, potentiometer in enumerate(potentiometers, start=1):
            board = APP023(bus, f"station{k}", potentiometer=potentiometer)
            defines = station_defines(names, k)
            board.run(load_firmware(self.firmware, defines))
            self.stations[k] = board
        self.monitor: PIC18F8680 | None = None
        if monitor:
            self.monitor = bus.attach(PIC18F8680(bus.sim, "monitor"))
            self.monitor.run(pc_monitor_interface)

    def station(self, k: int) -> APP023:
        """Student station k (1..6)."""
        _check_station(k, len(self.stations))
        return self.stations[k]

    @property
    def boards(self) -> list[APP023]:
        """The master, then the stations in order."""
        return [self.master, *self.stations.values()]

    def join(self, firmware: str | Path | ModuleType, station: int, *,
             defines: Mapping[str, int] | None = None) -> APP023:
        """Your own firmware on station k's board (its name and potentiometer), in place of the solution.

        The file runs as written (set MESSAGE_ID1 to station k's, see `station_ids`), or with `defines`.
        Join before the classroom runs, as a board is programmed before it goes on the bus.
        """
        board = self.station(station)
        process = board.mcu.process
        if process is not None and (process or process.dead):
            raise RuntimeError(f"station {station} is already running: join before the classroom runs "
                               "(before the simulator's first run), as a board is programmed before it is "
                               "connected to the bus")
        if isinstance(firmware, ModuleType):
            if defines:
                raise FirmwareError("defines apply when a file is loaded: give the path, not a loaded module")
        else:
            firmware = load_firmware(firmware, defines)
        board.run(firmware)
        return board

    def run(self, seconds: float) -> None:
        """Let the class run for `seconds` of simulated time; a board whose firmware crashed is an error."""
        sim = self.bus.sim
        sim.run_for(seconds)
        for board in self.boards:
            process = board.mcu.process
            if process is not None and process.failure is not None:
                raise FirmwareError(f"the firmware of {board.name} crashed:\n{process.failure_text}")
