"""One submission's sandbox, inside: a process that loaded the firmware library once and forks a fresh child for each
of that submission's exercises, so a firmware starts in milliseconds where booting Python takes a tenth of a second.

It runs no firmware itself. The grader asks on the control socket (FORK, with the child's two pipe ends; FORK_C for a C
firmware, which first loads the C translator and the kit's headers, once per sandbox, unless it did at boot from the
headers' state the grader handed it); it answers FORKED with the child's number, and ENDED with how a child ended (its
status and CPU time) once it has.
"""
from __future__ import annotations

import gc
import json
import os
import select
import signal
import socket
import sys
from typing import Any

from appsim.workshop.sandbox import child
from appsim.workshop.sandbox.protocol import (
    ENDED,
    ENDED_MESSAGE,
    FORK,
    FORK_C,
    FORKED,
    FORKED_MESSAGE,
    HELLO,
    MAX_CONTROL,
    MAX_STATE,
)


def main(settings: dict[str, Any]) -> None:
    """Boot, say hello, then fork a child per request until the grader closes the control socket."""
    control = socket.socket(fileno=settings["control_fd"])
    null = os.open(os.devnull, os.O_RDWR)
    for standard in (0, 1, 2):          # what the firmware prints is never read
        os.dup2(null, standard)
    os.close(null)
    signal.signal(signal.SIGXFSZ, signal.SIG_IGN)       # a file too big fails with an error instead
    signal.signal(signal.SIGINT, signal.SIG_IGN)        # Ctrl-C is the grader's
    _not_dumpable()
    child.boot()
    if "c_state_fd" in settings:        # the grader's (the kit's own headers): read, and closed before any child
        child.boot_c(settings["c_options"], _read_all(settings["c_state_fd"]))
    gc.freeze()                         # what the children inherit is never collected there: not touched, not copied
    ended_r, ended_w = os.pipe()
    os.set_blocking(ended_w, False)
    signal.set_wakeup_fd(ended_w)
    signal.signal(signal.SIGCHLD, lambda *_: None)      # a child ended: the wake-up pipe says so
    control.send(HELLO)
    control_fd = control.fileno()
    while True:
        ready = select.select([control_fd, ended_r], [], [])[0]
        if ended_r in ready:
            os.read(ended_r, 512)
            _report_ended(control)
        if control_fd in ready:
            try:
                message, fds, _, _ = socket.recv_fds(control, MAX_CONTROL, 2)
            except OSError:             # the fds did not fit (a limit lowered from inside): no child this time
                message, fds = FORK, []
            if not message:
                return                  # the grader is done with this submission
            if message == FORK_C and child.boot_c(settings["c_options"]):
                gc.freeze()             # once: this child and every later one start with the headers parsed
            pid = (_fork(settings, fds, keep={control_fd, ended_r, ended_w})
                   if message in (FORK, FORK_C) and len(fds) == 2 else 0)
            for fd in fds:
                os.close(fd)
            control.send(FORKED_MESSAGE.pack(FORKED, pid))


def _fork(settings: dict[str, Any], fds: list[int], keep: set[int]) -> int:
    """A child for one firmware (its pid), 0 if none can be started."""
    try:
        pid = os.fork()
    except OSError:
        return 0
    if pid == 0:
        _child(settings, fds, keep)
    return pid


def _child(settings: dict[str, Any], fds: list[int], keep: set[int]) -> None:
    """In the forked child: nothing of the zygote's but the two pipes, then the firmware's life."""
    status = 1
    try:
        signal.set_wakeup_fd(-1)
        signal.signal(signal.SIGCHLD, signal.SIG_DFL)
        for fd in keep:
            os.close(fd)
        child.main(settings, fds[0], fds[1])
        status = 0
    finally:
        os._exit(status)


def _read_all(descriptor: int, most: int = MAX_STATE) -> bytes:
    chunks, size = [], 0
    while size <= most:
        chunk = os.read(descriptor, 1 << 16)
        if not chunk:
            break
        chunks.append(chunk)
        size += len(chunk)
    os.close(descriptor)
    return b"".join(chunks)


def _report_ended(control: socket.socket) -> None:
    while True:
        try:
            pid, status, usage = os.wait4(-1, os.WNOHANG)
        except ChildProcessError:
            return
        if pid == 0:
            return
        control.send(ENDED_MESSAGE.pack(ENDED, pid, os.waitstatus_to_exitcode(status),
                                        usage.ru_utime + usage.ru_stime))


def _not_dumpable() -> None:
    """No other process of this user may read or write this one's memory (/proc/PID/mem), nor its files in /proc."""
    if sys.platform.startswith("linux"):
        import ctypes

        ctypes.CDLL(None).prctl(PR_SET_DUMPABLE, 0, 0, 0, 0)


PR_SET_DUMPABLE = 4


if __name__ == "__main__":
    main(json.loads(sys.argv[1]))
