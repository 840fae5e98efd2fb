"""What a first user trips on, tried as they do it: a typo in a file name, a notebook given to `check`, an exit status
read through a pipe, a syntax error, the kit's version; each through the `appsim` command, in a folder of their own."""
from __future__ import annotations

import json
import re
import shutil
import subprocess
import sys
from pathlib import Path

import pytest

KIT = Path(__file__).resolve().parent.parent


def appsim(*args: str, cwd: Path | None = None) -> subprocess.CompletedProcess[str]:
    return subprocess.run([sys.executable, "-m", "appsim", *args], capture_output=True, text=True, cwd=cwd,
                          timeout=120)


def notebook_with(tmp_path: Path, name: str, firmware: str) -> Path:
    """The kit's notebook `name` with `firmware` in its firmware cell, as a student saves it (outputs and all)."""
    notebook = json.loads((KIT / "notebooks" / name).read_text())
    [cell] = [c for c in notebook["cells"] if "firmware" in c["metadata"].get("tags", [])]
    cell["source"] = f"%%writefile {Path(name).stem}.py\n{firmware}".splitlines(keepends=True)
    cell["execution_count"], cell["outputs"] = 3, [{"output_type": "stream", "name": "stdout", "text": ["Writing"]}]
    path = tmp_path / name
    path.write_text(json.dumps(notebook))
    return path


# ---------------------------------------------------------------------------------------- check: what it is given
@pytest.mark.parametrize("command", ["check ex1", "board", "classroom --exercise 1 --join"])
def test_a_typo_in_the_firmware_s_name_is_refused_with_status_2_by_every_command(tmp_path, command):
    shutil.copy(KIT / "exercises" / "ex1.py", tmp_path / "my_ex1.py")
    result = appsim(*command.split(), "my_exl.py", cwd=tmp_path)
    assert result.returncode == 2, result.stdout + result.stderr
    assert result.stdout == "" and "Traceback" not in result.stderr
    assert "there is no firmware file at my_exl.py: did you mean my_ex1.py?" in result.stderr


@pytest.mark.parametrize("command", ["check ex1", "board"])
def test_a_folder_given_as_the_firmware_is_called_a_folder(tmp_path, command):
    (tmp_path / "ex1").mkdir()
    result = appsim(*command.split(), "ex1", cwd=tmp_path)
    assert result.returncode == 2 and result.stdout == ""
    assert "ex1 is a folder, not a firmware file: give the path of a .py or .c file" in result.stderr


def test_check_takes_a_notebook_and_judges_its_firmware_cell_as_grade_does(tmp_path):
    solved = notebook_with(tmp_path, "ex1.ipynb", (KIT / "solutions" / "ex1.py").read_text())
    result = appsim("check", "ex1", str(solved), "--seed", "3", cwd=tmp_path)
    assert result.returncode == 0 and result.stdout.startswith("EX1: 5/5 (seed 3)"), result.stdout + result.stderr
    starter = appsim("check", "ex1", str(KIT / "notebooks" / "ex1.ipynb"), "--seed", "3", cwd=tmp_path)
    assert starter.returncode == 1 and starter.stdout.startswith("EX1: 3/5 (seed 3)"), starter.stdout
    assert "Set RX_Filter0 to MESSAGE_ID1" in starter.stdout and "null" not in starter.stdout


def test_a_notebook_s_crash_is_on_the_line_of_its_firmware_cell(tmp_path):
    source = (KIT / "solutions" / "ex1.py").read_text().replace("    while True:", "    1 / 0\n    while True:", 1)
    crashing = notebook_with(tmp_path, "ex1.ipynb", source)
    line = 1 + source.splitlines().index("    1 / 0") + 1          # the cell's line: %%writefile is its line 1
    result = appsim("check", "ex1", str(crashing), "--seed", "3", cwd=tmp_path)
    assert result.returncode == 1 and "EX1: 0/5" in result.stdout
    assert f"at line {line} of ex1.ipynb (`1 / 0`)" in result.stdout, result.stdout


@pytest.mark.parametrize("notebook, words", [
    ("ex2.ipynb", "ex2.ipynb is EX2's notebook (its metadata says so), not EX1's: check it with `appsim check ex2 "),
    ("00_can_in_15_minutes.ipynb", "00_can_in_15_minutes.ipynb has no code cell tagged `firmware`"),
])
def test_a_notebook_of_another_exercise_or_none_is_refused_with_status_2(tmp_path, notebook, words):
    result = appsim("check", "ex1", str(KIT / "notebooks" / notebook), cwd=tmp_path)
    assert result.returncode == 2 and result.stdout == "" and words in result.stderr, result.stderr


