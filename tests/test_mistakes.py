"""Typical student mistakes (tests/mistakes.py, each a small edit of a solution) get exactly the verdict they deserve:
the checks that fail, and messages that name the cause in the workshop's words. The same on two seeds."""
from __future__ import annotations

from collections import Counter
from pathlib import Path

import pytest
from mistakes import MISTAKES, Mistake

from appsim.workshop.checks import check

SOLUTIONS = Path(__file__).resolve().parent.parent / "solutions"


def edited_source(mistake: Mistake) -> str:
    """The solution's source with the mistake's edits applied; an edit that no longer applies fails loudly."""
    source = (SOLUTIONS / f"{mistake.solution}.py").read_text()
    for old, new in mistake.edits:
        found = source.count(old)
        assert found == 1, (f"mistake {mistake.name} no longer applies to solutions/{mistake.solution}.py: {old!r} "
                            f"occurs {found} times there, not once. Update its edit in tests/mistakes.py.")
        source = source.replace(old, new)
    return source


@pytest.mark.parametrize("seed", [202, 7])
@pytest.mark.parametrize("mistake", MISTAKES, ids=[mistake.name for mistake in MISTAKES])
def test_a_typical_mistake_gets_the_verdict_it_deserves(mistake, seed, tmp_path):
    firmware = tmp_path / f"{mistake.name}.py"
    firmware.write_text(edited_source(mistake))
    verdict = check(mistake.exercise, firmware, seed=seed)
    assert {c.name for c in verdict.failed()} == mistake.failing, str(verdict)
    messages = "\n".join(c.message for c in verdict.failed())
    for word in mistake.words:
        assert word in messages, f"{word!r} not in:\n{messages}"


def test_every_mistake_applies_and_is_named_once_and_every_exercise_has_enough():
    for mistake in MISTAKES:
        assert edited_source(mistake) != (SOLUTIONS / f"{mistake.solution}.py").read_text(), mistake.name
        assert mistake.name.startswith(mistake.exercise + "_"), mistake.name
    assert [name for name, n in Counter(mistake.name for mistake in MISTAKES).items() if n > 1] == []
    per_exercise = Counter(mistake.exercise for mistake in MISTAKES)
    for exercise, fewest in [("ex1", 3), ("ex2", 3), ("ex3", 3), ("ex4", 3), ("ex5", 3), ("ex6", 3), ("demo1", 2)]:
        assert per_exercise[exercise] >= fewest, exercise
