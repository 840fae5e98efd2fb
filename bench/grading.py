"""Grading throughput: the solutions of Ex1..Ex6 and Demo1 checked in process, and graded by `appsim grade` (each
exercise's firmware in its own sandbox), the whole command as an instructor runs it: one submission, a class.

The kit's bytecode is compiled first, as `pip install` leaves an installed kit (and as Python's cache leaves a checkout
after its first run): where PYTHONDONTWRITEBYTECODE is set, every process would otherwise compile the kit again.
"""
from __future__ import annotations

import compileall
import json
import shutil
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import appsim
from appsim.workshop.course import C_FILES, EXERCISE_FILES, SOLUTIONS


def _files(language: str) -> dict[str, str]:
    return C_FILES if language == "c" else EXERCISE_FILES


def one_submission_s(seed: int = 1, language: str = "python") -> float:
    """Wall seconds to check the solutions of Ex1..Ex6 and Demo1 (in `language`) in process (every check must
    pass)."""
    from appsim.workshop.checks import check
    started = time.perf_counter()
    verdicts = [check(exercise, SOLUTIONS / name, seed=seed) for exercise, name in _files(language).items()]
    wall = time.perf_counter() - started
    failed = [v for v in verdicts if not v.passed]
    if failed:
        raise RuntimeError(f"the solutions failed their own checks: {failed}")
    return wall


def appsim_grade_s(submissions: int, jobs: int, seed: int = 1, *, trusted: bool = False,
                   language: str = "python") -> float:
    """Wall seconds for `appsim grade CLASS --jobs N` on `submissions` copies of the solutions (Ex1..Ex6, Demo1; in
    `language`), the whole command, Python's start included; `trusted` runs it without isolation (for the
    isolation's cost)."""
    compileall.compile_dir(Path(appsim.__file__).parent, quiet=1)
    with tempfile.TemporaryDirectory(prefix="appsim-bench-") as scratch:
        room = Path(scratch) / "class"
        for k in range(submissions):
            student = room / f"student{k:02d}"
            student.mkdir(parents=True)
            for name in _files(language).values():
                shutil.copy(SOLUTIONS / name, student)
        command = [sys.executable, "-m", "appsim", "grade", str(room), "--jobs", str(jobs), "--seed", str(seed),
                   "--json", str(Path(scratch) / "grades.jsonl"), *(["--trusted"] if trusted else [])]
        started = time.perf_counter()
        done = subprocess.run(command, check=True, capture_output=True, text=True)
        wall = time.perf_counter() - started
        full = f"{35 * submissions}/{35 * submissions} points"
        if full not in done.stdout:
            raise RuntimeError(f"the solutions did not get full marks:\n{done.stdout}")
        return wall


def worker_memory(names: list[str]) -> dict[str, dict[str, object]]:
    """`bench.memory` for these firmware (by name), in a Python of its own: as little loaded as `appsim grade` has."""
    compileall.compile_dir(Path(appsim.__file__).parent, quiet=1)
    done = subprocess.run([sys.executable, "-m", "bench.memory", *names], check=True, capture_output=True, text=True,
                          cwd=Path(__file__).resolve().parent.parent)
    return json.loads(done.stdout)
