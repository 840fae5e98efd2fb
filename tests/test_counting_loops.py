"""A loop that reads one register again and again while it counts (a timeout, a copy into an array) is no polling loop
to park: it turns on, as on the chip, until its count ends it; on a board, in `appsim check` and in the sandbox. One the
kit parked is looked at again with nothing changed (after 1, 2, 4 ... ms): its variables tell whether it counts."""
from __future__ import annotations

from pathlib import Path

import pytest
from test_sandbox_interrupts import both_ways

from appsim.board.app023 import APP023
from appsim.firmware.loader import load_firmware
from appsim.sim import PS_PER_SECOND
from appsim.workshop.checks import check
from appsim.workshop.checks import ex2 as ex2_check
from appsim.workshop.course import SOLUTIONS
from appsim.workshop.grading.worker import grade_exercise
from appsim.workshop.sandbox.children import Limits, Sandbox
from appsim.workshop.sandbox.isolation import isolation

SEED = 7

COPY_FIVE_TIMES = """from appsim.firmware import *

TxData = [0] * 5


def main():
    GLCD_Initial()
    k = 0
    while k < 5:                    # the same register five times: the board does not change, k does
        TxData[k] = SFR.ADRESH
        k += 1
    setcurGLCD(1, 1)
    putrsGLCD("AFTER")
    while True:
        CANIsRxReady()
"""

TIMEOUT_C = """#include <p18f8680.h>
#include "CAN18XX8.h"
#include "APP023_GLCD.h"
unsigned int turns;
void main(void)
{
    unsigned int t;
    GLCD_Initial();
    for (t = 0; t < 1000; t++) {        /* wait at most 1000 turns for a frame, then give up */
        if (RXB0CONbits.RXFUL) break;
        turns++;
    }
    setcurGLCD(1, 1);
    putrsGLCD(t < 1000 ? "GOT FRAME" : "TIMEOUT");
    while (1) { CANIsRxReady(); }
}
"""


TIMEOUT_WITH_TIMER1_C = TIMEOUT_C.replace(
    '#include "APP023_GLCD.h"\n', '#include "APP023_GLCD.h"\n#include <timers.h>\n', 1).replace(
    "    GLCD_Initial();\n",
    "    GLCD_Initial();\n"
    "    OpenTimer1(TIMER_INT_OFF & T1_16BIT_RW & T1_SOURCE_INT & T1_PS_1_1 & T1_OSC1EN_OFF & T1_SYNC_EXT_OFF);\n"
    "    WriteTimer1(0xFF00);                /* it overflows in 25.6 us, while the loop is parked */\n", 1)

LONG_TIMEOUT_C = TIMEOUT_C.replace("t < 1000", "t < 5000")


def _lcd_after(tmp_path: Path, name: str, source: str, seconds: float = 0.05) -> list[str]:
    from conftest import World
    world = World()
    path = tmp_path / name
    path.write_text(source)
    board = APP023(world.bus, "station1")
    board.run(load_firmware(path))
    world.run(seconds)
    return board.glcd.lines


def test_a_loop_that_copies_one_register_five_times_ends(tmp_path):
    """It used to park at its second turn, for ever: nothing on the board changed, so it looked like a polling loop."""
    assert _lcd_after(tmp_path, "copy.py", COPY_FIVE_TIMES)[0].startswith("AFTER")


def test_a_c_timeout_loop_times_out_when_no_frame_comes(tmp_path):
    assert _lcd_after(tmp_path, "timeout.c", TIMEOUT_C)[0].startswith("TIMEOUT")


