"""What a class handed in, read into memory as it is: each submission's firmware files, named and hashed.

A class is a folder or a zip of students' entries, as LMS exports make them: a folder or a zip per student (Moodle's
"Alice Smith_12345_assignsubmission_file_", Canvas's "smithalice_12345_67890_lab.zip"), or each student's files side
by side under such names. Each student's entries are searched for the exercises' files (in folders and in the zips they
hold); anything wrong (a symbolic link, an unreadable file, a broken zip, a refused member, a name two students share)
is that student's, named, never a stop for the class. Every read is bounded; nothing is written to disk.
"""
from __future__ import annotations

import functools
import hashlib
import io
import json
import os
import re
import stat
import unicodedata
import zipfile
from collections.abc import Callable, Iterable, Sequence
from dataclasses import dataclass, field
from pathlib import Path

from appsim.errors import GradeError
from appsim.workshop.course import C_FILES, EXERCISE_FILES, EXERCISES
from appsim.workshop.faults import Fault
from appsim.workshop.sandbox.protocol import MAX_SOURCE

MAX_NOTEBOOK = 16 << 20
MAX_ZIP = 256 << 20                 # a zip handed in, as a file
MAX_UNZIPPED = 256 << 20            # what the zips of one PATH unpack to, in all
MAX_MEMBERS = 10_000                # and how many files they hold
MAX_ZIP_DEPTH = 3                   # a class zip, a student's folder in it holding a zip, and a zip in that
MAX_FOLDER_DEPTH = 6                # folders searched below a student's entry
MAX_NAME = 64                       # characters of a submission's name (longer: cut, with a digest)
WHAT_A_SUBMISSION_IS = ("a submission is a folder holding any of ex1.py .. ex6.py and demo1_monitor.py (or in C ex1.c "
                        ".. ex6.c and demo1_monitor.c, or Jupyter notebooks ex1.ipynb ... whose firmware cell has the "
                        "tag `firmware`), or a .zip of one; a class is a folder (or a .zip) of submissions, as an LMS "
                        "exports them")
# LMS exports: Moodle names each student's folder (or each file) "Full Name_participant_assignsubmission_file_", then
# the file's own name; Canvas names each file "lastfirst_userid_submissionid_file" ("_LATE" after the name if late,
# and "-1", "-2" before the extension for a file handed in again under a name already used).
MOODLE = re.compile(r"^(?P<student>.+?_\d+)_assign(?:submission|feedback)_[a-z]+_(?P<rest>.*)$", re.S)
CANVAS = re.compile(r"^(?P<name>[^_]+?)(?:_LATE)?_(?P<user>\d+)_\d+_(?P<rest>.+)$", re.S)
CANVAS_AGAIN = re.compile(r"-\d+(?=\.[^.]+$)")


@dataclass(frozen=True)
class Submission:
    """One student's work: per exercise, the file as graded (its name and bytes) or why it cannot be graded."""

    name: str
    files: dict[str, tuple[str, bytes]] = field(default_factory=dict)
    problems: dict[str, Fault] = field(default_factory=dict)
    origin: str = ""                # where it came from (its entries in the class), for records and messages
    note: str = ""                  # what the grader did about its name, if anything

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


# ====================================================================== what was handed in, as a tree

@dataclass
class _Entry:
    """A file or folder handed in (on disk or in a zip): its name, where it is (for messages), and how to get its bytes
    or its entries; or why it cannot be had."""

    name: str
    where: str
    read: Callable[[], bytes] | None = None              # a file's bytes (OSError or GradeError)
    entries: Callable[[], list[_Entry]] | None = None    # a folder's
    problem: Fault | None = None
    zip_depth: int = 0                                   # zips it lies in

    @property
    def folder(self) -> bool:
        return self.entries is not None

    @property
    def is_zip(self) -> bool:
        return self.read is not None and self.name.lower().endswith(".zip")


class _Budget:
    """What the zips of one PATH may unpack to, in all (members and bytes)."""

    def __init__(self) -> None:
        self.members = MAX_MEMBERS
        self.bytes = MAX_UNZIPPED

    def take(self, members: int, size: int) -> None:
        if members > self.members:
            raise GradeError(f"with the zips read before it, it holds more than {MAX_MEMBERS} files")
        if size > self.bytes:
            raise GradeError(f"with the zips read before it, it unpacks to more than {MAX_UNZIPPED >> 20} MB")
        self.members -= members
        self.bytes -= size


