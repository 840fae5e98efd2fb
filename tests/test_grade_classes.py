"""Classes as LMS exports hand them over: Moodle's and Canvas's names, a zip of zips, a folder per student holding a
zip, uploads that share a name or carry odd ones; each student graded under a name of their own, every problem that
student's and named, never a stop for the class."""
from __future__ import annotations

import csv
import io
import json
import os
import zipfile

import pytest

from appsim.workshop.course import SOLUTIONS, STARTERS
from appsim.workshop.grading.grade import run
from appsim.workshop.grading.submissions import MAX_SOURCE, find_submissions
from appsim.workshop.sandbox.children import Limits

SEED = 2024
LIMITS = Limits(time_s=8, stall_s=2)
SOLUTION_EX1 = (SOLUTIONS / "ex1.py").read_text()
STARTER_EX1 = (STARTERS / "ex1.py").read_text()
SOLUTION_EX2 = (SOLUTIONS / "ex2.py").read_text()


def zipped(files: dict[str, str | bytes]) -> bytes:
    data = io.BytesIO()
    with zipfile.ZipFile(data, "w") as archive:
        for name, content in files.items():
            archive.writestr(name, content)
    return data.getvalue()


def by_name(paths) -> dict:
    return {s.name: s for s in find_submissions(paths)}


def test_a_moodle_export_zip_of_uploads_all_named_lab_zip_grades_every_student(tmp_path):
    """Moodle's "Download all submissions" (in folders): each student's folder holds their upload, and all uploads are
    called lab.zip. Every student is graded, under the name Moodle gave them; CSV and Gradescope hold them all."""
    students = {"Alice Smith_1001": SOLUTION_EX1, "Bob Jones_1002": STARTER_EX1, "Carol Wu_1003": SOLUTION_EX1}
    export = {f"{name}_assignsubmission_file_/lab.zip": zipped({"lab/ex1.py": source})
              for name, source in students.items()}
    export["Dan Ek_1004_assignsubmission_onlinetext_/onlinetext.html"] = "<p>see my zip</p>"
    export["Dan Ek_1004_assignsubmission_file_/lab.zip"] = zipped({"ex1.py": SOLUTION_EX1})
    (tmp_path / "CAN202-Lab1-1.zip").write_bytes(zipped(export))
    records = run([tmp_path / "CAN202-Lab1-1.zip"], results=tmp_path / "grades.jsonl", csv_path=tmp_path / "book.csv",
                  gradescope_path=tmp_path / "gradescope", jobs=2, seed=SEED, limits=LIMITS, out=io.StringIO())
    scores = {r["submission"]: r["exercises"]["ex1"]["score"] for r in records}
    assert scores == {"Alice Smith_1001": 5, "Bob Jones_1002": 3, "Carol Wu_1003": 5, "Dan Ek_1004": 5}
    assert "CAN202-Lab1-1.zip:Alice Smith_1001_assignsubmission_file_" in {r["origin"] for r in records}
    with open(tmp_path / "book.csv", newline="") as book:
        assert [row["submission"] for row in csv.DictReader(book)] == sorted(scores)
    scored = {json.loads(p.read_text())["score"] for p in (tmp_path / "gradescope").iterdir()}
    assert len(list((tmp_path / "gradescope").iterdir())) == 4 and scored == {35 - 30, 3}


def test_a_moodle_export_without_folders_and_a_canvas_export_group_each_student_s_files(tmp_path):
    moodle = tmp_path / "moodle"
    moodle.mkdir()
    (moodle / "Alice Smith_1001_assignsubmission_file_ex1.py").write_text(SOLUTION_EX1)
    (moodle / "Alice Smith_1001_assignsubmission_file_ex2.py").write_text(SOLUTION_EX2)
    (moodle / "Bob Jones_1002_assignsubmission_file_lab.zip").write_bytes(zipped({"lab/ex1.py": STARTER_EX1}))
    found = by_name([moodle])
    assert set(found) == {"Alice Smith_1001", "Bob Jones_1002"}
    assert set(found["Alice Smith_1001"].files) == {"ex1", "ex2"} and set(found["Bob Jones_1002"].files) == {"ex1"}
    canvas = {"smithalice_1001_9001_ex1.py": SOLUTION_EX1, "smithalice_1001_9002_ex2-1.py": SOLUTION_EX2,
              "jonesbob_LATE_1002_9003_lab.zip": zipped({"ex1.py": STARTER_EX1})}
    (tmp_path / "submissions.zip").write_bytes(zipped(canvas))
    found = by_name([tmp_path / "submissions.zip"])
    assert set(found) == {"smithalice_1001", "jonesbob_1002"}
    assert set(found["smithalice_1001"].files) == {"ex1", "ex2"}
    assert found["jonesbob_1002"].files["ex1"][1] == STARTER_EX1.encode()


