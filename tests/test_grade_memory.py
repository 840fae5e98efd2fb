"""The grader's memory is bounded per exercise whatever the firmware does: what the board, the chip, the bus and the
trace keep while judging is capped (a ring, a count, or a named fault), so a grading worker holds at most 64 MB more
for any firmware than for the honest solutions. The firmware used are the benchmark's (bench.memory.HOGS)."""
from __future__ import annotations

import io
import shutil

from appsim.chip.ecan.controller import ECAN, IGNORED_KEPT
from appsim.sim import COMPACT_EVENTS, Simulator
from appsim.workshop.course import EXERCISE_FILES, SOLUTIONS
from appsim.workshop.grading.grade import run
from appsim.workshop.sandbox.children import Limits
from bench.memory import HOGS

ABOVE_HONEST_MB = 64


def test_no_firmware_makes_a_grading_worker_hold_64_mb_more_than_the_solutions(tmp_path):
    """Every hog (an ignored write forever, every register in every mode, floods of frames, error frames, USART
    bytes and LCD text, Timer1 restarted forever, reads from endless call sites) graded beside the solutions."""
    room = tmp_path / "class"
    (room / "honest").mkdir(parents=True)
    for file in EXERCISE_FILES.values():
        shutil.copy(SOLUTIONS / file, room / "honest" / file)
    for number, (exercise, source) in enumerate(HOGS.values()):
        (room / f"hog{number}").mkdir()
        (room / f"hog{number}" / EXERCISE_FILES[exercise]).write_text(source)
    memory: dict = {}       # 15 s of CPU: the loopback flood fills its 20,000 frames in ~5 s in the sandbox here
    records = {r["submission"]: r for r in run([room], results=tmp_path / "grades.jsonl", jobs=2, seed=1,
                                                 limits=Limits(time_s=15, stall_s=5), out=io.StringIO(),
                                                 memory=memory)}
    honest = [memory["honest", exercise] for exercise in EXERCISE_FILES]
    most_peak = max(m.peak_kb for m in honest) + (ABOVE_HONEST_MB << 10)
    most_growth = max(m.growth_kb for m in honest) + (ABOVE_HONEST_MB << 10)
    over = {}
    for number, (name, (exercise, _)) in enumerate(HOGS.items()):
        held = memory[f"hog{number}", exercise]
        if held.peak_kb > most_peak or held.growth_kb > most_growth:
            over[name] = f"peak {held.peak_kb >> 10} MB, {held.growth_kb >> 10} MB more than when it started"
    assert over == {}, f"more than {ABOVE_HONEST_MB} MB above the solutions' {max(m.peak_kb for m in honest) >> 10} MB"
    flood = records[f"hog{list(HOGS).index('loopback flood')}"]["exercises"]["demo1"]
    assert flood["fault"] == "memory" and "a check keeps the last 20,000 frames sent in Loopback mode" in \
        flood["checks"][0]["message"]
    assert records["honest"]["score"] == records["honest"]["max_score"]


def test_the_ecan_keeps_the_latest_ignored_writes_and_counts_them_all():
    ecan = ECAN()
    ecan.write(0xF6F, 0x00)                 # CANCON: request Normal mode
    ecan.enter_requested_mode()
    for value in range(10 * IGNORED_KEPT):
        ecan.write(0xF00, value & 0xFF)     # RXF0SIDH outside Configuration mode: ignored
    assert ecan.ignored_count == 10 * IGNORED_KEPT and len(ecan.ignored_writes) == IGNORED_KEPT
    assert ecan.ignored_writes[-1] == ("RXF0SIDH", (10 * IGNORED_KEPT - 1) & 0xFF)


def test_cancelled_events_do_not_pile_up_in_the_simulator():
    sim = Simulator()
    for time in range(100 * COMPACT_EVENTS):
        sim.call_at(10**9 + time, lambda: None).cancel()
    assert len(sim._events) <= 2 * COMPACT_EVENTS
    fired = []
    sim.call_at(5, lambda: fired.append(sim.now))
    sim.run()
    assert fired == [5]
