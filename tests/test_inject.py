"""Injected errors: what could never fire is refused with why; several for one node fire in successive frames; a node
in Listen-only mode gets its injection once it is in Normal mode; one that never fired is reported, with why."""
from __future__ import annotations

import re
import subprocess
import sys
from pathlib import Path

import pytest
from test_bus_gotchas import normal_node

from appsim.firmware import *

KIT = Path(__file__).resolve().parent.parent


def appsim(*args: str) -> subprocess.CompletedProcess:
    return subprocess.run([sys.executable, "-m", "appsim", *args], capture_output=True, text=True, cwd=KIT,
                          timeout=300)


@pytest.mark.parametrize("given, why", [
    ("station1:stuff:0", "a stuff error is the sixth equal bit in a row between SOF and the end of the CRC "
                         "sequence: bits 5..146, not 0"),
    ("station1:stuff:147", "a stuff error is the sixth equal bit in a row between SOF and the end of the CRC "
                           "sequence: bits 5..146, not 147"),
    ("station1:bit:-1", "bits are counted from SOF = 0: bit -1 comes before any frame"),
    ("station1:bit:300", "bit 300 is past the end of any frame and the error frames that can follow it"),
    ("station1:bit:3:0x20000000", "no frame has identifier 0x20000000: identifiers are 0..0x7FF (11 bits) or, "
                                  "extended, 0..0x1FFFFFFF (29 bits)"),
    ("station1:bit:3:-5", "no frame has identifier -0x5"),
    ("station1:dominant:0", "a node drives in each bit what it decided at the bit before, and SOF (bit 0) is "
                            "dominant anyway: a dominant injection starts at bit 1 at the earliest"),
    ("station1:crc:5", "a CRC error is seen at a receiver's ACK delimiter, whatever the frame's length: give bit 0"),
    ("station1:ack:64", "an ACK error is seen at a transmitter's ACK slot"),
    ("station1:form:10", "a form error is a dominant bit where a frame has a fixed recessive one"),
])
def test_an_injection_that_could_never_fire_is_refused_with_why(given, why):
    result = appsim("classroom", "--inject", given)
    assert result.returncode == 2 and result.stdout == ""
    assert f"argument --inject: {given} could never fire: {why}" in result.stderr, result.stderr


@pytest.mark.parametrize("arguments, why", [
    ({"kind": "dominant", "bit": 40, "length": 0}, "a dominant injection lasts 1..1000 bits, not 0"),
    ({"kind": "dominant", "bit": 40, "length": 5000}, "not 5000"),
    ({"kind": "bit", "bit": 20, "frames": 0}, "an injection fires in 1 frame or more, not 0"),
    ({"kind": "stuff", "bit": 2}, "not 2"),
])
def test_bus_inject_refuses_the_same(world, arguments, why):
    from appsim.errors import InjectionError
    world.node("a", normal_node([(0x100, CAN_TX_PRIORITY_0)]))
    with pytest.raises(InjectionError, match=why):
        world.bus.inject("a", **arguments)


def three_nodes(world):
    """a sends 0x100 at 1 ms; b and c receive (all error-active, Normal mode)."""
    a = world.node("a", normal_node([(0x100, CAN_TX_PRIORITY_0)], delay_ms=1))
    world.node("b", normal_node())
    world.node("c", normal_node())
    world.run(0.0009)
    return a


def test_injections_for_one_node_fire_in_successive_frames(world):
    a = three_nodes(world)
    for _ in range(10):
        world.bus.inject("a", "bit", 20)
    world.run(0.05)
    events = world.bus.trace[:11]
    assert [e.error.split(":")[0] for e in events[:10]] == ["bit error at bit 20"] * 10
    assert events[10].ok and a.ecan.tec == 10 * 8 - 1
    assert world.bus.injections.not_fired() == []


def test_a_node_in_listen_only_mode_gets_its_injection_once_it_is_in_normal_mode():
    from appsim.bus.wire import Bus
    from appsim.sim import Simulator
    from appsim.workshop.classroom import Classroom
    sim = Simulator()
    bus = Bus(sim, 125_000)
    room = Classroom(bus, 4, seed=4)
    bus.inject("station4", "stuff", 30)
    room.run(1.0)
    flagged = [e for e in bus.trace if e.error.endswith("(station4)")]
    assert len(flagged) == 1 and flagged[0].error.startswith("stuff error at bit 30: six equal bits (injected)")
    assert bus.injections.not_fired() == []


@pytest.mark.parametrize("argv, said", [
    (["--exercise", "4", "--seconds", "0.1", "--inject", "station4:stuff:30"],
     "--inject station4:stuff:30 never fired: station4 was in Listen-only mode in all 1 frames it heard, and a "
     "Listen-only node sends no error flag"),
    (["--exercise", "2", "--seconds", "0.5", "--inject", "station1:bit:20:0x555"],
     "--inject station1:bit:20:0x555 never fired: no frame with identifier 0x555 went by station1 in Normal mode "
     "(it saw 0x088, 0x100, 0x110"),
    (["--exercise", "2", "--seconds", "0.5", "--inject", "station1:bit:150"],
     "--inject station1:bit:150 never fired: bit 150 is past the end of every frame station1 took part in"),
    (["--exercise", "1", "--seconds", "0.5", "--inject", "station1:stuff:30"],
     "--inject station1:stuff:30 never fired: station1 took part in no frame on the bus"),
])
def test_an_injection_that_never_fired_is_reported_with_why_and_the_exit_status_is_1(argv, said):
    result = appsim("classroom", *argv)
    assert result.returncode == 1 and "Traceback" not in result.stderr
    assert said in result.stderr, result.stderr


def test_two_thousand_injections_fire_in_two_thousand_frames():
    """Each fires once station2 detects its stuff error; while its REC is above 127, its passive error flag leaves the
    frame whole, so a few of them are frames that went through."""
    result = appsim("classroom", "--exercise", "2", "--seconds", "2",
                    *(arg for _ in range(2000) for arg in ("--inject", "station2:stuff:30")))
    assert result.returncode == 0 and "never fired" not in result.stderr, result.stderr
    errors = int(re.search(r"^\d+ frames, (\d+) error frames in 2.000 s", result.stdout, re.M)[1])
    assert 1500 < errors <= 2000