# A count kept where C keeps none: in a dict's value, an object's attribute (its class the firmware's own, a dataclass),
# local or global. Each loop reads ADRESH 50 times over, and then writes AFTER: within 10 ms if it counts, where one
# that parks turns once at each look (after 1, 2, 4 ... ms).
KEPT_COUNTS = {
    "a local dict's value": ("state = {'k': 0}", "state['k'] < 50", "state['k'] += 1"),
    "a global dict's value": ("STATE['k'] = 0", "STATE['k'] < 50", "STATE['k'] += 1"),
    "a local object's attribute": ("state = Counter()", "state.k < 50", "state.k += 1"),
    "a global object's attribute": ("COUNTER.k = 0", "COUNTER.k < 50", "COUNTER.k += 1"),
    "a dataclass's field": ("state = Kept()", "state.k < 50", "state.k += 1"),
    "an attribute two objects deep": ("state = Counter(); state.inner = Counter()", "state.inner.k < 50",
                                      "state.inner.k += 1"),
    "a class's attribute": ("State.k = 0", "State.k < 50", "State.k += 1"),
    "a slotted object's attribute": ("state = Boxed()", "state.k < 50", "state.k += 1"),
    "a slotted dataclass's field": ("state = SlottedKept()", "state.k < 50", "state.k += 1"),
}
KEPT_COUNT = """from dataclasses import dataclass

from appsim.firmware import *


class Counter:
    def __init__(self):
        self.k = 0


@dataclass
class Kept:
    k: int = 0


class State:
    k = 0


class Boxed:
    __slots__ = ("k",)

    def __init__(self):
        self.k = 0


@dataclass(slots=True)
class SlottedKept:
    k: int = 0


STATE = {{}}
COUNTER = Counter()


def main():
    GLCD_Initial()
    {start}
    while {test}:
        x = SFR.ADRESH
        {step}
    setcurGLCD(1, 1)
    putrsGLCD("AFTER")
    while True:
        CANIsRxReady()
"""


@pytest.mark.parametrize("name", sorted(KEPT_COUNTS))
def test_a_count_kept_in_a_dict_or_an_objects_attribute_is_seen(tmp_path, name):
    """Such a loop parked for ever: the kit compared dicts and objects by their kind only, so it saw no change."""
    start, test, step = KEPT_COUNTS[name]
    source = KEPT_COUNT.format(start=start, test=test, step=step)
    assert _lcd_after(tmp_path, "kept.py", source, 0.01)[0].startswith("AFTER")


def test_a_loop_that_makes_classes_and_code_at_each_turn_costs_bounded_memory(tmp_path):
    """The looks keep what they learnt of each code object (the firmware's or the kit's) and class (how to read its
    objects' attributes), each kept alive so that its id stays its own: KEPT_MOST of them, or a heartbeat that makes
    a class and code at each turn would keep one of each per counted read (about 128,000 a simulated second)."""
    from appsim.chip import polling
    step = ("beat += 1\n        made = type('Made', (), {})()\n        made.beat = beat\n"
            "        exec(compile('y = SFR.ADRESL', 'made', 'exec'))")
    source = KEPT_COUNT.format(start="beat = 0", test="True", step=step)
    _lcd_after(tmp_path, "classes.py", source, 0.2)
    assert len(polling._KEPT) <= polling.KEPT_MOST, len(polling._KEPT)


def test_a_counting_loop_is_found_while_changes_it_does_not_read_keep_coming(tmp_path):
    """Timer1 overflows (after 25.6 us, then every 6.5 ms) and sets TMR1IF: a change on the board, but not one the
    loop reads, so it stays parked, and its first look comes as if nothing had changed: 1 ms after it parked, so it
    has timed out by 4.5 ms (GLCD_Initial takes about 2 ms). A look that took the overflow for a change came to nothing
    and the next one only 2 ms later."""
    assert TIMEOUT_WITH_TIMER1_C.count("OpenTimer1") == 1
    assert _lcd_after(tmp_path, "timeout.c", TIMEOUT_WITH_TIMER1_C, 0.0045)[0].startswith("TIMEOUT")


def test_a_timeout_of_more_turns_than_a_look_gives_ends_later_than_on_the_chip(tmp_path):
    """5,000 turns: COUNTED_TURNS at each look (the first 1 ms after it parked, then every 8 ms while it counts), so
    it times out 34 ms after it began, where the chip takes a few (docs/differences.md, "Busy-waiting")."""
    assert _lcd_after(tmp_path, "timeout.c", LONG_TIMEOUT_C, 0.015)[0].strip() == ""
    assert _lcd_after(tmp_path, "timeout.c", LONG_TIMEOUT_C, 0.05)[0].startswith("TIMEOUT")


def test_a_pure_polling_loop_still_parks_until_the_frame(world):
    """Nothing in the loop changes but what it reads: it waits for the frame without turning (a handful of turns)."""
    from appsim.firmware import (
        CAN_CONFIG_ALL_VALID_MSG,
        CAN_TX_STD_FRAME,
        CANInitialize,
        CANIsRxReady,
        CANSendMessage,
        Delay10KTCYx,
    )
    turns = []

    def poller():
        CANInitialize(4, 10, 8, 4, 3, CAN_CONFIG_ALL_VALID_MSG)
        looked = [0]
        while not CANIsRxReady():
            looked[0] = looked[0] | 1           # a store that changes nothing: still the same state
        turns.append(looked[0])

    def sender():
        CANInitialize(4, 10, 8, 4, 3, CAN_CONFIG_ALL_VALID_MSG)
        Delay10KTCYx(25)
        CANSendMessage(0x100, [1], 1, CAN_TX_STD_FRAME)

    waiter = world.node("poller", poller)
    world.node("sender", sender)
    world.run(0.1)
    assert turns == [1]
    assert waiter.process.local_time < PS_PER_SECOND       # it did not spin through the 25 ms read by read


