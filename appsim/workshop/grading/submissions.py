"""What a class handed in, read into memory as it is: each submission's firmware files, named and hashed.

A submission is the regular files in its folder or zip: a symbolic link, an unreadable file or a broken zip is a fault
of that submission (or of that exercise), never a stop for the class. Every read is bounded; nothing is written to
disk.
"""
from __future__ import annotations

import hashlib
import io
import json
import os
import stat
import zipfile
from collections.abc import Callable, Iterable, Sequence
from dataclasses import dataclass, field
from pathlib import Path, PurePosixPath

from appsim.errors import GradeError
from appsim.workshop.course import C_FILES, EXERCISE_FILES, EXERCISES
from appsim.workshop.faults import Fault

MAX_SOURCE = 512 << 10              # a firmware file (sandbox.protocol.MAX_SOURCE)
MAX_NOTEBOOK = 16 << 20
MAX_ZIP = 256 << 20                 # a zip handed in, as a file
MAX_UNZIPPED = 256 << 20            # what a zip unpacks to, in all
MAX_MEMBERS = 10_000
WHAT_A_SUBMISSION_IS = ("a submission is a folder holding any of ex1.py .. ex6.py and demo1_monitor.py (or in C ex1.c "
                        ".. ex6.c and demo1_monitor.c, or Jupyter notebooks ex1.ipynb ... whose firmware cell has the "
                        "tag `firmware`), or a .zip of one; a class is a folder (or a .zip) of submissions")


@dataclass(frozen=True)
class Submission:
    """One student's work: per exercise, the file as graded (its name and bytes) or why it cannot be graded."""

    name: str
    files: dict[str, tuple[str, bytes]] = field(default_factory=dict)
    problems: dict[str, Fault] = field(default_factory=dict)
    origin: str = ""                # where it came from, for messages

    @property
    def digest(self) -> str:
        """SHA-256 of what was handed in, as graded: a changed file, an added or removed one, changes it."""
        content = hashlib.sha256()
        for exercise in EXERCISES:
            if exercise in self.files:
                name, source = self.files[exercise]
                content.update(f"{exercise}\0{name}\0{len(source)}\0".encode() + source)
            elif exercise in self.problems:
                content.update(f"{exercise}\0!{self.problems[exercise].kind}\0".encode())
        return content.hexdigest()


# ====================================================================== finding them

def find_submissions(paths: Sequence[str | Path]) -> list[Submission]:
    """The submissions under `paths` (submission folders, class folders, zips of either, single files), by name.

    GradeError for a PATH the grader cannot use at all (missing, not a folder, zip or firmware file) and for two
    submissions of the same name; everything wrong inside a submission is that submission's fault.
    """
    if not paths:
        raise GradeError(f"give at least one PATH to grade: {WHAT_A_SUBMISSION_IS}")
    found: list[Submission] = []
    for given in paths:
        path = Path(given)
        try:
            info = path.stat()
        except OSError as error:
            raise GradeError(f"{path} cannot be read ({error.strerror}): {WHAT_A_SUBMISSION_IS}") from None
        if stat.S_ISDIR(info.st_mode):
            found.extend(_from_folder(path, path.resolve().name))
        elif stat.S_ISREG(info.st_mode) and path.suffix.lower() == ".zip":
            found.extend(_from_zip_file(path, path.stem, class_zip=True))
        elif stat.S_ISREG(info.st_mode) and path.suffix.lower() in (".py", ".c", ".ipynb"):
            found.append(_submission(path.resolve().parent.name, [_Entry.on_disk(path)], str(path)))
        else:
            raise GradeError(f"{path} is not a folder, a .zip, a .py, a .c or a .ipynb file: {WHAT_A_SUBMISSION_IS}")
    names: dict[str, Submission] = {}
    for submission in found:
        if submission.name in names:
            raise GradeError(f"two submissions are named {submission.name!r} ({names[submission.name].origin} and "
                             f"{submission.origin}): results are kept by name, so rename one of them")
        names[submission.name] = submission
    return [names[name] for name in sorted(names)]


@dataclass(frozen=True)
class _Entry:
    """A file of a submission before it is read: its name, and how to get its bytes (or why they cannot be had)."""

    name: str
    read: Callable[[], bytes] | None = None        # raising OSError or GradeError
    problem: Fault | None = None

    @classmethod
    def on_disk(cls, path: Path) -> _Entry:
        return cls(path.name, read=lambda: _read_regular(path, _limit(path.name)))