# ---------------------------------------------------------------------------------------- what a script reads
@pytest.mark.parametrize("args, status", [(["check", "ex1", "--seed", "3"], 1),
                                          (["check", "ex1", str(KIT / "solutions" / "ex1.py"), "--seed", "3"], 0)])
def test_check_s_exit_status_survives_a_reader_that_has_gone(tmp_path, args, status):
    """`appsim check ex1 | head -2`: the reader closes the pipe before the verdict is written."""
    process = subprocess.Popen([sys.executable, "-m", "appsim", *args], cwd=KIT, stdout=subprocess.PIPE,
                               stderr=subprocess.PIPE)
    assert process.stdout is not None and process.stderr is not None
    process.stdout.close()
    errors = process.stderr.read().decode()
    assert process.wait(timeout=120) == status, errors
    assert errors == "", "no word about the closed pipe, no traceback"


def test_grade_goes_on_to_the_end_after_its_reader_has_gone(tmp_path):
    room = tmp_path / "class"
    for name in ("ann", "ben"):
        (room / name).mkdir(parents=True)
        shutil.copy(KIT / "solutions" / "ex1.py", room / name / "ex1.py")
    isolation = [] if shutil.which("bwrap") else ["--trusted"]
    process = subprocess.Popen([sys.executable, "-m", "appsim", "grade", str(room), "--seed", "3", *isolation],
                               stdout=subprocess.PIPE, stderr=subprocess.PIPE)
    assert process.stdout is not None and process.stderr is not None
    process.stdout.close()
    errors = process.stderr.read().decode()
    assert process.wait(timeout=300) == 0, errors
    assert len((tmp_path / "class.grades.jsonl").read_text().splitlines()) == 2, "both graded and kept"


def test_a_syntax_error_quotes_its_line_as_a_load_error_does(tmp_path):
    lines = (KIT / "exercises" / "ex1.py").read_text().splitlines(keepends=True)
    number = next(n for n, line in enumerate(lines, 1) if line.startswith("RX_Filter0 = 0x088"))
    lines[number - 1] = "RX_Filter0 = = 0x088\n"
    (tmp_path / "my_ex1.py").write_text("".join(lines))
    for result in (appsim("check", "ex1", "my_ex1.py", cwd=tmp_path), appsim("board", "my_ex1.py", cwd=tmp_path)):
        shown = result.stdout + result.stderr
        assert f"my_ex1.py, line {number}: invalid syntax: fix the Python syntax there" in shown, shown
        quoted = re.search(rf"^( *)\(line {number}: RX_Filter0 = = 0x088\)\n( *)\^$", shown, re.MULTILINE)
        assert quoted, shown
        assert len(quoted.group(2)) - len(quoted.group(1)) == len(f"(line {number}: RX_Filter0 = "), \
            "the caret under the second ="


# ---------------------------------------------------------------------------------------- an instructor's reruns
def a_class(root: Path, names: tuple[str, ...]) -> Path:
    for name in names:
        (root / name).mkdir(parents=True)
        shutil.copy(KIT / "solutions" / "ex1.py", root / name / "ex1.py")
    return root


def grade(*args: str, cwd: Path, seed: int = 3) -> subprocess.CompletedProcess[str]:
    isolation = [] if shutil.which("bwrap") else ["--trusted"]
    result = appsim("grade", *args, "--seed", str(seed), *isolation, cwd=cwd)
    assert result.returncode == 0, result.stdout + result.stderr
    return result


@pytest.mark.parametrize("given", ["gs2/", "made"])
def test_gradescope_given_a_folder_writes_the_one_submission_s_file_into_it(tmp_path, given):
    a_class(tmp_path / "class", ("ann",))
    (tmp_path / "made").mkdir()
    grade("class", "--gradescope", given, cwd=tmp_path)
    folder = tmp_path / given.rstrip("/")
    assert folder.is_dir() and [p.name for p in folder.iterdir()] == ["ann.json"]
    assert json.loads((folder / "ann.json").read_text())["score"] == 5


def test_gradescope_given_a_file_name_with_one_submission_writes_that_file(tmp_path):
    a_class(tmp_path / "class", ("ann",))
    grade("class", "--gradescope", "results.json", cwd=tmp_path)
    assert json.loads((tmp_path / "results.json").read_text())["score"] == 5


