"""Autograded checks for Ex1..Ex6 and Demo1: run a firmware in a seeded simulated classroom and judge what it did.

Only behaviour is judged (bus trace, ECAN registers, LCD, USB-CDC bytes), never the source: `check("ex2", path)`.
"""
from __future__ import annotations

import random
from collections.abc import Callable
from pathlib import Path
from types import ModuleType

from appsim.workshop.checks import demo1, ex1, ex2, ex3, ex4, ex5, ex6
from appsim.workshop.checks.trial import KIT, Fatal, Trial, hex_id, resolve, station_of
from appsim.workshop.checks.verdict import CheckResult, Verdict

__all__ = ["EXERCISES", "CheckResult", "Verdict", "check", "check_names"]

EXERCISES: tuple[str, ...] = ("ex1", "ex2", "ex3", "ex4", "ex5", "ex6", "demo1")
RUNS = "firmware runs"
_MODULES = {"ex1": ex1, "ex2": ex2, "ex3": ex3, "ex4": ex4, "ex5": ex5, "ex6": ex6, "demo1": demo1}
_STARTERS = {name: KIT / "exercises" / f"{name}.py" for name in EXERCISES[:-1]} | {
    "demo1": KIT / "exercises" / "demo1_monitor.py"}


def check_names(exercise: str | int) -> tuple[str, ...]:
    """The names of an exercise's checks, in the order every verdict of it lists them."""
    return (RUNS, *_MODULES[_exercise(exercise)].NAMES)


def check(exercise: str | int, firmware: str | Path | ModuleType | Callable[[], object] | None = None, *,
          seed: int | None = None, message_id: int | None = None) -> Verdict:
    """Run `firmware` (a file, a loaded module, or a bare `main`; None: your copy exercises/exN.py) and judge it.

    `seed` picks every potentiometer and anything else random (None: a fresh one, recorded in the
    verdict); the same seed gives the same verdict. The board takes the station of `message_id`, else
    of the firmware's MESSAGE_ID1 (Ex5: RTR_ID), else station 1.
    """
    name = _exercise(exercise)
    if seed is None:
        seed = random.SystemRandom().randrange(2**32)
    elif not isinstance(seed, int) or isinstance(seed, bool):
        raise TypeError(f"seed is an integer (or None for a fresh one); got {seed!r}")
    if message_id is not None and (not isinstance(message_id, int) or isinstance(message_id, bool)):
        raise TypeError(f"message_id is the station's MESSAGE_ID1, an integer such as 0x110; got {message_id!r}")
    module = _MODULES[name]
    try:
        loaded = resolve(_STARTERS[name] if firmware is None else firmware)
        station = 1 if name == "demo1" else station_of(name, loaded, message_id)
        trial = Trial(name, loaded, station, seed)
        results = module.run(trial)
    except Fatal as fatal:
        return Verdict(name, seed, (CheckResult(RUNS, False, str(fatal)),
                                    *(CheckResult(n, False, "Not judged: the firmware did not run (see above).")
                                      for n in module.NAMES)))
    where = ("as the CAN monitor" if name == "demo1"
             else f"on station {station}'s board (MESSAGE_ID1 = {hex_id(trial.own_id)}"
                  + (f", RTR_ID = {hex_id(trial.rtr_id)})" if name == "ex5" else ")"))
    runs = CheckResult(RUNS, True, f"{loaded.label} ran {trial.now / 10**9:.0f} ms {where} without crashing, "
                                   "main() still looping.")
    return Verdict(name, seed, (runs, *results))


def _exercise(exercise: str | int) -> str:
    if isinstance(exercise, int) and not isinstance(exercise, bool) and 1 <= exercise <= 6:
        return f"ex{exercise}"
    if isinstance(exercise, str) and exercise.strip().lower() in EXERCISES:
        return exercise.strip().lower()
    raise ValueError(f"exercise {exercise!r} does not exist: the workshop has Ex1..Ex6 (1..6 or 'ex1'..'ex6') "
                     "and 'demo1', the CAN monitor")
