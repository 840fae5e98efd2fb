"""The grades as they are kept: a JSON-lines results file that only the grader writes, a CSV gradebook, Gradescope.

Each record says what it judged: the submission's content hash, the seed and the kit's version. A rerun keeps a record
only while all three match, so a resubmission, another seed or another kit is graded again.
"""
from __future__ import annotations

import csv
import fcntl
import hashlib
import json
import os
import re
import stat
from collections.abc import Iterable, Mapping, Sequence
from pathlib import Path
from typing import Any

from appsim.errors import GradeError
from appsim.workshop import course
from appsim.workshop.course import EXERCISES

Record = dict[str, Any]
RESULTS_SUFFIX = ".grades.jsonl"
_FORMULA = ("=", "+", "-", "@", "\t", "\r")          # a spreadsheet would run a cell that starts so


def kit_version() -> str:
    """The kit's version and a digest of its code and reference solutions: what a grade was made with."""
    import appsim

    content = hashlib.sha256()
    package = Path(appsim.__file__).resolve().parent
    for path in sorted({*package.rglob("*.py"), *package.rglob("*.h"), *course.SOLUTIONS.glob("*.py"),
                        *course.SOLUTIONS.glob("*.c")}):
        content.update(path.relative_to(path.parents[1]).as_posix().encode() + b"\0" + path.read_bytes())
    return f"{appsim.__version__}+{content.hexdigest()[:12]}"


def default_results(paths: Sequence[Path]) -> Path:
    """Where a class's results go unless --json says: beside the (first) class given, named after it."""
    first = Path(paths[0]).resolve()
    name = first.stem if first.is_file() else first.name
    return first.parent / f"{name or 'class'}{RESULTS_SUFFIX}"


def check_output(path: Path, what: str, *, folder: bool = False) -> None:
    """That `path` can be written as `what`: a regular file (or, with `folder`, a folder), or new in a folder that
    exists and can be written. GradeError (before anything is graded) if not."""
    try:
        info = path.stat()
    except FileNotFoundError:
        parent = path.resolve().parent
        if not parent.is_dir():
            raise GradeError(f"{what} {path}: the folder {parent} does not exist; create it or give another path") \
                from None
        if not os.access(parent, os.W_OK):
            raise GradeError(f"{what} {path}: the folder {parent} cannot be written; give another path") from None
        return
    except OSError as error:
        raise GradeError(f"{what} {path} cannot be used: {error.strerror}") from None
    wanted = stat.S_ISDIR if folder else stat.S_ISREG
    if not wanted(info.st_mode):
        kind = _kind(info.st_mode)
        raise GradeError(f"{what} {path} is {kind}, not {'a folder' if folder else 'a regular file'}: give "
                         f"{'a folder' if folder else 'a file name'} "
                         f"(new or {'existing' if folder else 'one written by appsim grade'})")
    if not os.access(path, os.W_OK):
        raise GradeError(f"{what} {path} cannot be written; give another path")


def _kind(mode: int) -> str:
    for test, name in ((stat.S_ISDIR, "a folder"), (stat.S_ISFIFO, "a FIFO (named pipe)"), (stat.S_ISCHR, "a device"),
                       (stat.S_ISBLK, "a device"), (stat.S_ISSOCK, "a socket")):
        if test(mode):
            return name
    return "a special file"


class ResultsFile:
    """The JSON-lines results file, locked while one `appsim grade` writes it; records appended as they come."""

    def __init__(self, path: Path):
        check_output(path, "the results file (--json)")
        self.path = path
        self._file = open(path, "a+", encoding="utf-8")
        try:
            fcntl.flock(self._file, fcntl.LOCK_EX | fcntl.LOCK_NB)
        except BlockingIOError:
            self._file.close()
            raise GradeError(f"another appsim grade is writing {path}: wait for it, or give --json another file") \
                from None

    def records(self) -> dict[str, Record]:
        """The records in the file, by submission (an unfinished last line, from a kill, is dropped)."""
        self._file.seek(0)
        text = self._file.read()
        complete = text[:text.rfind("\n") + 1]
        if complete != text:                    # the line being written when the run was killed
            self._file.truncate(len(complete.encode("utf-8")))
        found: dict[str, Record] = {}
        for number, line in enumerate(complete.splitlines(), start=1):
            if not line.strip():
                continue
            try:
                record = json.loads(line)
                found[record["submission"]] = record
            except (ValueError, KeyError, TypeError):
                raise GradeError(f"{self.path}, line {number}, is not a grade record: give --json a results file "
                                 "written by appsim grade, or a new file name") from None
        return found

    def append(self, record: Record) -> None:
        self._file.write(json.dumps(record, sort_keys=True) + "\n")
        self._file.flush()
        os.fsync(self._file.fileno())

    def rewrite(self, records: Iterable[Record]) -> None:
        """All records, sorted by submission, replacing the file's content in one step."""
        temporary = self.path.with_name(f".{self.path.name}.{os.getpid()}.tmp")
        try:
            with open(temporary, "w", encoding="utf-8") as file:
                file.writelines(json.dumps(r, sort_keys=True) + "\n"
                                for r in sorted(records, key=lambda r: r["submission"]))
                file.flush()
                os.fsync(file.fileno())
            os.replace(temporary, self.path)
        finally:
            temporary.unlink(missing_ok=True)

    def close(self) -> None:
        self._file.close()