def _from_folder(folder: Path, name: str) -> list[Submission]:
    entries = _folder_entries(folder)
    if any(_may_hold_exercise(entry.name) for entry in entries):
        return [_submission(name, entries, str(folder))]
    found = []
    for entry in sorted(os.scandir(folder), key=lambda e: e.name):
        if entry.name.startswith((".", "__")):
            continue
        path = Path(entry.path)
        if entry.is_symlink() and (path.is_dir() or path.suffix.lower() == ".zip"):
            found.append(_refused(path.stem if path.suffix.lower() == ".zip" else entry.name, str(path), Fault(
                "symlink", f"{entry.name} in the class folder is a symbolic link to {os.readlink(path)}: a submission "
                           "is the files handed in, so it is not graded")))
        elif entry.is_dir(follow_symlinks=False):
            found.append(_submission(entry.name, _folder_entries(path), str(path)))
        elif entry.is_file(follow_symlinks=False) and path.suffix.lower() == ".zip":
            found.extend(_from_zip_file(path, path.stem))
    if not found:
        raise GradeError(f"{folder} holds no submission: {WHAT_A_SUBMISSION_IS}")
    return found


def _folder_entries(folder: Path) -> list[_Entry]:
    try:
        listing = sorted(os.scandir(folder), key=lambda e: e.name)
    except OSError as error:
        return [_Entry(name, problem=Fault("unreadable", f"the folder {folder.name} cannot be read: {error.strerror}"))
                for name in EXERCISE_FILES.values()]
    entries = []
    for entry in listing:
        path = Path(entry.path)
        if entry.is_symlink():
            entries.append(_Entry(entry.name, problem=Fault(
                "symlink", f"{entry.name} is a symbolic link to {os.readlink(path)}: a submission is the files "
                           "handed in, not links to other files, so it is not graded")))
        elif entry.is_file(follow_symlinks=False):
            entries.append(_Entry.on_disk(path))
        elif _exercise_of(entry.name):
            entries.append(_Entry(entry.name, problem=Fault("unreadable", f"{entry.name} is not a regular file")))
    return entries


def _from_zip_file(path: Path, name: str, *, class_zip: bool = False) -> list[Submission]:
    try:
        data = _read_regular(path, MAX_ZIP)
    except (OSError, GradeError) as error:
        return [_refused(name, str(path), Fault("unreadable", f"{path.name} cannot be read: {_why(error)}"))]
    return _from_zip(data, name, str(path), class_zip=class_zip)


def _from_zip(data: bytes, name: str, origin: str, *, class_zip: bool = False) -> list[Submission]:
    """A zip's submissions: one (its files, or one folder's); or, for a zip the instructor gives as a class
    (`class_zip`), one per folder or per inner zip. A student's zip holding several submissions is refused, so that
    no upload can speak for a classmate."""
    try:
        archive = zipfile.ZipFile(io.BytesIO(data))
        members = [m for m in archive.infolist() if not m.is_dir()]
        if len(members) > MAX_MEMBERS:
            raise GradeError(f"it holds {len(members)} files (at most {MAX_MEMBERS})")
        if sum(m.file_size for m in members) > MAX_UNZIPPED:
            raise GradeError(f"it unpacks to more than {MAX_UNZIPPED >> 20} MB")
        folders: dict[str, list[_Entry]] = {}
        inner: list[Submission] = []
        for member in members:
            member_path = PurePosixPath(member.filename.replace("\\", "/"))
            if any(part.startswith(("__MACOSX", ".")) for part in member_path.parts):
                continue
            folder = "/".join(member_path.parts[:-1])
            if member_path.suffix.lower() == ".zip" and class_zip:
                inner.extend(_from_zip(_read_member(archive, member, MAX_ZIP), member_path.stem,
                                       f"{origin}:{member_path}"))
            else:
                folders.setdefault(folder, []).append(_zip_entry(archive, member, member_path.name))
    except (zipfile.BadZipFile, zipfile.LargeZipFile, GradeError, OSError, RuntimeError, ValueError, EOFError,
            NotImplementedError) as error:
        return [_refused(name, origin, Fault("unreadable", f"{Path(origin).name} is not a zip that can be read "
                                                            f"({_why(error)}); ask for it again"))]
    holding = {folder: entries for folder, entries in folders.items()
               if any(_may_hold_exercise(e.name) for e in entries)}
    if len(holding) == 1 and not inner:
        return [_submission(name, next(iter(holding.values())), origin)]
    if len(holding) > 1 and not class_zip:
        shown = ", ".join(f"{folder or '(top)'}/" for folder in sorted(holding))
        return [_refused(name, origin, Fault("unreadable", f"{Path(origin).name} holds more than one submission "
                                                            f"({shown}): a zip is one student's work, one folder"))]
    found = inner + [_submission(PurePosixPath(folder).name or name, entries, f"{origin}:{folder}")
                     for folder, entries in holding.items()]
    return found or [_refused(name, origin, Fault("missing", f"{Path(origin).name} holds no firmware file: "
                                                             f"{WHAT_A_SUBMISSION_IS}"))]


