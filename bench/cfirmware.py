"""C firmware's speed: six C stations against six Python ones in the same classroom runs, and what translating and
loading a .c file costs (first in a process, then once the headers are known, then from the cache)."""
from __future__ import annotations

import statistics
import subprocess
import sys
import time

from appsim.bus.wire import Bus
from appsim.sim import Simulator
from appsim.workshop.classroom import Classroom
from appsim.workshop.course import C_FILES, SOLUTIONS


def classroom_run_s(language: str, seconds: float) -> float:
    """Wall seconds the classrooms of Ex2..Ex6 take to run `seconds` each, their stations' firmware in `language`
    (loading not counted)."""
    total = 0.0
    for exercise in range(2, 7):
        room = Classroom(Bus(Simulator(), 125_000), exercise, seed=exercise, language=language)
        started = time.perf_counter()
        room.run(seconds)
        total += time.perf_counter() - started
    return total


def first_load_ms() -> float:
    """A fresh Python that loads ex6.c: the translator imported, the kit's headers read, the file translated."""
    script = ("import time; from appsim.firmware.loader import load_firmware; t = time.perf_counter(); "
              f"load_firmware({str(SOLUTIONS / 'ex6.c')!r}); print(time.perf_counter() - t)")
    done = subprocess.run([sys.executable, "-c", script], check=True, capture_output=True, text=True)
    return 1000 * float(done.stdout.split()[-1])


def next_load_ms() -> float:
    """Each solution file translated and loaded, the headers known (the mean)."""
    from appsim.firmware import c18
    from appsim.firmware.loader import load_source

    c18.warm()
    times = []
    for name in C_FILES.values():
        source = (SOLUTIONS / name).read_bytes() + f"\n/* {time.perf_counter_ns()} */\n".encode()   # not cached
        started = time.perf_counter()
        load_source(SOLUTIONS / name, source)
        times.append(time.perf_counter() - started)
    return 1000 * statistics.mean(times)


_FRESH_CHILD = """
import gc, os, struct, sys, time
from appsim.firmware import c18
c18.warm()
gc.freeze()
path = sys.argv[1]
source = open(path, "rb").read()
read_end, write_end = os.pipe()
pid = os.fork()
if pid == 0:
    times = []
    for again in (b"", b"\\n/* again */\\n"):
        started = time.process_time()
        c18.translate(path, source + again, {}, ())
        times.append(1000 * (time.process_time() - started))
    os.write(write_end, struct.pack("dd", *times))
    os._exit(0)
os.close(write_end)
first, again = struct.unpack("dd", os.read(read_end, 16))
os.waitpid(pid, 0)
print(first, again)
"""


def fresh_child_ms() -> tuple[float, float]:
    """CPU ms to translate ex3.c in a child forked from a process that has the translator and the kit's headers
    loaded and its objects frozen (as a grading sandbox's zygote forks each exercise's child), and to translate it
    again in that child: what a translation pays for being the first in its process."""
    done = subprocess.run([sys.executable, "-c", _FRESH_CHILD, str(SOLUTIONS / "ex3.c")], check=True,
                          capture_output=True, text=True)
    first, again = map(float, done.stdout.split())
    return first, again


def cached_load_ms() -> float:
    from appsim.firmware.loader import load_firmware

    load_firmware(SOLUTIONS / "ex6.c")
    started = time.perf_counter()
    for _ in range(10):
        load_firmware(SOLUTIONS / "ex6.c")
    return 100 * (time.perf_counter() - started)
