"""One SHA-256 over everything the simulator shows: six classrooms, a demo-like room, two full-load runs, every check.

`python -m bench.fingerprint` prints it; a change that claims "same behaviour" must leave it as it was.
"""
from __future__ import annotations

import hashlib
import sys

EXERCISE_SECONDS = 1.0
FULL_LOAD_SECONDS = 0.01


def _room_lines(exercise: int) -> list[str]:
    from appsim.board.app023 import APP023
    from appsim.bus.wire import Bus
    from appsim.sim import Simulator
    from appsim.workshop.classroom import Classroom

    bus = Bus(Simulator(), 125_000)
    room = Classroom(bus, exercise, seed=exercise)
    room.run(EXERCISE_SECONDS)
    lines = [repr(event) for event in (*bus.trace, *bus.loopback_trace)]
    boards: list[APP023] = room.boards
    for board in boards:
        ecan = board.ecan
        registers = " ".join(f"{name}={ecan.get(name):02X}" for name in sorted(board.mcu.sfr_addresses)
                             if board.mcu.sfr_addresses[name] in range(0xF00, 0xF78))
        lines.append(f"{board.name} {registers} TEC={ecan.tec} REC={ecan.rec}")
        lines.append(board.glcd.text())
    return lines


def _full_load_lines() -> list[str]:
    from bench import fullload

    lines = []
    for one_sender in (False, True):
        result = fullload.run(7, 1.0, FULL_LOAD_SECONDS, one_sender=one_sender)
        lines.append(f"{result.frames} {result.mean_frame_bits!r} {result.bus_busy!r} {result.read_by_firmware!r}")
    return lines


def _verdict_lines(seed: int = 2024) -> list[str]:
    """The solutions' verdicts, each file named by its own name (as the grader names it), wherever the kit is."""
    import os

    from appsim.workshop.checks import check
    from appsim.workshop.course import EXERCISE_FILES, SOLUTIONS

    here = os.getcwd()
    os.chdir(SOLUTIONS)
    try:
        return [str(check(exercise, name, seed=seed)) for exercise, name in EXERCISE_FILES.items()]
    finally:
        os.chdir(here)


def parts() -> dict[str, str]:
    """Each part's own digest (to tell which part changed)."""
    sections = {f"ex{n}": _room_lines(n) for n in range(1, 7)}
    sections["full load"] = _full_load_lines()
    sections["checks"] = _verdict_lines()
    return {name: hashlib.sha256("\n".join(lines).encode()).hexdigest() for name, lines in sections.items()}


def main() -> None:
    digests = parts()
    for name, digest in digests.items():
        print(f"{name:>10}  {digest[:16]}")
    whole = hashlib.sha256("".join(digests.values()).encode()).hexdigest()
    print(f"{'all':>10}  {whole}")
    sys.stdout.flush()


if __name__ == "__main__":
    main()
