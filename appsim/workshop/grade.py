"""Grading a whole class: each submission's exercises checked with its firmware in sandboxed processes, results kept as they come.

`appsim grade PATH...` finds the submissions, grades them in parallel worker processes, appends each record to a
JSON-lines file as it finishes (a rerun resumes), and writes the gradebook (CSV) and Gradescope results.
"""
from __future__ import annotations

import ast
import csv
import json
import os
import random
import selectors
import signal
import subprocess
import sys
import zipfile
from collections import deque
from collections.abc import Iterable, Iterator, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, TextIO

from appsim.workshop.checks.trial import RTR_IDS, STATION_IDS
from appsim.workshop.sandbox import DEFAULT_LIMITS, Limits, RemoteFirmware, Sandbox

EXERCISE_FILES: dict[str, str] = {**{f"ex{n}": f"ex{n}.py" for n in range(1, 7)}, "demo1": "demo1_monitor.py"}
DEFAULT_RESULTS = Path("appsim-grades.jsonl")
WHAT_A_SUBMISSION_IS = ("a submission is a directory holding any of ex1.py .. ex6.py and demo1_monitor.py (or "
                        "Jupyter notebooks ex1.ipynb ... whose firmware cell has the tag `firmware`); a class is "
                        "a directory of submissions (or of .zip files of them)")
_MAX_UNZIPPED = 200 << 20
_NOWHERE = Path("/nonexistent/appsim-grade")
_ZERO = "Not judged: the firmware did not run (see above)."


class GradeError(Exception):
    """Input the grader cannot use (a path, a zip, an empty directory, a results file), with what to do."""


@dataclass(frozen=True)
class Submission:
    """One student's work: a firmware file per exercise handed in, and why an exercise's file cannot be used."""

    name: str
    files: dict[str, Path]
    problems: dict[str, str] = field(default_factory=dict)


# ====================================================================== finding the submissions

def find_submissions(paths: Sequence[str | Path], work: Path) -> list[Submission]:
    """The submissions under `paths` (directories, classes, zips, notebooks), sorted by name.

    Zips are extracted and notebooks' firmware cells written as .py files under `work`.
    """
    if not paths:
        raise GradeError(f"give at least one PATH to grade: {WHAT_A_SUBMISSION_IS}")
    found: list[Submission] = []
    for number, given in enumerate(paths):
        path = Path(given)
        place = work / str(number)
        if not path.exists():
            raise GradeError(f"{path} does not exist: {WHAT_A_SUBMISSION_IS}")
        if path.is_dir():
            found.extend(_from_directory(path, path.resolve().name, place))
        elif path.suffix.lower() == ".zip":
            found.extend(_from_zip(path, place))
        elif path.suffix.lower() in (".py", ".ipynb"):
            found.append(_submission(path.resolve().parent.name, [path], place))
        else:
            raise GradeError(f"{path} is not a directory, a .zip, a .py or a .ipynb file: {WHAT_A_SUBMISSION_IS}")
    names: dict[str, Submission] = {}
    for submission in found:
        if submission.name in names:
            raise GradeError(f"two submissions are both named {submission.name!r}: the results are kept by name, "
                             "so rename one of them")
        names[submission.name] = submission
    return [names[name] for name in sorted(names)]


def _from_directory(directory: Path, name: str, work: Path) -> list[Submission]:
    if _holds_exercises(directory):
        return [_submission(name, sorted(directory.iterdir()), work)]
    found = []
    for number, entry in enumerate(sorted(directory.iterdir())):
        if entry.name.startswith((".", "__")):
            continue
        if entry.is_dir() and _holds_exercises(entry):
            found.append(_submission(entry.name, sorted(entry.iterdir()), work / str(number)))
        elif entry.is_file() and entry.suffix.lower() == ".zip":
            found.extend(_from_zip(entry, work / str(number)))
    if not found:
        raise GradeError(f"{directory} holds no submission: {WHAT_A_SUBMISSION_IS}")
    return found