def _zip_entry(archive: zipfile.ZipFile, member: zipfile.ZipInfo, name: str) -> _Entry:
    if stat.S_ISLNK(member.external_attr >> 16):
        return _Entry(name, problem=Fault("symlink", f"{name} is a symbolic link in the zip: a submission is the files "
                                                     "handed in, not links to other files, so it is not graded"))
    return _Entry(name, read=lambda: _read_member(archive, member, _limit(name)))


def _read_member(archive: zipfile.ZipFile, member: zipfile.ZipInfo, limit: int) -> bytes:
    if member.file_size > limit:
        raise GradeError(f"{PurePosixPath(member.filename).name} is {member.file_size} bytes (at most {limit})")
    with archive.open(member) as file:
        data = file.read(limit + 1)         # a size in the zip's header can lie
    if len(data) > limit:
        raise GradeError(f"{PurePosixPath(member.filename).name} is larger than {limit} bytes")
    return data


# ====================================================================== one submission

def _submission(name: str, entries: Iterable[_Entry], origin: str) -> Submission:
    """A submission's files by exercise. An exercise handed in twice, in Python and in C (ex1.py and ex1.c), is graded
    from neither: which one the student meant is not for the grader to guess (`ambiguous`)."""
    handed: dict[str, dict[str, bytes]] = {}
    problems: dict[str, Fault] = {}
    notebooks: list[tuple[str, bytes]] = []
    for entry in entries:
        exercise = _exercise_of(entry.name)
        if exercise is None and not entry.name.lower().endswith(".ipynb"):
            continue
        if entry.problem is not None:
            if exercise is not None:
                problems.setdefault(exercise, entry.problem)
            continue
        assert entry.read is not None
        try:
            data = entry.read()
        except (OSError, GradeError, zipfile.BadZipFile, RuntimeError, ValueError, EOFError) as error:
            if exercise is not None:
                problems.setdefault(exercise, Fault("unreadable", f"{entry.name} cannot be read: {_why(error)}"))
            continue
        if entry.name.lower().endswith(".ipynb"):
            notebooks.append((entry.name, data))
        elif exercise is not None:
            handed.setdefault(exercise, {})[_canonical(exercise, entry.name)] = data
    files: dict[str, tuple[str, bytes]] = {}
    for exercise, by_name in handed.items():
        if len(by_name) > 1:
            problems[exercise] = _both(exercise, sorted(by_name))
        else:
            files[exercise] = next(iter(by_name.items()))
    for notebook, data in notebooks:
        exercise, firmware = firmware_from_notebook(notebook, data)
        if exercise is None or exercise in handed:
            continue                        # not an exercise's notebook; or the file handed in next to it wins
        if isinstance(firmware, Fault):
            problems.setdefault(exercise, firmware)
        else:
            files[exercise] = firmware
            problems.pop(exercise, None)
    for exercise in files:
        problems.pop(exercise, None)
    return Submission(name, files, problems, origin)


def _both(exercise: str, names: list[str]) -> Fault:
    return Fault("ambiguous", f"{' and '.join(names)} were both handed in for {exercise}: one exercise is graded from "
                              "one firmware, in Python or in C, so neither is graded. Hand in the one you mean.")


def _canonical(exercise: str, name: str) -> str:
    """The exercise's file name as graded, by the language of `name`: ex1.py, or ex1.c."""
    return C_FILES[exercise] if name.lower().endswith(".c") else EXERCISE_FILES[exercise]


def _refused(name: str, origin: str, fault: Fault) -> Submission:
    """A submission none of whose exercises can be graded, for `fault`."""
    return Submission(name, {}, dict.fromkeys(EXERCISES, fault), origin)


def _exercise_of(name: str) -> str | None:
    """The exercise a file is for, by its name: ex1.py .. ex6.py, demo1_monitor.py, their .c twins (notebooks: see
    their metadata)."""
    lowered = name.lower()
    for exercise, file_name in EXERCISE_FILES.items():
        if lowered in (file_name, C_FILES[exercise], file_name.removesuffix(".py") + ".ipynb"):
            return exercise
    return None


