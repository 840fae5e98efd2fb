"""Where this copy of the kit came from: the git commit of the checkout it runs from, or the one its wheel recorded.

No import of the rest of the kit, so the build (setup.py) loads this file alone to record the commit into the wheel.
"""
from __future__ import annotations

import subprocess
from pathlib import Path

RECORDED = "COMMIT"                 # the file in the package a wheel's build writes the commit into
DIRTY = "-dirty"                    # after a commit whose checkout had the kit's code changed (git describe's word)
CODE = ("appsim", "solutions")      # what the kit's digest covers (appsim.workshop.grading.results.kit_version)


def checkout_commit(root: Path) -> str | None:
    """HEAD of the git checkout whose top folder is `root`, with DIRTY if the kit's code there differs from it
    (changed or new files); None if `root` is no checkout's top (an installed kit) or git cannot tell."""
    def git(*args: str) -> str:
        return subprocess.run(["git", "-C", str(root), *args], capture_output=True, text=True, check=True,
                              timeout=30).stdout.strip()

    try:
        if Path(git("rev-parse", "--show-toplevel")).resolve() != root.resolve():
            return None
        head = git("rev-parse", "HEAD")
        changed = git("status", "--porcelain", "--untracked-files=all", "--", *CODE)
    except (OSError, subprocess.SubprocessError):
        return None
    return head + (DIRTY if changed else "")


def commit() -> str | None:
    """The commit this kit was built from (its wheel's record) or runs from (its checkout), else None."""
    package = Path(__file__).resolve().parent
    recorded = package / RECORDED
    if recorded.is_file():
        return recorded.read_text(encoding="utf-8").strip() or None
    return checkout_commit(package.parent)
