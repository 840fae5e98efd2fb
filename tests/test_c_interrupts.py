"""Interrupts in C18's C: `#pragma interrupt NAME` / `#pragma interruptlow NAME` and the vector's `_asm GOTO NAME
_endasm` mark the routines as @interrupt / @interruptlow do; C's `while (1);` and `while (!flag);` reach the loader's
rewrite of empty waiting loops in exactly its shape; a volatile global is the flag a routine and main() share; the C
twins of solutions/interrupts/ earn the Python twins' verdicts, traces and records, in process and sandboxed."""
from __future__ import annotations

import ast
import json
import re
import shutil
import subprocess
import sys

import pytest
from workshop import KIT, classroom

from appsim.chip.mcu import PIC18F8680
from appsim.chip.sfr import HIGH_VECTOR, LOW_VECTOR
from appsim.errors import CCompileError
from appsim.firmware import c18
from appsim.firmware.interrupts import MARK, routines
from appsim.firmware.loader import load_source
from appsim.sim import Simulator
from appsim.workshop.checks import check
from appsim.workshop.faults import board_fault

INTERRUPTS = KIT / "solutions" / "interrupts"
EXERCISES = ("ex1", "ex3", "ex6")

TICKS = """#include <p18f8680.h>
#include <timers.h>
volatile unsigned char ticks = 0;   /* set by the routine */
unsigned char seen = 0, turns = 0;
void high_isr(void);
#pragma code high_vector=0x08
void interrupt_at_high_vector(void)
{
    _asm GOTO high_isr _endasm
}
#pragma code
#pragma interrupt high_isr save=PROD
void high_isr(void)
{
    PIR1bits.TMR1IF = 0;
    ticks++;
}
void main(void)
{
    OpenTimer1(TIMER_INT_ON & T1_16BIT_RW & T1_SOURCE_INT & T1_PS_1_8 & T1_OSC1EN_OFF & T1_SYNC_EXT_OFF);
    INTCONbits.PEIE = 1;
    INTCONbits.GIE = 1;
    while (1) {
        while (ticks == seen);
        seen = ticks;
        turns++;
    }
}
"""


def run(source: str, seconds: float, name: str = "t.c"):
    module = load_source(name, source.encode())
    sim = Simulator()
    mcu = PIC18F8680(sim)
    process = mcu.run(module.main, routines(module))
    sim.run_for(seconds)
    return module, mcu, process


def test_cs_waiting_loops_reach_the_loaders_rewrite_in_exactly_its_shape(monkeypatch):
    """The tree the loader's `waits_for_interrupts` gets holds `while not flag: pass`, `while True: pass`,
    `while count == seen: Nop()`: what it rewrites in Python firmware, so the rewrite is the same code path."""
    seen: list[str] = []
    rewrite = c18.waits_for_interrupts

    def watching(tree: ast.Module, path, lines) -> None:
        main = next(f for f in tree.body if isinstance(f, ast.FunctionDef) and f.name == "__c_main")
        seen.extend(ast.unparse(node) for node in ast.walk(main) if isinstance(node, ast.While))
        rewrite(tree, path, lines)

    monkeypatch.setattr(c18, "waits_for_interrupts", watching)
    module = load_source("shapes.c", b"""#include <p18f8680.h>
volatile unsigned char flag;
unsigned int count, seen;
void main(void)
{
    while (!flag);
    while (!flag) { }
    while (count == seen) Nop();
    while (1);
}
""")
    assert seen == ["while not flag:\n    pass", "while not flag:\n    pass", "while count == seen:\n    Nop()",
                    "while True:\n    pass"]
    assert "__appsim_idle__" in module.__c_main.__code__.co_names, "the loader rewrote them"


def test_a_volatile_global_the_routine_sets_ends_mains_wait_at_each_interrupt():
    module, mcu, process = run(TICKS, 0.5)
    assert process.failure is None
    assert module.ticks == 9, "Timer1 overflows every 52.4288 ms: 9 times in 0.5 s"
    assert module.turns == module.seen == 9, "main() went round once per interrupt, waiting in between"
    assert mcu.interrupts.armed


def test_the_pragmas_mark_the_routines_as_the_python_decorators_do():
    module = load_source("two.c", (INTERRUPTS / "ex3.c").read_bytes())
    assert getattr(module.high_isr, MARK) == HIGH_VECTOR and getattr(module.low_isr, MARK) == LOW_VECTOR
    assert set(routines(module)) == {HIGH_VECTOR, LOW_VECTOR}
    assert not hasattr(module, "interrupt_at_high_vector"), "the vector's GOTO is no function of the module"


def test_a_routine_placed_at_the_vector_itself_is_taken_there():
    source = TICKS.replace("void interrupt_at_high_vector(void)\n{\n    _asm GOTO high_isr _endasm\n}\n#pragma code\n",
                           "").replace("#pragma interrupt high_isr save=PROD\nvoid high_isr(void)\n{\n"
                                       "    PIR1bits.TMR1IF = 0;\n    ticks++;\n}\n",
                                       "#pragma interrupt high_isr\nvoid high_isr(void)\n{\n"
                                       "    PIR1bits.TMR1IF = 0;\n    ticks++;\n}\n#pragma code\n")
    assert "_asm" not in source
    module, _, process = run(source, 0.2)
    assert process.failure is None and module.ticks == 3