def _disk_folder(folder: Path, where: str) -> _Entry:
    def entries() -> list[_Entry]:
        found = []
        for entry in sorted(os.scandir(folder), key=lambda e: e.name):
            path, name = Path(entry.path), _decoded(entry.name)
            inside = f"{where}/{name}"
            if entry.is_symlink():
                found.append(_Entry(name, inside, problem=Fault(
                    "symlink", f"{name} is a symbolic link to {_decoded(os.readlink(path))}: a submission is the files "
                               "handed in, not links to other files, so it is not graded")))
            elif entry.is_dir(follow_symlinks=False):
                found.append(_disk_folder(path, inside))
            elif entry.is_file(follow_symlinks=False):
                found.append(_Entry(name, inside, read=functools.partial(_read_regular, path, _limit(name))))
            else:
                found.append(_Entry(name, inside, problem=Fault("unreadable", f"{name} is not a regular file")))
        return found
    return _Entry(_decoded(folder.name), where, entries=entries)


def _zip_folder(data: bytes, where: str, depth: int, budget: _Budget) -> _Entry:
    """A zip's content as a folder (BadZipFile, GradeError ... if it cannot be one). Members whose path is absolute or
    leads out of the zip are refused, each by name."""
    archive = zipfile.ZipFile(io.BytesIO(data))
    members = [m for m in archive.infolist() if not m.is_dir()]
    budget.take(len(members), sum(m.file_size for m in members))
    tree: dict[str, object] = {}
    refused: list[_Entry] = []
    for member in members:
        raw = member.filename.replace("\\", "/")
        parts = [p for p in raw.split("/") if p not in ("", ".")]
        name = _decoded(parts[-1]) if parts else raw
        if raw.startswith("/") or re.match(r"^[A-Za-z]:", raw) or ".." in parts or not parts:
            refused.append(_Entry(name, f"{where}:{raw}", problem=Fault(
                "unreadable", f"the zip's member {raw!r} was refused: a path outside the zip's own folders (absolute, "
                              "or through ..) is never read; zip the files themselves")))
            continue
        node = tree
        for part in parts[:-1]:
            child = node.setdefault(part, {})
            node = child if isinstance(child, dict) else {}
        node[parts[-1]] = member

    def entries_of(node: dict[str, object], path: str) -> list[_Entry]:
        found = []
        for name in sorted(node):
            item, inside = node[name], f"{where}:{path}{name}"
            if isinstance(item, dict):
                found.append(_Entry(_decoded(name), inside, zip_depth=depth,
                                    entries=functools.partial(entries_of, item, f"{path}{name}/")))
            else:
                assert isinstance(item, zipfile.ZipInfo)
                found.append(_zip_member(archive, item, _decoded(name), inside, depth))
        return found + (refused if not path else [])
    return _Entry(where.rsplit("/", 1)[-1], where, entries=lambda: entries_of(tree, ""), zip_depth=depth)


def _zip_member(archive: zipfile.ZipFile, member: zipfile.ZipInfo, name: str, where: str, depth: int) -> _Entry:
    if stat.S_ISLNK(member.external_attr >> 16):
        return _Entry(name, where, problem=Fault("symlink", f"{name} is a symbolic link in the zip: a submission is "
                                                            "the files handed in, not links to other files, so it is "
                                                            "not graded"))
    return _Entry(name, where, read=lambda: _read_member(archive, member, _limit(name)), zip_depth=depth)


def _opened(entry: _Entry, budget: _Budget) -> _Entry:
    """A zip file as the folder it holds, or an entry that says why it cannot be."""
    assert entry.read is not None
    try:
        if entry.zip_depth >= MAX_ZIP_DEPTH:
            raise GradeError(f"a zip inside {MAX_ZIP_DEPTH} zips is not opened")
        return _zip_folder(entry.read(), entry.where, entry.zip_depth + 1, budget)
    except (zipfile.BadZipFile, zipfile.LargeZipFile, GradeError, OSError, RuntimeError, ValueError, EOFError,
            NotImplementedError) as error:
        return _Entry(entry.name, entry.where, problem=Fault(
            "unreadable", f"{entry.name} is not a zip that can be read ({_why(error)}); ask for it again"))


