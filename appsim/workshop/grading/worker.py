"""A grading process, forked from the grader: exercises to grade arrive as JSON lines on one pipe, each verdict leaves
as a line on another.

Its first sandbox boots while it loads the simulator; each exercise's firmware then runs in a fresh process of its
submission's sandbox (see appsim.workshop.sandbox) while the board and the checks run here.
"""
from __future__ import annotations

import base64
import importlib
import json
import os
import signal
import sys
import traceback
from typing import IO, TYPE_CHECKING, Any, NamedTuple

from appsim.workshop.course import C_FILES, EXERCISE_FILES
from appsim.workshop.faults import Fault
from appsim.workshop.sandbox.children import Limits, Sandbox
from appsim.workshop.sandbox.isolation import Isolation

if TYPE_CHECKING:
    from appsim.workshop.grading.results import Record


class Started(NamedTuple):
    """A worker as its grader holds it: its process, the pipe its tasks go down, the pipe its verdicts come up."""

    pid: int
    tasks: IO[str]
    verdicts: IO[str]


def start_worker(settings: dict[str, Any], log: int, processor: int | None) -> Started:
    """Fork a worker (on `processor`, if given) that grades with `settings` (isolation, limits) and writes what goes
    wrong to file descriptor `log`. A fork, not a new Python: it starts with the grader's own kit already loaded."""
    tasks_r, tasks_w = os.pipe()
    verdicts_r, verdicts_w = os.pipe()
    grader = os.getpid()
    pid = os.fork()
    if pid == 0:
        _worker(grader, settings, tasks_r, verdicts_w, log, processor)
    os.close(tasks_r)
    os.close(verdicts_w)
    return Started(pid, os.fdopen(tasks_w, "w", encoding="utf-8"), os.fdopen(verdicts_r, "r", encoding="utf-8"))


def _worker(grader: int, settings: dict[str, Any], tasks: int, verdicts: int, log: int, processor: int | None) -> None:
    """The forked worker's life, which never returns into the grader's code: only its pipes and its log kept (a
    classmate's worker holds no end of them), then `main` until the tasks end."""
    import fcntl  # POSIX: the grader forks its workers on Linux and macOS only

    status = 1
    try:
        _die_with(grader)
        if hasattr(signal, "pthread_sigmask"):
            signal.pthread_sigmask(signal.SIG_SETMASK, ())      # none held back, whatever the grader was doing
        tasks, log, verdicts = (fcntl.fcntl(fd, fcntl.F_DUPFD, 4) for fd in (tasks, log, verdicts))   # out of the way
        os.dup2(tasks, 0)
        os.dup2(log, 1)                     # nothing printed in here can break a verdict
        os.dup2(log, 2)
        os.dup2(verdicts, 3)
        os.closerange(4, os.sysconf("SC_OPEN_MAX") if hasattr(os, "sysconf") else 1 << 16)
        sys.stdout = sys.stderr = open(2, "w", encoding="utf-8", errors="replace", closefd=False)
        if processor is not None:
            try:
                os.sched_setaffinity(0, {processor})
            except OSError:
                pass
        main(settings, open(0, encoding="utf-8", closefd=False), open(3, "w", encoding="utf-8", closefd=False))
        status = 0
    except BaseException:               # the grader records the lost exercise, with this traceback's last line
        traceback.print_exc()
        sys.stderr.flush()
    finally:
        os._exit(status)


def main(settings: dict[str, Any], tasks: IO[str], verdicts: IO[str]) -> None:
    """Grade each task (one JSON line) of `tasks`, until they end, with one verdict line each on `verdicts`."""
    signal.signal(signal.SIGINT, signal.SIG_IGN)        # Ctrl-C is the grader's to handle
    isolation = None if settings["isolation"] is None else Isolation(**settings["isolation"])
    with Sandbox(isolation, Limits(**settings["limits"])) as sandbox:
        sandbox.warm()
        for module in ("appsim.workshop.checks", "appsim.workshop.sandbox.host"):    # while the sandbox boots
            importlib.import_module(module)

        for line in tasks:
            task: dict[str, Any] = json.loads(line)
            source = None if task["source"] is None else base64.b64decode(task["source"])
            start_kb = memory_kb("VmRSS")
            _forget_peak()
            result = grade_exercise(sandbox, task["exercise"], task["name"], source, task["seed"], task["problem"],
                                    owner=task["owner"], spare=task["spare"])
            verdicts.write(json.dumps({"task": task["task"], "result": result,
                                       "memory_kb": [start_kb, memory_kb("VmHWM")]}) + "\n")
            verdicts.flush()


def _forget_peak() -> None:
    """Start this process's memory high-water mark again from what it holds now (Linux: clear_refs 5)."""
    try:
        with open("/proc/self/clear_refs", "w") as refs:
            refs.write("5")
    except OSError:
        pass


def memory_kb(which: str) -> int | None:
    """This process's resident set now (`VmRSS`), or its high-water mark since `_forget_peak` (`VmHWM`), in kB; None
    where the system does not say."""
    try:
        with open("/proc/self/status") as status:
            for line in status:
                if line.startswith(which + ":"):
                    return int(line.split()[1])
    except (OSError, ValueError, IndexError):
        pass
    return None


def grade_exercise(sandbox: Sandbox, exercise: str, name: str, source: bytes | None, seed: int,
                   problem: dict[str, str] | None, *, owner: object = None, spare: bool = False) -> Record:
    """The record of one exercise: its firmware (`source`, handed in as `name`) checked in the sandbox of submission
    `owner`, or a zero; `spare` boots the next submission's sandbox meanwhile."""
    from appsim.workshop.checks import check, not_judged
    from appsim.workshop.sandbox.host import SandboxedFirmware

    if source is None:
        fault = Fault(**problem) if problem else Fault(
            "missing", f"{EXERCISE_FILES[exercise]} is missing from this submission (and {C_FILES[exercise]}, its C "
                       f"twin): nothing to grade for {exercise}")
        return exercise_record(not_judged(exercise, seed, fault.kind, fault.message))
    if name.lower().endswith(".c") and sandbox.c_state is None:
        from appsim.firmware import c18  # the kit's own headers, parsed here once: every later sandbox adopts them
        sandbox.expect_c(c18.header_state(sandbox.limits.c_options))
    firmware = SandboxedFirmware(sandbox, name, source, sandbox.limits, owner=owner, spare=spare)
    try:
        verdict = check(exercise, firmware, seed=seed)
    except Exception as error:          # the checks themselves failed: still a record, never a lost class
        verdict = not_judged(exercise, seed, "grader", f"the checks could not judge this firmware: "
                                                       f"{type(error).__name__}: {error}")
    finally:
        firmware.close()
    return exercise_record(verdict)


def exercise_record(verdict: Any) -> Record:
    data = verdict.to_dict()
    return {"score": data["score"], "max_score": data["max_score"], "fault": data["fault"], "checks": data["checks"]}


def _die_with(grader: int) -> None:
    """End this worker (and so, through --die-with-parent, its sandboxes) when the grader that forked it ends, however
    it ends: PR_SET_PDEATHSIG on Linux; elsewhere the worker ends when its tasks pipe does."""
    if not sys.platform.startswith("linux"):
        return
    import ctypes

    ctypes.CDLL(None, use_errno=True).prctl(PR_SET_PDEATHSIG, signal.SIGKILL)
    if os.getppid() != grader:              # the grader ended before the call
        os._exit(1)


PR_SET_PDEATHSIG = 1

