"""`appsim grade`: a class's submissions, exercise by exercise, each firmware in its own sandbox, in parallel workers.

The coordinator reads the submissions, checks every output path, makes sure the machine can isolate firmware, resumes
from the results file, hands exercises to worker processes and keeps each submission's record as soon as it is whole.
"""
from __future__ import annotations

import base64
import collections
import dataclasses
import functools
import json
import os
import random
import selectors
import signal
import sys
import tempfile
import time
from collections.abc import Callable, Iterator, Sequence
from contextlib import contextmanager
from pathlib import Path
from typing import IO, Any, NamedTuple, TextIO

from appsim import provenance
from appsim.errors import GradeError, OutputError, SandboxUnavailable
from appsim.output import cannot_write, check_distinct
from appsim.workshop.course import EXERCISE_FILES, EXERCISES
from appsim.workshop.grading.results import (
    Record,
    ResultsFile,
    check_output,
    default_results,
    kit_version,
    printable,
    record_of,
    still_valid,
    summary_line,
    write_csv,
    write_gradescope,
)
from appsim.workshop.grading.submissions import Submission, find_submissions
from appsim.workshop.grading.worker import exercise_record, start_worker
from appsim.workshop.sandbox.children import BOOT_S, DEFAULT_LIMITS, Limits
from appsim.workshop.sandbox.isolation import Isolation, isolation

SLACK_S = 30.0                      # a worker may take this much longer than an exercise's own limits, then it is ended
ORDER = ("demo1", *(e for e in EXERCISES if e != "demo1"))      # the longest first: the last submission's others
#                                                                 may go to another worker, so the workers end together


# ====================================================================== the command

def run(paths: Sequence[str | Path], *, results: Path | None = None, csv_path: Path | None = None,
        gradescope_path: str | Path | None = None, jobs: int | None = None, seed: int | None = None,
        limits: Limits = DEFAULT_LIMITS, trusted: bool = False, regrade: bool = False,
        out: TextIO = sys.stdout, memory: dict[tuple[str, str], Memory] | None = None) -> list[Record]:
    """Grade the submissions under `paths`, resuming from `results`; the records of these submissions, by name.

    `gradescope_path` is a folder of NAME.json (for several submissions, or given as a folder: one that exists or a
    name ending in "/"), else the one submission's results.json. `memory`, if given, gets the grading worker's memory
    for each (submission, exercise) graded (see `Memory`)."""
    if sys.platform == "win32":
        raise GradeError("appsim grade runs on Linux (or macOS with --trusted); on Windows, run it in WSL")
    results = results or default_results([Path(p) for p in paths])
    gradescope = None if gradescope_path is None else Path(gradescope_path)
    try:
        check_distinct([("--json", results), ("--csv", csv_path), ("--gradescope", gradescope)],
                       [("PATH", Path(p)) for p in paths])
    except OutputError as error:
        raise GradeError(str(error)) from None
    check_output(results, "the results file (--json)")
    if csv_path is not None:
        check_output(csv_path, "the gradebook (--csv)")
    walls = None if trusted else _walls([*map(Path, paths), results, csv_path, gradescope])
    with _Pool(limits, walls, jobs) as pool:           # the workers load while the submissions are read
        submissions = find_submissions([Path(p) for p in paths])
        gradescope_folder = gradescope is not None and (len(submissions) != 1 or gradescope.is_dir()
                                                        or str(gradescope_path).endswith(("/", os.sep)))
        if gradescope is not None:
            check_output(gradescope, "the Gradescope output (--gradescope)", folder=gradescope_folder)
        kit = kit_version() + "".join(f" {option}" for option in limits.c_options)   # C18's -Oi grades otherwise
        commit = provenance.commit()
        book = ResultsFile(results)
        try:
            previous = book.records()
            if seed is None:
                seeds = collections.Counter(previous[s.name]["seed"] for s in submissions if s.name in previous)
                seed = seeds.most_common(1)[0][0] if seeds else random.SystemRandom().randrange(2**32)
            todo = [s for s in submissions if regrade or not still_valid(previous.get(s.name), s.digest, seed, kit)]
            kept = len(submissions) - len(todo)
            print(f"appsim grade: {len(submissions)} submission(s), seed {seed} (the same seed gives the same "
                  f"grades), kit {kit} (git commit {commit or 'unknown'}), results in {results}"
                  + (f"; {kept} already graded there with this seed and kit, kept" if kept else "")
                  + ("; NOT ISOLATED (--trusted)" if trusted else ""), file=out, flush=True)
            for submission in submissions:
                if submission.note:
                    print(f"appsim grade: {printable(submission.name)}: {printable(submission.note)}", file=out)
            for number, record in enumerate(pool.grade(todo, seed, kit, commit, memory), start=1):
                with _ctrl_c_held():                # a record kept is a record reported, and the other way round
                    _writing(results, functools.partial(book.append, record))
                    previous[record["submission"]] = record
                    print(f"[{kept + number}/{len(submissions)}] {summary_line(record)}", file=out, flush=True)
            book.rewrite(previous.values())
        finally:
            book.close()
    records = [previous[s.name] for s in submissions]
    if csv_path is not None:
        _writing(csv_path, functools.partial(write_csv, csv_path, records))
    if gradescope is not None:
        _writing(gradescope, functools.partial(write_gradescope, gradescope, records, folder=gradescope_folder))
    total, best = sum(r["score"] for r in records), sum(r["max_score"] for r in records)
    print(f"graded {len(todo)} submission(s)" + (f", kept {kept} already graded" if kept else "")
          + f": {total}/{best} points in all" + (f" {len(records)}" if kept else "")
          + f", mean {total / max(1, len(records)):.1f}/{records[0]['max_score'] if records else 0}; seed {seed}; "
          f"results in {results}"
          + (f", gradebook {csv_path}" if csv_path else "")
          + (f", Gradescope {gradescope}{'/' if gradescope_folder else ''}" if gradescope else ""), file=out)
    return records


