"""The kit's notebooks stay as they ship while students work: they are clean (tools/clean-notebooks), a student runs
and saves a copy of their own (`appsim notebooks`), and `git pull` updates the kit without meeting that work."""
from __future__ import annotations

import json
import os
import re
import shlex
import subprocess
import sys
from pathlib import Path

import nbformat
import pytest
from nbclient import NotebookClient
from test_wheel import _clone_as_it_is

KIT = Path(__file__).resolve().parent.parent
CLEAN = KIT / "tools" / "clean-notebooks"
GIT_USER = {"GIT_AUTHOR_NAME": "kit", "GIT_AUTHOR_EMAIL": "kit@example.org", "GIT_COMMITTER_NAME": "kit",
            "GIT_COMMITTER_EMAIL": "kit@example.org"}


def git(checkout: Path, *args: str) -> str:
    return subprocess.run(["git", *args], cwd=checkout, capture_output=True, text=True, check=True, timeout=120,
                          env={**os.environ, **GIT_USER}).stdout


def run_and_save(path: Path) -> nbformat.NotebookNode:
    """The notebook run top to bottom in a real kernel in its own folder, and saved there, as a student does."""
    notebook = nbformat.read(path, as_version=4)
    NotebookClient(notebook, timeout=120, kernel_name="python3", resources={"metadata": {"path": str(path.parent)}},
                   allow_errors=True).execute()
    nbformat.write(notebook, path)
    return notebook


def test_the_kit_s_notebooks_are_clean():
    result = subprocess.run([sys.executable, str(CLEAN), "--check"], capture_output=True, text=True)
    assert result.returncode == 0, result.stdout + result.stderr + "\n(run tools/clean-notebooks)"


def test_a_notebook_run_and_saved_cleans_back_to_the_kit_s(tmp_path):
    kit = (KIT / "notebooks" / "ex1.ipynb").read_text()
    (tmp_path / "ex1.ipynb").write_text(kit)
    notebook = run_and_save(tmp_path / "ex1.ipynb")
    assert any(cell.get("outputs") for cell in notebook.cells) and (tmp_path / "ex1.py").is_file()
    assert (tmp_path / "ex1.ipynb").read_text() != kit
    cleaned = subprocess.run([sys.executable, str(CLEAN), str(tmp_path / "ex1.ipynb")], capture_output=True, text=True)
    assert cleaned.returncode == 0 and "cleaned" in cleaned.stdout, cleaned.stderr
    assert (tmp_path / "ex1.ipynb").read_text() == kit, "cleaning is the one mechanical step back to the shipped file"


def workshop_commands(readme: str) -> list[str]:
    """The README's commands for taking the workshop, one a part of its `&&` line."""
    section = readme[readme.index("## The workshop"):]
    block = re.search(r"```bash\n(.*?)```", section, re.DOTALL).group(1)
    return [part.strip() for line in block.splitlines() if line.strip() for part in line.split("&&")]


