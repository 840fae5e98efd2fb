"""The benchmark suite runs in its tiny configuration and prints every row of its table (no timing asserted)."""
from __future__ import annotations

import subprocess
import sys
from pathlib import Path

import pytest

from bench import fullload

KIT = Path(__file__).resolve().parent.parent
ROWS = (
    "real-time factor: 7 nodes, 1 Mbit/s, 100 % load",
    "frames per wall second at that load",
    "real-time factor: 7 nodes, 1 Mbit/s, 100 % load, each reads one sender's frames",
    "real-time factor: 7 nodes, 125 kbit/s (the workshop's), 100 % load",
    "real-time factor: 14 nodes, 100% load",
    "real-time factor: 28 nodes, 100% load",
    "real-time factor: 7 nodes, 25% load",
    "full model / python-can virtual bus, 1 sender -> 6 receivers",
    "busy-wait on CANIsRxReady(), a frame every 100 ms",
    "busy-wait on CANIsRxReady(), no frames",
    "check one submission (solutions of Ex1..Ex6 and Demo1), in process",
    "appsim grade: one full submission (Ex1..Ex6, Demo1), sandboxed",
    "appsim grade: a class of 2 with --jobs 2",
    "grading worker's peak memory per exercise: the solutions",
    "grading worker's peak memory per exercise: firmware written to make the grader keep more",
    "the worst of them above the solutions' peak",
    "classroom at Ex6, the stations polling (solutions/)",
    "classroom at Ex6, the stations interrupt-driven (solutions/interrupts/)",
    "interrupts' cost in the Ex6 classroom (interrupt-driven / polling)",
    "appsim grade of Ex1, Ex3, Ex6, sandboxed: interrupt-driven / polling",
    "C: ex3.c translated in a child forked from a zygote, first / again in that child",
    "linked: Ex2 frame spacing at a python-can peer",
    "linked: RTR round trip peer -> master -> peer",
    "notebook knob turn, as before: the classroom rerun from zero, LCD drawn by matplotlib",
    "python-can interface 'appsim': frames/s from one program to another, served bus at 1 Mbit/s",
    "python-can interface 'appsim' / python-can virtual bus",
    "Gradescope: run_autograder on one full submission (after setup.sh)",
    "Gradescope run / appsim grade, one full submission",
    "notebook knob turn: the live classroom goes on 0.2 s, LCD redrawn (Ex2..Ex6)",
    "notebook knob turn on Ex1: the board restarts (it reads its knob once)",
    "real-time factor: Ex6 classroom under a steady error flood from outside, 125 kbit/s",
    "real-time factor: Ex6 classroom under a varied error flood from outside, 125 kbit/s",
    "memory of a trace event: the classroom's frames",
    "memory of a trace event: a steady error flood",
    "memory of a trace event: a varied error flood",
    "linked classroom, an in-process virtual peer at full rate for 3 s: most frames python-can's queue held for the "
    "link",
    "linked classroom, an in-process virtual peer at full rate for 3 s: resident memory growth after the first 0.6 s",
    "linked classroom, an in-process virtual peer at full rate for 3 s: most it fell behind real time",
)


def bench(*args: str) -> subprocess.CompletedProcess[str]:
    return subprocess.run([sys.executable, "-m", "bench", *args], cwd=KIT, capture_output=True, text=True,
                          timeout=300, check=False)


def cells(line: str) -> list[str]:
    return [cell.strip() for cell in line.strip().strip("|").split("|")]


def test_quick_suite_prints_the_table_with_a_figure_or_a_reason_in_every_row():
    result = bench("--quick")
    assert result.returncode == 0, result.stderr
    lines = [line for line in result.stdout.splitlines() if line.startswith("|")]
    assert cells(lines[0])[:7] == ["measurement", "min", "median", "max", "unit", "target", "met"]
    rows = {cells(line)[0]: cells(line) for line in lines[2:]}
    assert set(ROWS) <= set(rows)
    for name, row in rows.items():
        low, mid, high, note = row[1], row[2], row[3], row[7]
        if low == "-":
            assert note.startswith("not available yet"), f"{name}: no number and no reason"
        else:
            assert float(low.replace(",", "")) <= float(mid.replace(",", "")) <= float(high.replace(",", ""))
    rtf = rows["real-time factor: 7 nodes, 1 Mbit/s, 100 % load"]
    assert rtf[5].startswith(">= 1") and rtf[6] in ("yes", "NO")
    limit = rows["frames per wall second at that load"][7]
    frames_per_s = float(limit.split("bus limit ")[1].split(" frames/s")[0].replace(",", ""))
    # an 8-byte standard frame is 111 bits unstuffed and at most 135 stuffed, plus 3 bits of intermission
    assert 1e6 / (135 + 3) <= frames_per_s <= 1e6 / (111 + 3)
    assert "run(s) per figure, on " in result.stdout.splitlines()[0]
    assert "firmware read 17% of deliveries" in rows["real-time factor: 7 nodes, 1 Mbit/s, 100 % load, "
                                                      "each reads one sender's frames"][7]


def test_runs_below_one_is_refused_with_the_reason():
    result = bench("--quick", "--runs", "0")
    assert result.returncode != 0 and "--runs is how often each figure is measured, at least 1" in result.stderr


def test_full_load_keeps_the_bus_full_and_the_filters_decide_what_the_firmware_reads():
    every = fullload.run(7, 1.0, 0.003)
    one = fullload.run(7, 1.0, 0.003, one_sender=True)
    slow = fullload.run(7, 1.0, 0.02, bit_rate=125_000)
    for run in (every, one, slow):
        assert run.bus_busy > 0.95, "every node always has a frame queued: the wire never rests"
    assert every.read_by_firmware > 0.95      # a frame ending as the run ends is read after it
    assert abs(one.read_by_firmware - 1 / 6) < 0.02, "each node's filters pass the next node's frames only"
    assert slow.bus_limit_fps * 7.5 < every.bus_limit_fps < slow.bus_limit_fps * 8.5


def test_a_node_count_the_identifiers_cannot_name_is_refused():
    with pytest.raises(ValueError, match="2 to 32 nodes, not 40"):
        fullload.run(40, 1.0, 0.001)