def _writing(path: Path, write: Callable[[], None]) -> None:
    """`write()`, a failure said in the workshop's words (a full disk: the grades so far are kept, the same command
    again resumes)."""
    try:
        write()
    except OSError as error:
        raise GradeError(f"{cannot_write(path, error)}. The grades so far are kept in the results file: make room and "
                         "run the same command again to resume") from None


def _walls(secrets: Sequence[Path | None]) -> Isolation:
    try:
        return isolation([path for path in secrets if path is not None])
    except SandboxUnavailable as error:
        raise GradeError(f"this machine cannot isolate student firmware: {error}. Nothing was graded. Grade on a "
                         "Linux machine with bubblewrap, or, for a class whose code you trust (your own test "
                         "submissions), add --trusted to run it without isolation (docs/grading.md)") from None


# ====================================================================== the workers

@dataclasses.dataclass
class _Task:
    number: int
    submission: Submission
    exercise: str

    def line(self, seed: int, others_follow: bool) -> str:
        """The task for a worker; `others_follow` says whether other submissions' tasks wait after it."""
        name, source = self.submission.files.get(self.exercise, (EXERCISE_FILES[self.exercise], None))
        problem = self.submission.problems.get(self.exercise)
        return json.dumps({"task": self.number, "exercise": self.exercise, "name": name, "seed": seed,
                           "owner": self.submission.name, "spare": others_follow,
                           "source": None if source is None else base64.b64encode(source).decode(),
                           "problem": None if problem is None else dataclasses.asdict(problem)}) + "\n"