def _ex1_that_reads_adresh_three_times() -> bytes:
    """The Ex1 solution, its A/D value read three times over (a loop with a counter) before it is sent."""
    source = (SOLUTIONS / "ex1.c").read_text()
    done = source.replace("void read_potentiometer(void)\n{\n",
                          "void read_potentiometer(void)\n{\n    unsigned char k;\n", 1)
    done = done.replace("    TxData[3] = ADRESH;\n", "    for (k = 0; k < 3; k++)\n        TxData[3] = ADRESH;\n", 1)
    assert done.count("for (k = 0") == 1
    return done.encode()


def test_a_firmware_with_a_counting_loop_gets_full_marks_in_check_and_in_the_sandbox(tmp_path):
    path = tmp_path / "ex1.c"
    path.write_bytes(_ex1_that_reads_adresh_three_times())
    verdict = check("ex1", path, seed=SEED).to_dict()
    assert verdict["score"] == verdict["max_score"], verdict
    with Sandbox(isolation(), Limits()) as sandbox:
        record = grade_exercise(sandbox, "ex1", "ex1.c", path.read_bytes(), SEED, None, owner="ada")
    assert (record["score"], record["fault"]) == (verdict["score"], verdict["fault"]), record


def test_a_heartbeat_counter_in_the_main_loop_costs_turns_not_marks(tmp_path):
    """The Ex3 solution with a counter in its main loop, which never ends (a heartbeat): the loop counts, so it turns
    COUNTED_TURNS reads per change on the board, where it parked before; the checks and the grader's limits hold."""
    source = (SOLUTIONS / "ex3.c").read_text()
    beating = source.replace("void main(void)\n", "unsigned int heartbeat;\nvoid main(void)\n", 1)
    beating = beating.replace("    while (1) {\n", "    while (1) {\n        heartbeat++;\n", 1)
    assert beating.count("heartbeat") == 2
    path = tmp_path / "ex3.c"
    path.write_text(beating)
    verdict = check("ex3", path, seed=SEED).to_dict()
    assert verdict["score"] == verdict["max_score"], verdict
    with Sandbox(isolation(), Limits()) as sandbox:
        record = grade_exercise(sandbox, "ex3", "ex3.c", path.read_bytes(), SEED, None, owner="ada")
    assert (record["score"], record["fault"]) == (verdict["score"], None), record


EX2 = (SOLUTIONS / "ex2.py").read_text()
COUNTING_EX2 = {
    "a heartbeat in its main loop": ("    while True:\n", "    beats = 0\n    while True:\n        beats += 1\n"),
    "a timeout of 700 turns before each frame it sends": (
        "            PIR1bits.TMR1IF = 0\n",
        "            PIR1bits.TMR1IF = 0\n            waited = 0\n"
        "            while waited < 700 and not CANIsRxReady():\n                waited += 1\n"),
    "a timeout of 700 turns counted in a dict's value": (
        "            PIR1bits.TMR1IF = 0\n",
        "            PIR1bits.TMR1IF = 0\n            waited = {'turns': 0}\n"
        "            while waited['turns'] < 700 and not CANIsRxReady():\n                waited['turns'] += 1\n"),
    "a timeout of 700 turns counted in an object's attribute": (
        "            PIR1bits.TMR1IF = 0\n",
        "            PIR1bits.TMR1IF = 0\n            waited = type('Waited', (), {'turns': 0})()\n"
        "            while waited.turns < 700 and not CANIsRxReady():\n                waited.turns += 1\n"),
    "the A/D value read three times over": (
        "    TxData[3] = SFR.ADRESH\n", "    for _ in range(3):\n        TxData[3] = SFR.ADRESH\n"),
    # more registers than a read-ahead offers (16): the child judges the others by the places the board sends it
    "a sum over 17 registers, three times over": (
        "            PIR1bits.TMR1IF = 0\n",
        "            PIR1bits.TMR1IF = 0\n            total = 0\n            for _ in range(3):\n"
        + "".join(f"                total += SFR.{name}\n" for name in (
            "ADRESH", "ADRESL", "PORTJ", "RXB0CON", "RXB1CON", "TXB0CON", "COMSTAT", "CANSTAT", "PIR3", "PIE3",
            "INTCON", "PIR1", "T1CON", "ADCON0", "ADCON1", "ADCON2", "RXB0D0"))),
}