def _from_zip(path: Path, work: Path) -> list[Submission]:
    if not zipfile.is_zipfile(path):
        raise GradeError(f"{path} is not a zip file (or is damaged): {WHAT_A_SUBMISSION_IS}")
    root = work / "unzipped"
    with zipfile.ZipFile(path) as archive:
        if sum(member.file_size for member in archive.infolist()) > _MAX_UNZIPPED:
            raise GradeError(f"{path} unpacks to more than {_MAX_UNZIPPED >> 20} MB: that is not a submission")
        archive.extractall(root)            # member names with .. or a leading / stay inside `root`
    entries = [entry for entry in root.iterdir() if not entry.name.startswith((".", "__"))]
    if len(entries) == 1 and entries[0].is_dir() and _holds_exercises(entries[0]):
        root = entries[0]                   # alice.zip holding alice/ex1.py ...: the submission is "alice"
    try:
        return _from_directory(root, path.stem, work / "files")
    except GradeError:
        raise GradeError(f"{path} holds no submission: {WHAT_A_SUBMISSION_IS}") from None


def _exercise_of(path: Path) -> str | None:
    """The exercise a file is for: ex1.py, demo1_monitor.py, or a notebook's {"appsim": {"exercise": ...}}."""
    if path.suffix == ".py":
        return next((ex for ex, name in EXERCISE_FILES.items() if name == path.name), None)
    if path.suffix == ".ipynb":
        try:
            exercise = json.loads(path.read_text(encoding="utf-8"))["metadata"]["appsim"]["exercise"]
        except (OSError, ValueError, KeyError, TypeError):
            exercise = path.stem.removesuffix("_monitor")
        return exercise if exercise in EXERCISE_FILES else None
    return None


def _holds_exercises(directory: Path) -> bool:
    return any(entry.is_file() and _exercise_of(entry) for entry in directory.iterdir())


def _submission(name: str, entries: Iterable[Path], work: Path) -> Submission:
    files: dict[str, Path] = {}
    problems: dict[str, str] = {}
    notebooks = []
    for entry in entries:
        exercise = _exercise_of(entry) if entry.is_file() else None
        if exercise is None:
            continue
        if entry.suffix == ".py":
            files[exercise] = entry.resolve()
        else:
            notebooks.append((exercise, entry))
    for exercise, notebook in notebooks:
        if exercise in files:
            continue                        # the .py file handed in next to it wins
        try:
            source = firmware_from_notebook(notebook)
        except GradeError as error:
            problems[exercise] = str(error)
            continue
        target = work / "notebooks" / exercise / EXERCISE_FILES[exercise]
        target.parent.mkdir(parents=True, exist_ok=True)
        target.write_text(source, encoding="utf-8")
        files[exercise] = target
    return Submission(name, files, problems)


def firmware_from_notebook(path: Path) -> str:
    """The Python of a notebook's cells tagged `firmware`; IPython magics (`%%writefile ex1.py`) become comments."""
    try:
        cells = json.loads(path.read_text(encoding="utf-8"))["cells"]
    except (OSError, ValueError, KeyError, TypeError):
        raise GradeError(f"{path.name} is not a Jupyter notebook that can be read") from None
    sources = []
    for cell in cells:
        if cell.get("cell_type") == "code" and "firmware" in cell.get("metadata", {}).get("tags", []):
            source = cell.get("source", "")
            source = "".join(source) if isinstance(source, list) else str(source)
            sources.append("\n".join(f"# {line}" if line.lstrip().startswith(("%", "!")) else line
                                     for line in source.splitlines()))
    if not sources:
        raise GradeError(f"{path.name} has no code cell tagged `firmware`: the notebook's firmware cell carries "
                         "that tag (View > Cell Toolbar > Tags in Jupyter)")
    return "\n\n".join(sources) + "\n"


# ====================================================================== grading one submission

def grade_submission(submission: Submission, seed: int, sandbox: Sandbox, limits: Limits = DEFAULT_LIMITS) -> dict[str, Any]:
    """Every exercise of `submission` checked with its firmware in `sandbox`: the submission's record."""
    exercises = {exercise: _grade_exercise(exercise, submission, seed, sandbox, limits)
                 for exercise in EXERCISE_FILES}
    return {"submission": submission.name,
            "score": sum(e["score"] for e in exercises.values()),
            "max_score": sum(e["max_score"] for e in exercises.values()),
            "seed": seed, "exercises": exercises}