def test_a_routine_no_vector_reaches_is_refused_with_cs_vector_to_write():
    with pytest.raises(CCompileError) as refused:
        load_source("t.c", TICKS.replace("_asm GOTO high_isr _endasm", "").encode())
    message = str(refused.value)
    assert "interrupt_at_high_vector() is at the interrupt vector 0x08" in message, message
    with pytest.raises(CCompileError) as refused:
        load_source("t.c", re.sub(r"#pragma code high_vector.*?#pragma code\n", "", TICKS, flags=re.S).encode())
    assert "nothing at the vector 0x08 jumps to high_isr" in str(refused.value)
    assert "#pragma code high_vector=0x08, then void interrupt_at_high_vector(void) { _asm GOTO high_isr _endasm }" \
        in str(refused.value)


def test_an_interrupt_with_no_routine_is_told_in_cs_words():
    source = re.sub(r"void high_isr\(void\);.*?void main", "void main", TICKS, flags=re.S)
    _, _, process = run(source, 0.2, name="none.c")
    fault = board_fault(process)
    assert fault is not None and fault.kind == "exception", fault
    assert "the firmware has no #pragma interrupt routine" in fault.message and "@interrupt" not in fault.message
    assert "#pragma code high_vector=0x08, a function holding only `_asm GOTO NAME _endasm`" in fault.message


def test_a_routine_that_crashes_is_named_in_cs_words():
    source = TICKS.replace("    ticks++;\n",
                           "    ticks++;\n    if (ticks == 2) { unsigned char a[2]; a[ticks] = 1; }\n")
    _, _, process = run(source, 0.3, name="crash.c")
    fault = board_fault(process)
    assert fault is not None and fault.kind == "exception", fault
    assert fault.message.startswith("high_isr(), the high-priority interrupt routine (#pragma interrupt, vector 0x08), "
                                    "crashed at line 17 of crash.c"), fault.message


def test_reset_inside_a_routine_is_refused_and_from_main_restarts_the_c_program():
    inside = TICKS.replace("    ticks++;\n", "    ticks++;\n    if (ticks == 2) Reset();\n")
    _, _, process = run(inside, 0.3)
    fault = board_fault(process)
    assert fault is not None and "Reset() inside the interrupt routine high_isr()" in fault.message, fault
    from_main = TICKS.replace("unsigned char seen = 0, turns = 0;", "unsigned char seen = 0, turns = 0;\n"
                              "unsigned char resets = 0;").replace(
        "        turns++;\n", "        turns++;\n        if (ticks == 2) { resets++; Reset(); }\n")
    module, _, process = run(from_main, 0.3)
    assert process.failure is None
    assert module.resets == 0 and module.ticks == module.seen, "C startup ran again: every global initialised again"


@pytest.mark.parametrize("seed", [202, 7])
@pytest.mark.parametrize("exercise", EXERCISES)
def test_the_c_interrupt_solutions_earn_the_python_twins_verdicts(exercise, seed):
    python = check(exercise, INTERRUPTS / f"{exercise}.py", seed=seed)
    c = check(exercise, INTERRUPTS / f"{exercise}.c", seed=seed)
    assert c.score == c.max_score, str(c)
    assert [(r.name, r.passed, r.message.replace(".c ran", ".py ran")) for r in c.checks] == \
        [(r.name, r.passed, r.message) for r in python.checks]


@pytest.mark.parametrize("exercise", [1, 3, 6])
def test_six_interrupt_driven_c_stations_give_the_trace_of_six_python_ones(exercise):
    traces = []
    for language in ("python", "c"):
        room = classroom(exercise, seed=exercise, firmware_dir=INTERRUPTS, language=language)
        room.run(1.0)
        assert all(board.mcu.process.failure is None for board in room.boards)
        assert all(board.mcu.interrupts.armed for board in room.stations.values()), "they run interrupt-driven"
        traces.append(([repr(e) for e in (*room.bus.trace, *room.bus.loopback_trace)],
                       [board.glcd.text() for board in room.boards]))
    assert len(traces[0][0]) > 10
    assert traces[1] == traces[0]


def grade(folder, tmp_path, *extra: str) -> dict[str, dict]:
    results = tmp_path / "grades.jsonl"
    done = subprocess.run([sys.executable, "-m", "appsim", "grade", str(folder), "--seed", "31", "--json",
                           str(results), *extra], capture_output=True, text=True, timeout=600)
    assert done.returncode == 0, done.stdout + done.stderr
    return {r["submission"]: r for r in map(json.loads, results.read_text().splitlines())}


@pytest.mark.skipif(not shutil.which("bwrap"), reason="needs bubblewrap: the sandbox")
def test_the_c_interrupt_solutions_graded_sandboxed_get_the_python_twins_records(tmp_path):
    room = tmp_path / "class"
    for language, suffix in (("c", ".c"), ("python", ".py")):
        (room / language).mkdir(parents=True)
        for exercise in EXERCISES:
            shutil.copy(INTERRUPTS / f"{exercise}{suffix}", room / language / f"{exercise}{suffix}")
    (room / "crashes").mkdir()
    (room / "crashes" / "ex3.c").write_text(TICKS.replace("    ticks++;\n", "    ticks++;\n    if (ticks == 2) "
                                                          "Reset();\n"))
    records = grade(room, tmp_path)
    for exercise in EXERCISES:
        c, python = records["c"]["exercises"][exercise], records["python"]["exercises"][exercise]
        assert c["score"] == c["max_score"] and c["fault"] is None, c
        assert json.dumps(c).replace(f"{exercise}.c", "FILE") == json.dumps(python).replace(f"{exercise}.py", "FILE")
    crashed = records["crashes"]["exercises"]["ex3"]
    in_process = check("ex3", room / "crashes" / "ex3.c", seed=31)
    assert crashed["fault"] == in_process.fault == "exception"
    assert crashed["checks"][0]["message"] == in_process.checks[0].message
