"""`appsim grade` as an instructor runs it: a class graded in one run, each fault reported as what it was, the station
decided as `check` decides it, broken input a fault of its own submission, outputs checked first, resume by content."""
from __future__ import annotations

import csv
import io
import json
import os
import signal
import subprocess
import sys
import time
import zipfile
from pathlib import Path

import pytest

from appsim.errors import GradeError
from appsim.workshop.checks import check
from appsim.workshop.course import EXERCISE_FILES, SOLUTIONS, STARTERS
from appsim.workshop.grading.grade import run
from appsim.workshop.grading.submissions import find_submissions
from appsim.workshop.grading.worker import grade_exercise
from appsim.workshop.sandbox import children
from appsim.workshop.sandbox.children import Limits, Sandbox
from appsim.workshop.sandbox.isolation import isolation

KIT = Path(__file__).resolve().parent.parent
SEED = 2024
LIMITS = Limits(time_s=8, stall_s=2, memory_mb=128)
STARTER_EX1 = (STARTERS / "ex1.py").read_text()
SOLUTION_EX1 = (SOLUTIONS / "ex1.py").read_text()
FORMULA = "=SUM(1,2)"


def solution(exercise: str) -> str:
    return (SOLUTIONS / EXERCISE_FILES[exercise]).read_text()


def firmware(body: str, *, helpers: str = "") -> str:
    """A firmware file for station 1 whose main() does `body` (indented by 4) after CANInitialize."""
    return ("from appsim.firmware import *\n" + helpers + "\nMESSAGE_ID1 = 0x100\n\n\ndef main():\n"
            "    CANInitialize(4, 10, 8, 4, 3, CAN_CONFIG_VALID_STD_MSG)\n"
            + "".join(f"    {line}\n" for line in body.splitlines()))


def build_class(root: Path) -> None:
    """The test class: full marks, a typical mistake, and one submission per kind of fault or oddity."""
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
        "gina": {"ex1": firmware("spins = 0\nwhile True:\n    spins += 1"), "ex2": solution("ex2")},
        "hank": {"ex1": firmware("hoard = []\nwhile True:\n    hoard.append(bytearray(1 << 20))")},
        "ivan": {"ex1": firmware("import os\nos.fork()\nwhile True:\n    CANIsRxReady()"),
                 "ex2": firmware("import subprocess\nsubprocess.run(['true'])"),
                 "ex3": firmware("import socket\nsocket.create_connection(('192.0.2.1', 80), timeout=0.5)")},
        "ken": {"ex1": SOLUTION_EX1.replace("    TxData[3] = SFR.ADRESH\n    TxData[4] = SFR.ADRESL",
                                            "    TxData[3] = 0x02\n    TxData[4] = 0x00")},
        # the station comes from the firmware as loaded: a computed MESSAGE_ID1, Ex1's own 0x088, an ID of no station
        "mia": {"ex1": SOLUTION_EX1.replace("MESSAGE_ID1 = 0x100", "MESSAGE_ID1 = 0x088"),
                "ex2": solution("ex2").replace("MESSAGE_ID1 = 0x100", "MESSAGE_ID1, SPARE = 0x100 + 2 * 0x10, 0"),
                "ex3": solution("ex3").replace("MESSAGE_ID1 = 0x100", "MESSAGE_ID1 = 0x160")},
        # any standard library import that works in `appsim check` works in the sandbox
        "pat": {"ex1": "import statistics, datetime, queue, json, fractions\n" + SOLUTION_EX1},
        FORMULA: {"ex1": STARTER_EX1},
    }
    for name, files in submissions.items():
        (root / name).mkdir(parents=True)
        for exercise, text in files.items():
            (root / name / EXERCISE_FILES[exercise]).write_text(text)
    (root / "nora").mkdir()
    (root / "nora" / "ex1.py").symlink_to(root / "alice" / "ex1.py")               # a classmate's file
    (root / "nora" / "ex2.py").symlink_to(SOLUTIONS / "ex2.py")                    # the kit's solution
    (root / "nora" / "ex3.py").write_text(solution("ex3"))
    notebook = json.loads((KIT / "notebooks" / "ex1.ipynb").read_text())
    for cell in notebook["cells"]:
        if "firmware" in cell.get("metadata", {}).get("tags", []):
            cell["source"] = "%%writefile ex1.py\n" + SOLUTION_EX1
    with zipfile.ZipFile(root / "lena.zip", "w") as archive:     # a zip of a folder holding a notebook
        archive.writestr("lena/lab1.ipynb", json.dumps(notebook))
    (root / "oscar.zip").write_bytes(b"PK\x03\x04 this is not a zip")                # a broken upload


