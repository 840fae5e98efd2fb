"""The Gradescope autograder as Gradescope runs it: the zip `appsim gradescope-autograder` writes is laid out in
Gradescope's folders (source, submission, results) under a root of the test's own, setup.sh's install step puts the kit
in a fresh venv from the wheel inside the zip, and run_autograder grades the solutions and the starters into a
results.json that follows Gradescope's documented schema, with `appsim grade`'s checks, seed and verdict."""
from __future__ import annotations

import json
import os
import shutil
import stat
import subprocess
import sys
import zipfile
from pathlib import Path

import jsonschema
import pytest

from appsim.workshop.course import EXERCISE_FILES, EXERCISES, SOLUTIONS, STARTERS

SEED = 2024
VISIBILITY = {"enum": ["hidden", "after_due_date", "after_published", "visible"]}
FORMAT = {"enum": ["text", "html", "simple_format", "md", "ansi"]}
# Gradescope's "Autograder Specifications", Output format: every key it documents, and no other.
RESULTS_SCHEMA = {
    "type": "object", "additionalProperties": False,
    "properties": {
        "score": {"type": "number"}, "execution_time": {"type": "number"}, "output": {"type": "string"},
        "output_format": FORMAT, "test_output_format": FORMAT, "test_name_format": FORMAT,
        "visibility": VISIBILITY, "stdout_visibility": VISIBILITY, "extra_data": {"type": "object"},
        "tests": {"type": "array", "items": {
            "type": "object", "additionalProperties": False,
            "properties": {"score": {"type": "number"}, "max_score": {"type": "number"},
                           "status": {"enum": ["passed", "failed"]}, "name": {"type": "string"},
                           "name_format": FORMAT, "number": {"type": "string"}, "output": {"type": "string"},
                           "output_format": FORMAT, "tags": {"type": "array", "items": {"type": "string"}},
                           "visibility": VISIBILITY, "extra_data": {"type": "object"}}}},
        "leaderboard": {"type": "array"},
    },
    "anyOf": [{"required": ["score"]}, {"required": ["tests"]}],
}


@pytest.fixture(scope="module")
def autograder(tmp_path_factory) -> Path:
    """Gradescope's /autograder under a folder of this test's: the zip's files in source/, the kit installed by
    setup.sh's install step into a fresh venv, run_autograder copied to the root as Gradescope does."""
    root = tmp_path_factory.mktemp("autograder")
    made = subprocess.run([sys.executable, "-m", "appsim", "gradescope-autograder", str(root / "autograder.zip"),
                           "--seed", str(SEED)], capture_output=True, text=True, timeout=600, cwd=root)
    assert made.returncode == 0, made.stderr
    with zipfile.ZipFile(root / "autograder.zip") as archive:
        archive.extractall(root / "source")
        for info in archive.infolist():         # zipfile does not restore permissions: as Gradescope's unzip does
            os.chmod(root / "source" / info.filename, info.external_attr >> 16 or 0o644)
    shutil.copy2(root / "source" / "run_autograder", root / "run_autograder")
    env = {**os.environ, "APPSIM_AUTOGRADER_ROOT": str(root), "APPSIM_AUTOGRADER_PYTHON": sys.executable,
           "PYTHONPATH": ""}
    setup = subprocess.run(["bash", str(root / "source" / "setup.sh"), "--install-only"], env=env, cwd=root / "source",
                           capture_output=True, text=True, timeout=900)
    assert setup.returncode == 0, setup.stdout[-3000:] + setup.stderr[-3000:]
    assert "setup.sh: appsim" in setup.stdout
    return root


def gradescope(root: Path, files: dict[str, bytes], *, path: str = "/usr/bin:/bin") -> dict:
    """Run run_autograder on a submission of `files`, as Gradescope does (working folder /autograder)."""
    submission, results = root / "submission", root / "results"
    for folder in (submission, results):
        shutil.rmtree(folder, ignore_errors=True)
        folder.mkdir()
    for name, content in files.items():
        (submission / name).parent.mkdir(parents=True, exist_ok=True)
        (submission / name).write_bytes(content)
    env = {"PATH": path, "APPSIM_AUTOGRADER_ROOT": str(root), "HOME": str(root), "LANG": "C.UTF-8"}
    ran = subprocess.run([str(root / "run_autograder")], cwd=root, env=env, capture_output=True, text=True,
                         timeout=900)
    assert ran.returncode == 0, ran.stdout[-3000:] + ran.stderr[-3000:]
    answer = json.loads((results / "results.json").read_text())
    jsonschema.validate(answer, RESULTS_SCHEMA)
    return answer


