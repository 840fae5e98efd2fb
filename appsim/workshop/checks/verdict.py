"""What an autograded check says: one result per thing judged, and the verdict on a whole exercise.

Printable in a terminal (`str`), shown as a green/red table in Jupyter (`_repr_html_`), and as plain data (`to_dict`).
"""
from __future__ import annotations

import html
from collections.abc import Sequence
from dataclasses import dataclass
from typing import Any


@dataclass(frozen=True)
class CheckResult:
    """One thing judged: its short name, whether it passed, and what was seen (and what to look at)."""

    name: str
    passed: bool
    message: str
    points: int = 1


@dataclass(frozen=True)
class Verdict:
    """The checks of one exercise on one firmware, run with `seed` (the same seed gives the same verdict)."""

    exercise: str
    seed: int
    checks: tuple[CheckResult, ...]
    fault: str | None = None        # why the firmware could not be judged (appsim.workshop.faults.KINDS), else None

    @property
    def score(self) -> int:
        return sum(check.points for check in self.checks if check.passed)

    @property
    def max_score(self) -> int:
        return sum(check.points for check in self.checks)

    @property
    def passed(self) -> bool:
        """Full marks."""
        return self.score == self.max_score

    def failed(self) -> list[CheckResult]:
        """The checks that did not pass, in order."""
        return [check for check in self.checks if not check.passed]

    def to_dict(self) -> dict[str, Any]:
        return {"exercise": self.exercise, "score": self.score, "max_score": self.max_score, "seed": self.seed,
                "fault": self.fault, "checks": [{"name": c.name, "passed": c.passed, "message": c.message, "points": c.points}
                           for c in self.checks]}

    def __str__(self) -> str:
        return f"{self.exercise.upper()}: {self.score}/{self.max_score} (seed {self.seed})\n{results_text(self.checks)}"

    def _repr_html_(self) -> str:
        colour = GREEN if self.passed else RED
        return (f"<div><b style='color:{colour}'>{html.escape(self.exercise.upper())}: "
                f"{self.score}/{self.max_score}</b> <span style='color:#57606a'>(seed {self.seed})</span>"
                f"{results_html(self.checks)}</div>")


GREEN, RED = "#1a7f37", "#cf222e"


def results_text(checks: Sequence[CheckResult]) -> str:
    """Results as a terminal shows them: PASS or FAIL and the name, the message indented below."""
    lines = []
    for check in checks:
        lines.append(f"  {'PASS' if check.passed else 'FAIL'}  {check.name}")
        lines.extend(f"        {line}" for line in check.message.splitlines())
    return "\n".join(lines)


def results_html(checks: Sequence[CheckResult]) -> str:
    """Results as Jupyter shows them: a table, one green or red row each."""
    rows = "".join(
        f"<tr style='background:{'#dafbe1' if c.passed else '#ffebe9'}'>"
        f"<td style='font-weight:bold;color:{GREEN if c.passed else RED};padding:2px 8px'>"
        f"{'PASS' if c.passed else 'FAIL'}</td>"
        f"<td style='padding:2px 8px;white-space:nowrap'>{html.escape(c.name)}</td>"
        f"<td style='padding:2px 8px;text-align:left;white-space:pre-wrap'>{html.escape(c.message)}</td></tr>"
        for c in checks)
    return f"<table style='border-collapse:collapse'>{rows}</table>"
