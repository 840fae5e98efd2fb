"""What CAN Workshop 202 is made of: its exercises, the classroom's bus and stations, and the firmware files it ships.

The starters and reference solutions live in the repository's exercises/ and solutions/ folders and ship inside the
package (appsim.workshop.exercises, appsim.workshop.solutions), so they are found the same way installed or edited.
"""
from __future__ import annotations

from importlib import resources
from pathlib import Path

from appsim.can.bittiming import BitTiming

CLASSROOM_BIT_RATE = 125_000        # CANInitialize(4, 10, 8, 4, 3, ...) at Fosc = 40 MHz
CLASSROOM_TIMING = BitTiming(sjw=4, brp=10, seg1ph=8, seg2ph=4, prseg=3)    # the classroom's, in every exercise
EXERCISES: tuple[str, ...] = ("ex1", "ex2", "ex3", "ex4", "ex5", "ex6", "demo1")
CLASSROOM_EXERCISES = range(1, 7)   # what the stations can run: EX1.C .. EX6.C
EXERCISE_FILES: dict[str, str] = {**{f"ex{n}": f"ex{n}.py" for n in CLASSROOM_EXERCISES},
                                  "demo1": "demo1_monitor.py"}
C_FILES: dict[str, str] = {exercise: name.removesuffix(".py") + ".c" for exercise, name in EXERCISE_FILES.items()}
STATIONS = 6
MASTER_ID = 0x088                   # the master console's broadcast, every 100 ms


def station_ids(station: int) -> dict[str, int]:
    """Station k's constants as the workshop assigns them: MESSAGE_ID1 and the Ex5 RTR ID."""
    if not isinstance(station, int) or isinstance(station, bool) or not 1 <= station <= STATIONS:
        raise ValueError(f"station {station!r} is not in the classroom: stations are numbered 1..{STATIONS}")
    return {"MESSAGE_ID1": 0x100 + 0x10 * (station - 1), "RTR_ID": 0x81 + (station - 1)}


STATION_IDS: tuple[int, ...] = tuple(station_ids(k)["MESSAGE_ID1"] for k in range(1, STATIONS + 1))
RTR_IDS: tuple[int, ...] = tuple(station_ids(k)["RTR_ID"] for k in range(1, STATIONS + 1))


def exercise_name(exercise: object) -> str:
    """The exercise as the kit names it ("ex3", "demo1"), from 3, "3", "ex3", "EX3", " Ex3 " or "demo1"."""
    text = str(exercise).strip().lower() if isinstance(exercise, (int, str)) and not isinstance(exercise, bool) else ""
    if text.isdigit():
        text = f"ex{text}"
    if text in EXERCISES:
        return text
    raise ValueError(f"exercise {exercise!r} does not exist: the workshop has Ex1..Ex6 (1..6, ex1..ex6) and "
                     "demo1, the CAN monitor")


# STARTERS, SOLUTIONS (folders) and MASTER_FIRMWARE (a file), found when first asked for: importing this module
# needs neither (a firmware in the grader's sandbox may import the kit, where the solutions are not to be found).
_FILES = {"STARTERS": ("appsim.workshop.exercises", ""), "SOLUTIONS": ("appsim.workshop.solutions", ""),
          "MASTER_FIRMWARE": ("appsim.workshop", "master.py")}


def __getattr__(name: str) -> Path:
    if name not in _FILES:
        raise AttributeError(f"module {__name__!r} has no attribute {name!r}")
    package, file = _FILES[name]
    root = Path(__file__).resolve().parents[2]
    if (root / "pyproject.toml").is_file() and package != __package__:
        # A source checkout (edited or run as python -m appsim) uses its own folders, whatever else is installed.
        folder = root / package.rpartition(".")[2]
    else:
        folder = Path(str(resources.files(package)))
    path = globals()[name] = folder / file
    return path


def starter(exercise: object, language: str = "python") -> Path:
    """The starter file of an exercise, as students get it (exercises/ex3.py; in C, exercises/ex3.c)."""
    return __getattr__("STARTERS") / _file(exercise, language)


def solution(exercise: object, language: str = "python") -> Path:
    """The reference solution of an exercise (solutions/ex3.py, or .c), which the classroom's stations run."""
    return __getattr__("SOLUTIONS") / _file(exercise, language)


def _file(exercise: object, language: str) -> str:
    if language not in ("python", "c"):
        raise ValueError(f"the workshop's firmware is in 'python' or 'c'; got {language!r}")
    return (C_FILES if language == "c" else EXERCISE_FILES)[exercise_name(exercise)]