def files_of(folder: Path) -> dict[str, bytes]:
    return {name: (folder / name).read_bytes() for name in EXERCISE_FILES.values()}


def grade_here(tmp_path: Path, files: dict[str, bytes]) -> dict:
    """`appsim grade` of the same files with the same seed, here."""
    submission = tmp_path / "submission"
    submission.mkdir()
    for name, content in files.items():
        (submission / name).write_bytes(content)
    result = subprocess.run([sys.executable, "-m", "appsim", "grade", str(submission), "--seed", str(SEED)],
                            capture_output=True, text=True, timeout=600)
    assert result.returncode == 0, result.stderr
    return json.loads((tmp_path / "submission.grades.jsonl").read_text())


def same_verdict(answer: dict, record: dict) -> None:
    """One Gradescope test per check, with the check's points, words and outcome, and the same total."""
    expected = [(f"{exercise.upper()}: {check['name']}", check["points"] if check["passed"] else 0, check["points"],
                 "passed" if check["passed"] else "failed", check["message"])
                for exercise in EXERCISES for check in record["exercises"][exercise]["checks"]]
    assert [(t["name"], t["score"], t["max_score"], t["status"], t["output"]) for t in answer["tests"]] == expected
    assert answer["score"] == record["score"] == sum(t["score"] for t in answer["tests"])
    assert answer["extra_data"]["seed"] == SEED == record["seed"]


def test_the_zip_has_what_gradescope_expects_at_its_root(autograder):
    with zipfile.ZipFile(autograder / "autograder.zip") as archive:
        names = archive.namelist()
        modes = {info.filename: info.external_attr >> 16 for info in archive.infolist()}
        settings = json.loads(archive.read("appsim-autograder.json"))
    assert {"setup.sh", "run_autograder", "appsim-autograder.json"} <= set(names)
    assert all("/" not in name for name in names), "the files at the root of the zip, not in a folder"
    assert [name for name in names if name.endswith(".whl")] == [settings["wheel"]]
    assert modes["setup.sh"] & stat.S_IXUSR and modes["run_autograder"] & stat.S_IXUSR
    assert settings["seed"] == SEED and settings["visibility"] == "visible"
    assert (autograder / "appsim-venv" / "bin" / "python").exists()
    assert "apt-get install" in (autograder / "source" / "setup.sh").read_text() and "bubblewrap" in \
        (autograder / "source" / "setup.sh").read_text()


def test_the_solutions_get_full_marks_as_appsim_grade_gives_them(autograder, tmp_path):
    files = files_of(SOLUTIONS)
    answer = gradescope(autograder, files)
    assert answer["score"] == 35 and all(test["status"] == "passed" for test in answer["tests"])
    assert answer["extra_data"]["isolated"] is True, "this machine has bubblewrap: each firmware in its sandbox"
    assert "appsim grade` with the same seed gives the same marks" in answer["output"]
    same_verdict(answer, grade_here(tmp_path, files))


def test_the_starters_get_the_marks_and_the_words_appsim_grade_gives_them(autograder, tmp_path):
    files = files_of(STARTERS)
    answer = gradescope(autograder, files)
    record = grade_here(tmp_path, files)
    same_verdict(answer, record)
    assert 0 < answer["score"] < 35
    failed = [test for test in answer["tests"] if test["status"] == "failed"]
    assert failed and all(test["output"] and test["score"] == 0 for test in failed)
    assert all(test["visibility"] == "visible" and test["tags"][0] in EXERCISES for test in answer["tests"])


def test_an_upload_of_one_folder_is_that_submission_and_a_missing_file_is_zero_for_it(autograder):
    files = {f"my work/{name}": content for name, content in files_of(SOLUTIONS).items() if name != "ex6.py"}
    answer = gradescope(autograder, files)
    assert answer["score"] == 30
    ex6 = [test for test in answer["tests"] if test["name"].startswith("EX6:")]
    assert ex6 and all(test["score"] == 0 and "missing" in test["tags"] for test in ex6)


def test_an_empty_upload_says_what_to_hand_in(autograder):
    answer = gradescope(autograder, {})
    assert answer["score"] == 0
    assert "ex1.py" in answer["output"]


def test_where_the_container_cannot_isolate_it_says_so_and_grades_with_the_container_as_the_boundary(
        autograder, tmp_path):
    no_bwrap = tmp_path / "bin"                  # an image without bubblewrap (or whose kernel refuses namespaces)
    no_bwrap.mkdir()
    for tool in ("bash", "env", "python3"):
        found = shutil.which(tool)
        if found:
            os.symlink(found, no_bwrap / tool)
    files = files_of(STARTERS)
    answer = gradescope(autograder, files, path=str(no_bwrap))
    assert answer["extra_data"]["isolated"] is False
    assert "does not let appsim build its sandbox (bubblewrap (bwrap) is not installed" in answer["output"]
    assert "the container is the boundary" in answer["output"]
    same_verdict(answer, grade_here(tmp_path, files))