def _grade_exercise(exercise: str, submission: Submission, seed: int, sandbox: Sandbox,
                    limits: Limits) -> dict[str, Any]:
    from appsim.workshop.checks import check

    path = submission.files.get(exercise)
    if path is None:
        reason = submission.problems.get(exercise) or (
            f"{EXERCISE_FILES[exercise]} is missing from this submission: nothing to grade for {exercise}")
        return _zero(exercise, seed, "missing", reason)
    firmware = RemoteFirmware(sandbox, path, limits)
    try:
        verdict = check(exercise, firmware, seed=seed, message_id=station_id(exercise, path))
        failure = ""
    except Exception as error:          # the checks themselves failed: still a record, never a lost class
        verdict, failure = None, f"the checks could not judge this firmware: {type(error).__name__}: {error}"
    finally:
        firmware.close()
    if firmware.fault is not None:
        return _zero(exercise, seed, firmware.fault.kind, firmware.fault.message)
    if verdict is None:
        return _zero(exercise, seed, "grader", failure)
    return {"score": verdict.score, "max_score": verdict.max_score, "fault": None,
            "checks": [{"name": c.name, "passed": c.passed, "message": c.message, "points": c.points}
                       for c in verdict.checks]}


def _zero(exercise: str, seed: int, fault: str, reason: str) -> dict[str, Any]:
    """No marks for `exercise`, for `reason`; its checks listed as not judged."""
    from appsim.workshop.checks import check

    listing = check(exercise, _NOWHERE / EXERCISE_FILES[exercise], seed=seed)     # every check, none passed
    first, *rest = listing.checks
    checks = [{"name": first.name, "passed": False, "message": reason, "points": first.points}]
    checks += [{"name": c.name, "passed": False, "message": _ZERO, "points": c.points} for c in rest]
    return {"score": 0, "max_score": listing.max_score, "fault": fault, "checks": checks}


def station_id(exercise: str, path: Path) -> int | None:
    """The MESSAGE_ID1 a firmware file assigns (Ex5: its RTR_ID's station's), read from its source, never run."""
    try:
        tree = ast.parse(path.read_text(encoding="utf-8"))
    except (OSError, SyntaxError, ValueError):
        return None
    values = _top_level_integers(tree)
    rtr_id = values.get("RTR_ID")
    if exercise == "ex5" and rtr_id in RTR_IDS:
        return STATION_IDS[RTR_IDS.index(rtr_id)]
    return values.get("MESSAGE_ID1")


def _top_level_integers(tree: ast.Module) -> dict[str, int]:
    """`NAME = <integer expression>` at the top of a file, evaluated without running it (+ - * << >> | & ^)."""
    operators = {ast.Add: int.__add__, ast.Sub: int.__sub__, ast.Mult: int.__mul__, ast.LShift: int.__lshift__,
                 ast.RShift: int.__rshift__, ast.BitOr: int.__or__, ast.BitAnd: int.__and__, ast.BitXor: int.__xor__}
    values: dict[str, int] = {}

    def value(node: ast.expr) -> int:
        if isinstance(node, ast.Constant) and type(node.value) is int:
            return node.value
        if isinstance(node, ast.Name) and node.id in values:
            return values[node.id]
        if isinstance(node, ast.BinOp) and type(node.op) in operators:
            left, right = value(node.left), value(node.right)
            if isinstance(node.op, ast.LShift) and not 0 <= right <= 64:
                raise ValueError("shift")
            return operators[type(node.op)](left, right)
        if isinstance(node, ast.UnaryOp) and isinstance(node.op, ast.USub):
            return -value(node.operand)
        raise ValueError("not an integer expression")

    for statement in tree.body:
        if isinstance(statement, ast.Assign) and len(statement.targets) == 1:
            target, expression = statement.targets[0], statement.value
        elif isinstance(statement, ast.AnnAssign) and statement.value is not None:
            target, expression = statement.target, statement.value
        else:
            continue
        if isinstance(target, ast.Name):
            try:
                values[target.id] = value(expression)
            except ValueError:
                values.pop(target.id, None)
    return values


# ====================================================================== worker processes

def worker() -> None:
    """A grading process: tasks as JSON lines on stdin, one record per line on stdout (see `_graded`)."""
    signal.signal(signal.SIGINT, signal.SIG_IGN)        # Ctrl-C is the coordinator's to handle
    replies = os.fdopen(os.dup(1), "w", encoding="utf-8")
    os.dup2(2, 1)                                       # nothing printed in here can break a reply
    with Sandbox() as sandbox:
        for line in sys.stdin:
            task = json.loads(line)
            submission = Submission(task["name"], {e: Path(p) for e, p in task["files"].items()}, task["problems"])
            record = grade_submission(submission, task["seed"], sandbox, Limits(**task["limits"]))
            replies.write(json.dumps(record) + "\n")
            replies.flush()


