"""The README's newcomer path ("Your first hour"), run as written in a fresh virtual environment, to the first
passing check (in Python, then in C) and a classroom that the reader's board joins without a collision.

Marked `readme` (about a minute, most of it making the venv and installing the kit): `python -m pytest -m "not
readme"` leaves it out. What it covers: every command of that section's code blocks, in order, in bash, each line's
exit status and output checked. Two stand-ins: the `git clone` the prose asks for is a copy of this worktree as a
clone would have it (its tracked and new files, nothing that git ignores), and the venv comes with
--system-site-packages from this machine's Python, so the kit's dependencies are there already and pip downloads none
of them (pip builds the kit as the README says, with the setuptools and wheel its own configuration finds). Not
covered: downloading the dependencies, Windows' activate.
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
STATUS = re.compile(r"^@@ (\d+) (\d+)$", re.MULTILINE)

pytestmark = pytest.mark.readme


def newcomer_commands(readme: str) -> list[str]:
    """The shell lines of the README's newcomer section, in order."""
    section = readme[readme.index(SECTION):]
    section = section[:section.index("\n## ", 1)]
    assert "`git clone ADDRESS appsim`" in section, "the prose says how to clone"
    blocks = re.findall(r"```bash\n(.*?)```", section, re.DOTALL)
    return [line for block in blocks for line in block.splitlines() if line.strip()]


def clone_of_the_worktree(into: Path) -> Path:
    """The worktree's files as `git clone` would give them (tracked ones and new ones, nothing git ignores)."""
    listed = subprocess.run(["git", "-C", str(KIT), "ls-files", "-z", "--cached", "--others", "--exclude-standard"],
                            capture_output=True, check=True).stdout.decode().split("\0")
    for name in filter(None, listed):
        if (KIT / name).is_file():
            (into / name).parent.mkdir(parents=True, exist_ok=True)
            shutil.copy2(KIT / name, into / name)
    return into


def test_the_readme_takes_a_newcomer_from_a_clone_to_a_passing_check(tmp_path):
    commands = newcomer_commands((KIT / "README.md").read_text())
    assert commands[:2] == ["cd appsim", next(c for c in commands if c.startswith(VENV))], \
        "the block starts in the clone and makes the venv"
    clone_of_the_worktree(tmp_path / "appsim")
    script = []
    for number, line in enumerate(commands):
        if line.startswith(VENV):
            line = line.replace("python3 -m venv", f"{sys.executable} -m venv --system-site-packages", 1)
        script += [line, f'echo "@@ {number} $?"']
    environment = {name: value for name, value in os.environ.items() if name not in ("VIRTUAL_ENV", "PYTHONPATH")}
    result = subprocess.run(["bash", "-c", "\n".join(script)], cwd=tmp_path, env=environment, capture_output=True,
                            text=True, timeout=900)
    out = result.stdout
    statuses = {commands[int(number)]: int(status) for number, status in STATUS.findall(out)}
    assert len(statuses) == len(commands), f"every line ran:\n{out}\n{result.stderr}"
    starter = next(c for c in commands if c.startswith("appsim check ex1 ") and "my_ex1.py" not in c)
    assert {command: status for command, status in statuses.items() if status} == {starter: 1}, result.stderr
    assert f"{tmp_path}/appsim/exercises/ex1.py ran" in out, "the venv's appsim, installed from the clone"
    assert "MASTER CONSOLE" in out and "EX1: 3/5" in out and "EX1: 5/5" in out
    assert "my_ex1.c ran" in out and out.count("EX1: 5/5") == 2, "the same fix in C passes too"
    assert "station2 runs my_ex3.py" in out and "warning" not in result.stderr
    classroom = out[out.index("station2 runs my_ex3.py"):]
    assert re.search(r"\d+ frames, 0 error frames in 2.000 s", classroom), "station 2's ID: no collision"