# ====================================================================== finding them

def find_submissions(paths: Sequence[str | Path]) -> list[Submission]:
    """The submissions under `paths` (submission folders, class folders, zips of either, single files), by name.

    GradeError for a PATH the grader cannot use at all (missing, not a folder, zip or firmware file); everything
    wrong inside a submission is that submission's fault. Names are made unique (see `_unique`).
    """
    if not paths:
        raise GradeError(f"give at least one PATH to grade: {WHAT_A_SUBMISSION_IS}")
    found: list[tuple[str, list[_Entry], str, _Budget]] = []        # (name, entries, origin, its PATH's budget)
    for given in paths:
        path = Path(given)
        try:
            info = path.stat()
        except OSError as error:
            raise GradeError(f"{path} cannot be read ({error.strerror}): {WHAT_A_SUBMISSION_IS}") from None
        budget = _Budget()
        own = _decoded(path.resolve().name)            # origins start there: the same class gives the same records
        if stat.S_ISDIR(info.st_mode):
            parts = _from_class_folder(_disk_folder(path, own), own, budget, path)
        elif stat.S_ISREG(info.st_mode) and path.suffix.lower() == ".zip":
            upload = _Entry(own, own, read=functools.partial(_read_regular, path, MAX_ZIP))
            parts = _from_zip(upload, _decoded(path.stem), budget)
        elif stat.S_ISREG(info.st_mode) and path.suffix.lower() in (".py", ".c", ".ipynb"):
            entry = _Entry(own, own, read=functools.partial(_read_regular, path, _limit(path.name)))
            parts = [(_decoded(path.resolve().parent.name), [entry], own)]
        else:
            raise GradeError(f"{path} is not a folder, a .zip, a .py, a .c or a .ipynb file: {WHAT_A_SUBMISSION_IS}")
        found += [(*part, budget) for part in parts]
    named = _unique([(name, origin) for name, _, origin, _ in found])
    return sorted((_submission(name, entries, origin, budget, note)
                   for (name, note), (_, entries, origin, budget) in zip(named, found, strict=True)),
                  key=lambda s: s.name)


def _from_class_folder(root: _Entry, name: str, budget: _Budget, path: Path) -> list[tuple[str, list[_Entry], str]]:
    """A folder given as PATH: one submission if it holds an exercise's file itself, else a class of its entries."""
    try:
        entries = _visible(root)
    except OSError as error:
        raise GradeError(f"{path} cannot be read ({error.strerror}): {WHAT_A_SUBMISSION_IS}") from None
    if any(_may_hold_exercise(e.name) for e in entries if not e.folder):
        return [(name, entries, root.where)]
    students = _students(entries, budget)
    if not students:
        raise GradeError(f"{path} holds no submission: {WHAT_A_SUBMISSION_IS}")
    return students


def _from_zip(upload: _Entry, name: str, budget: _Budget) -> list[tuple[str, list[_Entry], str]]:
    """A zip given as PATH: one submission (its files, or one folder's, named after the zip), or a class, possibly in
    one folder of its own (a class zip's)."""
    opened = _opened(upload, budget)
    if opened.problem is not None:
        return [(name, [opened], upload.where)]
    entries = _visible(opened)
    for _ in range(MAX_FOLDER_DEPTH):
        if any(_may_hold_exercise(e.name) for e in entries if not e.folder):
            return [(name, entries, upload.where)]
        if len(entries) != 1 or not entries[0].folder or _lms(entries[0].name, folder=True) is not None:
            break
        inner = _visible(entries[0])
        if any(_may_hold_exercise(e.name) for e in inner if not e.folder):
            return [(name, inner, entries[0].where)]          # a student's zip of their own folder
        entries = inner                                       # the one folder a class zip is made of
    return _students(entries, budget) or [(name, [], upload.where)]