def test_the_readme_s_workshop_keeps_the_clone_clean_and_git_pull_meets_no_work(tmp_path):
    """The README's way, literally: its commands (pip apart), the notebook JupyterLab opens run and saved, then the
    kit updated upstream (a notebook and a starter changed) and pulled."""
    upstream = _clone_as_it_is(tmp_path / "upstream")
    git(upstream, "add", "-A")
    git(upstream, "commit", "-q", "--allow-empty", "-m", "the kit as it is")
    student = tmp_path / "appsim"
    git(tmp_path, "clone", "-q", str(upstream), str(student))
    opened = None
    for command in workshop_commands((student / "README.md").read_text()):
        words = shlex.split(command)
        if words[:2] == ["pip", "install"]:
            continue                                # this Python has the kit's notebooks extra already
        if words[0] == "appsim":
            done = subprocess.run([sys.executable, "-m", "appsim", *words[1:]], cwd=student, capture_output=True,
                                  text=True, timeout=120)
            assert done.returncode == 0, done.stdout + done.stderr
        elif words[:2] == ["jupyter", "lab"]:
            [opened] = [student / word for word in words[2:] if not word.startswith("-")]
    assert opened is not None and (opened / "ex1.ipynb").is_file(), "JupyterLab opens a folder with the notebooks"
    mine = run_and_save(opened / "ex1.ipynb")
    assert (opened / "ex1.py").is_file() and any(cell.get("outputs") for cell in mine.cells)
    assert git(student, "status", "--porcelain") == "", "running and saving a notebook leaves the clone clean"

    notebook = json.loads((upstream / "notebooks" / "ex1.ipynb").read_text())
    notebook["cells"].insert(1, {"cell_type": "markdown", "id": "a1b2c3d4", "metadata": {}, "source": ["New words."]})
    (upstream / "notebooks" / "ex1.ipynb").write_text(json.dumps(notebook, indent=1) + "\n")
    (upstream / "exercises" / "ex1.py").write_text((upstream / "exercises" / "ex1.py").read_text() + "# updated\n")
    git(upstream, "commit", "-q", "-am", "the kit updated")
    git(student, "pull", "-q", "--ff-only")
    assert git(student, "status", "--porcelain") == ""
    assert nbformat.read(opened / "ex1.ipynb", as_version=4) == mine, "the student's work is as they saved it"
    again = subprocess.run([sys.executable, "-m", "appsim", "notebooks"], cwd=student, capture_output=True, text=True,
                           timeout=120)
    assert again.returncode == 0 and "the kit has changed ex1.ipynb since you copied it: yours is kept" in again.stdout


def test_appsim_notebooks_copies_what_is_missing_and_never_overwrites(tmp_path):
    mine = tmp_path / "mine"
    first = subprocess.run([sys.executable, "-m", "appsim", "notebooks", str(mine)], capture_output=True, text=True)
    shipped = sorted(path.name for path in (KIT / "notebooks").glob("*.ipynb"))
    assert first.returncode == 0 and f"{len(shipped)} notebook(s) copied" in first.stdout, first.stderr
    assert sorted(path.name for path in mine.iterdir()) == shipped
    copy = json.loads((mine / "ex3.ipynb").read_text())
    assert copy["metadata"]["appsim"]["exercise"] == "ex3", "appsim grade still knows its exercise"
    (mine / "ex3.ipynb").write_text("my own work")
    (mine / "ex2.ipynb").unlink()
    again = subprocess.run([sys.executable, "-m", "appsim", "notebooks", str(mine)], capture_output=True, text=True)
    assert "1 notebook(s) copied (ex2.ipynb)" in again.stdout and (mine / "ex3.ipynb").read_text() == "my own work"
    assert "ex3.ipynb: there already, not copied by appsim notebooks: kept" in again.stdout


@pytest.mark.parametrize("where, words", [("file", "is not a folder"), ("inside-a-file", "cannot make the folder")])
def test_appsim_notebooks_refuses_a_place_it_cannot_use_with_status_2(tmp_path, where, words):
    (tmp_path / "file").write_text("")
    target = {"file": tmp_path / "file", "inside-a-file": tmp_path / "file" / "notebooks"}[where]
    result = subprocess.run([sys.executable, "-m", "appsim", "notebooks", str(target)], capture_output=True, text=True)
    assert result.returncode == 2 and words in result.stderr and "Traceback" not in result.stderr, result.stderr


@pytest.mark.skipif(not hasattr(os, "geteuid") or os.geteuid() != 0, reason="as root only: JupyterLab refuses root")
def test_the_readme_says_what_jupyter_lab_wants_as_root(tmp_path):
    """As root (a container, a CI runner) JupyterLab refuses to start without --allow-root: the README says so."""
    refused = subprocess.run([sys.executable, "-m", "jupyterlab", "--no-browser", str(tmp_path)], capture_output=True,
                             text=True, timeout=120, env={**os.environ, "JUPYTER_RUNTIME_DIR": str(tmp_path / "rt")})
    assert "Use --allow-root to bypass" in refused.stderr, refused.stderr[-2000:]
    section = (KIT / "README.md").read_text().split("## The workshop")[1].split("\n## ")[0]
    assert re.search(r"as root,\s+`jupyter lab` also wants `--allow-root`", section), section