class _Worker:
    """One grading process, its task now, and where its errors go (read only if it dies).

    On Linux each worker keeps to one processor, and its sandboxed children with it: a register read hands the
    processor from one to the other and back, which is cheaper on one processor than across two.
    """

    def __init__(self, settings: dict[str, Any], processor: int | None):
        self.log: IO[bytes] = tempfile.TemporaryFile()
        self.pid, self.stdin, self.stdout = start_worker(settings, self.log.fileno(), processor)
        self.status: int | None = None
        self.task: _Task | None = None
        self.submission: Submission | None = None      # the one whose exercises it grades (its sandbox's)
        self.deadline = 0.0

    def give(self, task: _Task, seed: int, allowed_s: float, others_follow: bool) -> None:
        self.task, self.submission = task, task.submission
        self.deadline = time.monotonic() + allowed_s
        self.stdin.write(task.line(seed, others_follow))
        self.stdin.flush()

    def why_it_died(self) -> str:
        """The last line it wrote to its log (a traceback's), once it has ended; then `end`."""
        self._reap()
        self.log.seek(0)
        lines = self.log.read().decode("utf-8", "replace").strip().splitlines()
        self.end()
        return lines[-1] if lines else f"it ended with status {self.status}"

    def end(self) -> None:
        self._reap()
        for stream in (self.stdin, self.stdout, self.log):
            try:
                stream.close()
            except OSError:
                pass

    def _reap(self) -> None:
        if self.status is None:
            try:
                os.kill(self.pid, signal.SIGKILL)
            except ProcessLookupError:
                pass
            self.status = os.waitstatus_to_exitcode(os.waitpid(self.pid, 0)[1])


@contextmanager
def _ctrl_c_held() -> Iterator[None]:
    """Ctrl-C (SIGINT) during the block takes effect when it ends. The grader's one thread holds it back; where signals
    cannot be held (Windows), the block runs as it is."""
    if not hasattr(signal, "pthread_sigmask"):
        yield
        return
    held = signal.pthread_sigmask(signal.SIG_BLOCK, {signal.SIGINT})
    try:
        yield
    finally:
        signal.pthread_sigmask(signal.SIG_SETMASK, held)


class _Pool:
    """The grading workers: started at once (they load the simulator meanwhile), given exercises one at a time."""

    def __init__(self, limits: Limits, walls: Isolation | None, jobs: int | None):
        self.limits = limits
        self.settings = {"isolation": None if walls is None else dataclasses.asdict(walls),
                         "limits": dataclasses.asdict(limits)}
        self.processors = sorted(os.sched_getaffinity(0)) if hasattr(os, "sched_getaffinity") else []
        self.count = max(1, jobs or len(self.processors) or os.cpu_count() or 1)
        self.workers = [self._worker(k) for k in range(self.count)]
        self.restarts = 0

    def __enter__(self) -> _Pool:
        return self

    def __exit__(self, *exc: object) -> None:
        for worker in self.workers:
            worker.end()

    def grade(self, submissions: Sequence[Submission], seed: int, kit: str, commit: str | None,
              memory: dict[tuple[str, str], Memory] | None = None) -> Iterator[Record]:
        """Each submission's record as soon as all its exercises are graded (in no fixed order); `memory` gets what
        each exercise's worker held (see `Memory`)."""
        waiting = collections.deque(_Task(n, s, e) for n, (s, e) in
                                    enumerate((s, e) for s in submissions for e in ORDER))
        done: dict[str, dict[str, Record]] = {s.name: {} for s in submissions}
        allowed_s = self.limits.wall_s + BOOT_S + SLACK_S
        selector = selectors.DefaultSelector()

        def next_task(worker: _Worker) -> None:
            if waiting:
                task = _next_for(worker, waiting, [w.submission for w in self.workers if w is not worker])
                worker.give(task, seed, allowed_s, bool(waiting) and waiting[-1].submission is not task.submission)
                selector.register(worker.stdout, selectors.EVENT_READ, worker)

        def finish(task: _Task, result: Record) -> Record | None:
            marks = done[task.submission.name]
            marks[task.exercise] = result
            if len(marks) < len(EXERCISES):
                return None
            return record_of(task.submission.name, task.submission.digest, seed, kit, marks, commit,
                             task.submission.origin)

        try:
            for worker in self.workers:
                next_task(worker)
            while any(worker.task is not None for worker in self.workers):
                timeout = max(0.0, min(w.deadline for w in self.workers if w.task is not None) - time.monotonic())
                for key, _ in selector.select(timeout):
                    worker = key.data
                    line = worker.stdout.readline()
                    selector.unregister(worker.stdout)
                    task, worker.task = worker.task, None
                    assert task is not None
                    result, held = _result(line)
                    if held is not None and memory is not None:
                        memory[task.submission.name, task.exercise] = held
                    # it died (or wrote half a line): the grader's fault, not the student's
                    if result is None:
                        result = _lost(task, seed, "the grader's worker process ended while grading it "
                                                   f"({worker.why_it_died()})")
                        worker = self._replace(worker)
                    record = finish(task, result)
                    if record is not None:
                        yield record
                    next_task(worker)
                now = time.monotonic()
                for worker in list(self.workers):
                    if worker.task is not None and now > worker.deadline:
                        selector.unregister(worker.stdout)
                        task, worker.task = worker.task, None
                        replacement = self._replace(worker)
                        record = finish(task, _lost(task, seed, f"the grader did not finish it within {allowed_s:g} s"))
                        if record is not None:
                            yield record
                        next_task(replacement)
        finally:
            selector.close()

    def _replace(self, worker: _Worker) -> _Worker:
        """A new worker in place of one that died or hung."""
        worker.end()
        self.restarts += 1
        if self.restarts > 3 * self.count + 3:
            raise GradeError(f"the grader's worker processes keep ending ({self.restarts} so far): something is wrong "
                             "with this installation; run the same command again to resume what was graded")
        index = self.workers.index(worker)
        replacement = self.workers[index] = self._worker(index)
        return replacement

    def _worker(self, index: int) -> _Worker:
        return _Worker(self.settings, self.processors[index % len(self.processors)] if self.processors else None)


