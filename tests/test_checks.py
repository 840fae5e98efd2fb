"""The autograded checks: solutions get full marks, starters fail pointing at their TODO, verdicts are reproducible,
a hard-coded answer fails on another seed, and a firmware that cannot be judged gets zero with a clear message."""
from __future__ import annotations

import sys
from pathlib import Path

import pytest

from appsim.firmware.loader import load_firmware
from appsim.workshop.checks import EXERCISES, CheckResult, Verdict, check, check_names
from appsim.workshop.checks.trial import Trial, resolve

KIT = Path(__file__).resolve().parent.parent


def solution(exercise: str) -> Path:
    return KIT / "solutions" / ("demo1_monitor.py" if exercise == "demo1" else f"{exercise}.py")


def failing_text(verdict: Verdict) -> str:
    return "\n".join(c.message for c in verdict.failed())


def copy_with(tmp_path: Path, exercise: str, old: str, new: str) -> Path:
    text = solution(exercise).read_text()
    assert text.count(old) == 1, f"{old!r} is not once in the solution"
    path = tmp_path / f"{exercise}_changed.py"
    path.write_text(text.replace(old, new))
    return path


# ------------------------------------------------------------------ solutions and starters
@pytest.mark.parametrize("seed", [202, 8680])
@pytest.mark.parametrize("exercise", EXERCISES)
def test_every_solution_gets_full_marks(exercise, seed):
    verdict = check(exercise, solution(exercise), seed=seed)
    assert verdict.passed, str(verdict)
    assert verdict.score == verdict.max_score == len(check_names(exercise))
    assert [c.name for c in verdict.checks] == list(check_names(exercise))


@pytest.mark.parametrize("message_id", [0x120, 0x150])
@pytest.mark.parametrize("exercise", ["ex1", "ex2", "ex3", "ex4", "ex6"])
def test_a_solution_built_for_another_station_gets_full_marks_there(exercise, message_id):
    firmware = load_firmware(solution(exercise), {"MESSAGE_ID1": message_id})
    verdict = check(exercise, firmware, seed=3)
    assert verdict.passed, str(verdict)
    assert f"station {(message_id - 0x100) // 0x10 + 1}'s board" in verdict.checks[0].message


def test_ex5_takes_the_station_of_its_rtr_id():
    verdict = check("ex5", load_firmware(solution("ex5"), {"RTR_ID": 0x84}), seed=3)
    assert verdict.passed, str(verdict)
    assert "station 4's board" in verdict.checks[0].message


STARTER_TODOS = {
    "ex1": ["RX_Filter0", "see the TODO"],
    "ex2": ["Loopback", "CAN_OP_MODE_NORMAL", "see the TODO"],
    "ex3": ["RX_Filter0 = 0x088", "see the TODO"],
    "ex4": ["CAN_OP_MODE_LISTEN", "TODO 1, 2"],
    "ex5": ["CAN_TX_RTR_FRAME", "RX_Filter0 must be RTR_ID", "see the TODO"],
    "ex6": ["RX_ID2 == MESSAGE_ID1", "RXB1's MASK", "see the TODO"],
    "demo1": ["SPBRG = 129", "TODO 1", "CAN_OP_MODE_LISTEN", "TODO 2"],
}


@pytest.mark.parametrize("exercise", EXERCISES)
def test_every_untouched_starter_fails_pointing_at_its_todo(exercise):
    verdict = check(exercise, seed=202)            # None: the student's copy in exercises/
    assert verdict.checks[0].passed and "exercises/" in verdict.checks[0].message
    assert not verdict.passed
    for words in STARTER_TODOS[exercise]:
        assert words in failing_text(verdict), str(verdict)


# ------------------------------------------------------------------ seeds
def test_the_same_seed_gives_the_same_verdict_and_another_seed_other_values():
    first = check("ex3", solution("ex3"), seed=41).to_dict()
    assert check("ex3", solution("ex3"), seed=41).to_dict() == first
    assert check("ex3", solution("ex3"), seed=42).to_dict() != first
    assert first["seed"] == 41 and first["score"] == first["max_score"]


