"""`appsim grade` attacked through C: every route the C translator offers a dishonest student (a header outside the
kit's, a translation unit too big or too deep, a macro bomb, an endless #include) ends that exercise with a named
`load` fault within its budget, and the class goes on: the honest classmates in C get their full marks, nothing of the
run is left behind, and no file outside the sandbox is read."""
from __future__ import annotations

import io
import time
from pathlib import Path

import pytest

from appsim.workshop.course import C_FILES
from appsim.workshop.grading.grade import run
from appsim.workshop.sandbox.children import Limits

KIT = Path(__file__).resolve().parent.parent
LIMITS = Limits(time_s=8, stall_s=2, memory_mb=128)
SECRET = "/etc/hostname"

BOMB = "#define A0 x x x x x x x x\n" + "".join(f"#define A{n} A{n - 1} A{n - 1} A{n - 1} A{n - 1}\n"
                                                for n in range(1, 24)) + "int y = A23;\n"
ATTACKS = {        # name: (the attack, put before the starter's own text; words the record's message must hold)
    "outside_header": (f'#include "{SECRET}"\n', "includes only its own headers"),
    "parent_header": ('#include "../../alice_c/ex1.c"\n', "includes only its own headers"),
    "absolute_solution": (f'#include "{KIT}/solutions/ex1.c"\n', "includes only its own headers"),
    "itself": ("#include __FILE__\n", "includes only its own headers"),
    "macro_bomb": (BOMB, "macro bomb"),
    "argument_bomb": ("#define F(x) x x x x x x x x\n#define G(x) F(F(F(F(x))))\nint y = G(G(G(G(1))));\n",
                      "a macro bomb"),
    "deep_nesting": ("int deep = " + "(" * 5000 + "1" + ")" * 5000 + ";\n", "nest more than"),
    "huge_unit": ("".join(f"int v{n} = {n};\n" for n in range(24_000)), "more than 10,000 lines"),   # in 512 kB
    "inline_asm": ("void attack(void) { _asm MOVLW 0x55 _endasm }\n", "inline assembly"),
}
STARTER = (KIT / "exercises" / "ex1.c").read_text()


@pytest.fixture(scope="module")
def graded(tmp_path_factory):
    root = tmp_path_factory.mktemp("attacked_c") / "class"
    honest = {"alice_c": {e: (KIT / "solutions" / name).read_text() for e, name in C_FILES.items() if e != "demo1"},
              "ken_c": {"ex1": STARTER}}
    for name, files in honest.items():
        (root / name).mkdir(parents=True)
        for exercise, text in files.items():
            (root / name / C_FILES[exercise]).write_text(text)
    for name, (attack, _) in ATTACKS.items():
        (root / name).mkdir(parents=True)
        (root / name / "ex1.c").write_text(attack + STARTER)
    started = time.monotonic()
    records = run([root], results=root.parent / "grades.jsonl", jobs=2, seed=2024, limits=LIMITS, out=io.StringIO())
    return {r["submission"]: r for r in records}, time.monotonic() - started


@pytest.mark.parametrize("name", sorted(ATTACKS))
def test_each_c_attack_is_a_named_load_fault(graded, name):
    record = graded[0][name]["exercises"]["ex1"]
    message = record["checks"][0]["message"]
    assert record["fault"] == "load" and record["score"] == 0, f"{record['fault']}: {message}"
    assert ATTACKS[name][1] in message, message
    assert "Traceback" not in message


def test_the_honest_classmates_in_c_get_their_marks_while_attacked(graded):
    records, _ = graded
    alice = records["alice_c"]
    assert all(e["score"] == e["max_score"] for x, e in alice["exercises"].items() if x != "demo1"), alice
    ken = records["ken_c"]["exercises"]["ex1"]
    assert 0 < ken["score"] < ken["max_score"] and ken["fault"] is None


def test_the_attacked_class_is_graded_within_the_exercises_budgets(graded):
    records, seconds = graded
    assert len(records) == len(ATTACKS) + 2
    assert seconds < (len(ATTACKS) + 8) * LIMITS.time_s, "each attack ends within its exercise's budget"


def test_no_attack_read_the_file_it_named(graded):
    for name in ("outside_header", "absolute_solution", "parent_header"):
        message = graded[0][name]["exercises"]["ex1"]["checks"][0]["message"]
        assert Path(SECRET).read_text().strip() not in message if Path(SECRET).exists() else True
        assert "RX_Filter0  MESSAGE_ID1" not in message