def _graded(submissions: Sequence[Submission], seed: int, limits: Limits, jobs: int) -> Iterator[dict[str, Any]]:
    """Records as the workers finish them (in no fixed order)."""
    if not submissions:                  # everything was graded before (a resumed run): start no worker
        return
    waiting = deque(submissions)
    workers = [subprocess.Popen([sys.executable, "-c", "from appsim.workshop.grade import worker; worker()"],
                                stdin=subprocess.PIPE, stdout=subprocess.PIPE, text=True, encoding="utf-8")
               for _ in range(max(1, min(jobs, len(submissions))))]
    selector = selectors.DefaultSelector()
    busy: dict[subprocess.Popen, str] = {}

    def give(process: subprocess.Popen) -> None:
        assert process.stdin is not None
        if not waiting:
            selector.unregister(process.stdout)     # type: ignore[arg-type]
            process.stdin.close()
            return
        submission = waiting.popleft()
        task = {"name": submission.name, "files": {e: str(p) for e, p in submission.files.items()},
                "problems": submission.problems, "seed": seed,
                "limits": {"time_s": limits.time_s, "stall_s": limits.stall_s, "memory_mb": limits.memory_mb}}
        process.stdin.write(json.dumps(task) + "\n")
        process.stdin.flush()
        busy[process] = submission.name

    try:
        for process in workers:
            selector.register(process.stdout, selectors.EVENT_READ, process)    # type: ignore[arg-type]
            give(process)
        while busy:
            for key, _ in selector.select():
                process = key.data
                line = process.stdout.readline()
                if not line:
                    raise GradeError(f"a grading process died while grading {busy[process]!r} (see the errors "
                                     "above); rerun the same command to resume")
                del busy[process]
                yield json.loads(line)
                give(process)
    finally:
        for process in workers:
            if process.poll() is None:
                process.kill()
            process.wait()
        selector.close()


# ====================================================================== results

def load_results(path: Path) -> list[dict[str, Any]]:
    """The records of a JSON-lines results file (an unfinished last line, from a kill, is dropped)."""
    if not path.exists():
        return []
    records = []
    text = path.read_text(encoding="utf-8")
    complete = text[:text.rfind("\n") + 1]
    if complete != text:
        with open(path, "r+", encoding="utf-8") as file:     # the line being written when the run was killed
            file.truncate(len(complete.encode("utf-8")))
    for number, line in enumerate(complete.splitlines(), start=1):
        if not line.strip():
            continue
        try:
            record = json.loads(line)
            record["submission"], record["seed"]
        except (ValueError, KeyError, TypeError):
            raise GradeError(f"{path}, line {number}, is not a grade record: give --json a results file written "
                             "by `appsim grade`, or a new file name") from None
        records.append(record)
    return records


def _append(file: TextIO, record: dict[str, Any]) -> None:
    file.write(json.dumps(record, sort_keys=True) + "\n")
    file.flush()
    os.fsync(file.fileno())


def write_results(path: Path, records: Iterable[dict[str, Any]]) -> None:
    """All records, sorted by submission, replacing `path` in one step."""
    temporary = path.with_name(path.name + ".tmp")
    with open(temporary, "w", encoding="utf-8") as file:
        file.writelines(json.dumps(record, sort_keys=True) + "\n" for record in sorted(records, key=lambda r: r["submission"]))
        file.flush()
        os.fsync(file.fileno())
    os.replace(temporary, path)


def write_csv(path: Path, records: Sequence[dict[str, Any]]) -> None:
    """The gradebook: one row per submission, a column per exercise, the total and the maximum."""
    with open(path, "w", newline="", encoding="utf-8") as file:
        writer = csv.writer(file)
        writer.writerow(["submission", *EXERCISE_FILES, "total", "max_score"])
        for record in sorted(records, key=lambda r: r["submission"]):
            writer.writerow([record["submission"], *(record["exercises"][e]["score"] for e in EXERCISE_FILES),
                             record["score"], record["max_score"]])


