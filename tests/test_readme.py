"""The README as a newcomer on Debian follows it: its top block, and "Your first hour" from a clone to the first
passing check (in Python, then in C) and a classroom that the reader's board joins without a collision, each run as
written in a fresh venv.

Marked `readme` (about two minutes, most of it making the venvs and installing the kit): `python -m pytest -m "not
readme"` leaves it out. What it covers: every command of those code blocks, in order, in bash, with Debian's own PATH
(no venv active: `python3` and `pip` are the system's), each line's exit status and output checked; of the top block,
all but its last line, the test command, which is the one running this (CI runs that block whole, .ci/run). Two
stand-ins: the `git clone` the prose asks for is a copy of this worktree as a clone would have it (its tracked and new
files, nothing that git ignores), and the venv's `python3 -m venv .venv` is `tests/venvs.py .venv` run by this Python,
a venv that also sees this Python's packages (in a venv or not), so pip downloads none of the kit's dependencies (pip
builds the kit as the README says, with the setuptools and wheel its own configuration finds). Not covered:
downloading the dependencies, Windows' activate.
"""
from __future__ import annotations

import os
import re
import shutil
import subprocess
import sys
from pathlib import Path

import pytest

KIT = Path(__file__).resolve().parent.parent
SECTION = "## Your first hour"
VENV = "python3 -m venv .venv && . .venv/bin/activate"
TEST_COMMAND = "pip install -e '.[test]' && python -m pytest"
STATUS = re.compile(r"^@@ (\d+) (\d+)$", re.MULTILINE)
DEBIAN_PATH = ("/usr/local/sbin:/usr/local/bin:/usr/sbin:/usr/bin:/sbin:/bin" if os.geteuid() == 0
               else "/usr/local/bin:/usr/bin:/bin:/usr/local/games:/usr/games")       # a fresh login's, root or not

pytestmark = pytest.mark.readme


def shell_lines(block: str) -> list[str]:
    return [line for line in block.splitlines() if line.strip()]


def top_block(readme: str) -> list[str]:
    """The shell lines of the README's first code block, the one above everything else."""
    return shell_lines(re.search(r"```bash\n(.*?)```", readme, re.DOTALL).group(1))


def newcomer_commands(readme: str) -> list[str]:
    """The shell lines of the README's newcomer section, in order."""
    section = readme[readme.index(SECTION):]
    section = section[:section.index("\n## ", 1)]
    assert "`git clone ADDRESS appsim`" in section, "the prose says how to clone"
    blocks = re.findall(r"```bash\n(.*?)```", section, re.DOTALL)
    return [line for block in blocks for line in shell_lines(block)]


def run_as_written(commands: list[str], cwd: Path) -> tuple[dict[str, int], subprocess.CompletedProcess[str]]:
    """Each line in one bash, as a newcomer on Debian types it (the venv's stand-in apart): its exit status, by line,
    and the whole run."""
    script = []
    for number, line in enumerate(commands):
        if line.startswith(VENV):
            line = line.replace("python3 -m venv", f"{sys.executable} {KIT / 'tests' / 'venvs.py'}", 1)
        script += [line, f'echo "@@ {number} $?"']
    environment = {name: value for name, value in os.environ.items() if name not in ("VIRTUAL_ENV", "PYTHONPATH")}
    environment["PATH"] = DEBIAN_PATH
    result = subprocess.run(["bash", "-c", "\n".join(script)], cwd=cwd, env=environment, capture_output=True,
                            text=True, timeout=900)
    statuses = {commands[int(number)]: int(status) for number, status in STATUS.findall(result.stdout)}
    assert len(statuses) == len(commands), f"every line ran:\n{result.stdout}\n{result.stderr}"
    return statuses, result


def clone_of_the_worktree(into: Path) -> Path:
    """The worktree's files as `git clone` would give them (tracked ones and new ones, nothing git ignores)."""
    listed = subprocess.run(["git", "-C", str(KIT), "ls-files", "-z", "--cached", "--others", "--exclude-standard"],
                            capture_output=True, check=True).stdout.decode().split("\0")
    for name in filter(None, listed):
        if (KIT / name).is_file():
            (into / name).parent.mkdir(parents=True, exist_ok=True)
            shutil.copy2(KIT / name, into / name)
    return into


def test_the_readme_s_top_block_works_as_written_on_a_fresh_debian(tmp_path):
    commands = top_block((KIT / "README.md").read_text())
    assert commands[0].startswith(VENV), "the block first makes the venv that Debian's pip insists on"
    assert commands[-1].startswith(TEST_COMMAND), "the block ends with the test command (CI runs it, .ci/run)"
    clone = clone_of_the_worktree(tmp_path / "appsim")
    statuses, result = run_as_written(commands[:-1], clone)
    assert not any(statuses.values()), f"{statuses}\n{result.stdout[-3000:]}\n{result.stderr[-3000:]}"
    assert "MASTER CONSOLE" in result.stdout and (clone / "appsim-demo" / "trace.log").stat().st_size > 0


def test_the_readme_takes_a_newcomer_from_a_clone_to_a_passing_check(tmp_path):
    commands = newcomer_commands((KIT / "README.md").read_text())
    assert commands[:2] == ["cd appsim", next(c for c in commands if c.startswith(VENV))], \
        "the block starts in the clone and makes the venv"
    clone_of_the_worktree(tmp_path / "appsim")
    statuses, result = run_as_written(commands, tmp_path)
    out = result.stdout
    starter = next(c for c in commands if c.startswith("appsim check ex1 ") and "my_ex1.py" not in c)
    assert {command: status for command, status in statuses.items() if status} == {starter: 1}, result.stderr
    assert f"{tmp_path}/appsim/exercises/ex1.py ran" in out, "the venv's appsim, installed from the clone"
    assert "MASTER CONSOLE" in out and "EX1: 3/5" in out and "EX1: 5/5" in out
    assert "my_ex1.c ran" in out and out.count("EX1: 5/5") == 2, "the same fix in C passes too"
    assert "station2 runs my_ex3.py" in out and "warning" not in result.stderr
    classroom = out[out.index("station2 runs my_ex3.py"):]
    assert re.search(r"\d+ frames, 0 error frames in 2.000 s", classroom), "station 2's ID: no collision"