def test_a_nested_container_that_forbids_user_namespaces_is_told_apart(autograder, tmp_path):
    """Gradescope's Docker container: no new user namespace may be made inside it (bwrap --disable-userns makes one
    like it here)."""
    bwrap = shutil.which("bwrap")
    if bwrap is None:
        pytest.skip("needs bubblewrap to make a container that forbids user namespaces")
    files = files_of(SOLUTIONS)
    submission, results = autograder / "submission", autograder / "results"
    for folder in (submission, results):
        shutil.rmtree(folder, ignore_errors=True)
        folder.mkdir()
    for name, content in files.items():
        (submission / name).write_bytes(content)
    ran = subprocess.run([bwrap, "--dev-bind", "/", "/", "--unshare-user", "--disable-userns", "--",
                          str(autograder / "run_autograder")], cwd=autograder, capture_output=True, text=True,
                         env={"PATH": "/usr/bin:/bin", "APPSIM_AUTOGRADER_ROOT": str(autograder), "HOME": "/",
                              "LANG": "C.UTF-8"}, timeout=900)
    if ran.returncode != 0 and not results.joinpath("results.json").exists():
        pytest.skip(f"this kernel does not run bwrap nested here: {ran.stderr[-300:]}")
    answer = json.loads((results / "results.json").read_text())
    jsonschema.validate(answer, RESULTS_SCHEMA)
    assert answer["extra_data"]["isolated"] is False and "bubblewrap cannot build a sandbox here" in answer["output"]
    assert answer["score"] == 35


def test_a_visibility_and_a_bad_output_are_checked_before_anything_is_written(tmp_path):
    result = subprocess.run([sys.executable, "-m", "appsim", "gradescope-autograder", str(tmp_path / "nope" / "a.zip")],
                            capture_output=True, text=True, timeout=120)
    assert result.returncode == 2 and "does not exist" in result.stderr and "Traceback" not in result.stderr
    result = subprocess.run([sys.executable, "-m", "appsim", "gradescope-autograder", str(tmp_path / "a.tar")],
                            capture_output=True, text=True, timeout=120)
    assert result.returncode == 2 and "takes the autograder as a .zip" in result.stderr
    result = subprocess.run([sys.executable, "-m", "appsim", "gradescope-autograder", str(tmp_path / "a.zip"),
                             "--visibility", "sometimes"], capture_output=True, text=True, timeout=120)
    assert result.returncode == 2 and "invalid choice" in result.stderr
    assert not list(tmp_path.iterdir())


def test_an_autograder_made_with_c18s_minus_oi_grades_c_with_it_as_appsim_grade_does(autograder, tmp_path):
    """`appsim gradescope-autograder -Oi`: its run_autograder builds .c submissions with C18's -Oi, as `appsim grade
    -Oi` does: Ex3's `(RxData[3] << 8) | RxData[4]` without a cast loses the A/D's high byte under C18's default (LCD
    line 3 wrong, 4/5) and keeps it under -Oi (5/5). The second autograder shares the first one's installed kit."""
    from test_c_firmware import SHIFT_NO_CAST, _edited

    source = _edited("ex3", SHIFT_NO_CAST, ("char LCD[22];", "char LCD[22];\nunsigned int adc;")).encode()
    root = tmp_path / "autograder"
    made = subprocess.run([sys.executable, "-m", "appsim", "gradescope-autograder", str(tmp_path / "oi.zip"),
                           "--seed", str(SEED), "-Oi"], capture_output=True, text=True, timeout=600)
    assert made.returncode == 0, made.stderr
    with zipfile.ZipFile(tmp_path / "oi.zip") as archive:
        archive.extractall(root / "source")
        assert json.loads(archive.read("appsim-autograder.json"))["c_options"] == ["-Oi"]
    (root / "appsim-venv").symlink_to(autograder / "appsim-venv")
    shutil.copy2(autograder / "run_autograder", root / "run_autograder")
    scores = {}
    for name, zip_root in (("default", autograder), ("-Oi", root)):
        answer = gradescope(zip_root, {"ex3.c": source})
        scores[name] = sum(t["score"] for t in answer["tests"] if t["name"].startswith("EX3:"))
        lcd = next(t for t in answer["tests"] if t["name"].startswith("EX3:") and t["number"] == "3.3")
        assert lcd["status"] == ("passed" if name == "-Oi" else "failed"), lcd
    assert scores == {"default": 4, "-Oi": 5}
