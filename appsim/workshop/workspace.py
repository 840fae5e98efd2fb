"""Your own copy of the workshop's notebooks, to run and edit, made from the kit's and kept when the kit is updated.

The kit's notebooks stay as they ship (tracked, without outputs), so `git pull` never meets a student's work; each copy
remembers the kit's notebook it was made from, so that a later `appsim notebooks` can say which ones the kit changed.
"""
from __future__ import annotations

import hashlib
import json
import os
from dataclasses import dataclass, field
from pathlib import Path

from appsim.errors import OutputError

FOLDER = "my_notebooks"             # the default, in the clone: .gitignore ignores it
STAMP = "copied_from"               # metadata.appsim.copied_from: the SHA-256 of the kit notebook it was made from


@dataclass
class Copies:
    """What `copy_notebooks` did, notebook by notebook (file names)."""

    folder: Path
    copied: list[str] = field(default_factory=list)          # new in the folder
    kept: list[str] = field(default_factory=list)            # there already, made from the kit's notebook as it is
    changed: list[str] = field(default_factory=list)         # there already, the kit's notebook has changed since
    unknown: list[str] = field(default_factory=list)         # there already, not a copy this command made

    def report(self) -> str:
        lines = [f"{self.folder}/: {len(self.copied)} notebook(s) copied"
                 + (f" ({', '.join(self.copied)})" if self.copied else "")
                 + (f", {len(self.kept)} of yours kept as they are" if self.kept else "")]
        if self.changed:
            lines.append(f"  the kit has changed {', '.join(self.changed)} since you copied it: yours is kept. To take "
                         "the kit's new one, rename yours (ex3.ipynb -> ex3-mine.ipynb) and run appsim notebooks "
                         "again")
        if self.unknown:
            lines.append(f"  {', '.join(self.unknown)}: there already, not copied by appsim notebooks: kept")
        ignored = ", which git ignores" if self.folder.name == FOLDER else ""
        lines.append(f"Your work stays in {self.folder}/{ignored}, not in the kit's notebooks/: `git pull` updates the "
                     f"kit without touching it. Open the notebooks with: jupyter lab {self.folder}/"
                     + (" --allow-root (as root)" if hasattr(os, "geteuid") and os.geteuid() == 0 else ""))
        return "\n".join(lines)


def kit_notebooks() -> Path:
    """The folder of the kit's own notebooks: `notebooks/` of the checkout the kit runs from."""
    root = Path(__file__).resolve().parents[2]
    folder = root / "notebooks"
    if not ((root / "pyproject.toml").is_file() and folder.is_dir()):
        raise OutputError("the workshop's notebooks come with the kit's repository, and this kit was installed "
                          "without one: clone it (git clone ADDRESS appsim), then `pip install -e .` in the clone and "
                          "run appsim notebooks there")
    return folder


def copy_notebooks(into: Path, source: Path | None = None) -> Copies:
    """Copy each of the kit's notebooks into `into` (made if missing) unless a notebook of that name is there: yours
    are never overwritten. Each copy records the kit's notebook it was made from (its metadata)."""
    source = source or kit_notebooks()
    copies = Copies(into)
    if into.exists() and not into.is_dir():
        raise OutputError(f"{into} is not a folder: give appsim notebooks a folder for your notebooks")
    try:
        into.mkdir(parents=True, exist_ok=True)
    except OSError as error:
        raise OutputError(f"cannot make the folder {into} for your notebooks: {error.strerror}") from None
    for notebook in sorted(source.glob("*.ipynb")):
        kit = notebook.read_bytes()
        digest = hashlib.sha256(kit).hexdigest()
        mine = into / notebook.name
        if mine.exists():
            stamp = _stamp(mine)
            (copies.unknown if stamp is None else copies.kept if stamp == digest else copies.changed).append(mine.name)
            continue
        content = json.loads(kit)
        content.setdefault("metadata", {}).setdefault("appsim", {})[STAMP] = digest
        try:
            with open(mine, "x", encoding="utf-8") as file:            # "x": never over a file made meanwhile
                file.write(json.dumps(content, indent=1, ensure_ascii=False) + "\n")
        except OSError as error:
            raise OutputError(f"cannot write {mine}: {error.strerror}") from None
        copies.copied.append(mine.name)
    return copies


def _stamp(path: Path) -> str | None:
    """The kit notebook's digest a copy records, or None (not a notebook this command made, or unreadable)."""
    try:
        stamp = json.loads(path.read_bytes())["metadata"]["appsim"][STAMP]
    except (OSError, ValueError, KeyError, TypeError):
        return None
    return stamp if isinstance(stamp, str) else None
