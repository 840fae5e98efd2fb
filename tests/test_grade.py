"""`appsim grade`: a small class graded in one run, each tampering and fault reported as what it is; determinism, resume, outputs."""
from __future__ import annotations

import csv
import io
import json
import signal
import subprocess
import sys
import time
import zipfile
from pathlib import Path

import pytest

from appsim.workshop.grade import EXERCISE_FILES, GradeError, find_submissions, run
from appsim.workshop.sandbox import Limits

KIT = Path(__file__).resolve().parent.parent
SOLUTIONS = KIT / "solutions"
SEED = 2024
LIMITS = Limits(time_s=4, stall_s=2, memory_mb=128)
STARTER_EX1 = (KIT / "exercises" / "ex1.py").read_text()
SOLUTION_EX1 = (SOLUTIONS / "ex1.py").read_text()


def solution(exercise: str) -> str:
    return (SOLUTIONS / EXERCISE_FILES[exercise]).read_text()


def firmware(body: str, *, helpers: str = "") -> str:
    """A firmware file for station 1 whose main() does `body` (indented by 4) after the Ex1 set-up."""
    return ("from appsim.firmware import *\n" + helpers + "\nMESSAGE_ID1 = 0x100\n\n\ndef main():\n"
            "    CANInitialize(4, 10, 8, 4, 3, CAN_CONFIG_VALID_STD_MSG)\n"
            + "".join(f"    {line}\n" for line in body.splitlines()))


def build_class(root: Path, hidden: Path) -> dict[str, dict[str, str]]:
    """The test class: full marks, a typical mistake, and one submission per tampering or fault."""
    submissions = {
        "alice": {exercise: solution(exercise) for exercise in EXERCISE_FILES},          # full marks
        "bob": {"ex1": STARTER_EX1, "ex2": solution("ex2")},         # the starter's filter: RXB0 gets nothing
        "carol": {"ex1": "import appsim.workshop.checks, appsim.workshop.checks.verdict\n"
                         "appsim.workshop.checks.verdict.Verdict.score = property(lambda self: 999)\n"
                         "appsim.workshop.checks.check = lambda *args, **kwargs: None\n" + STARTER_EX1},
        "dave": {"ex1": STARTER_EX1.replace("def main():", 'print(\'{"score": 100, "max_score": 100}\')\n\n\n'
                                                           "def main():\n    print('{\"score\": 100}')")},
        "erin": {"ex1": firmware("import sys\nsys.exit(0)"), "ex2": firmware("import os\nos._exit(0)"),
                 "ex3": firmware("return")},
        "frank": {"ex1": firmware("scale()", helpers="\ndef scale():\n    return 1023 // 0\n"),
                  "ex2": solution("ex2")},
        "gina": {"ex1": firmware("while True:\n    pass"), "ex2": solution("ex2")},
        "hank": {"ex1": firmware("hoard = []\nwhile True:\n    hoard.append(bytearray(1 << 20))")},
        "ivan": {"ex1": firmware("import os\nos.fork()\nwhile True:\n    CANIsRxReady()"),
                 "ex2": firmware("import subprocess\nsubprocess.run(['true'])"),
                 "ex3": firmware("import socket\nsocket.create_connection(('127.0.0.1', 80))")},
        "judy": {"ex1": firmware(f"print(open({str(hidden)!r}).read())"),
                 "ex2": firmware(f"open({str(hidden.with_name('gradebook.csv'))!r}, 'w').write('judy,100')"),
                 "ex3": solution("ex3").replace("def main():", "def main():\n    open('notes.txt', 'w').write('mine')")},
        "ken": {"ex1": SOLUTION_EX1.replace("    TxData[3] = SFR.ADRESH\n    TxData[4] = SFR.ADRESL",
                                            "    TxData[3] = 0x02\n    TxData[4] = 0x00")},
    }
    for name, files in submissions.items():
        (root / name).mkdir(parents=True)
        for exercise, text in files.items():
            (root / name / EXERCISE_FILES[exercise]).write_text(text)
    notebook = json.loads((KIT / "notebooks" / "ex1.ipynb").read_text())
    for cell in notebook["cells"]:
        if "firmware" in cell.get("metadata", {}).get("tags", []):
            cell["source"] = "%%writefile ex1.py\n" + SOLUTION_EX1
    with zipfile.ZipFile(root / "lena.zip", "w") as archive:     # a zip of a folder holding a notebook
        archive.writestr("lena/lab1.ipynb", json.dumps(notebook))
    return submissions


