"""A fresh venv for the tests that install the kit as a user does, over the packages the running Python has.

`python -m venv --system-site-packages` does not give that when the tests run in a venv (as the README has them): it
gives the base Python's own packages (Debian's dist-packages), not the venv's. Here the new venv's site-packages gets a
`.pth` that adds the running interpreter's site folders as site folders (their own `.pth` files run, as they would
for --system-site-packages), after its own: Python and pip see what is installed here (so pip downloads none of the
kit's dependencies), and what is installed into the new venv comes first (a kit installed editable here is found only
where the new venv has none of its own).

    python tests/venvs.py DIR        # the same from a shell (tests/test_readme.py stands it in for `python3 -m venv`)
"""
from __future__ import annotations

import os
import site
import subprocess
import sys
from pathlib import Path

PTH = "running-python.pth"


def site_folders() -> list[str]:
    """The site folders of the running Python (a venv's, or the installation's), user site included if enabled."""
    folders = list(site.getsitepackages())
    if site.ENABLE_USER_SITE:
        folders.append(site.getusersitepackages())
    return [folder for folder in dict.fromkeys(folders) if os.path.isdir(folder)]


def make_venv(path: Path, *, pip: bool = True, python: Path | None = None) -> Path:
    """A new venv at `path` (with pip, or `--without-pip`) that also sees the running Python's packages; its bin.
    `python` makes it (default: the running one; another must be of the same version)."""
    subprocess.run([str(python or sys.executable), "-m", "venv", *([] if pip else ["--without-pip"]), str(path)],
                   check=True, timeout=300)
    python = path / "bin" / "python"
    own = subprocess.run([str(python), "-c", "import sysconfig; print(sysconfig.get_paths()['purelib'])"],
                         capture_output=True, text=True, check=True).stdout.strip()
    Path(own, PTH).write_text("".join(f"import site; site.addsitedir({folder!r})\n" for folder in site_folders()))
    return path / "bin"


if __name__ == "__main__":
    if len(sys.argv) != 2:
        sys.exit(f"usage: {sys.argv[0]} DIR")
    make_venv(Path(sys.argv[1]))
