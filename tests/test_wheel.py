"""The kit as a package: a wheel built from the repository, installed in a venv outside it, runs the workshop from
any folder, with the starters and solutions it carries inside (no repository on the path)."""
from __future__ import annotations

import json
import os
import re
import shutil
import subprocess
import sys
from pathlib import Path

import pytest
from venvs import make_venv

KIT = Path(__file__).resolve().parent.parent
WHEEL = os.environ.get("APPSIM_TEST_WHEEL")             # .ci/run builds one; without it, the test builds its own


def _tracked_copy(to: Path) -> Path:
    """The repository's tracked files, as a fresh clone has them (no build/ or egg-info of an earlier build)."""
    listed = subprocess.run(["git", "ls-files", "-z"], cwd=KIT, capture_output=True, check=True).stdout
    for name in filter(None, listed.decode().split("\0")):
        target = to / name
        target.parent.mkdir(parents=True, exist_ok=True)
        if (KIT / name).is_file():
            shutil.copy2(KIT / name, target)
    return to


def _clone_as_it_is(to: Path) -> Path:
    """A git clone of the repository with the worktree's files as they are now (changed, new, deleted): what a build
    in this worktree sees, its commit and whether its code differs from it included."""
    subprocess.run(["git", "clone", "-q", "--no-hardlinks", str(KIT), str(to)], check=True, timeout=300)
    listed = subprocess.run(["git", "ls-files", "-z", "--cached", "--others", "--exclude-standard"], cwd=KIT,
                            capture_output=True, check=True).stdout
    for name in filter(None, listed.decode().split("\0")):
        if (KIT / name).is_file():
            (to / name).parent.mkdir(parents=True, exist_ok=True)
            shutil.copy2(KIT / name, to / name)
        else:
            (to / name).unlink(missing_ok=True)
    return to


def git_commit(checkout: Path) -> str:
    """HEAD, with -dirty if the kit's code (appsim/, solutions/) differs from it: what the kit is to call itself."""
    def git(*args: str) -> str:
        return subprocess.run(["git", *args], cwd=checkout, capture_output=True, text=True, check=True).stdout.strip()
    return git("rev-parse", "HEAD") + ("-dirty" if git("status", "--porcelain", "--", "appsim", "solutions") else "")


@pytest.fixture(scope="module")
def installed(tmp_path_factory) -> Path:
    """The bin folder of a venv that has the kit from a wheel (its dependencies: this Python's, in a venv or not)."""
    base = tmp_path_factory.mktemp("wheel")
    if WHEEL:
        wheel = Path(WHEEL)
    else:
        if shutil.which("git") is None or not (KIT / ".git").exists():
            pytest.skip("builds the wheel from a git checkout (or set APPSIM_TEST_WHEEL)")
        source = _clone_as_it_is(base / "source")
        subprocess.run([sys.executable, "-m", "pip", "wheel", "--no-deps", "-q", "-w", str(base / "dist"),
                        str(source)], check=True, timeout=600)
        [wheel] = (base / "dist").glob("appsim-*.whl")
    bin = make_venv(base / "venv")
    subprocess.run([str(bin / "python"), "-m", "pip", "install", "-q", "--no-deps", "--force-reinstall", str(wheel)],
                   check=True, timeout=300)
    return bin


@pytest.fixture
def elsewhere(tmp_path) -> Path:
    """A folder outside the repository, where a user runs the kit."""
    return tmp_path


def appsim(bin: Path, cwd: Path, *args: str) -> subprocess.CompletedProcess[str]:
    return subprocess.run([str(bin / "appsim"), *args], cwd=cwd, capture_output=True, text=True, timeout=600,
                          env={**os.environ, "PYTHONPATH": ""})


def test_the_kit_imported_is_the_wheels(installed, elsewhere):
    found = subprocess.run([str(installed / "python"), "-c", "import appsim; print(appsim.__file__)"], cwd=elsewhere,
                           capture_output=True, text=True, check=True).stdout.strip()
    assert Path(found).is_relative_to(installed.parent), f"appsim came from {found}, not from the wheel"


def test_the_installed_kit_names_the_commit_its_wheel_was_built_from(installed, elsewhere):
    result = subprocess.run([str(installed / "appsim"), "--version"], cwd=elsewhere, capture_output=True, text=True,
                            env={**os.environ, "PYTHONPATH": ""})
    assert result.returncode == 0, result.stderr
    version, commit = result.stdout.splitlines()
    assert re.fullmatch(r"appsim \d+\.\d+\.\d+\+[0-9a-f]{12}", version), version
    assert commit.startswith(f"git commit {git_commit(KIT)}"), f"{commit}: built from {git_commit(KIT)}"


