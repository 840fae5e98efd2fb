"""A grading process: exercises to grade arrive as JSON lines on stdin, each verdict leaves as a line on stdout.

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
from typing import TYPE_CHECKING, Any

from appsim.workshop.course import EXERCISE_FILES
from appsim.workshop.faults import Fault
from appsim.workshop.sandbox.children import Limits, Sandbox
from appsim.workshop.sandbox.isolation import Isolation

if TYPE_CHECKING:
    from appsim.workshop.grading.results import Record


def main() -> None:
    """Settings on the first line (isolation, limits), then one task per line until stdin ends."""
    _die_with_the_grader()
    signal.signal(signal.SIGINT, signal.SIG_IGN)        # Ctrl-C is the coordinator's to handle
    replies = os.fdopen(os.dup(1), "w", encoding="utf-8")
    os.dup2(2, 1)                                       # nothing printed in here can break a reply
    settings = json.loads(sys.stdin.readline())
    isolation = None if settings["isolation"] is None else Isolation(**settings["isolation"])
    with Sandbox(isolation, Limits(**settings["limits"])) as sandbox:
        sandbox.warm()
        for module in ("appsim.workshop.checks", "appsim.workshop.sandbox.host"):    # while the sandbox boots
            importlib.import_module(module)

        for line in sys.stdin:
            task: dict[str, Any] = json.loads(line)
            source = None if task["source"] is None else base64.b64decode(task["source"])
            result = grade_exercise(sandbox, task["exercise"], task["name"], source, task["seed"], task["problem"],
                                    owner=task["owner"], spare=task["spare"])
            replies.write(json.dumps({"task": task["task"], "result": result}) + "\n")
            replies.flush()


def grade_exercise(sandbox: Sandbox, exercise: str, name: str, source: bytes | None, seed: int,
                   problem: dict[str, str] | None, *, owner: object = None, spare: bool = False) -> Record:
    """The record of one exercise: its firmware (`source`, handed in as `name`) checked in the sandbox of submission
    `owner`, or a zero; `spare` boots the next submission's sandbox meanwhile."""
    from appsim.workshop.checks import check, not_judged
    from appsim.workshop.sandbox.host import SandboxedFirmware

    if source is None:
        fault = Fault(**problem) if problem else Fault(
            "missing", f"{EXERCISE_FILES[exercise]} is missing from this submission: nothing to grade for {exercise}")
        return exercise_record(not_judged(exercise, seed, fault.kind, fault.message))
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


def _die_with_the_grader() -> None:
    """End this worker (and so, through --die-with-parent, its sandboxes) when the grader that started it ends,
    however it ends: PR_SET_PDEATHSIG on Linux; elsewhere the worker ends when its stdin does."""
    if not sys.platform.startswith("linux"):
        return
    import ctypes

    parent = os.getppid()
    ctypes.CDLL(None, use_errno=True).prctl(PR_SET_PDEATHSIG, signal.SIGKILL)
    if os.getppid() != parent:              # the grader ended before the call
        os._exit(1)


PR_SET_PDEATHSIG = 1


if __name__ == "__main__":
    main()
