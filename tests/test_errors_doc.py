"""docs/errors.md: every counter in its scenario tables, worked by hand there, is what the simulation gives."""
from __future__ import annotations

import re
from pathlib import Path

import pytest
from conftest import World
from test_bus_gotchas import normal_node
from test_fault_confinement import same_identifier, wrong_rate_sender

from appsim.firmware import *

DOC = Path(__file__).resolve().parent.parent / "docs" / "errors.md"


def odd_listener():
    CANInitialize(4, 8, 8, 4, 3, CAN_CONFIG_ALL_MSG)       # 156.25 kbit/s on a 125 kbit/s bus
    while True:
        CANIsRxReady()


def lone(world):
    return {"a": world.node("a", normal_node([(0x100, CAN_TX_PRIORITY_0)]))}


def same_id_active(world):
    a, b, c = same_identifier(world, b_passive=False)
    return {"a": a, "b": b, "c": c}


def same_id_b_passive(world):
    a, b, c = same_identifier(world, b_passive=True)
    return {"a": a, "b": b, "c": c}


def wrong_rate_listener(world):
    return {"master": world.node("master", normal_node([(0x088, CAN_TX_PRIORITY_0)])),
            "station": world.node("station", normal_node()),
            "odd": world.node("odd", odd_listener)}


def wrong_rate_sender_scenario(world):
    return {"odd": world.node("odd", wrong_rate_sender), "station": world.node("station", normal_node())}


def injected_crc(world):
    nodes = {"a": world.node("a", normal_node([(0x100, CAN_TX_PRIORITY_0)], delay_ms=1)),
             "b": world.node("b", normal_node()), "c": world.node("c", normal_node())}
    world.bus.inject("b", "crc")
    return nodes


def bus_off(world):
    nodes = {"a": world.node("a", normal_node([(0x100, CAN_TX_PRIORITY_0)])),
             "l": world.node("l", normal_node())}
    world.bus.inject("a", "bit", 20, frames=32)
    return nodes


SCENARIOS = {"A": lone, "B": same_id_active, "C": same_id_b_passive, "D": wrong_rate_listener,
             "E": wrong_rate_sender_scenario, "F": injected_crc, "G": bus_off}


def tables() -> dict[str, tuple[list[str], list[tuple[int, list[tuple[int, int]]]]]]:
    """Each scenario's table: the node columns, and (event, [(TEC, REC) per node]) rows."""
    found = {}
    for section in re.split(r"^### ", DOC.read_text(), flags=re.M)[1:]:
        letter = section[0]
        lines = [line for line in section.splitlines() if line.startswith("|")]
        header = [cell.strip() for cell in lines[0].strip("|").split("|")]
        names = [cell.split()[0] for cell in header[2:]]
        rows = []
        for line in lines[2:]:
            cells = [cell.strip() for cell in line.strip("|").split("|")]
            rows.append((int(cells[0]), [tuple(int(n) for n in cell.split()[0].split("/")) for cell in cells[2:]]))
        found[letter] = (names, rows)
    return found


def test_the_doc_has_a_table_for_every_scenario():
    assert sorted(tables()) == sorted(SCENARIOS)


@pytest.mark.parametrize("letter", sorted(SCENARIOS))
def test_scenario_counters_match_the_doc(letter):
    names, rows = tables()[letter]
    world = World()
    nodes = SCENARIOS[letter](world)
    for event, expected in rows:
        while world.bus.trace.total < event:
            world.run(0.0001)
            assert world.sim.now < 2 * 10**12, f"scenario {letter}: event {event} never came"
        got = [(nodes[name].ecan.tec, nodes[name].ecan.rec) for name in names]
        assert got == expected, f"scenario {letter}, after event {event}: {dict(zip(names, got, strict=True))}"
