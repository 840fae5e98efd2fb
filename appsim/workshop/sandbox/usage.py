"""What one exercise's firmware has used of its limits, as the kernel counts it: the grader's CPU time for it, and the
time the grader sat idle because the firmware's process neither computed nor waited for a CPU (it slept).

A busy machine slows both processes down but costs neither: time spent waiting for a CPU is nobody's fault.
"""
from __future__ import annotations

import os
import time
from dataclasses import dataclass

NS = 1e-9


def schedstat(path: str) -> int | None:
    """A descriptor of a task's /proc schedstat (time on a CPU, time waiting for one), or None where there is none."""
    try:
        fd = os.open(path, os.O_RDONLY | os.O_CLOEXEC)
    except OSError:
        return None
    if read_schedstat(fd) is None:
        os.close(fd)
        return None
    return fd


def read_schedstat(fd: int) -> tuple[float, float] | None:
    """(seconds on a CPU, seconds runnable and waiting for one); None once the task is gone."""
    try:
        fields = os.pread(fd, 128, 0).split()
        return int(fields[0]) * NS, int(fields[1]) * NS
    except (OSError, IndexError, ValueError):
        return None


@dataclass
class Used:
    """What has been used so far, in seconds."""

    grader_cpu: float
    idle: float | None          # None where the kernel does not tell (not Linux)


class Usage:
    """Counts from now: the grader's thread (this one) and the firmware's process (`pid`, None if not known)."""

    def __init__(self, pid: int | None):
        self._started = time.monotonic()
        self._grader = schedstat("/proc/thread-self/schedstat")
        self._firmware = schedstat(f"/proc/{pid}/schedstat") if pid is not None else None
        self._cpu_started = time.process_time()
        self._grader_at = self._at(self._grader)
        self._firmware_at = self._at(self._firmware)

    @staticmethod
    def _at(fd: int | None) -> tuple[float, float]:
        counts = None if fd is None else read_schedstat(fd)
        return counts or (0.0, 0.0)

    def used(self) -> Used:
        grader_cpu = time.process_time() - self._cpu_started
        if self._grader is None or self._firmware is None:
            return Used(grader_cpu, None)
        grader, firmware = read_schedstat(self._grader), read_schedstat(self._firmware)
        if grader is None or firmware is None:
            return Used(grader_cpu, None)
        busy = sum(now - then for now, then in zip(grader + firmware, self._grader_at + self._firmware_at, strict=True))
        return Used(grader_cpu, max(0.0, time.monotonic() - self._started - busy))

    def close(self) -> None:
        for fd in (self._grader, self._firmware):
            if fd is not None:
                os.close(fd)
        self._grader = self._firmware = None