def gradescope(record: dict[str, Any]) -> dict[str, Any]:
    """One submission as Gradescope's results.json: a test per exercise, its checks in the output."""
    tests = []
    for exercise, result in record["exercises"].items():
        lines = [f"{'PASS' if c['passed'] else 'FAIL'}  {c['name']}: {c['message']}" for c in result["checks"]]
        tests.append({"name": exercise, "score": result["score"], "max_score": result["max_score"],
                      "output": "\n".join(lines),
                      "status": "passed" if result["score"] == result["max_score"] else "failed"})
    return {"score": record["score"], "output": f"Graded by appsim with seed {record['seed']}.", "tests": tests}


def write_gradescope(path: Path, records: Sequence[dict[str, Any]]) -> None:
    """One submission: `path` is its results.json. More: `path` is a directory of NAME.json, one per submission."""
    if len(records) == 1:
        path.write_text(json.dumps(gradescope(records[0]), indent=1) + "\n", encoding="utf-8")
        return
    path.mkdir(parents=True, exist_ok=True)
    for record in records:
        (path / f"{record['submission']}.json").write_text(json.dumps(gradescope(record), indent=1) + "\n",
                                                           encoding="utf-8")


# ====================================================================== the command

def summary_line(record: dict[str, Any]) -> str:
    """One submission on one terminal line: its total and each exercise (with the fault that zeroed it)."""
    parts = []
    for exercise, result in record["exercises"].items():
        fault = result.get("fault")
        parts.append(f"{exercise} {result['score']}/{result['max_score']}"
                     + (f" ({fault})" if fault and fault != "missing" else "" if not fault else " (-)"))
    return f"{record['submission']:<24} {record['score']:>3}/{record['max_score']:<3}  " + "  ".join(parts)


def run(paths: Sequence[str | Path], *, results: Path = DEFAULT_RESULTS, csv_path: Path | None = None,
        gradescope_path: Path | None = None, jobs: int | None = None, seed: int | None = None,
        limits: Limits = DEFAULT_LIMITS, out: TextIO = sys.stdout) -> list[dict[str, Any]]:
    """Grade the submissions under `paths`, resuming from `results`; the records of these submissions, by name."""
    import tempfile

    with tempfile.TemporaryDirectory(prefix="appsim-grade-") as work:
        submissions = find_submissions(paths, Path(work))
        previous = load_results(results)
        seeds = {record["seed"] for record in previous}
        if len(seeds) > 1:
            raise GradeError(f"{results} holds grades made with different seeds ({', '.join(map(str, sorted(seeds)))}); "
                             "give --json a new file to grade afresh")
        if seeds and seed is not None and seed not in seeds:
            raise GradeError(f"{results} holds grades made with seed {seeds.pop()}, not {seed}: resume with that "
                             "seed (or without --seed), or give --json a new file to grade afresh with this one")
        if seed is None:
            seed = seeds.pop() if seeds else random.SystemRandom().randrange(2**32)
        done = {record["submission"]: record for record in previous}
        todo = [s for s in submissions if s.name not in done]
        resumed = len(submissions) - len(todo)
        print(f"appsim grade: {len(submissions)} submission(s), seed {seed} (the same seed gives the same grades), "
              f"results in {results}" + (f"; {resumed} already graded there, not regraded" if resumed else ""),
              file=out, flush=True)
        with open(results, "a", encoding="utf-8") as file:
            for number, record in enumerate(_graded(todo, seed, limits, jobs or os.cpu_count() or 1), start=1):
                _append(file, record)
                done[record["submission"]] = record
                print(f"[{resumed + number}/{len(submissions)}] {summary_line(record)}", file=out, flush=True)
    write_results(results, done.values())
    records = [done[s.name] for s in submissions]
    if csv_path is not None:
        write_csv(csv_path, records)
    if gradescope_path is not None:
        write_gradescope(gradescope_path, records)
    total = sum(r["score"] for r in records)
    best = sum(r["max_score"] for r in records)
    print(f"graded {len(records)} submission(s): {total}/{best} points in all, "
          f"mean {total / max(1, len(records)):.1f}/{records[0]['max_score'] if records else 0}; seed {seed}; "
          f"results in {results}" + (f", gradebook {csv_path}" if csv_path else "")
          + (f", Gradescope {gradescope_path}" if gradescope_path else ""), file=out)
    return records
