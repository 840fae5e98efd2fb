"""A benchmark figure (min/median/max over runs, with its target) and the table that prints them.

Figures measured in one run of the suite are comparable with each other: same machine, same load.
"""
from __future__ import annotations

import platform
import statistics
from collections.abc import Callable, Sequence
from dataclasses import dataclass


@dataclass(frozen=True)
class Figure:
    """One row of the table: a measurement repeated over runs, or a row that could not be measured (`note`)."""

    name: str
    unit: str
    values: tuple[float, ...] = ()
    target: float | None = None         # the figure must reach this (>= target, or <= when `lower_is_better`)
    aim: float | None = None
    lower_is_better: bool = False
    note: str = ""                      # what is printed beside it (the physical limit, or why no number)

    @property
    def median(self) -> float:
        return statistics.median(self.values)

    @property
    def met(self) -> bool | None:
        """Whether the median meets the target (None: no target, or no number)."""
        if self.target is None or not self.values:
            return None
        return self.median <= self.target if self.lower_is_better else self.median >= self.target

    def target_text(self) -> str:
        if self.target is None:
            return ""
        sign = "<" if self.lower_is_better else ">="
        aim = f" (aim {_number(self.aim)})" if self.aim is not None else ""
        return f"{sign} {_number(self.target)}{aim}"


def repeat(runs: int, measure: Callable[[], float]) -> tuple[float, ...]:
    """`measure()` run `runs` times (at least once)."""
    return tuple(measure() for _ in range(max(runs, 1)))


def _number(value: float) -> str:
    if value == 0:
        return "0"
    if abs(value) >= 1000:
        return f"{value:,.0f}"
    if abs(value) >= 100:
        return f"{value:.0f}"
    if abs(value) >= 10:
        return f"{value:.1f}"
    if abs(value) >= 0.1:
        return f"{value:.2f}"
    return f"{value:.3g}"


def machine() -> str:
    """The machine the figures were measured on, in one line."""
    cpu = platform.processor() or platform.machine()
    try:
        with open("/proc/cpuinfo", encoding="utf-8") as info:
            names = [line.split(":", 1)[1].strip() for line in info if line.startswith("model name")]
        if names:
            cpu = f"{names[0]} x {len(names)}"
    except OSError:
        pass
    return f"{cpu}; {platform.python_implementation()} {platform.python_version()} on {platform.system()}"


def table(figures: Sequence[Figure]) -> str:
    """The figures as a Markdown table (so the README can take it as is)."""
    header = ("measurement", "min", "median", "max", "unit", "target", "met", "")
    rows = []
    for f in figures:
        if f.values:
            low, mid, high = _number(min(f.values)), _number(f.median), _number(max(f.values))
        else:
            low = mid = high = "-"
        met = {None: "", True: "yes", False: "NO"}[f.met]
        rows.append((f.name, low, mid, high, f.unit, f.target_text(), met, f.note))
    widths = [max(len(str(row[i])) for row in [header, *rows]) for i in range(len(header))]
    right = {1, 2, 3}

    def line(cells: Sequence[str]) -> str:
        return "| " + " | ".join(c.rjust(w) if i in right else c.ljust(w)
                                 for i, (c, w) in enumerate(zip(cells, widths, strict=True))) + " |"

    rule = "|" + "|".join(("-" * (w + 1) + ":") if i in right else "-" * (w + 2)
                          for i, w in enumerate(widths)) + "|"
    return "\n".join([line(header), rule, *(line(r) for r in rows)])
