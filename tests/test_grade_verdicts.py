"""`appsim check` (in the student's own process) and `appsim grade` (in the grader's sandbox) give one verdict: the same
checks passed and failed, the same fault, the same messages, for the solutions, the starters and every typical mistake,
on two seeds."""
from __future__ import annotations

import io
from pathlib import Path

import pytest
from mistakes import MISTAKES
from test_mistakes import edited_source

from appsim.workshop.checks import check
from appsim.workshop.course import EXERCISE_FILES, EXERCISES, SOLUTIONS, STARTERS
from appsim.workshop.grading.grade import run
from appsim.workshop.sandbox.children import Limits

SEEDS = (202, 7)


def firmwares() -> dict[str, tuple[str, str]]:
    """Submission name -> (exercise, source): every solution, every starter, every mistake."""
    found = {}
    for exercise in EXERCISES:
        found[f"solution_{exercise}"] = (exercise, (SOLUTIONS / EXERCISE_FILES[exercise]).read_text())
        found[f"starter_{exercise}"] = (exercise, (STARTERS / EXERCISE_FILES[exercise]).read_text())
    for mistake in MISTAKES:
        found[f"mistake_{mistake.name}"] = (mistake.exercise, edited_source(mistake))
    for name, (exercise, edits) in ODD.items():
        source = (SOLUTIONS / EXERCISE_FILES[exercise]).read_text()
        for old, new in edits:
            assert source.count(old) == 1, (name, old)
            source = source.replace(old, new)
        found[f"odd_{name}"] = (exercise, source)
    return found


# Legal but odd: what the sandbox once judged otherwise than `appsim check` (an IntEnum station was station 1, a 2 MB
# LCD text broke the protocol, a station-less identifier scored 0), or what a check once crashed on (a bus the
# master's 0x088 never got through).
ENUM = "import enum\n\n\nclass Station(enum.IntEnum):\n    ONE = 0x100\n    FOUR = 0x130\n\n\n"
INDEX = "class Four:\n    def __index__(self):\n        return 0x120\n\n\n"
ODD = {
    "intenum_station": ("ex2", [("MESSAGE_ID1 = 0x100", ENUM + "MESSAGE_ID1 = Station.FOUR")]),
    "index_station": ("ex3", [("MESSAGE_ID1 = 0x100", INDEX + "MESSAGE_ID1 = Four()")]),
    "string_station": ("ex2", [("MESSAGE_ID1 = 0x100", "MESSAGE_ID1 = '0x130'")]),
    "huge_identifier": ("ex2", [("MESSAGE_ID1 = 0x100", "MESSAGE_ID1 = 1 << 70")]),
    "no_station_ex2": ("ex2", [("MESSAGE_ID1 = 0x100", "MESSAGE_ID1 = 0x160")]),
    "no_station_ex6": ("ex6", [("MESSAGE_ID1 = 0x100", "MESSAGE_ID1 = 0x160")]),
    "no_station_rtr": ("ex5", [("RTR_ID = 0x81", "RTR_ID = 0x87")]),
    "lcd_2_mb": ("ex1", [("    GLCD_Initial()\n", "    GLCD_Initial()\n    putsGLCD('Z' * (2 << 20))\n")]),
    "big_data": ("ex2", [("TxData = [0x01, 0x02, 0x03, 0x00, 0x00]", "TxData = [0x01, 0x02, 0x03, 0x00, 0x00] + "
                                                                       "[0] * 3_000_000")]),
    "bus_hog_ex4": ("ex4", [("def main():\n", "def main():\n    CANInitialize(4, 10, 8, 4, 3, "
                                                "CAN_CONFIG_VALID_STD_MSG)\n    while True:\n        "
                                                "CANSendMessage(0, [0] * 8, 8, CAN_TX_PRIORITY_0 & "
                                                "CAN_TX_STD_FRAME)\n")]),
}


@pytest.fixture(scope="module")
def both_ways(tmp_path_factory):
    """For each seed: the grade records of a class made of every firmware (`local_verdict` gives in-process ones)."""
    root = tmp_path_factory.mktemp("verdicts")
    sources = firmwares()
    for name, (exercise, source) in sources.items():
        (root / "class" / name).mkdir(parents=True)
        (root / "class" / name / EXERCISE_FILES[exercise]).write_text(source)
    graded = {}
    for seed in SEEDS:
        records = run([root / "class"], results=root / f"grades{seed}.jsonl", jobs=2, seed=seed,
                      limits=Limits(time_s=30, stall_s=5), out=io.StringIO())
        graded[seed] = {r["submission"]: r["exercises"][sources[r["submission"]][0]] for r in records}
    return root, sources, graded


def local_verdict(root: Path, name: str, exercise: str, seed: int, monkeypatch) -> dict:
    monkeypatch.chdir(root / "class" / name)          # the file by its own name, as the grader's child names it
    verdict = check(exercise, EXERCISE_FILES[exercise], seed=seed).to_dict()
    return {"score": verdict["score"], "max_score": verdict["max_score"], "fault": verdict["fault"],
            "checks": verdict["checks"]}


@pytest.mark.parametrize("seed", SEEDS)
@pytest.mark.parametrize("name", sorted(firmwares()))
def test_check_and_grade_give_the_same_verdict(both_ways, name, seed, monkeypatch):
    root, sources, graded = both_ways
    exercise = sources[name][0]
    assert graded[seed][name] == local_verdict(root, name, exercise, seed, monkeypatch)


def test_the_class_covers_every_exercise_with_passing_and_failing_firmware(both_ways):
    _, sources, graded = both_ways
    for exercise in EXERCISES:
        scores = [graded[SEEDS[0]][n]["score"] for n, (e, _) in sources.items() if e == exercise]
        assert max(scores) > min(scores), exercise