@pytest.fixture(scope="module")
def graded(tmp_path_factory):
    base = tmp_path_factory.mktemp("grading")
    build_class(base / "class")
    results = base / "grades.jsonl"
    records = run([base / "class"], results=results, csv_path=base / "gradebook.csv",
                  gradescope_path=base / "gradescope", jobs=2, seed=SEED, limits=LIMITS, out=io.StringIO())
    return base, {record["submission"]: record for record in records}, results


def exercise(records, name: str, ex: str) -> dict:
    return records[name]["exercises"][ex]


def first_message(records, name: str, ex: str) -> str:
    return exercise(records, name, ex)["checks"][0]["message"]


def test_full_marks_for_the_solutions_and_a_missing_exercise_is_zero_with_its_reason(graded):
    _, records, _ = graded
    alice = records["alice"]
    assert alice["score"] == alice["max_score"] == 35 and alice["seed"] == SEED
    assert all(e["fault"] is None for e in alice["exercises"].values())
    bob_ex3 = exercise(records, "bob", "ex3")
    assert bob_ex3["score"] == 0 and bob_ex3["fault"] == "missing"
    assert "ex3.py is missing" in bob_ex3["checks"][0]["message"]
    assert bob_ex3["max_score"] == alice["exercises"]["ex3"]["max_score"]


def test_a_typical_mistake_loses_the_checks_it_fails_and_nothing_else(graded):
    _, records, _ = graded
    ex1 = exercise(records, "bob", "ex1")
    assert ex1["fault"] is None and 0 < ex1["score"] < ex1["max_score"]
    assert "RXB0 receives its own frame" in [c["name"] for c in ex1["checks"] if not c["passed"]]
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
    ("hank", "ex1", "memory", "memory"),
    ("ivan", "ex1", "exception", "os.fork()"),
    ("ivan", "ex2", "exception", "Operation not permitted"),
    ("ivan", "ex3", "exception", "socket.create_connection"),
])
def test_each_fault_is_zero_marks_with_what_it_was(graded, name, ex, fault, words):
    _, records, _ = graded
    result = exercise(records, name, ex)
    assert (result["score"], result["fault"]) == (0, fault)
    assert words in result["checks"][0]["message"]
    assert not any(check["passed"] for check in result["checks"])


def test_an_exception_shows_the_students_own_line_and_not_the_kits(graded):
    message = first_message(graded[1], "frank", "ex1")
    assert "main() crashed at line 4 of ex1.py (`return 1023 // 0`): ZeroDivisionError" in message
    assert "appsim" not in message and "/tmp" not in message and "/firmware" not in message


def test_the_rest_of_a_faulty_submission_is_still_graded(graded):
    _, records, _ = graded
    for name in ("frank", "gina"):
        assert exercise(records, name, "ex2")["score"] == exercise(records, "alice", "ex2")["max_score"]


def test_hard_coded_ad_values_fail_against_the_seeded_potentiometer(graded):
    _, records, _ = graded
    ex1 = exercise(records, "ken", "ex1")
    failed = {c["name"] for c in ex1["checks"] if not c["passed"]}
    assert ex1["fault"] is None and "sends MESSAGE_ID1 with 01 02 03 ADRESH ADRESL" in failed