def test_a_class_folder_whose_student_folders_each_hold_only_a_zip_is_graded_from_the_zips(tmp_path):
    for name, source in (("alice", SOLUTION_EX1), ("bob", STARTER_EX1)):
        (tmp_path / "class" / name).mkdir(parents=True)
        (tmp_path / "class" / name / "my upload.zip").write_bytes(zipped({"Lab 1/ex1.py": source}))
    found = by_name([tmp_path / "class"])
    assert {n: s.files["ex1"][1] for n, s in found.items()} == {"alice": SOLUTION_EX1.encode(),
                                                                  "bob": STARTER_EX1.encode()}


def test_a_student_s_zip_holding_a_classmate_s_folder_speaks_for_nobody_else(tmp_path):
    """mallory.zip holding alice/ex1.py next to Alice's own folder: Alice's submission is her folder alone."""
    (tmp_path / "class" / "alice").mkdir(parents=True)
    (tmp_path / "class" / "alice" / "ex1.py").write_text(SOLUTION_EX1)
    (tmp_path / "class" / "mallory.zip").write_bytes(zipped({"alice/ex1.py": "broken(", "alice/ex2.py": "broken("}))
    found = by_name([tmp_path / "class"])
    assert found["alice"].files == {"ex1": ("ex1.py", SOLUTION_EX1.encode())}
    assert set(found["mallory"].files) == {"ex1", "ex2"}


@pytest.mark.parametrize("raw, shown", [
    ("bob\nsmith", "bob?smith"),
    ("=HYPERLINK(\"x\")", "=HYPERLINK(\"x\")"),
    ("x" * 200, None),
    (os.fsdecode(b"caf\xe9"), "caf\N{REPLACEMENT CHARACTER}"),
])
def test_an_odd_name_is_graded_under_one_a_record_a_gradebook_and_a_file_can_carry(tmp_path, raw, shown):
    folder = tmp_path / "class" / raw
    folder.mkdir(parents=True)
    (folder / "ex1.py").write_text(SOLUTION_EX1)
    (tmp_path / "class" / "alice").mkdir()
    (tmp_path / "class" / "alice" / "ex1.py").write_text(SOLUTION_EX1)
    records = run([tmp_path / "class"], results=tmp_path / "grades.jsonl", csv_path=tmp_path / "book.csv",
                  gradescope_path=tmp_path / "gradescope", jobs=2, seed=SEED, limits=LIMITS, out=io.StringIO())
    names = sorted(r["submission"] for r in records)
    odd = next(n for n in names if n != "alice")
    assert odd == shown if shown is not None else len(odd) <= 64 and odd.startswith("xxxx")
    assert all(c.isprintable() for c in odd)
    with open(tmp_path / "book.csv", newline="", encoding="utf-8") as book:
        assert len(list(csv.DictReader(book))) == 2
    assert len(list((tmp_path / "gradescope").iterdir())) == 2
    json.loads((tmp_path / "grades.jsonl").read_text().splitlines()[0])


def test_names_that_differ_only_in_case_are_told_apart_for_a_file_system_that_ignores_case(tmp_path):
    for name in ("Alice", "alice"):
        (tmp_path / "class" / name).mkdir(parents=True)
        (tmp_path / "class" / name / "ex1.py").write_text(SOLUTION_EX1)
    names = [s.name for s in find_submissions([tmp_path / "class"])]
    assert len({n.casefold() for n in names}) == 2


def test_a_refused_zip_member_is_named_in_the_verdict(tmp_path):
    (tmp_path / "class").mkdir()
    (tmp_path / "class" / "eve.zip").write_bytes(zipped({"../ex1.py": SOLUTION_EX1, "/etc/ex2.py": SOLUTION_EX2}))
    eve = by_name([tmp_path / "class"])["eve"]
    for exercise, member in (("ex1", "'../ex1.py'"), ("ex2", "'/etc/ex2.py'")):
        assert eve.problems[exercise].kind == "unreadable"
        assert f"the zip's member {member} was refused" in eve.problems[exercise].message
    (tmp_path / "class" / "eve.zip").write_bytes(zipped({"../../notes.txt": "x", "lab/ex1.py": SOLUTION_EX1}))
    eve = by_name([tmp_path / "class"])["eve"]
    assert "ex1" in eve.files
    assert eve.problems["ex2"].kind == "missing" and "'../../notes.txt' was refused" in eve.problems["ex2"].message


