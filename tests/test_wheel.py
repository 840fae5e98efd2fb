"""The kit as a package: a wheel built from the repository, installed in a venv outside it, runs the workshop from
any folder, with the starters and solutions it carries inside (no repository on the path)."""
from __future__ import annotations

import os
import shutil
import subprocess
import sys
from pathlib import Path

import pytest

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


@pytest.fixture(scope="module")
def installed(tmp_path_factory) -> Path:
    """The bin folder of a venv that has the kit from a wheel (its dependencies from this Python's)."""
    base = tmp_path_factory.mktemp("wheel")
    if WHEEL:
        wheel = Path(WHEEL)
    else:
        if shutil.which("git") is None or not (KIT / ".git").exists():
            pytest.skip("builds the wheel from a git checkout (or set APPSIM_TEST_WHEEL)")
        source = _tracked_copy(base / "source")
        subprocess.run([sys.executable, "-m", "pip", "wheel", "--no-deps", "-q", "-w", str(base / "dist"),
                        str(source)], check=True, timeout=600)
        [wheel] = (base / "dist").glob("appsim-*.whl")
    venv = base / "venv"
    subprocess.run([sys.executable, "-m", "venv", "--system-site-packages", str(venv)], check=True)
    subprocess.run([str(venv / "bin" / "python"), "-m", "pip", "install", "-q", "--no-deps", "--force-reinstall",
                    str(wheel)], check=True, timeout=300)
    return venv / "bin"


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
    assert (elsewhere / "class.grades.jsonl").exists()


def test_the_wheel_holds_the_c_headers_starters_and_solutions_and_checks_c(installed, elsewhere):
    listed = subprocess.run([str(installed / "python"), "-c",
                             "from importlib import resources; from appsim.workshop.course import solution, starter; "
                             "headers = resources.files('appsim.firmware.c18') / 'include'; "
                             "print(sorted(p.name for p in headers.iterdir() if p.name.endswith('.h'))); "
                             "print(solution('ex1', 'c').read_text(), end='')"],
                            cwd=elsewhere, capture_output=True, text=True, check=True).stdout
    names, _, source = listed.partition("\n")
    assert names == str(sorted(["p18f8680.h", "CAN18XX8.h", "adc.h", "timers.h", "usart.h", "delays.h", "stdio.h",
                                "string.h", "stdlib.h", "APP023_GLCD.h"]))
    (elsewhere / "ex1.c").write_text(source)
    result = appsim(installed, elsewhere, "check", "ex1", "ex1.c")
    assert result.returncode == 0 and result.stdout.startswith("EX1: 5/5"), result.stdout + result.stderr