def _students(entries: Iterable[_Entry], budget: _Budget) -> list[tuple[str, list[_Entry], str]]:
    """A class's entries by student: a folder, a zip or (in an LMS export) a file each; the entries an LMS named after
    one student are that student's together. Any other entry is a submission of its own, whatever its name (two named
    alike are told apart by `_unique`): no upload can add to a classmate's."""
    by_student: dict[str, tuple[str, list[_Entry], list[str]]] = {}
    for entry in entries:
        lms = _lms(entry.name, folder=entry.folder)
        if entry.folder:
            student, content = lms[0] if lms else entry.name, entry
        elif entry.is_zip or (lms and lms[1].lower().endswith(".zip")):
            stem = (lms[1] if lms else entry.name)[:-len(".zip")]
            student, content = lms[0] if lms else stem, _opened(entry, budget)
        elif lms is not None and _may_hold_exercise(lms[1]):
            student, content = lms[0], _Entry(lms[1], entry.where, entry.read, entry.entries, entry.problem,
                                              entry.zip_depth)
        elif entry.problem is not None and entry.problem.kind == "symlink" and not _may_hold_exercise(entry.name):
            student = entry.name.removesuffix(".zip")       # a student's folder or zip, as a link
            content = _Entry(entry.name, entry.where, problem=Fault(
                "symlink", f"{entry.name} in the class is a symbolic link: a submission is the files handed in, so "
                           "it is not graded"))
        else:
            continue                    # the class's own files: a README, a grade sheet, an LMS's text submission
        key = f"lms:{_key(student)}" if lms else f"entry:{entry.where}"   # only an LMS's names tie entries together
        kept = by_student.setdefault(key, (student, [], []))
        kept[1].append(content)
        kept[2].append(entry.where)
    return [(student, contents, "; ".join(origins)) for student, contents, origins in by_student.values()]


def _lms(name: str, *, folder: bool = False) -> tuple[str, str] | None:
    """(student, the file's own name) from an LMS export's name: Moodle's for files and folders, Canvas's for files."""
    moodle = MOODLE.match(name)
    if moodle:
        return moodle["student"], moodle["rest"]
    canvas = None if folder else CANVAS.match(name)
    if canvas:
        return f"{canvas['name']}_{canvas['user']}", CANVAS_AGAIN.sub("", canvas["rest"])
    return None


def _visible(folder: _Entry) -> list[_Entry]:
    """A folder's entries but for what archivers and systems add (__MACOSX, .DS_Store, .ipynb_checkpoints...)."""
    assert folder.entries is not None
    return [e for e in folder.entries() if not e.name.startswith((".", "__MACOSX"))]


# ====================================================================== names

def _unique(found: Sequence[tuple[str, str]]) -> list[tuple[str, str]]:
    """Each (name, origin) as a name a record, a gradebook and a file may carry, unique whatever the class holds
    (compared as a file system that ignores case would), and what became of it: [(name, note)]. Names two
    submissions share get a digest of where each came from, so that each keeps its name from one run to the next."""
    names = [_clean(name) for name, _ in found]
    notes = [f"its name {raw!r} was made one a record and a file can carry" if name != raw else ""
             for name, (raw, _) in zip(names, found, strict=True)]
    for attempt in range(4):
        keys: dict[str, list[int]] = {}
        for index, name in enumerate(names):
            keys.setdefault(_key(name), []).append(index)
        shared = [indexes for indexes in keys.values() if len(indexes) > 1]
        if not shared:
            break
        for indexes in shared:
            origins = "; ".join(found[i][1] for i in indexes)
            for i in indexes:
                notes[i] = (f"{len(indexes)} submissions would be named {names[i]!r} ({origins}): each is graded "
                            "under a name of its own")
                names[i] = f"{names[i]}~{_digest(found[i][1] + '#' * attempt)}"
    return list(zip(names, notes, strict=True))


def _clean(name: str) -> str:
    """A name without what a terminal, a spreadsheet line or a file system cannot show: undecodable bytes, control
    characters, surrounding blanks; at most MAX_NAME characters (a longer one is cut, with a digest of it all)."""
    text = unicodedata.normalize("NFC", name.encode("utf-8", "surrogateescape").decode("utf-8", "replace"))
    text = "".join(c if c.isprintable() else "?" for c in text).strip() or "submission"
    if len(text) > MAX_NAME:
        text = f"{text[:MAX_NAME - 7]}~{_digest(name)}"
    return text


def _key(name: str) -> str:
    return unicodedata.normalize("NFC", name).casefold()


def _digest(text: str) -> str:
    return hashlib.sha256(text.encode("utf-8", "surrogateescape")).hexdigest()[:6]


