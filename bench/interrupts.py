"""What interrupts cost: a classroom whose stations run the interrupt-driven solutions (solutions/interrupts/) against
one running the polling ones, and the same three exercises checked in process and graded in the sandbox both ways.
"""
from __future__ import annotations

import compileall
import shutil
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import appsim
from appsim.bus.wire import Bus
from appsim.sim import Simulator
from appsim.workshop.classroom import Classroom
from appsim.workshop.course import EXERCISE_FILES, SOLUTIONS

INTERRUPT_DRIVEN = SOLUTIONS / "interrupts"
EXERCISES = ("ex1", "ex3", "ex6")           # those solutions/interrupts/ has


def classroom_wall_ms_per_simulated_s(exercise: int, folder: Path, seconds: float) -> float:
    """Wall milliseconds per simulated second of the classroom (master, six stations, the PC's monitor) at `exercise`,
    the stations running `folder`'s solution."""
    room = Classroom(Bus(Simulator(), 125_000), exercise, seed=exercise, firmware_dir=folder)
    room.run(0.05)                                  # their set-up, not timed
    started = time.perf_counter()
    room.run(seconds)
    return (time.perf_counter() - started) * 1000 / seconds


def checks_s(folder: Path, seed: int = 1) -> float:
    """Wall seconds to check Ex1, Ex3 and Ex6 of `folder` in process (each must get full marks)."""
    from appsim.workshop.checks import check

    started = time.perf_counter()
    verdicts = [check(exercise, folder / EXERCISE_FILES[exercise], seed=seed) for exercise in EXERCISES]
    wall = time.perf_counter() - started
    if not all(v.passed for v in verdicts):
        raise RuntimeError(f"the solutions in {folder} failed their own checks: {verdicts}")
    return wall


def appsim_grade_s(folder: Path, seed: int = 1) -> float:
    """Wall seconds for `appsim grade` of one submission of `folder`'s Ex1, Ex3 and Ex6 (the whole command, sandboxed,
    --jobs 2), which must earn full marks."""
    compileall.compile_dir(Path(appsim.__file__).parent, quiet=1)
    with tempfile.TemporaryDirectory(prefix="appsim-bench-") as scratch:
        student = Path(scratch) / "class" / "student"
        student.mkdir(parents=True)
        for exercise in EXERCISES:
            shutil.copy(folder / EXERCISE_FILES[exercise], student)
        command = [sys.executable, "-m", "appsim", "grade", str(student.parent), "--jobs", "2", "--seed", str(seed),
                   "--json", str(Path(scratch) / "grades.jsonl")]
        started = time.perf_counter()
        done = subprocess.run(command, check=True, capture_output=True, text=True)
        wall = time.perf_counter() - started
        if "ex1 5/5  ex2 0/5 (missing)  ex3 5/5" not in done.stdout or "ex6 5/5" not in done.stdout:
            raise RuntimeError(f"the solutions in {folder} did not get full marks:\n{done.stdout}")
        return wall