@pytest.fixture(scope="module")
def graded(tmp_path_factory):
    base = tmp_path_factory.mktemp("grading")
    hidden = base / "hidden_checks.txt"
    hidden.write_text("the hidden checks")
    build_class(base / "class", hidden)
    results = base / "grades.jsonl"
    records = run([base / "class"], results=results, csv_path=base / "gradebook.csv",
                  gradescope_path=base / "gradescope", jobs=2, seed=SEED, limits=LIMITS, out=io.StringIO())
    return base, {record["submission"]: record for record in records}, results


def exercise(records, name: str, ex: str) -> dict:
    return records[name]["exercises"][ex]


def first_message(records, name: str, ex: str) -> str:
    return exercise(records, name, ex)["checks"][0]["message"]


def test_full_marks_solutions_and_a_missing_exercise_is_zero_with_its_reason(graded):
    _, records, _ = graded
    alice = records["alice"]
    assert alice["score"] == alice["max_score"] > 0 and alice["seed"] == SEED
    assert all(e["fault"] is None for e in alice["exercises"].values())
    bob_ex3 = exercise(records, "bob", "ex3")
    assert bob_ex3["score"] == 0 and bob_ex3["fault"] == "missing"
    assert "ex3.py is missing" in bob_ex3["checks"][0]["message"]
    assert bob_ex3["max_score"] == alice["exercises"]["ex3"]["max_score"]


def test_a_typical_mistake_loses_the_checks_it_fails_and_nothing_else(graded):
    _, records, _ = graded
    ex1 = exercise(records, "bob", "ex1")
    assert ex1["fault"] is None and 0 < ex1["score"] < ex1["max_score"]
    failed = [c["name"] for c in ex1["checks"] if not c["passed"]]
    assert "RXB0 receives its own frame" in failed
    assert exercise(records, "bob", "ex2")["score"] == exercise(records, "alice", "ex2")["max_score"]


def test_monkeypatching_the_checks_and_printing_fake_results_change_nothing(graded):
    _, records, _ = graded
    starter = exercise(records, "bob", "ex1")
    assert exercise(records, "carol", "ex1") == starter     # the kit it patched is not the one that grades
    assert exercise(records, "dave", "ex1") == starter      # what it printed was never read


@pytest.mark.parametrize("name, ex, fault, words", [
    ("erin", "ex1", "exited", "exited"),
    ("erin", "ex2", "exited", "exited"),
    ("erin", "ex3", "returned", "main() returned"),
    ("frank", "ex1", "exception", "ZeroDivisionError"),
    ("gina", "ex1", "stalled", "stopped answering"),
    ("hank", "ex1", "memory", "memory limit"),
    ("ivan", "ex1", "forbidden", "os.fork"),
    ("ivan", "ex2", "forbidden", "_posixsubprocess"),
    ("ivan", "ex3", "forbidden", "socket"),
    ("judy", "ex1", "forbidden", "reading"),
    ("judy", "ex2", "forbidden", "writing"),
])
def test_each_fault_is_zero_marks_with_what_it_was(graded, name, ex, fault, words):
    _, records, _ = graded
    result = exercise(records, name, ex)
    assert (result["score"], result["fault"]) == (0, fault)
    assert words in result["checks"][0]["message"]
    assert not any(check["passed"] for check in result["checks"])


def test_an_exception_shows_the_students_own_line_and_not_the_kits(graded):
    message = first_message(graded[1], "frank", "ex1")
    assert "ex1.py, line 11, in main: scale()\n  ex1.py, line 4, in scale: return 1023 // 0" in message
    assert "appsim" not in message and "/tmp" not in message


def test_files_outside_the_temporary_directory_stay_untouched_inside_is_allowed(graded):
    base, records, _ = graded
    assert str(base / "hidden_checks.txt") in first_message(records, "judy", "ex1")
    assert not (base / "gradebook.csv").read_text().count("judy,100")
    assert exercise(records, "judy", "ex3")["score"] == exercise(records, "alice", "ex3")["max_score"]