def test_a_rerun_says_how_many_it_graded_and_how_many_it_kept(tmp_path):
    a_class(tmp_path / "class", ("ann", "ben", "cat"))
    first = grade("class", cwd=tmp_path)
    assert "graded 3 submission(s): 15/105 points in all" in first.stdout, first.stdout
    (tmp_path / "class" / "ben" / "ex2.py").write_text((KIT / "solutions" / "ex2.py").read_text())
    again = grade("class", cwd=tmp_path)
    assert "graded 1 submission(s), kept 2 already graded: 20/105 points in all 3, mean 6.7/35" in again.stdout, \
        again.stdout


# ---------------------------------------------------------------------------------------- the bit-timing calculator
def test_bittiming_lists_the_workshop_s_setting_first_under_a_title_in_caninitialize_s_order():
    result = appsim("bittiming", "125000", "--fosc", "40000000")
    assert result.returncode == 0, result.stderr
    title, legend, header, first, *rows = result.stdout.splitlines()
    assert title.startswith("125,000 bit/s at Fosc = 40 MHz: 80 valid settings give it exactly; 10 listed (--top), "
                            "the classroom's first"), title
    assert header.split()[:5] == ["SJW", "BRP", "PHSEG1", "PHSEG2", "PROPSEG"] and "CANInitialize(SJW, BRP" in legend
    assert first.split()[:5] == ["4", "10", "8", "4", "3"]
    assert first.endswith("the classroom's: every exercise's CANInitialize")
    assert len(rows) == 9 and not any("classroom" in row for row in rows)


def test_bittiming_gives_the_nearest_rate_s_settings_where_none_is_exact_with_status_1():
    result = appsim("bittiming", "33000", "--top", "3")
    assert result.returncode == 1, result.stderr
    title, _, header, *rows = result.stdout.splitlines()
    assert title.startswith("no valid setting gives exactly 33,000 bit/s at Fosc = 40 MHz (8..25 TQ a bit, BRP 1..64); "
                            "the nearest rate is 33,057.85 bit/s (+0.18 %): 22 settings give it"), title
    assert len(rows) == 3 and all(row.split()[1] == "55" and row.split()[7] == "+0.18" for row in rows), rows
    far = appsim("bittiming", "1")
    assert far.returncode == 1 and "further off than any CAN node tolerates (1.58 % at best)" in far.stdout


# ---------------------------------------------------------------------------------------- which kit this is
def test_version_names_the_kit_as_its_records_do_and_the_checkout_s_commit(tmp_path):
    from test_wheel import git_commit

    a_class(tmp_path / "class", ("ann",))
    grade("class", cwd=tmp_path)
    [record] = [json.loads(line) for line in (tmp_path / "class.grades.jsonl").read_text().splitlines()]
    result = appsim("--version", cwd=tmp_path)
    assert result.returncode == 0 and result.stderr == "", result.stderr
    version, commit = result.stdout.splitlines()
    assert version == f"appsim {record['kit']}", "the version and code digest every record carries"
    assert record["commit"] == git_commit(KIT) and commit.startswith(f"git commit {record['commit']}")
    if record["commit"].endswith("-dirty"):
        assert "its code differs from that commit" in commit


def test_the_docs_gradescope_example_and_record_are_what_grade_writes(tmp_path):
    """docs/grading.md's results.json, "..." standing for what it leaves out, and its record's fields."""
    docs = (KIT / "docs" / "grading.md").read_text()
    room = tmp_path / "class" / "alice"                 # the example's: the Ex1 solution and the Ex2 starter
    room.mkdir(parents=True)
    shutil.copy(KIT / "solutions" / "ex1.py", room)
    shutil.copy(KIT / "exercises" / "ex2.py", room)
    grade("class", "--gradescope", "results.json", cwd=tmp_path, seed=2024)
    [record] = [json.loads(line) for line in (tmp_path / "class.grades.jsonl").read_text().splitlines()]
    example = re.search(r"`--gradescope`: Gradescope's autograder .*?```json\n(.*?)```", docs, re.DOTALL).group(1)
    shown = re.search(r'"kit": "([^"]+)",\s+"commit": "([^"]+)"', docs)
    written = (tmp_path / "results.json").read_text()
    written = written.replace(record["kit"], shown.group(1)).replace(str(record["commit"]), shown.group(2))
    pattern = ".*?".join(re.escape(part) for part in example.split("..."))
    assert re.fullmatch(pattern, written, re.DOTALL), f"docs:\n{example}\nwritten:\n{written}"
    fields = re.search(r"`--json`, one line per submission:\n\n```json\n(.*?)```", docs, re.DOTALL).group(1)
    assert set(re.findall(r'"(\w+)": ', fields)) >= set(record) | set(record["exercises"]["ex1"]), fields