def test_no_seed_draws_one_and_records_it():
    verdict = check("ex1", solution("ex1"))
    assert isinstance(verdict.seed, int)
    assert check("ex1", solution("ex1"), seed=verdict.seed).to_dict() == verdict.to_dict()


def test_a_hard_coded_ad_value_passes_only_on_the_seed_it_was_copied_from(tmp_path):
    value = Trial("ex2", resolve(solution("ex2")), 1, 5).potentiometers[0]     # what station 1 reads with seed 5
    cheat = copy_with(tmp_path, "ex2", "    TxData[3] = SFR.ADRESH\n    TxData[4] = SFR.ADRESL",
                      f"    TxData[3] = {value >> 8}\n    TxData[4] = {value & 0xFF}")
    assert check("ex2", cheat, seed=5).passed
    other = check("ex2", cheat, seed=6)
    assert [c.name for c in other.failed()] == ["frames carry MESSAGE_ID1 and 01 02 03 ADRESH ADRESL"]
    assert f"bytes 3 and 4 say {value}" in failing_text(other)


# ------------------------------------------------------------------ firmware that cannot be judged
def zero_with(verdict: Verdict, *words: str) -> None:
    assert verdict.score == 0 and verdict.max_score == len(check_names(verdict.exercise))
    assert not verdict.checks[0].passed
    for word in words:
        assert word in verdict.checks[0].message, verdict.checks[0].message
    assert all(c.message.startswith("Not judged") for c in verdict.checks[1:])


def test_a_firmware_written_with_a_dataclass_and_an_enum_loads_in_check_and_in_the_sandbox(tmp_path):
    """Both look their class's module up while the file's top runs: the loader did not list the firmware's module
    among Python's, so the file failed "while loading, before main() ran" with an AttributeError of dataclasses."""
    from appsim.workshop.grading.worker import grade_exercise
    from appsim.workshop.sandbox.children import Limits, Sandbox
    from appsim.workshop.sandbox.isolation import isolation

    path = copy_with(tmp_path, "ex2", "TxData = [0x01, 0x02, 0x03, 0x00, 0x00]\n",
                     "import dataclasses\nimport enum\n\n\n@dataclasses.dataclass\nclass Frame:\n"
                     "    data: list[int]\n\n\nclass Kind(enum.Enum):\n    DATA = 1\n\n\n"
                     "TxData = Frame([0x01, 0x02, 0x03, 0x00, 0x00]).data if Kind.DATA.value else []\n")
    verdict = check("ex2", path, seed=1).to_dict()
    assert verdict["score"] == verdict["max_score"], verdict
    with Sandbox(isolation(), Limits()) as sandbox:
        record = grade_exercise(sandbox, "ex2", "ex2.py", path.read_bytes(), 1, None, owner="ada")
    assert (record["score"], record["fault"]) == (verdict["score"], None), record
    assert not any(name.startswith("firmware_") for name in sys.modules), "the module was let go"


def test_a_crash_gives_zero_with_the_error_and_the_line(tmp_path):
    crash = copy_with(tmp_path, "ex2", "            read_potentiometer()\n",
                      "            read_potentiometer()\n            TxData[5] = 0\n")
    line = crash.read_text().splitlines().index("            TxData[5] = 0") + 1
    zero_with(check("ex2", crash, seed=1), "crashed", f"line {line}", "IndexError: list assignment index out of range")


def test_a_typo_crashes_on_its_line_with_pythons_did_you_mean(tmp_path):
    typo = copy_with(tmp_path, "ex3", "CANSetFilter(CAN_FILTER_B1_F1,", "CANSetFliter(CAN_FILTER_B1_F1,")
    line = next(n for n, text in enumerate(typo.read_text().splitlines(), 1) if "CANSetFliter" in text)
    zero_with(check("ex3", typo, seed=1), f"crashed at line {line}",
              "NameError: name 'CANSetFliter' is not defined. Did you mean: 'CANSetFilter'?")
    early = copy_with(tmp_path, "ex1", "TxData = [0x01,", "TxData = [CAN_TX_PRIORTY_0,")
    zero_with(check("ex1", early, seed=1), "before main() ran",
              "NameError: name 'CAN_TX_PRIORTY_0' is not defined. Did you mean: 'CAN_TX_PRIORITY_0'? Only constants")


