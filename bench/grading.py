"""Grading throughput: wall time to grade the solutions of Ex1..Ex6 with `appsim.checks.check`, and a class.

Rows the kit cannot measure yet (the checks or `appsim grade` missing) say so instead of a number.
"""
from __future__ import annotations

import importlib.util
import time

from appsim.classroom import EXERCISES, SOLUTIONS

NOT_YET = "not available yet"


def checks_available() -> bool:
    return importlib.util.find_spec("appsim.checks") is not None


def one_submission_s(seed: int = 1) -> float:
    """Wall seconds to check the solutions of Ex1..Ex6 as one student's submission (every check must pass)."""
    from appsim.checks import check
    started = time.perf_counter()
    verdicts = [check(f"ex{n}", SOLUTIONS / f"ex{n}.py", seed=seed) for n in EXERCISES]
    wall = time.perf_counter() - started
    failed = [v for v in verdicts if not v.passed]
    if failed:
        raise RuntimeError(f"the solutions failed their own checks: {failed}")
    return wall