def test_the_rest_of_a_faulty_submission_is_still_graded(graded):
    _, records, _ = graded
    for name in ("frank", "gina"):
        assert exercise(records, name, "ex2")["score"] == exercise(records, "alice", "ex2")["max_score"]


def test_hard_coded_ad_values_fail_against_the_seeded_potentiometer(graded):
    _, records, _ = graded
    ex1 = exercise(records, "ken", "ex1")
    failed = {c["name"]: c["message"] for c in ex1["checks"] if not c["passed"]}
    assert ex1["fault"] is None and "sends MESSAGE_ID1 with 01 02 03 ADRESH ADRESL" in failed


def test_a_zipped_notebook_is_graded_by_its_firmware_cell(graded):
    _, records, _ = graded
    assert exercise(records, "lena", "ex1")["score"] == exercise(records, "alice", "ex1")["max_score"]


def test_the_same_class_and_seed_give_identical_json(graded, tmp_path):
    base, _, results = graded
    again = tmp_path / "again.jsonl"
    run([base / "class"], results=again, jobs=2, seed=SEED, limits=LIMITS, out=io.StringIO())
    assert again.read_text() == results.read_text()


def test_csv_and_gradescope_agree_with_the_json(graded):
    base, records, _ = graded
    with open(base / "gradebook.csv", newline="") as file:
        rows = list(csv.DictReader(file))
    assert [row["submission"] for row in rows] == sorted(records)
    for row in rows:
        record = records[row["submission"]]
        assert int(row["total"]) == record["score"] and int(row["max_score"]) == record["max_score"]
        assert all(int(row[ex]) == record["exercises"][ex]["score"] for ex in EXERCISE_FILES)
    for name, record in records.items():
        results = json.loads((base / "gradescope" / f"{name}.json").read_text())
        assert results["score"] == record["score"]
        assert [(t["name"], t["score"], t["max_score"]) for t in results["tests"]] == [
            (ex, e["score"], e["max_score"]) for ex, e in record["exercises"].items()]
        assert {t["status"] for t in results["tests"]} <= {"passed", "failed"}


def test_an_interrupted_run_resumes_without_regrading_and_ends_with_the_same_gradebook(graded, tmp_path):
    base, records, _ = graded
    names = ["alice", "bob", "carol", "dave", "frank"]
    for name in names:
        (tmp_path / "class" / name).mkdir(parents=True)
        for file in (base / "class" / name).iterdir():
            (tmp_path / "class" / name / file.name).write_text(file.read_text())
    results = tmp_path / "grades.jsonl"
    command = [sys.executable, "-m", "appsim", "grade", str(tmp_path / "class"), "--json", str(results),
               "--seed", str(SEED), "--jobs", "1", "--time-limit", "4"]
    first = subprocess.Popen(command, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
    deadline = time.monotonic() + 120
    while not (results.exists() and results.read_text().count("\n") >= 1) and first.poll() is None:
        assert time.monotonic() < deadline, "no record written in 120 s"
        time.sleep(0.05)
    first.send_signal(signal.SIGKILL)
    first.wait()
    kept = [json.loads(line)["submission"] for line in results.read_text().splitlines()]
    assert 1 <= len(kept) < len(names)
    refused = subprocess.run([*command[:-4], "--seed", str(SEED + 1)], capture_output=True, text=True, check=False)
    assert refused.returncode == 2 and f"seed {SEED}" in refused.stderr
    second = subprocess.run(command, capture_output=True, text=True, check=True)
    assert f"{len(kept)} already graded there, not regraded" in second.stdout
    assert second.stdout.count("\n[") == len(names) - len(kept)
    assert [json.loads(line) for line in results.read_text().splitlines()] == [records[n] for n in names]


@pytest.mark.parametrize("make, words", [
    (lambda d: d / "nowhere", "does not exist"),
    (lambda d: (d / "empty").mkdir() or d / "empty", "holds no submission"),
    (lambda d: (d / "class.zip").write_text("not a zip") and d / "class.zip", "is not a zip file"),
])
def test_bad_input_is_named_with_what_a_submission_should_hold(tmp_path, make, words):
    path = make(tmp_path)
    with pytest.raises(GradeError, match=words) as error:
        find_submissions([path], tmp_path / "work")
    assert str(path) in str(error.value) and "ex1.py" in str(error.value)