def test_a_library_error_is_a_crash_with_the_libraries_words(tmp_path):
    nine = copy_with(tmp_path, "ex2", "CANSendMessage(MESSAGE_ID1, TxData, 5,",
                     "CANSendMessage(MESSAGE_ID1, TxData * 2, 9,")
    zero_with(check("ex2", nine, seed=1), "crashed", "8 data bytes")


def test_a_file_that_does_not_load_gives_zero(tmp_path):
    broken = copy_with(tmp_path, "ex1", "def main():", "def main()")
    zero_with(check("ex1", broken, seed=1), "does not load", "line", "syntax")
    early = copy_with(tmp_path, "ex1", "TxData = [0x01,", "TxData = CANIsRxReady() + [0x01,")
    line = next(n for n, text in enumerate(early.read_text().splitlines(), 1) if "CANIsRxReady() +" in text)
    zero_with(check("ex1", early, seed=1), "does not load", "before main() ran", f"line {line}")
    zero_with(check("ex1", tmp_path / "missing.py", seed=1), "no firmware file")


def test_a_main_that_returns_gives_zero(tmp_path):
    once = copy_with(tmp_path, "ex2", "    while True:\n", "    for turn in range(3):\n")
    zero_with(check("ex2", once, seed=1), "main() returned", "loop forever")


def test_an_id_that_is_no_stations_fails_only_the_check_that_depends_on_the_station(tmp_path):
    """Its board takes station 1's place: being on the bus, the period and not receiving its own frames are judged as
    for any station; the frames' check fails, saying what is wrong in the student's names."""
    odd = copy_with(tmp_path, "ex2", "MESSAGE_ID1 = 0x100 ", "MESSAGE_ID1 = 0x105 ")
    for verdict, shown in ((check("ex2", odd, seed=1), "0x105"),
                           (check("ex2", solution("ex2"), seed=1, message_id=0x160), "0x160")):
        assert verdict.fault is None and verdict.score == verdict.max_score - 1
        [failed] = verdict.failed()
        assert failed.name == "frames carry MESSAGE_ID1 and 01 02 03 ADRESH ADRESL"
        assert f"MESSAGE_ID1 = {shown} is not a station's identifier" in failed.message
        assert "0x100, 0x110 ... 0x150" in failed.message
        assert f"in station 1's place (MESSAGE_ID1 = {shown}: not a station's" in verdict.checks[0].message


# ------------------------------------------------------------------ what can be handed in
def test_a_bare_main_runs_as_station_1_or_as_message_id_says():
    assert check("ex6", load_firmware(solution("ex6")).main, seed=9).passed
    moved = load_firmware(solution("ex6"), {"MESSAGE_ID1": 0x130}).main
    assert check("ex6", moved, seed=9, message_id=0x130).passed
    assert not check("ex6", moved, seed=9).passed, "a bare main() is station 1 unless message_id says otherwise"


def test_exercises_are_named_or_numbered_and_anything_else_is_refused():
    assert check(1, solution("ex1"), seed=1).exercise == "ex1"
    with pytest.raises(ValueError, match="Ex1..Ex6"):
        check("ex7", solution("ex1"))
    with pytest.raises(TypeError, match="seed"):
        check("ex1", solution("ex1"), seed="1")


def test_a_verdict_reads_in_a_terminal_in_jupyter_and_as_data():
    verdict = Verdict("ex9", 1, (CheckResult("a <thing>", True, "seen"), CheckResult("b", False, "not seen", 2)))
    assert (verdict.score, verdict.max_score, verdict.passed) == (1, 3, False)
    assert verdict.to_dict()["checks"][1] == {"name": "b", "passed": False, "message": "not seen", "points": 2}
    assert "PASS  a <thing>" in str(verdict) and "FAIL  b" in str(verdict) and "1/3" in str(verdict)
    assert "<table" in verdict._repr_html_() and "a &lt;thing&gt;" in verdict._repr_html_()