def _may_hold_exercise(name: str) -> bool:
    """An exercise's file by its name, or a notebook (which may name its exercise in its metadata)."""
    return _exercise_of(name) is not None or name.lower().endswith(".ipynb")


def firmware_from_notebook(name: str, data: bytes) -> tuple[str | None, tuple[str, bytes] | Fault]:
    """The exercise of a notebook (its metadata {"appsim": {"exercise": ...}}, else its name) and its firmware: the
    code of its cells tagged `firmware` (`firmware-c` for the C cell; IPython magics such as `%%writefile ex1.py`
    become comments), as the file it would be (ex1.py, or ex1.c), or why there is none.

    A notebook with a firmware cell in each language grades the one its `FIRMWARE = "ex1.c"` cell names (the file
    its Station and check cells run); without that choice, the Python one."""
    exercise = _exercise_of(name)
    try:
        notebook = json.loads(data)
        cells = notebook["cells"]
        named = notebook.get("metadata", {}).get("appsim", {}).get("exercise")
        if named in EXERCISES:
            exercise = named
        by_language: dict[str, list[str]] = {}
        chosen = None
        for cell in cells:
            if cell.get("cell_type") != "code":
                continue
            source = cell.get("source", "")
            source = "".join(source) if isinstance(source, list) else str(source)
            if {"firmware", "firmware-c"} & set(cell.get("metadata", {}).get("tags", [])):
                language = _cell_language(source)
                comment = "//" if language == "c" else "#"
                by_language.setdefault(language, []).append("\n".join(
                    f"{comment} {line}" if line.lstrip().startswith(("%", "!")) else line
                    for line in source.splitlines()))
            else:
                chosen = _firmware_choice(source) or chosen
    except (ValueError, KeyError, TypeError, AttributeError, RecursionError):
        return exercise, Fault("unreadable", f"{name} is not a Jupyter notebook that can be read")
    if not by_language:
        return exercise, Fault("missing", f"{name} has no code cell tagged `firmware`: the notebook's firmware cell "
                                          "carries that tag (View > Cell Toolbar > Tags in Jupyter)")
    language = chosen if chosen in by_language else "python" if "python" in by_language else next(iter(by_language))
    if exercise is None:
        return None, Fault("missing", f"{name} names no exercise")
    graded = C_FILES[exercise] if language == "c" else EXERCISE_FILES[exercise]
    return exercise, (graded, ("\n\n".join(by_language[language]) + "\n").encode())


def _cell_language(source: str) -> str:
    """The language of a firmware cell: C if its `%%writefile` writes a .c file."""
    first = source.lstrip().split("\n", 1)[0].split()
    return "c" if first[:1] == ["%%writefile"] and first[-1].lower().endswith(".c") else "python"


def _firmware_choice(source: str) -> str | None:
    """The language a cell's `FIRMWARE = "ex1.c"` (a plain string, read without running anything) chooses."""
    for line in source.splitlines():
        words = line.split("#", 1)[0].split("=", 1)
        if len(words) == 2 and words[0].strip() == "FIRMWARE":
            value = words[1].strip()
            if len(value) > 2 and value[0] == value[-1] and value[0] in "'\"":
                return "c" if value[1:-1].lower().endswith(".c") else "python"
    return None


# ====================================================================== reading

def _limit(name: str) -> int:
    return MAX_NOTEBOOK if name.lower().endswith(".ipynb") else MAX_SOURCE


def _read_regular(path: Path, limit: int) -> bytes:
    """A regular file's bytes, never following a symbolic link, at most `limit` of them (else GradeError)."""
    descriptor = os.open(path, os.O_RDONLY | os.O_NOFOLLOW | os.O_NONBLOCK)
    try:
        info = os.fstat(descriptor)
        if not stat.S_ISREG(info.st_mode):
            raise GradeError("it is not a regular file")
        if info.st_size > limit:
            raise GradeError(f"it is {info.st_size} bytes (at most {limit})")
        with os.fdopen(descriptor, "rb", closefd=False) as file:
            data = file.read(limit + 1)
    finally:
        os.close(descriptor)
    if len(data) > limit:
        raise GradeError(f"it is larger than {limit} bytes")
    return data


def _why(error: BaseException) -> str:
    return error.strerror if isinstance(error, OSError) and error.strerror else str(error) or type(error).__name__