def test_demo_runs_from_a_folder_outside_the_repository(installed, elsewhere):
    result = appsim(installed, elsewhere, "demo", "--seconds", "0.5")
    assert result.returncode == 0, result.stderr
    assert "station6" in result.stdout and (elsewhere / "appsim-demo" / "trace.log").stat().st_size > 0


def test_check_uses_the_solutions_inside_the_wheel(installed, elsewhere):
    solution = subprocess.run([str(installed / "python"), "-c",
                               "from appsim.workshop.course import solution; "
                               "print(solution('ex1').read_text(), end='')"],
                              cwd=elsewhere, capture_output=True, text=True, check=True).stdout
    (elsewhere / "ex1.py").write_text(solution)
    result = appsim(installed, elsewhere, "check", "ex1", "ex1.py")
    assert result.returncode == 0 and result.stdout.startswith("EX1: 5/5"), result.stdout + result.stderr


def test_a_classroom_runs_the_solutions_inside_the_wheel(installed, elsewhere):
    result = appsim(installed, elsewhere, "classroom", "--exercise", "3", "--seconds", "0.3")
    assert result.returncode == 0, result.stderr
    assert all(f"station{k}       1{k - 1}0" in result.stdout for k in range(1, 7)), result.stdout


def test_grade_grades_a_class_with_the_wheel(installed, elsewhere):
    room = elsewhere / "class" / "alice"
    room.mkdir(parents=True)
    for exercise in ("ex1", "ex2"):
        subprocess.run([str(installed / "python"), "-c", "import shutil, sys\nfrom appsim.workshop.course import "
                        f"solution\nshutil.copy(solution('{exercise}'), '{room / (exercise + '.py')}')"],
                       cwd=elsewhere, check=True)
    isolation = [] if shutil.which("bwrap") else ["--trusted"]
    result = appsim(installed, elsewhere, "grade", "class", "--seed", "3", *isolation)
    assert result.returncode == 0, result.stdout + result.stderr
    assert "alice" in result.stdout and "Traceback" not in result.stderr
    [record] = [json.loads(line) for line in (elsewhere / "class.grades.jsonl").read_text().splitlines()]
    version = appsim(installed, elsewhere, "--version").stdout.splitlines()
    assert version[0] == f"appsim {record['kit']}" and version[1].startswith(f"git commit {record['commit']}"), \
        "the record names the kit as --version does: a gradebook matched to its commit"


def test_the_wheel_holds_the_c_headers_starters_and_solutions_and_checks_c(installed, elsewhere):
    listed = subprocess.run([str(installed / "python"), "-c",
                             "from importlib import resources; from appsim.workshop.course import solution, starter; "
                             "headers = resources.files('appsim.firmware.c18') / 'include'; "
                             "print(sorted(p.name for p in headers.iterdir() if p.name.endswith('.h'))); "
                             "twins = resources.files('appsim.workshop.solutions.interrupts'); "
                             "assert {'ex1.c', 'ex3.c', 'ex6.c'} <= {p.name for p in twins.iterdir()}; "
                             "print(solution('ex1', 'c').read_text(), end='')"],
                            cwd=elsewhere, capture_output=True, text=True, check=True).stdout
    names, _, source = listed.partition("\n")
    assert names == str(sorted(["p18f8680.h", "CAN18XX8.h", "adc.h", "timers.h", "usart.h", "delays.h", "stdio.h",
                                "string.h", "stdlib.h", "APP023_GLCD.h"]))
    (elsewhere / "ex1.c").write_text(source)
    result = appsim(installed, elsewhere, "check", "ex1", "ex1.c")
    assert result.returncode == 0 and result.stdout.startswith("EX1: 5/5"), result.stdout + result.stderr


def test_the_workshop_dbc_and_the_python_can_interface_ship_in_the_wheel(installed, elsewhere):
    where = appsim(installed, elsewhere, "dbc")
    assert where.returncode == 0, where.stderr
    dbc = Path(where.stdout.strip())
    assert dbc.is_file() and "site-packages" in dbc.parts, dbc
    result = appsim(installed, elsewhere, "classroom", "--exercise", "2", "--dbc", "--seconds", "0.2")
    assert "MASTER_BROADCAST: TxData0=1 TxData1=2 TxData2=3 ADRES=" in result.stdout, result.stdout + result.stderr
    found = subprocess.run([str(installed / "python"), "-c", "import can; print(can.interface."
                            "_get_class_for_interface('appsim').__module__)"], cwd=elsewhere, capture_output=True,
                           text=True, env={**os.environ, "PYTHONPATH": ""})
    assert found.stdout.strip() == "appsim.can.pythoncan", found.stderr