# Pure polling loops whose variables are made again at each turn, equal but new: no change, in every run.
FRESH_EX2 = {
    "a dict": "{'turn': 1}",
    "an object of its own class": "type('Fresh', (), {})()",
    "a complex number": "complex(1, 2)",
    "a NaN": "float('nan')",
    "a generator": "(n for n in range(2))",
    "a huge shared list": "[[[0] * 1024] * 1024] * 1024",
}


@pytest.fixture(scope="module")
def sandbox():
    with Sandbox(isolation(), Limits(time_s=30, stall_s=5)) as sandbox:
        yield sandbox


@pytest.mark.parametrize("name", sorted(FRESH_EX2))
def test_a_polling_loop_with_fresh_objects_still_polls_the_same_in_every_run(sandbox, tmp_path, monkeypatch, name):
    """An object made again at each turn is no change (it used to be compared by its identity, which memory reuse
    makes the same or not from run to run), and a huge list costs the look a bounded budget, not a watchdog fault:
    the bus is the plain solution's, in-process and sandboxed."""
    old = "    while True:\n"
    fresh = EX2.replace(old, f"    while True:\n        fresh = {FRESH_EX2[name]}\n", 1)
    (tmp_path / "plain").mkdir()
    plain = both_ways(sandbox, tmp_path / "plain", monkeypatch, "ex2", EX2, ex2_check.run)
    local, remote = both_ways(sandbox, tmp_path, monkeypatch, "ex2", fresh, ex2_check.run)
    assert local == remote == plain[0] == plain[1]


@pytest.mark.parametrize("name", sorted(COUNTING_EX2))
def test_a_counting_loop_does_the_same_sandboxed_as_in_process(sandbox, tmp_path, monkeypatch, name):
    """The loop is judged where the firmware runs, in the grader's sandbox by the child: its turns, its looks and what
    it sends are the same as in `appsim check`, and it passes Ex2's checks."""
    old, new = COUNTING_EX2[name]
    assert EX2.count(old) == 1
    local, remote = both_ways(sandbox, tmp_path, monkeypatch, "ex2", EX2.replace(old, new), ex2_check.run)
    assert remote == local
    judged, trace, _ = local
    assert isinstance(judged, list) and all(passed for _, passed, _ in judged), judged
    assert len(trace) > 5, "it sent frames"


HOSTILE_VARIABLES = """from appsim.firmware import *

ran = []


class Evil(list):
    def __iter__(self):
        ran.append("__iter__")
        raise RuntimeError("__iter__")

    def __hash__(self):
        ran.append("__hash__")
        raise RuntimeError("__hash__")

    def __eq__(self, other):
        ran.append("__eq__")
        raise RuntimeError("__eq__")

    @property
    def __class__(self):
        ran.append("__class__")
        raise RuntimeError("__class__")


class Slotted:
    __module__ = "appsim.chip.fake"         # as if it were the kit's own
    __slots__ = ("x",)

    def __getattribute__(self, name):
        ran.append("__getattribute__")
        raise RuntimeError(name)


class Meta(type):
    def __hash__(cls):
        ran.append("metaclass __hash__")
        raise RuntimeError("__hash__")

    @property
    def __dict__(cls):
        ran.append("metaclass __dict__")
        raise RuntimeError("__dict__")


class Odd(metaclass=Meta):
    pass


class OwnDict:
    @property
    def __dict__(self):
        ran.append("__dict__ property")
        raise RuntimeError("__dict__")


class Key(str):
    def __hash__(self):
        ran.append("key __hash__")
        return str.__hash__(self)

    def __eq__(self, other):            # it records, and answers: type() compares the keys while it makes Keyed
        ran.append("key __eq__")
        return str.__eq__(self, other)


class Items(dict):
    def items(self):
        ran.append("items")
        raise RuntimeError("items")

    def __iter__(self):
        ran.append("dict __iter__")
        raise RuntimeError("__iter__")


class Holder:
    def __getattribute__(self, name):
        ran.append("holder __getattribute__")
        raise RuntimeError(name)


Keyed = type("Keyed", (), {Key("__module__"): "x", Key("__dict__"): 1, Key("count"): 0})


class Spy:
    def __getattr__(self, name):
        ran.append("spy " + name)
        raise AttributeError(name)


class Probe(property):              # a C descriptor that calls Python, where the kit looks for __dict__
    __dict__ = property.__dict__["__isabstractmethod__"]


class Borrowed:                     # another class's C descriptor as its __dict__
    __dict__ = type.__dict__["__doc__"]


class Spying(dict):
    def values(self):
        ran.append("namespace values")
        raise RuntimeError("values")


class Prepared(type):               # a class body whose namespace, its frame's locals, is the firmware's mapping
    @classmethod
    def __prepare__(mcs, name, bases, **keywords):
        return Spying()


def main():
    GLCD_Initial()
    evil, slotted, odd, k = Evil([1, 2]), Slotted(), Odd(), 0
    own, keyed, items, holder = OwnDict(), Keyed(), Items({Key("a"): Evil([4])}), Holder()
    probe, borrowed = Probe(Spy()), Borrowed()
    object.__setattr__(holder, "evil", Evil([3]))
    ran.clear()

    class Body(metaclass=Prepared):
        turns = 0
        while turns < 3:
            turns += 1
            seen = SFR.ADRESL
    while k < 5:
        k += 1
        x = SFR.ADRESH
    setcurGLCD(1, 1)
    putrsGLCD("AFTER " + ",".join(ran))
    while True:
        CANIsRxReady()
"""


