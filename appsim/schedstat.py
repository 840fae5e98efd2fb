"""How a task spends its time, as Linux counts it in /proc/.../schedstat: on a CPU, or ready to run and waiting for
one. The rest of its time it slept. Where there is no schedstat (other systems), these give None.
"""
from __future__ import annotations

import os

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
