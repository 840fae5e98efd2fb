"""`appsim grade` attacked through C: every route the C translator offers a dishonest student (a header outside the
kit's, a translation unit too big or too deep, a macro bomb, an endless #include) ends that exercise with a named
`load` fault within its budget, and the class goes on: the honest classmates in C get their full marks, nothing of the
run is left behind, and no file outside the sandbox is read.

The C twins of issue 22's attacks, where C offers a route: an answer key on the grader's import path or in its current
folder (C's route is #include: refused, and its text never shown), a header of the kit's name placed there (the kit's
own is read), the kit's copy in the sandbox by its path; the translation's own names (`__M`, `__rt`, `__lib_...`),
which a C global cannot take; polling from endless call sites (macro-made reads); a file over issue 22's size limit, a
notebook's C cell over it, a zip member leading out of the zip. C has no route to the sandbox's files (no fopen), to
its pipes or its mount table (no pointer reaches anything but the firmware's own memory), so the attacks on those
(forged reads, forged errors, the mount table) have no C twin: the Python ones stand for them."""
from __future__ import annotations

import io
import json
import os
import sys
import time
import zipfile
from pathlib import Path

import nbformat
import pytest

from appsim.workshop.course import C_FILES
from appsim.workshop.grading.grade import run
from appsim.workshop.grading.submissions import MAX_SOURCE
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
                      "the macro F() expands to more than 200,000 tokens"),
    "deep_nesting": ("int deep = " + "(" * 5000 + "1" + ")" * 5000 + ";\n", "nest more than"),
    "huge_unit": ("".join(f"int v{n} = {n};\n" for n in range(24_000)), "more than 10,000 lines"),   # in 512 kB
    "inline_asm": ("void attack(void) { _asm MOVLW 0x55 _endasm }\n", "inline assembly"),
    "vector_asm_elsewhere": ("void attack(void) { _asm GOTO main _endasm }\n", "belongs alone in a function at the"),
    "answer_key_on_path": ('#include "answers_on_path.c"\n', "includes only its own headers"),
    "answer_key_here": ("#include <answers_here.c>\n", "includes only its own headers"),
    "kit_copy_by_path": ('#include "/kit/appsim/firmware/c18/include/CAN18XX8.h"\n', "includes only its own headers"),
    "kit_solutions_by_path": ('#include "/kit/appsim/workshop/solutions/ex1.c"\n', "includes only its own headers"),
    "shadowing_header": ('#include "CAN18XX8.h"\nint stolen = STOLEN_KEY;\n', "STOLEN_KEY is not declared"),
}
# Not load faults: attacks that the translation turns into ordinary firmware, graded as the starter they carry.
AS_STARTER = {
    # Globals named as the translation's own names, assigned garbage at C startup: renamed, so nothing is clobbered
    "translation_names": "".join(f"int {name} = 0x55;\n" for name in (
        "__M", "__rt", "__lib_CANSendMessage", "__appsim_idle__", "__c18_interrupt", "__current_mcu", "__Restart",
        "__c_main", "__c_startup", "__c18__", "__builtins__", "__import__")),
}
# Whole firmware: every read from a new call site (macro-made), for ever: the grader's memory stays bounded
READS = "".join(f"#define R{n} R{n - 1} R{n - 1}\n" for n in range(1, 12))
SITES = ("#include <p18f8680.h>\nunsigned char x;\n#define R0 x = RXB0CON;\n" + READS
         + "void main(void)\n{\n    while (1) {\n        R11\n    }\n}\n")
STARTER = (KIT / "exercises" / "ex1.c").read_text()


@pytest.fixture(scope="module")
def course_folders(tmp_path_factory):
    """An instructor's course folder on the grader's import path, and another as its current folder, each holding an
    answer key in C (the reference Ex1) and a header named as the kit's: the sandbox must give neither."""
    on_path, here = tmp_path_factory.mktemp("course_on_path"), tmp_path_factory.mktemp("course_here")
    key = (KIT / "solutions" / "ex1.c").read_text()
    shadow = "#define STOLEN_KEY 0x100\n#define CANIsRxReady() 1\n"
    for folder, name in ((on_path, "answers_on_path.c"), (here, "answers_here.c")):
        (folder / name).write_text(key)
        (folder / "CAN18XX8.h").write_text(shadow)
        (folder / "can18xx8.h").write_text(shadow)
    sys.path.insert(min(2, len(sys.path)), str(on_path))
    old = os.environ.get("PYTHONPATH")
    os.environ["PYTHONPATH"] = str(on_path)
    yield here
    sys.path.remove(str(on_path))
    if old is None:
        os.environ.pop("PYTHONPATH")
    else:
        os.environ["PYTHONPATH"] = old


