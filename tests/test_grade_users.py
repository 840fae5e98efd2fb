"""`appsim grade` where instructors really run it: from the folder that holds the clone, in a venv whose base Python
lives in a private (0700) home, and as an ordinary user (with the kit installed from a wheel, in a venv in that user's
private home) — the grading and attack tests pass there as they do here."""
from __future__ import annotations

import json
import os
import shutil
import stat
import subprocess
import sys
import tempfile
from pathlib import Path

import pytest
from venvs import make_venv

from appsim.workshop.course import C_FILES, EXERCISE_FILES, SOLUTIONS

KIT = Path(__file__).resolve().parent.parent
USER = os.environ.get("APPSIM_TEST_USER")                   # set by .ci/run, which creates the user and its venv
USER_PYTHON = os.environ.get("APPSIM_TEST_USER_PYTHON")
STDLIB_IMPORTS = "import statistics, datetime, queue\n"


def private(path: Path) -> bool:
    """Whether some folder above `path` is closed to other users (a 0700 home)."""
    return any(not (parent.stat().st_mode & stat.S_IXOTH) for parent in path.resolve().parents)


def a_class(root: Path) -> Path:
    room = root / "class"
    for name, transform in (("alice", lambda s: s), ("pat", lambda s: STDLIB_IMPORTS + s)):
        (room / name).mkdir(parents=True)
        for file in EXERCISE_FILES.values():
            (room / name / file).write_text(transform((SOLUTIONS / file).read_text()))
    (room / "cara").mkdir()                 # in C: the translator (pcpp, pycparser) must reach the sandbox too
    for file in C_FILES.values():
        (room / "cara" / file).write_text((SOLUTIONS / file).read_text())
    return room


def python_in_a_private_home(home: Path) -> Path:
    """The running Python's base installation, or where that is open to all (Debian's /usr) a copy of it (its binary
    and standard library) in `home`, closed to other users as pyenv's is: its python."""
    version = f"python{sys.version_info.major}.{sys.version_info.minor}"
    if private(Path(sys.base_prefix)):
        return Path(sys._base_executable)
    home.mkdir(mode=0o700)
    (home / "bin").mkdir()
    shutil.copy2(sys._base_executable, home / "bin" / version)
    shutil.copytree(Path(sys.base_prefix) / sys.platlibdir / version, home / "lib" / version, symlinks=False,
                    ignore=shutil.ignore_patterns("__pycache__", "site-packages", "dist-packages", "test", "idlelib"))
    python = home / "bin" / version
    prefix = subprocess.run([str(python), "-c", "import sys; print(sys.prefix)"], capture_output=True, text=True)
    if prefix.stdout.strip() != str(home):
        pytest.skip(f"a copy of this Python ({sys.base_prefix}) does not run from another folder: {prefix.stderr}")
    return python


def test_from_the_folder_holding_the_clone_in_a_venv_over_a_private_python(tmp_path):
    python = python_in_a_private_home(tmp_path / "home")
    assert private(python)
    venv = make_venv(tmp_path / "venv", pip=False, python=python).parent
    holder = tmp_path / "work"
    clone = holder / "appsim"                               # `git clone ... appsim`: a folder named like the package
    clone.mkdir(parents=True)
    (clone / "README.md").write_text("a clone")
    for module in ("cli.py", "workshop.py"):                # were the clone folder taken for the kit, these would run
        (clone / module).write_text("raise ImportError('the clone folder was imported as the kit')")
    room = a_class(tmp_path)
    console = venv / "bin" / "appsim"                       # as pip writes the console script
    console.write_text(f"#!{venv / 'bin' / 'python'}\nimport sys\nfrom appsim.cli import main\nsys.exit(main())\n")
    console.chmod(0o755)
    result = subprocess.run([str(console), "grade", str(room), "--seed", "5"], cwd=holder, capture_output=True,
                            text=True, timeout=300)
    assert result.returncode == 0, result.stdout + result.stderr
    assert "alice                     35/35" in result.stdout and "pat                       35/35" in result.stdout
    assert "cara                      35/35" in result.stdout, result.stdout


@pytest.mark.skipif(not (USER and USER_PYTHON and os.geteuid() == 0),
                    reason="needs root and APPSIM_TEST_USER / APPSIM_TEST_USER_PYTHON (.ci/run sets them up)")
def test_the_grading_and_attack_tests_pass_as_an_ordinary_user():
    import pwd

    account = pwd.getpwnam(USER)
    assert private(Path(USER_PYTHON).parent), "the user's venv is meant to be in its private home"
    copy = Path(tempfile.mkdtemp(prefix="appsim-as-user-"))
    try:
        for part in ("tests", "exercises", "solutions", "notebooks"):
            shutil.copytree(KIT / part, copy / part, ignore=shutil.ignore_patterns("__pycache__", "*.pyc"))
        for path in (copy, *copy.rglob("*")):
            os.chown(path, account.pw_uid, account.pw_gid)
        env = {"PATH": f"{Path(USER_PYTHON).parent}:/usr/bin:/bin", "HOME": account.pw_dir, "LANG": "C.UTF-8"}
        runuser = shutil.which("runuser") or "/usr/sbin/runuser"     # found on root's PATH, not the user's
        result = subprocess.run(
            [runuser, "-u", USER, "--", USER_PYTHON, "-m", "pytest", "-q", "-p", "no:cacheprovider", "-x",
             "tests/test_grade.py", "tests/test_grade_attacks.py", "tests/test_grade_mounts.py",
             "tests/test_grade_classes.py", "tests/test_grade_attacks_c.py", "tests/test_c_interrupts.py",
             "tests/test_c_firmware.py::test_a_class_in_c_is_graded_in_the_sandbox_either_language_per_exercise"],
            cwd=copy, env=env, capture_output=True, text=True, timeout=900)
        assert result.returncode == 0, result.stdout[-6000:] + result.stderr[-3000:]
        assert " passed" in result.stdout and "skipped" not in result.stdout.splitlines()[-1]
    finally:
        shutil.rmtree(copy, ignore_errors=True)


def test_a_second_checkout_grades_with_its_own_code_from_its_own_folder(tmp_path):
    """`python -m appsim grade` in a checkout while another copy of the kit is installed (an instructor's second
    clone, a CI clone in /tmp): the workers and their sandboxes run the checkout's code, as the command does."""
    from test_wheel import _tracked_copy

    checkout = _tracked_copy(tmp_path / "second-clone")
    marker = "# the second checkout's own code\n"
    grade_py = checkout / "appsim" / "workshop" / "grading" / "worker.py"
    grade_py.write_text(marker + grade_py.read_text())
    room = a_class(tmp_path)
    result = subprocess.run([sys.executable, "-m", "appsim", "grade", str(room), "--seed", "5"], cwd=checkout,
                            capture_output=True, text=True, timeout=300)
    assert result.returncode == 0, result.stdout + result.stderr
    assert "alice                     35/35" in result.stdout, result.stdout + result.stderr
    kits = {json.loads(line)["kit"] for line in (tmp_path / "class.grades.jsonl").read_text().splitlines()}
    ours = subprocess.run([sys.executable, "-c", "from appsim.workshop.grading.results import kit_version; "
                           "print(kit_version())"], cwd=checkout, capture_output=True, text=True, check=True)
    assert kits == {ours.stdout.strip()}, "the records carry the checkout's own kit version"