# The Ex2 solution with its main loop's turns counted where the looks do not see them (itertools.count) and sent in
# TxData[0]: a polling loop that turns more than the plain one shows on the bus.
TURNS_EX2 = EX2.replace(
    "from appsim.firmware import *\n",
    "import itertools\n\nfrom appsim.chip.sfr import current_mcu\nfrom appsim.firmware import *\n").replace(
    "    while True:\n", "    turns = itertools.count()\n    while True:\n        next(turns)\n", 1).replace(
    "            read_potentiometer()\n",
    "            read_potentiometer()\n            TxData[0] = min(next(turns) // 16, 255)\n", 1)
POLLING_WITH = {
    "a complex NaN made at each turn": "        reading = {'volts': complex('nan')}\n",
    "the kit's MCU's own variables": "        chip = vars(current_mcu())\n",
    "a dict of 200,000 items": "        table = TABLE\n",
    "a dict emptied by deletions": "        emptied = EMPTIED\n",
    "an object of 20,000 attributes": "        many = MANY\n",
    "a list of 5,000,000 items": "        huge = HUGE\n",
}
BIG = ("TABLE = dict.fromkeys(range(200_000), 0)\nEMPTIED = dict.fromkeys(range(300_000), 0)\n"
       "for _k in range(1, 300_000):\n    del EMPTIED[_k]\n\n\nclass Many:\n    pass\n\n\nMANY = Many()\n"
       "for _k in range(20_000):\n    setattr(MANY, f'a{_k}', _k)\nHUGE = [0] * 5_000_000\n")


@pytest.mark.parametrize("name", sorted(POLLING_WITH))
def test_a_polling_loop_turns_the_same_whatever_it_holds_in_every_run_and_both_ways(sandbox, tmp_path, monkeypatch,
                                                                                   name):
    """A complex NaN's hash is its identity's (the loop turned 0, 2 or 3 times more from run to run); the kit's MCU's
    dict changes as the board runs (sandboxed, the loop turned 2,700 times); a big dict or object was copied whole
    at each look (a 700-turn timeout took 195 s in `check`, and a CPU-time fault in the grader), and so was a list
    of millions."""
    body = TURNS_EX2.replace("        next(turns)\n", "        next(turns)\n" + POLLING_WITH[name], 1)
    body = body.replace("TxData = [", BIG + "\n\nTxData = [", 1)
    old, timeout = COUNTING_EX2["a timeout of 700 turns before each frame it sends"]
    (tmp_path / "plain").mkdir()
    plain = both_ways(sandbox, tmp_path / "plain", monkeypatch, "ex2", TURNS_EX2.replace(old, timeout, 1),
                      ex2_check.run)
    runs = [both_ways(sandbox, tmp_path, monkeypatch, "ex2", body.replace(old, timeout, 1), ex2_check.run)
            for _ in range(2)]
    assert all(run == plain for run in runs), name


def test_comparing_variables_runs_none_of_the_firmwares_own_code(tmp_path):
    """The kit looks at the loop's variables without calling anything of theirs: an object whose methods raise (or
    lie about its class) neither crashes the firmware at a register read nor hides the count."""
    assert _lcd_after(tmp_path, "hostile.py", HOSTILE_VARIABLES)[0].rstrip() == "AFTER"