@pytest.fixture(scope="module")
def graded(tmp_path_factory, course_folders):
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
    for name, attack in AS_STARTER.items():
        (root / name).mkdir(parents=True)
        (root / name / "ex1.c").write_text(attack + STARTER)
    (root / "sites").mkdir()
    (root / "sites" / "demo1_monitor.c").write_text(SITES)
    (root / "oversized").mkdir()
    (root / "oversized" / "ex1.c").write_text(STARTER + "/*" + "x" * MAX_SOURCE + "*/\n")
    (root / "oversized_cell").mkdir()
    notebook = nbformat.read(KIT / "notebooks" / "ex1.ipynb", as_version=4)
    for cell in notebook.cells:
        tags = cell.metadata.get("tags", [])
        if "firmware-c" in tags:
            cell.source = "%%writefile ex1.c\n" + STARTER + "/*" + "x" * MAX_SOURCE + "*/\n"
        if "firmware-choice" in tags:
            cell.source = 'FIRMWARE = "ex1.c"'
    nbformat.write(notebook, root / "oversized_cell" / "ex1.ipynb")
    with zipfile.ZipFile(root / "zip_out.zip", "w") as archive:
        archive.writestr("../ex1.c", STARTER)
        archive.writestr("ex2.c", (KIT / "solutions" / "ex2.c").read_text())
    started = time.monotonic()
    with pytest.MonkeyPatch.context() as patch:
        patch.chdir(course_folders)
        records = run([root], results=root.parent / "grades.jsonl", jobs=2, seed=2024, limits=LIMITS,
                      out=io.StringIO())
    return {r["submission"]: r for r in records}, time.monotonic() - started


@pytest.mark.parametrize("name", sorted(ATTACKS))
def test_each_c_attack_is_a_named_load_fault(graded, name):
    record = graded[0][name]["exercises"]["ex1"]
    message = record["checks"][0]["message"]
    assert record["fault"] == "load" and record["score"] == 0, f"{record['fault']}: {message}"
    assert ATTACKS[name][1] in message, message
    assert "Traceback" not in message


@pytest.mark.parametrize("name", sorted(AS_STARTER))
def test_an_attack_the_translation_makes_harmless_is_graded_as_the_starter_it_carries(graded, name):
    records, _ = graded
    assert json.dumps(records[name]["exercises"]["ex1"]).replace(name, "X") == \
        json.dumps(records["ken_c"]["exercises"]["ex1"]).replace("ken_c", "X")


def test_polling_from_endless_call_sites_is_judged_and_the_class_goes_on(graded):
    demo1 = graded[0]["sites"]["exercises"]["demo1"]
    assert demo1["fault"] is None and demo1["checks"][0]["passed"], demo1["checks"][0]["message"]
    assert demo1["score"] < demo1["max_score"]


def test_c_files_are_held_to_issue_22s_size_limits_and_zip_rules(graded):
    records, _ = graded
    oversized = records["oversized"]["exercises"]["ex1"]
    assert oversized["fault"] == "unreadable" and f"at most {MAX_SOURCE:,} bytes" in oversized["checks"][0]["message"]
    cell = records["oversized_cell"]["exercises"]["ex1"]
    assert cell["fault"] == "unreadable" and "of C" in cell["checks"][0]["message"], cell["checks"][0]["message"]
    zipped = records["zip_out"]["exercises"]
    assert zipped["ex1"]["fault"] == "unreadable" and "'../ex1.c' was refused" in zipped["ex1"]["checks"][0]["message"]
    assert zipped["ex2"]["score"] == zipped["ex2"]["max_score"]


def test_no_answer_key_or_shadowing_header_reached_the_firmware(graded):
    records, _ = graded
    for name in ("answer_key_on_path", "answer_key_here", "shadowing_header", "kit_solutions_by_path"):
        message = records[name]["exercises"]["ex1"]["checks"][0]["message"]
        assert "RX_Filter0  MESSAGE_ID1" not in message and "0x100" not in message.split(":", 2)[-1][:40], message


def test_the_honest_classmates_in_c_get_their_marks_while_attacked(graded):
    records, _ = graded
    alice = records["alice_c"]
    assert all(e["score"] == e["max_score"] for x, e in alice["exercises"].items() if x != "demo1"), alice
    ken = records["ken_c"]["exercises"]["ex1"]
    assert 0 < ken["score"] < ken["max_score"] and ken["fault"] is None


def test_the_attacked_class_is_graded_within_the_exercises_budgets(graded):
    records, seconds = graded
    assert len(records) == len(ATTACKS) + len(AS_STARTER) + 6
    assert seconds < (len(ATTACKS) + 8) * LIMITS.time_s, "each attack ends within its exercise's budget"


def test_no_attack_read_the_file_it_named(graded):
    for name in ("outside_header", "absolute_solution", "parent_header"):
        message = graded[0][name]["exercises"]["ex1"]["checks"][0]["message"]
        assert Path(SECRET).read_text().strip() not in message if Path(SECRET).exists() else True
        assert "RX_Filter0  MESSAGE_ID1" not in message