def _next_for(worker: _Worker, waiting: collections.deque[_Task], others: list[Submission | None]) -> _Task:
    """The task `worker` takes next (removed from `waiting`): the next of the submission it grades, else the first of
    one no other worker grades, else the first. A submission's exercises are graded in one worker, and so in one
    sandbox: its sandbox boots once (and loads the C translator once), where two workers would boot one each."""
    index = next((i for i, t in enumerate(waiting) if t.submission is worker.submission), None)
    if index is None:
        index = next((i for i, t in enumerate(waiting) if not any(t.submission is o for o in others)), 0)
    task = waiting[index]
    del waiting[index]
    return task


class Memory(NamedTuple):
    """What a grading worker held (its resident set, kB) when it took an exercise, and at its peak while grading it."""

    start_kb: int
    peak_kb: int

    @property
    def growth_kb(self) -> int:
        return self.peak_kb - self.start_kb


def _result(line: str) -> tuple[Record | None, Memory | None]:
    """A worker's answer line (None if it is not one: the worker died mid-line) and the memory it held for it."""
    if not line.endswith("\n"):
        return None, None
    try:
        answer = json.loads(line)
        result, held = answer["result"], answer.get("memory_kb")
    except (ValueError, KeyError, TypeError, AttributeError):
        return None, None
    memory = Memory(*held) if isinstance(held, list) and len(held) == 2 and all(isinstance(v, int) for v in held) \
        else None
    return (result if isinstance(result, dict) else None), memory


def _lost(task: _Task, seed: int, why: str) -> Record:
    """The record of an exercise the grader itself failed on (not the student's doing)."""
    from appsim.workshop.checks import not_judged

    name = printable(task.submission.name)
    print(f"appsim grade: {name} {task.exercise}: {why}", file=sys.stderr, flush=True)
    return exercise_record(not_judged(task.exercise, seed, "grader", f"not graded: {why}. Grade it again"))