def test_the_station_is_decided_from_the_firmware_as_loaded_as_check_decides_it(graded):
    base, records, _ = graded
    for ex, station in (("ex1", 1), ("ex2", 3)):
        result = exercise(records, "mia", ex)
        assert result["score"] == result["max_score"], result
        assert f"station {station}'s board" in result["checks"][0]["message"]
        local = check(ex, base / "class" / "mia" / EXERCISE_FILES[ex], seed=SEED)
        assert [(c.name, c.passed) for c in local.checks] == [(c["name"], c["passed"]) for c in result["checks"]]
    assert "MESSAGE_ID1 = 0x088" in first_message(records, "mia", "ex1")


def test_an_identifier_of_no_station_costs_only_the_checks_that_depend_on_the_station(graded):
    """Ex3 with MESSAGE_ID1 = 0x160: its board takes station 1's place; receiving, the LCD and the filters are judged
    as for any station, and the one check of what it sends fails, in its own names (it used to get 0/5)."""
    base, records, _ = graded
    result = exercise(records, "mia", "ex3")
    assert result["fault"] is None and result["score"] == result["max_score"] - 1
    [failed] = [c for c in result["checks"] if not c["passed"]]
    assert failed["name"] == "keeps sending MESSAGE_ID1 on Timer1"
    assert failed["message"].startswith("MESSAGE_ID1 = 0x160 is not a station's identifier: the classroom's stations "
                                        "use 0x100, 0x110 ... 0x150")
    assert "Otherwise right" in failed["message"] and "0x160 DATA 01 02 03" in failed["message"]
    local = check("ex3", base / "class" / "mia" / "ex3.py", seed=SEED).to_dict()
    assert local["checks"][1:] == result["checks"][1:] and local["fault"] is None


def test_standard_library_imports_work_as_in_appsim_check(graded):
    _, records, _ = graded
    assert exercise(records, "pat", "ex1")["score"] == exercise(records, "alice", "ex1")["max_score"]


def test_a_symbolic_link_is_refused_as_such_and_the_link_target_is_graded_only_as_its_owners(graded):
    _, records, _ = graded
    for ex in ("ex1", "ex2"):
        result = exercise(records, "nora", ex)
        assert (result["score"], result["fault"]) == (0, "symlink")
        assert "symbolic link" in result["checks"][0]["message"]
    assert exercise(records, "nora", "ex3")["score"] == exercise(records, "alice", "ex3")["max_score"]
    assert records["alice"]["score"] == 35


def test_a_broken_zip_is_its_own_submissions_fault_and_the_class_goes_on(graded):
    _, records, _ = graded
    oscar = records["oscar"]
    assert oscar["score"] == 0
    assert {e["fault"] for e in oscar["exercises"].values()} == {"unreadable"}
    assert "oscar.zip is not a zip that can be read" in first_message(records, "oscar", "ex1")
    assert exercise(records, "lena", "ex1")["score"] == exercise(records, "alice", "ex1")["max_score"]


def test_csv_and_gradescope_agree_with_the_json_and_a_formula_name_stays_text(graded):
    base, records, _ = graded
    with open(base / "gradebook.csv", newline="") as file:
        rows = list(csv.DictReader(file))
    names = ["'" + n if n.startswith("=") else n for n in sorted(records)]
    assert [row["submission"] for row in rows] == names
    assert "'" + FORMULA in [row["submission"] for row in rows]
    for row, name in zip(rows, sorted(records), strict=True):
        record = records[name]
        assert int(row["total"]) == record["score"] and int(row["max_score"]) == record["max_score"]
        assert all(int(row[ex]) == record["exercises"][ex]["score"] for ex in EXERCISE_FILES)
    assert not any(cell.startswith(("=", "+", "-", "@")) for row in rows for cell in row.values())
    files = {path.name for path in (base / "gradescope").iterdir()}
    assert len(files) == len(records) and all("/" not in f and not f.startswith(".") for f in files)
    alice = json.loads((base / "gradescope" / "alice.json").read_text())
    assert alice["score"] == records["alice"]["score"]
    assert [(t["name"], t["score"]) for t in alice["tests"]] == [
        (ex, e["score"]) for ex, e in records["alice"]["exercises"].items()]


def test_each_record_says_what_it_judged(graded):
    _, records, results = graded
    for record in records.values():
        assert len(record["hash"]) == 64 and record["seed"] == SEED and "+" in record["kit"]
    assert records["alice"]["hash"] != records["bob"]["hash"]
    assert [json.loads(line)["submission"] for line in results.read_text().splitlines()] == sorted(records)


