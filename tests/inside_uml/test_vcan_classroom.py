"""The kit on a real Linux vcan0: a simulated board and the whole classroom, seen by can-utils."""
from __future__ import annotations

import subprocess
import sys

from appsim.bus.link import BusLink
from appsim.bus.wire import Bus
from appsim.sim import PS_PER_SECOND, Simulator, ps
from appsim.workshop.classroom import Classroom


def run(sim: Simulator, link: BusLink, seconds: float) -> None:
    """Fast-forward with the link polled every millisecond (no pacing needed: vcan buffers frames)."""
    end = sim.now + ps(seconds)
    while sim.now < end:
        link.poll()
        sim.run(until=min(end, sim.now + PS_PER_SECOND // 1000))


def test_candump_sees_the_classroom_and_a_frame_from_cansend_shows_on_a_station_lcd(candump, cansend):
    dump = candump()
    sim = Simulator()
    bus = Bus(sim, 125_000)
    classroom = Classroom(bus, 6, seed=5, monitor=False)
    with BusLink(bus, interface="socketcan", channel="vcan0") as link:
        run(sim, link, 0.25)
        cansend("130#R")                               # the instructor polls station 4 by hand
        run(sim, link, 0.01)
    station4 = classroom.station(4)
    value = station4.adc.potentiometer
    assert "RTR ID 0x130" in station4.glcd.lines[5], str(station4.glcd)
    lines = dump.wait_for(len(bus.frames()))           # every frame on the simulated bus, 130#R included
    assert lines[0] == "088#0102030200", "the master's first broadcast (its A/D is 512 = 0x200)"
    assert "130#R" in lines
    answer = f"130#010203{value >> 8:02X}{value & 0xFF:02X}"
    assert lines[lines.index("130#R") + 1] == answer, "station 4 answers the RTR from cansend on vcan0"
    assert link.received == 1 and sum(link.rejected.values()) == 0


def test_appsim_classroom_puts_the_workshop_on_vcan0(candump):
    dump = candump()
    result = subprocess.run([sys.executable, "-m", "appsim", "classroom", "--exercise", "5",
                             "--interface", "socketcan", "--channel", "vcan0", "--seconds", "0.5"],
                            capture_output=True, text=True, timeout=60)
    assert result.returncode == 0, result.stderr
    lines = dump.wait_for(10)
    assert "088#0102030200" in lines, "the master's broadcast (its A/D is 512 = 0x200)"
    assert any(line.startswith("081#R") for line in lines), "station 1's RTR (Ex5)"
    assert any(line.startswith("081#01020302") for line in lines), "the master's answer"
    assert "frames sent outside" in result.stdout
