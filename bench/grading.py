"""Grading throughput: wall time to grade the solutions of Ex1..Ex6 with `appsim.workshop.checks.check` in process,
and with `appsim grade` (each submission's firmware sandboxed in its own process): one submission, a class.
"""
from __future__ import annotations

import shutil
import subprocess
import sys
import tempfile
import time
from pathlib import Path

from appsim.workshop.course import CLASSROOM_EXERCISES as EXERCISES
from appsim.workshop.course import SOLUTIONS

def one_submission_s(seed: int = 1) -> float:
    """Wall seconds to check the solutions of Ex1..Ex6 as one student's submission (every check must pass)."""
    from appsim.workshop.checks import check
    started = time.perf_counter()
    verdicts = [check(f"ex{n}", SOLUTIONS / f"ex{n}.py", seed=seed) for n in EXERCISES]
    wall = time.perf_counter() - started
    failed = [v for v in verdicts if not v.passed]
    if failed:
        raise RuntimeError(f"the solutions failed their own checks: {failed}")
    return wall


def appsim_grade_s(submissions: int, jobs: int, seed: int = 1) -> float:
    """Wall seconds for `appsim grade CLASS --jobs N` on `submissions` copies of the solutions (Ex1..Ex6),
    the whole command as an instructor runs it, Python's start included."""
    with tempfile.TemporaryDirectory(prefix="appsim-bench-") as scratch:
        room = Path(scratch) / "class"
        for k in range(submissions):
            student = room / f"student{k:02d}"
            student.mkdir(parents=True)
            for n in EXERCISES:
                shutil.copy(SOLUTIONS / f"ex{n}.py", student)
        started = time.perf_counter()
        subprocess.run([sys.executable, "-m", "appsim", "grade", str(room), "--jobs", str(jobs), "--seed", str(seed),
                        "--json", str(Path(scratch) / "grades.jsonl")], check=True, capture_output=True)
        return time.perf_counter() - started