def test_the_same_class_and_seed_give_identical_json(graded, tmp_path):
    base, _, results = graded
    again = tmp_path / "again.jsonl"
    run([base / "class"], results=again, jobs=2, seed=SEED, limits=LIMITS, out=io.StringIO())
    assert again.read_text() == results.read_text()


# ====================================================================== resuming, as a command

def grade_command(*args: str) -> list[str]:
    return [sys.executable, "-m", "appsim", "grade", *args]


def small_class(root: Path, names=("alice", "bob", "carol", "dave")) -> None:
    sources = {"alice": SOLUTION_EX1, "bob": STARTER_EX1, "carol": SOLUTION_EX1.replace("0x100", "0x110"),
               "dave": STARTER_EX1.replace("0x100", "0x120")}
    for name in names:
        (root / name).mkdir(parents=True)
        (root / name / "ex1.py").write_text(sources[name])


def test_a_killed_run_resumes_and_ends_with_the_same_results_as_an_uninterrupted_one(tmp_path):
    small_class(tmp_path / "class")
    whole = tmp_path / "whole.jsonl"
    subprocess.run(grade_command(str(tmp_path / "class"), "--json", str(whole), "--seed", str(SEED), "--jobs", "1"),
                   check=True, capture_output=True)
    results = tmp_path / "class.grades.jsonl"            # the default: beside the class, named after it
    command = grade_command(str(tmp_path / "class"), "--seed", str(SEED), "--jobs", "1")
    first = subprocess.Popen(command, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
    deadline = time.monotonic() + 120
    while not (results.exists() and results.read_text().count("\n") >= 1) and first.poll() is None:
        assert time.monotonic() < deadline, "no record written in 120 s"
        time.sleep(0.02)
    first.send_signal(signal.SIGKILL)
    first.wait()
    kept = len(results.read_text().splitlines())
    assert 1 <= kept < 4
    second = subprocess.run(command, capture_output=True, text=True, check=True)
    assert f"{kept} already graded there with this seed and kit, kept" in second.stdout
    assert second.stdout.count("\n[") == 4 - kept
    assert results.read_text() == whole.read_text()


def test_a_changed_submission_is_graded_again_and_the_others_are_kept(tmp_path):
    small_class(tmp_path / "class", ("alice", "bob"))
    results = tmp_path / "grades.jsonl"
    command = grade_command(str(tmp_path / "class"), "--json", str(results), "--seed", str(SEED))
    subprocess.run(command, check=True, capture_output=True)
    before = {json.loads(line)["submission"]: json.loads(line) for line in results.read_text().splitlines()}
    (tmp_path / "class" / "bob" / "ex1.py").write_text(SOLUTION_EX1)             # bob hands in again
    again = subprocess.run(command, capture_output=True, text=True, check=True)
    assert "1 already graded there" in again.stdout and "[2/2] bob" in again.stdout
    after = {json.loads(line)["submission"]: json.loads(line) for line in results.read_text().splitlines()}
    assert after["alice"] == before["alice"]
    assert after["bob"]["hash"] != before["bob"]["hash"] and after["bob"]["score"] > before["bob"]["score"]
    regraded = subprocess.run([*command, "--regrade"], capture_output=True, text=True, check=True)
    assert "already graded" not in regraded.stdout and regraded.stdout.count("\n[") == 2
    other_seed = subprocess.run([*command[:-2], "--seed", str(SEED + 1)], capture_output=True, text=True, check=True)
    assert "already graded" not in other_seed.stdout and f"seed {SEED + 1}" in other_seed.stdout


# ====================================================================== input and output the grader refuses first

@pytest.mark.parametrize("option, make, words", [
    ("--json", lambda d: d / "missing" / "grades.jsonl", "does not exist"),
    ("--json", lambda d: d, "is a folder, not a regular file"),
    ("--json", lambda d: os.mkfifo(d / "fifo") or d / "fifo", "is a FIFO"),
    ("--csv", lambda d: Path("/dev/null"), "is a device"),
    ("--gradescope", lambda d: (d / "g.json").write_text("{}") and d / "g.json", "not a folder"),
])
def test_an_output_path_of_the_wrong_kind_is_refused_before_anything_is_graded(tmp_path, option, make, words):
    small_class(tmp_path / "class", ("alice", "bob"))
    path = make(tmp_path)
    started = time.monotonic()
    result = subprocess.run(grade_command(str(tmp_path / "class"), option, str(path)), capture_output=True,
                            text=True, timeout=60)
    assert result.returncode == 2 and words in result.stderr, result.stderr
    assert "Traceback" not in result.stderr and result.stdout == ""
    assert time.monotonic() - started < 10
    assert not (tmp_path / "class.grades.jsonl").exists() or option == "--json"


@pytest.mark.parametrize("args, words", [
    (["--jobs", "0"], "--jobs is how many exercises are graded at once, a whole number: 1 or more; got 0"),
    (["--jobs", "two"], "--jobs is how many exercises are graded at once, a whole number: 1 or more; got 'two'"),
    (["--time-limit", "0"], "the time limit is CPU seconds, more than 0 and at most 3600 (an hour); got 0"),
])
def test_bad_numbers_are_refused_in_words(tmp_path, args, words):
    small_class(tmp_path / "class", ("alice",))
    result = subprocess.run(grade_command(str(tmp_path / "class"), *args), capture_output=True, text=True)
    assert result.returncode == 2 and words in result.stderr and "Traceback" not in result.stderr


def test_without_isolation_nothing_is_graded_unless_the_class_is_trusted(tmp_path):
    small_class(tmp_path / "class", ("alice",))
    bare = tmp_path / "bin"
    bare.mkdir()
    env = {**os.environ, "PATH": str(bare)}                   # no bwrap on this PATH
    refused = subprocess.run(grade_command(str(tmp_path / "class")), capture_output=True, text=True, env=env)
    assert refused.returncode == 2 and "cannot isolate student firmware" in refused.stderr
    assert "bubblewrap" in refused.stderr and "--trusted" in refused.stderr and "Nothing was graded" in refused.stderr
    assert not (tmp_path / "class.grades.jsonl").exists()
    trusted = subprocess.run(grade_command(str(tmp_path / "class"), "--trusted"), capture_output=True, text=True,
                             env=env, check=True)
    assert "NOT ISOLATED (--trusted)" in trusted.stdout and "alice" in trusted.stdout


@pytest.mark.parametrize("make, words", [
    (lambda d: d / "nowhere", "cannot be read"),
    (lambda d: (d / "empty").mkdir() or d / "empty", "holds no submission"),
    (lambda d: (d / "notes.txt").write_text("x") and d / "notes.txt", "is not a folder, a .zip"),
])
def test_a_path_that_holds_no_class_is_named_with_what_a_submission_should_hold(tmp_path, make, words):
    path = make(tmp_path)
    with pytest.raises(GradeError, match=words) as error:
        find_submissions([path])
    assert str(path) in str(error.value) and "ex1.py" in str(error.value)


def test_two_submissions_of_one_name_are_each_graded_under_a_name_of_their_own(tmp_path):
    """A folder alice/ and an upload alice.zip (a classmate's, named after her): neither takes the name from the other,
    each record says where it came from, and a second run gives them the same names (so it resumes)."""
    small_class(tmp_path / "class", ("alice",))
    with zipfile.ZipFile(tmp_path / "class" / "alice.zip", "w") as archive:
        archive.writestr("ex1.py", STARTER_EX1)
    found = find_submissions([tmp_path / "class"])
    names = [s.name for s in found]
    assert len(names) == 2 and all(n.startswith("alice~") for n in names) and len(set(names)) == 2
    assert all("2 submissions would be named 'alice'" in s.note for s in found)
    assert {s.origin for s in found} == {"class/alice", "class/alice.zip"}
    assert [s.name for s in find_submissions([tmp_path / "class"])] == names


def test_ctrl_c_ends_with_one_line_exit_130_and_keeps_what_was_graded(tmp_path):
    small_class(tmp_path / "class")
    results = tmp_path / "class.grades.jsonl"
    grader = subprocess.Popen(grade_command(str(tmp_path / "class"), "--seed", str(SEED), "--jobs", "1"),
                              stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    deadline = time.monotonic() + 120
    while not (results.exists() and results.read_text().count("\n") >= 1) and grader.poll() is None:
        assert time.monotonic() < deadline, "no record written in 120 s"
        time.sleep(0.02)
    grader.send_signal(signal.SIGINT)
    out, err = grader.communicate(timeout=60)
    assert grader.returncode == 130, err
    assert "interrupted" in err and "run the same command again" in err and "Traceback" not in err
    kept = [json.loads(line)["submission"] for line in results.read_text().splitlines()]
    assert kept and kept == [line.split()[1] for line in out.splitlines() if line.startswith("[")]


def _graded(tmp_path: Path, files: dict[str, dict[str, str]], limits: Limits) -> dict[str, dict]:
    """Each submission's exercises, graded as one class (`files`: submission -> exercise -> source)."""
    for name, sources in files.items():
        (tmp_path / "class" / name).mkdir(parents=True)
        for exercise, source in sources.items():
            (tmp_path / "class" / name / EXERCISE_FILES[exercise]).write_text(source)
    records = run([tmp_path / "class"], results=tmp_path / "grades.jsonl", jobs=1, seed=SEED, limits=limits,
                  out=io.StringIO())
    return {record["submission"]: record["exercises"] for record in records}


def _graded_alone(tmp_path: Path, exercise: str, source: str, limits: Limits) -> dict:
    return _graded(tmp_path, {"sam": {exercise: source}}, limits)["sam"][exercise]


def test_a_firmware_that_keeps_the_grader_busy_is_stopped_by_the_grader_s_cpu_time(tmp_path):
    """A write and a read on every turn of the loop, never waiting: each read crosses to the board (the write changes
    the board, so no read-ahead answers it). The grader's own CPU time for it counts against the limit, so it ends as
    "time" with its reason, long before the wall time. Graded as Demo1, the longest exercise (1 simulated second:
    2.5 million crossings, about 20 s of the grader's CPU on the test machine); Ex1's 30 ms took it 0.7 s, under the
    limit, once a round trip cost 15 us, and the exercise was judged instead."""
    chatty = firmware("while True:\n    SFR.TXB0D0 = 1\n    SFR.TXB0D0")
    started = time.monotonic()
    result = _graded_alone(tmp_path, "demo1", chatty, Limits(time_s=1, stall_s=5, wall_time_s=120))
    assert result["fault"] == "time" and result["score"] == 0
    assert "CPU time limit: simulating the board for this firmware took the grader more than 1 s" in \
        result["checks"][0]["message"]
    assert time.monotonic() - started < 60


def test_a_firmware_that_computes_in_its_own_process_is_stopped_by_its_own_cpu_time(tmp_path):
    """Computing between register reads (a time-varying one, so the loop never parks and is never stalled), the
    firmware spends its own process's CPU, not the grader's: the kernel's CPU limit ends it as "time", saying so."""
    thinker = firmware("while True:\n    sum(range(10 ** 6))\n    SFR.TMR1L")
    started = time.monotonic()
    result = _graded_alone(tmp_path, "ex1", thinker, Limits(time_s=1, stall_s=5, wall_time_s=120))
    assert result["fault"] == "time" and result["score"] == 0
    assert "CPU time limit: the firmware computed for more than 1 s in its own process" in \
        result["checks"][0]["message"]
    assert time.monotonic() - started < 60


def _cpu_loop_of(seconds: float) -> int:
    """How many turns of `sum(range(1000))` take about `seconds` of CPU here."""
    started = time.process_time()
    for _ in range(200):
        sum(range(1000))
    return max(1, round(200 * seconds / (time.process_time() - started)))


def test_a_busy_machine_does_not_cost_a_student_points(tmp_path):
    """Graded while every core is busy with other work, two firmwares get the marks `appsim check` gives them, because
    the limits count CPU time and sleep, never time spent waiting for a CPU: the classic Ex2 slip (TMR1IF never cleared:
    it converts and tries to send on every turn, reading ten registers a turn), and an Ex1 that computes for a third
    of the stall time between two register accesses (on a busy machine, that took longer than the stall time)."""
    busy_ex2 = solution("ex2").replace("            PIR1bits.TMR1IF = 0\n", "")
    thinking_ex1 = SOLUTION_EX1.replace("    CANInitialization()\n", f"    for _ in range({_cpu_loop_of(1.0)}):\n"
                                        "        sum(range(1000))\n    CANInitialization()\n", 1)
    assert thinking_ex1 != SOLUTION_EX1
    expected = {}
    for name, (exercise, source) in {"bo": ("ex2", busy_ex2), "cy": ("ex1", thinking_ex1)}.items():
        (tmp_path / f"{name}.py").write_text(source)
        expected[name] = check(exercise, tmp_path / f"{name}.py", seed=SEED).to_dict()
    burners = [subprocess.Popen([sys.executable, "-c", "while True: pass"]) for _ in range(2 * (os.cpu_count() or 1))]
    try:
        graded = _graded(tmp_path, {"bo": {"ex2": busy_ex2}, "cy": {"ex1": thinking_ex1}}, Limits(time_s=20, stall_s=3))
    finally:
        for burner in burners:
            burner.kill()
            burner.wait()
    for name, exercise in (("bo", "ex2"), ("cy", "ex1")):
        result = graded[name][exercise]
        assert result["fault"] is None, f"{name}: {result['checks'][0]['message']}"
        assert (result["score"], [c["passed"] for c in result["checks"]]) == \
            (expected[name]["score"], [c["passed"] for c in expected[name]["checks"]])


def test_a_firmware_that_sleeps_between_accesses_is_stopped_by_its_time_asleep(tmp_path):
    """A firmware that touches a register every 0.4 s (never long enough without a word to be stalled) sleeps in all
    beyond the stall time: it ends as "stalled", saying it slept, without waiting for the wall-time limit."""
    sleeper = firmware("import time\nwhile True:\n    SFR.TMR1L\n    time.sleep(0.4)")     # time-varying: never parks
    started = time.monotonic()
    result = _graded_alone(tmp_path, "ex1", sleeper, Limits(time_s=30, stall_s=2, wall_time_s=300))
    assert result["fault"] == "stalled" and result["score"] == 0
    assert "the firmware slept: more than 2 s in all" in result["checks"][0]["message"]
    assert time.monotonic() - started < 60


def test_a_sandbox_left_waiting_past_its_boot_time_costs_the_next_student_nothing(monkeypatch):
    """Each submission takes the sandbox that booted while the one before was graded. One that waited longer than
    BOOT_S for its turn (the submission before took that long: a slow firmware, a busy machine) is replaced, never
    handed over dead: the next student got 'stalled', for nothing their firmware did."""
    monkeypatch.setattr(children, "BOOT_S", 4.0)
    source = (SOLUTIONS / EXERCISE_FILES["ex1"]).read_bytes()
    with Sandbox(isolation(), Limits()) as sandbox:
        first = grade_exercise(sandbox, "ex1", "ex1.py", source, SEED, None, owner="alice", spare=True)
        time.sleep(5.0)                 # the next sandbox booted meanwhile and has waited past its boot time since
        second = grade_exercise(sandbox, "ex1", "ex1.py", source, SEED, None, owner="bob")
        third = grade_exercise(sandbox, "ex1", "ex1.py", source, SEED, None, owner="bob")
    assert first["fault"] is None, first["checks"][0]["message"]
    assert second == first and third == first


def test_each_exercise_of_a_submission_runs_in_a_fresh_process_of_its_sandbox():
    """A submission's exercises share its sandbox, one fresh process each: what one firmware leaves in its own process
    (a patched library) is gone for the next, as it is in `appsim check`."""
    patcher = firmware("import appsim.firmware.an738 as an738\nan738.CANSendMessage = None\nspins = 0\n"
                       "while True:\n    spins += 1")
    source = (SOLUTIONS / EXERCISE_FILES["ex1"]).read_bytes()
    with Sandbox(isolation(), Limits(stall_s=1)) as sandbox:
        honest = grade_exercise(sandbox, "ex1", "ex1.py", source, SEED, None, owner="carol")
        zygote = sandbox._zygote
        broken = grade_exercise(sandbox, "ex1", "ex1.py", patcher.encode(), SEED, None, owner="carol")
        after = grade_exercise(sandbox, "ex1", "ex1.py", source, SEED, None, owner="carol")
        assert sandbox._zygote is zygote
    assert broken["score"] == 0
    assert after == honest and honest["score"] == honest["max_score"]


def test_a_firmware_that_cannot_be_told_apart_in_its_sandbox_still_ends_when_its_time_is_up(tmp_path):
    """Where the grader cannot tell the firmware's process apart (no number for it outside its sandbox), it ends the
    whole sandbox when the firmware's time is up, and the next exercise gets a fresh one. The grader hung there once,
    its watchdog waiting on itself: a process of its own here, so that a hang fails this test instead of hanging it."""
    spinner_source = firmware("spins = 0\nwhile True:\n    spins += 1").encode()
    script = tmp_path / "grade_spinner.py"
    script.write_text(f"""import json
from appsim.workshop.grading.worker import grade_exercise
from appsim.workshop.sandbox import children
from appsim.workshop.sandbox.isolation import isolation

children.Zygote.host_pid = lambda self, pid: None
with children.Sandbox(isolation(), children.Limits(stall_s=1)) as sandbox:
    spinner = grade_exercise(sandbox, "ex1", "ex1.py", {spinner_source!r}, {SEED}, None,
                             owner="uma")
    after = grade_exercise(sandbox, "ex1", "ex1.py", {SOLUTION_EX1.encode()!r}, {SEED}, None, owner="uma")
print(json.dumps([spinner, after]))
""")
    done = subprocess.run([sys.executable, str(script)], capture_output=True, text=True, timeout=120, check=True)
    spinner, after = json.loads(done.stdout)
    assert spinner["fault"] == "stalled", spinner
    assert after["score"] == after["max_score"], after


def test_a_worker_that_dies_costs_its_exercise_a_grader_fault_with_its_last_words_and_the_class_goes_on(
        tmp_path, monkeypatch, capsys):
    """A grading worker that dies in the middle of an exercise (a bug of the kit's, a kill from outside) costs that
    exercise a `grader` fault that quotes the worker's last line and says to grade it again; a fresh worker grades the
    rest. (Workers are forked from the grader, so this grader's patch is theirs too.)"""
    from appsim.workshop.grading import worker

    real = worker.grade_exercise

    def dies_on_victors_ex2(sandbox, exercise, name, source, seed, problem, *, owner=None, spare=False):
        if (owner, exercise) == ("victor", "ex2"):
            print("RuntimeError: the worker's last words", file=sys.stderr, flush=True)
            os._exit(3)
        return real(sandbox, exercise, name, source, seed, problem, owner=owner, spare=spare)

    monkeypatch.setattr(worker, "grade_exercise", dies_on_victors_ex2)
    for name in ("victor", "wendy"):
        (tmp_path / "class" / name).mkdir(parents=True)
        for ex in ("ex1", "ex2"):
            (tmp_path / "class" / name / EXERCISE_FILES[ex]).write_text(solution(ex))
    records = {r["submission"]: r for r in run([tmp_path / "class"], results=tmp_path / "grades.jsonl", jobs=2,
                                                  seed=SEED, limits=LIMITS, out=io.StringIO())}
    lost = exercise(records, "victor", "ex2")
    assert lost["fault"] == "grader" and lost["score"] == 0
    message = lost["checks"][0]["message"]
    assert "the worker's last words" in message and "Grade it again" in message
    assert "victor ex2: the grader's worker process ended" in capsys.readouterr().err
    for name, ex in (("victor", "ex1"), ("wendy", "ex1"), ("wendy", "ex2")):
        assert exercise(records, name, ex)["score"] == exercise(records, name, ex)["max_score"], (name, ex)
