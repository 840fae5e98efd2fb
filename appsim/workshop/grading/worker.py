"""A grading process: exercises to grade arrive as JSON lines on stdin, each verdict leaves as a line on stdout.

Its first sandboxed child starts booting before it loads the simulator; each exercise's firmware then runs in a fresh
child (see appsim.workshop.sandbox) while the board and the checks run here.
"""
from __future__ import annotations

import base64
import json
import os
import signal
import sys
from typing import Any

from appsim.workshop.sandbox.children import Limits, Sandbox
from appsim.workshop.sandbox.isolation import Isolation


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
        from appsim.workshop.grading.grade import grade_exercise  # the simulator loads while the child boots

        for line in sys.stdin:
            task: dict[str, Any] = json.loads(line)
            source = None if task["source"] is None else base64.b64decode(task["source"])
            result = grade_exercise(sandbox, task["exercise"], task["name"], source, task["seed"], task["problem"],
                                    owner=task["owner"], spare=task["spare"])
            replies.write(json.dumps({"task": task["task"], "result": result}) + "\n")
            replies.flush()


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