def test_a_broken_upload_in_a_student_s_folder_is_that_student_s_fault_and_the_class_goes_on(tmp_path):
    (tmp_path / "class" / "Olga P_7_assignsubmission_file_").mkdir(parents=True)
    (tmp_path / "class" / "Olga P_7_assignsubmission_file_" / "lab.zip").write_bytes(b"PK\x03\x04 not a zip")
    (tmp_path / "class" / "alice").mkdir()
    (tmp_path / "class" / "alice" / "ex1.py").write_text(SOLUTION_EX1)
    found = by_name([tmp_path / "class"])
    assert {p.kind for p in found["Olga P_7"].problems.values()} == {"unreadable"}
    assert "lab.zip is not a zip that can be read" in found["Olga P_7"].problems["ex1"].message
    assert "ex1" in found["alice"].files


@pytest.mark.parametrize("kind", ["file", "notebook cell"])
def test_a_firmware_over_the_size_limit_is_refused_before_it_runs_with_its_size_and_the_limit(tmp_path, kind):
    """1.5 MB of Python as ex1.py or as a notebook's firmware cell: the same fault, the same words (a cell used to
    reach the sandbox, which took at most 1 MB, and end as `exited`)."""
    source = SOLUTION_EX1 + "#" * (3 * MAX_SOURCE)
    (tmp_path / "class" / "zed").mkdir(parents=True)
    if kind == "file":
        (tmp_path / "class" / "zed" / "ex1.py").write_text(source)
    else:
        cell = {"cell_type": "code", "metadata": {"tags": ["firmware"]}, "source": source, "outputs": [],
                "execution_count": None}
        (tmp_path / "class" / "zed" / "ex1.ipynb").write_text(json.dumps({"cells": [cell], "metadata": {},
                                                                           "nbformat": 4, "nbformat_minor": 5}))
    [record] = run([tmp_path / "class"], results=tmp_path / "grades.jsonl", jobs=1, seed=SEED, limits=LIMITS,
                   out=io.StringIO())
    result = record["exercises"]["ex1"]
    assert (result["score"], result["fault"]) == (0, "unreadable")
    message = result["checks"][0]["message"]
    size = len(source.encode()) + (kind != "file")          # the cells as graded end with a newline
    assert f"{size:,} bytes" in message and f"at most {MAX_SOURCE:,} bytes" in message


def test_a_class_given_twice_names_each_copy_apart_and_a_rerun_keeps_the_names(tmp_path):
    for section in ("monday", "tuesday"):
        (tmp_path / section / "alice").mkdir(parents=True)
        (tmp_path / section / "alice" / "ex1.py").write_text(SOLUTION_EX1)
    first = [s.name for s in find_submissions([tmp_path / "monday", tmp_path / "tuesday"])]
    assert len(set(first)) == 2
    assert [s.name for s in find_submissions([tmp_path / "monday", tmp_path / "tuesday"])] == first


def test_what_an_lms_export_adds_around_the_uploads_is_left_alone(tmp_path):
    """A wrapping folder, macOS's __MACOSX, .DS_Store, an LMS's HTML text submission: no submission of their own."""
    export = {"Lab 1 submissions/Alice Smith_1001_assignsubmission_file_/ex1.py": SOLUTION_EX1,
              "Lab 1 submissions/Alice Smith_1001_assignsubmission_onlinetext_/onlinetext.html": "<p>hi</p>",
              "__MACOSX/Lab 1 submissions/._x": "", "Lab 1 submissions/.DS_Store": ""}
    (tmp_path / "export.zip").write_bytes(zipped(export))
    assert list(by_name([tmp_path / "export.zip"])) == ["Alice Smith_1001"]


def test_a_zip_nested_too_deep_or_unpacking_too_large_is_refused_by_name(tmp_path):
    inner = zipped({"ex1.py": SOLUTION_EX1})
    for _ in range(4):
        inner = zipped({"deeper.zip": inner})
    (tmp_path / "class").mkdir()
    (tmp_path / "class" / "nest.zip").write_bytes(inner)
    problem = by_name([tmp_path / "class"])["nest"].problems["ex1"]
    assert problem.kind == "unreadable" and "a zip inside 3 zips is not opened" in problem.message
    with zipfile.ZipFile(tmp_path / "class" / "bomb.zip", "w", zipfile.ZIP_DEFLATED) as archive:
        archive.writestr("ex1.py", SOLUTION_EX1)
        with archive.open("padding.bin", "w", force_zip64=True) as padding:
            for _ in range(257):
                padding.write(bytes(1 << 20))
    problem = by_name([tmp_path / "class"])["bomb"].problems["ex1"]
    assert problem.kind == "unreadable" and "unpacks to more than 256 MB" in problem.message