def still_valid(record: Record | None, digest: str, seed: int, kit: str) -> bool:
    """Whether `record` grades what is handed in now, with this seed and this kit (and the grader failed on none
    of its exercises)."""
    return (record is not None and record.get("hash") == digest and record.get("seed") == seed
            and record.get("kit") == kit
            and not any(e.get("fault") == "grader" for e in record.get("exercises", {}).values()))


# ====================================================================== the gradebook and Gradescope

def cell(text: object) -> str:
    """A CSV cell a spreadsheet shows as text: one that starts like a formula gets a leading apostrophe."""
    text = str(text)
    return "'" + text if text.startswith(_FORMULA) else text


def write_csv(path: Path, records: Sequence[Record]) -> None:
    """The gradebook: a row per submission, a column per exercise, the total, the maximum and the faults."""
    with open(path, "w", newline="", encoding="utf-8") as file:
        writer = csv.writer(file)
        writer.writerow(["submission", *EXERCISES, "total", "max_score", "faults"])
        for record in sorted(records, key=lambda r: r["submission"]):
            faults = "; ".join(f"{e}: {r['fault']}" for e, r in record["exercises"].items() if r.get("fault"))
            writer.writerow([cell(record["submission"]), *(record["exercises"][e]["score"] for e in EXERCISES),
                             record["score"], record["max_score"], cell(faults)])


def gradescope(record: Record) -> Record:
    """One submission as Gradescope's results.json: a test per exercise, its checks in the output."""
    tests = []
    for exercise, result in record["exercises"].items():
        lines = [f"{'PASS' if c['passed'] else 'FAIL'}  {c['name']}: {c['message']}" for c in result["checks"]]
        tests.append({"name": exercise, "score": result["score"], "max_score": result["max_score"],
                      "output": "\n".join(lines),
                      "status": "passed" if result["score"] == result["max_score"] else "failed"})
    commit = f" (git commit {record['commit']})" if record.get("commit") else ""
    return {"score": record["score"], "output": f"Graded by appsim {record.get('kit', '')}{commit} with seed "
                                                f"{record['seed']}.", "tests": tests}


def write_gradescope(path: Path, records: Sequence[Record], *, folder: bool) -> None:
    """`folder`: `path` is a folder of NAME.json, one per submission; else `path` is the one submission's
    results.json."""
    if not folder:
        [record] = records
        path.write_text(json.dumps(gradescope(record), indent=1) + "\n", encoding="utf-8")
        return
    path.mkdir(parents=True, exist_ok=True)
    for record in records:
        (path / f"{file_name(record['submission'])}.json").write_text(json.dumps(gradescope(record), indent=1) + "\n",
                                                                      encoding="utf-8")


def file_name(name: str) -> str:
    """A submission's name as a safe file name (letters, digits, . _ -), made unique by a digest if it had to change."""
    safe = re.sub(r"[^A-Za-z0-9._-]", "_", name).lstrip(".") or "submission"
    return safe if safe == name else f"{safe[:80]}-{hashlib.sha256(name.encode()).hexdigest()[:8]}"


def printable(name: str) -> str:
    """A submission's name as a terminal may show it (no control characters, no escape sequences)."""
    return "".join(c if c.isprintable() else "?" for c in name)


def summary_line(record: Record) -> str:
    """One submission on one terminal line: its total and each exercise (with the fault that zeroed it)."""
    parts = []
    for exercise, result in record["exercises"].items():
        fault = result.get("fault")
        parts.append(f"{exercise} {result['score']}/{result['max_score']}" + (f" ({fault})" if fault else ""))
    return f"{printable(record['submission']):<24} {record['score']:>3}/{record['max_score']:<3}  " + "  ".join(parts)


def record_of(name: str, digest: str, seed: int, kit: str, exercises: Mapping[str, Record],
              commit: str | None = None, origin: str = "") -> Record:
    """A submission's record; `commit` is the kit's git commit (`appsim.provenance.commit`), for the instructor to
    match a grade to (the record is kept or graded again by `kit` alone); `origin`, where in the class it came from."""
    ordered = {exercise: exercises[exercise] for exercise in EXERCISES}
    return {"submission": name, "origin": origin, "hash": digest, "seed": seed, "kit": kit, "commit": commit,
            "score": sum(e["score"] for e in ordered.values()),
            "max_score": sum(e["max_score"] for e in ordered.values()),
            "exercises": ordered}