def _decoded(name: str | bytes) -> str:
    """A file name as the system gives it (bytes a name is not UTF-8 in come as surrogates: see `_clean`)."""
    return os.fsdecode(name) if isinstance(name, bytes) else name


# ====================================================================== one submission

def _submission(name: str, entries: list[_Entry], origin: str, budget: _Budget, note: str = "") -> Submission:
    """A student's files: each exercise's file found in their entries (the one nearest the top; two as near are that
    exercise's fault), read bounded; notebooks give their firmware cells. An entry that cannot be read at all (a
    broken zip, a link) is the fault of every exercise not found elsewhere; a refused member is named. An exercise
    handed in in both languages as near the top (ex1.py and ex1.c) is graded from neither: which one the student
    meant is not for the grader to guess (`ambiguous`)."""
    found = _Found()
    for entry in entries:
        _search(entry, 0, budget, found)
    files: dict[str, tuple[str, bytes]] = {}
    problems: dict[str, Fault] = {}
    for exercise, candidates in found.exercises.items():
        candidates.sort(key=lambda pair: pair[0])
        nearest = [e for depth, e in candidates if depth == candidates[0][0]]
        if len({_canonical(exercise, e.name) for e in nearest}) > 1:
            problems[exercise] = _both(exercise, sorted(_inside(e) for e in nearest))
            continue
        if len(nearest) > 1:
            problems[exercise] = Fault("unreadable", f"two files for {exercise} in this submission ("
                                                     f"{' and '.join(_inside(e) for e in nearest)}): hand in one")
            continue
        entry = nearest[0]
        if entry.problem is not None:
            problems[exercise] = entry.problem
            continue
        data = _bytes(entry, problems, exercise)
        if data is not None:
            files[exercise] = (_canonical(exercise, entry.name), data)
    for _, notebook in sorted(found.notebooks, key=lambda pair: pair[0]):
        data = _bytes(notebook, problems, _exercise_of(notebook.name))
        if data is None:
            continue
        named, firmware = firmware_from_notebook(notebook.name, data)
        if named is None or named in files or problems.get(named, _NONE).kind == "ambiguous":
            continue                        # not an exercise's notebook; or the file handed in next to it wins
        if isinstance(firmware, Fault):
            problems.setdefault(named, firmware)
        else:
            files[named] = firmware
            problems.pop(named, None)
    for exercise in files:
        problems.pop(exercise, None)
    refused = "; ".join(found.refused[:3]) + (f" (and {len(found.refused) - 3} more)" if len(found.refused) > 3
                                               else "")
    for exercise in EXERCISES:
        if exercise in files or exercise in problems:
            continue
        if found.whole is not None:
            problems[exercise] = found.whole
        elif refused:
            problems[exercise] = Fault("missing", f"{EXERCISE_FILES[exercise]} is missing from this submission (and "
                                                  f"{C_FILES[exercise]}, its C twin): nothing to grade for {exercise} "
                                                  f"({refused})")
    return Submission(name, files, problems, origin, note)


_NONE = Fault("missing", "")


def _both(exercise: str, names: list[str]) -> Fault:
    return Fault("ambiguous", f"{' and '.join(names)} were both handed in for {exercise}: one exercise is graded from "
                              "one firmware, in Python or in C, so neither is graded. Hand in the one you mean.")


def _canonical(exercise: str, name: str) -> str:
    """The exercise's file name as graded, by the language of `name`: ex1.py, or ex1.c."""
    return C_FILES[exercise] if name.lower().endswith(".c") else EXERCISE_FILES[exercise]


@dataclass
class _Found:
    """What a search of a student's entries found: per exercise its files (with how deep each lies), the notebooks,
    what was refused, and the fault of an entry that could not be read at all."""

    exercises: dict[str, list[tuple[int, _Entry]]] = field(default_factory=dict)
    notebooks: list[tuple[int, _Entry]] = field(default_factory=list)
    refused: list[str] = field(default_factory=list)
    whole: Fault | None = None


