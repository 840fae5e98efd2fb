"""Autograded checks for Ex1..Ex6 and Demo1: run a firmware in a seeded simulated classroom and judge what it did.

Only behaviour is judged (bus trace, ECAN registers, LCD, USB-CDC bytes), never the source: `check("ex2", path)`.
"""
from __future__ import annotations

import random
from collections.abc import Callable, Sequence
from pathlib import Path
from types import ModuleType

from appsim.errors import FirmwareError
from appsim.firmware.identity import shown
from appsim.firmware.loader import read_firmware
from appsim.workshop.checks import demo1, ex1, ex2, ex3, ex4, ex5, ex6
from appsim.workshop.checks.trial import Fatal, Loadable, Trial, notebook_firmware, placement, resolve
from appsim.workshop.checks.verdict import CheckResult, Verdict
from appsim.workshop.course import EXERCISES, exercise_name, starter

__all__ = ["EXERCISES", "CheckResult", "Verdict", "check", "check_names", "prepare", "refusal"]

RUNS = "firmware runs"
NOT_JUDGED = "Not judged: the firmware did not run (see above)."
_MODULES = {"ex1": ex1, "ex2": ex2, "ex3": ex3, "ex4": ex4, "ex5": ex5, "ex6": ex6, "demo1": demo1}


def check_names(exercise: str | int) -> tuple[str, ...]:
    """The names of an exercise's checks, in the order every verdict of it lists them."""
    return (RUNS, *_MODULES[exercise_name(exercise)].NAMES)


def not_judged(exercise: str | int, seed: int, fault: str, reason: str) -> Verdict:
    """The verdict on a firmware that could not run: `reason` in the first check, every other not judged."""
    name = exercise_name(exercise)
    return Verdict(name, seed, (CheckResult(RUNS, False, reason),
                                *(CheckResult(n, False, NOT_JUDGED) for n in _MODULES[name].NAMES)), fault)


def refusal(exercise: str | int, firmware: str | Path) -> str | None:
    """Why `firmware` is no file to check `exercise` with, in the words `appsim check` refuses it with (nothing there,
    a folder, a notebook without a firmware cell or of another exercise); None if it is one. A file that is one but
    does not load is judged: the check says why it earns nothing."""
    path = Path(firmware)
    name = exercise_name(exercise)
    try:
        if path.suffix.lower() != ".ipynb":
            read_firmware(path)
            return None
        named = notebook_firmware(path)[0]
    except FirmwareError as error:
        return str(error)
    if named is not None and named != name:
        return (f"{path.name} is {named.upper()}'s notebook (its metadata says so), not {name.upper()}'s: check it "
                f"with `appsim check {named} {path}`, or give {name.upper()}'s")
    return None


def prepare(exercise: str, firmware: str | Path | ModuleType | Callable[[], object] | Loadable, seed: int,
            message_id: int | None = None, c_options: Sequence[str] = ()) -> Trial:
    """The trial of `exercise` (as `exercise_name` gives it) for `firmware`, on the station `placement` picks (Demo1:
    a board of its own); nothing runs yet. A firmware that does not load is `Fatal`. `c_options`: C18's options for
    a .c file (-Oi)."""
    loaded = resolve(firmware, c_options)
    return Trial(exercise, loaded, 1 if exercise == "demo1" else placement(exercise, loaded, message_id), seed)


def check(exercise: str | int, firmware: str | Path | ModuleType | Callable[[], object] | Loadable | None = None,
          *, seed: int | None = None, message_id: int | None = None, c_options: Sequence[str] = ()) -> Verdict:
    """Run `firmware` (a file, .py or .c, a loaded module, or a bare `main`; None: the starter exercises/exN.py) and
    judge it.

    `seed` picks every potentiometer and anything else random (None: a fresh one, recorded in the
    verdict); the same seed gives the same verdict. The board takes the station of `message_id`, else
    of the firmware's MESSAGE_ID1 (Ex5: RTR_ID), else station 1; an identifier that is no station's takes station 1's
    place, and only the checks that depend on it fail for it. `c_options`: C18's command-line options for a .c file
    (`("-Oi",)`: integer promotions).
    """
    name = exercise_name(exercise)
    if seed is None:
        seed = random.SystemRandom().randrange(2**32)
    elif not isinstance(seed, int) or isinstance(seed, bool):
        raise TypeError(f"seed is an integer (or None for a fresh one); got {seed!r}")
    if message_id is not None and (not isinstance(message_id, int) or isinstance(message_id, bool)):
        raise TypeError(f"message_id is the station's MESSAGE_ID1, an integer such as 0x110; got {message_id!r}")
    try:
        trial = prepare(name, starter(name) if firmware is None else firmware, seed, message_id, c_options)
        results = _MODULES[name].run(trial)
    except Fatal as fatal:
        return not_judged(name, seed, fatal.fault.kind, fatal.fault.message)
    named = f"MESSAGE_ID1 = {shown(trial.own_id)}" + (f", RTR_ID = {shown(trial.rtr_id)}" if name == "ex5" else "")
    where = ("as the CAN monitor" if name == "demo1" else
             f"on station {trial.station}'s board ({named})" if trial.identity_problem is None else
             f"in station {trial.station}'s place ({named}: not a station's, see below)")
    runs = CheckResult(RUNS, True, f"{trial.firmware.label} ran {trial.now / 10**9:.0f} ms {where} without crashing, "
                                   "main() still looping.")
    return Verdict(name, seed, (runs, *results))