def _search(entry: _Entry, depth: int, budget: _Budget, found: _Found) -> None:
    """Every exercise's file and every notebook in `entry` (a file, a folder, a zip), with how deep it lies."""
    if entry.is_zip:
        entry = _opened(entry, budget)
    exercise = _exercise_of(entry.name)
    if entry.problem is not None:
        upload = depth == 0 or entry.name.lower().endswith(".zip") or entry.problem.kind == "symlink"
        if exercise is not None:
            found.exercises.setdefault(exercise, []).append((depth, entry))
        elif upload and found.whole is None:
            found.whole = entry.problem         # an upload that cannot be opened: what it holds cannot be graded
        else:
            found.refused.append(entry.problem.message)
    elif entry.folder:
        if depth > MAX_FOLDER_DEPTH:
            found.refused.append(f"{entry.where}: folders deeper than {MAX_FOLDER_DEPTH} are not searched")
            return
        try:
            inside = _visible(entry)
        except OSError as error:
            found.refused.append(f"the folder {entry.name} cannot be read: {error.strerror}")
            return
        for item in inside:
            _search(item, depth + 1, budget, found)
    elif entry.name.lower().endswith(".ipynb"):
        found.notebooks.append((depth, entry))
    elif exercise is not None:
        found.exercises.setdefault(exercise, []).append((depth, entry))


def _inside(entry: _Entry) -> str:
    return entry.where.split(":", 1)[-1] if ":" in entry.where else entry.name


def _bytes(entry: _Entry, problems: dict[str, Fault], exercise: str | None) -> bytes | None:
    """A file's bytes, or None with why noted for its exercise."""
    assert entry.read is not None
    try:
        return entry.read()
    except (OSError, GradeError, zipfile.BadZipFile, RuntimeError, ValueError, EOFError) as error:
        if exercise is not None:
            problems.setdefault(exercise, Fault("unreadable", f"{entry.name} cannot be read: {_why(error)}"))
        return None


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
    become comments), as the file it would be (ex1.py, or ex1.c), or why there is none. The cells are held to the
    size of a firmware file.

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
    # a lone surrogate passes here, and is the load error of the firmware
    firmware = ("\n\n".join(by_language[language]) + "\n").encode("utf-8", "surrogatepass")
    if len(firmware) > MAX_SOURCE:
        return exercise, Fault("unreadable", f"the firmware cells of {name} are {_size(len(firmware))} of "
                                             f"{'C' if language == 'c' else 'Python'}: {_too_big()}")
    suffix = ".c" if language == "c" else ".py"
    graded = ((C_FILES if language == "c" else EXERCISE_FILES)[exercise] if exercise is not None
              else Path(name).stem + suffix)
    return exercise, (graded, firmware)


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
    return MAX_NOTEBOOK if name.lower().endswith(".ipynb") else MAX_ZIP if name.lower().endswith(".zip") \
        else MAX_SOURCE


def _size(count: int) -> str:
    return f"{count:,} bytes"


def _too_big() -> str:
    return f"a firmware file (or a notebook's firmware cells) is at most {_size(MAX_SOURCE)}"


def _too_large(size: int, limit: int) -> GradeError:
    if limit == MAX_SOURCE:
        return GradeError(f"it is {_size(size)}: {_too_big()}")
    return GradeError(f"it is {_size(size)} (at most {_size(limit)})")


def _read_regular(path: Path, limit: int) -> bytes:
    """A regular file's bytes, never following a symbolic link, at most `limit` of them (else GradeError)."""
    descriptor = os.open(path, os.O_RDONLY | os.O_NOFOLLOW | os.O_NONBLOCK)
    try:
        info = os.fstat(descriptor)
        if not stat.S_ISREG(info.st_mode):
            raise GradeError("it is not a regular file")
        if info.st_size > limit:
            raise _too_large(info.st_size, limit)
        with os.fdopen(descriptor, "rb", closefd=False) as file:
            data = file.read(limit + 1)
    finally:
        os.close(descriptor)
    if len(data) > limit:
        raise _too_large(len(data), limit)
    return data


def _read_member(archive: zipfile.ZipFile, member: zipfile.ZipInfo, limit: int) -> bytes:
    if member.file_size > limit:
        raise _too_large(member.file_size, limit)
    with archive.open(member) as file:
        data = file.read(limit + 1)         # a size in the zip's header can lie
    if len(data) > limit:
        raise _too_large(len(data), limit)
    return data


def _why(error: BaseException) -> str:
    return error.strerror if isinstance(error, OSError) and error.strerror else str(error) or type(error).__name__
