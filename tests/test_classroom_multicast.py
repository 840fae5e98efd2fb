"""A classroom spread over three PCs, as in a real lab: the instructor's master console and two students'
boards, each simulated on its own machine (a network namespace), on one bus through python-can's udp_multicast.
"""
from __future__ import annotations

import inspect
import json

import pytest
from can.interfaces.udp_multicast import UdpMulticastBus
from netns import HostWatch, namespaces  # noqa: F401 - namespaces is a fixture

pytestmark = pytest.mark.netns
PORT = inspect.signature(UdpMulticastBus).parameters["port"].default
GROUP = UdpMulticastBus.DEFAULT_GROUP_IPv4

PC = """
import json, sys
from appsim.board.app023 import APP023
from appsim.bus.wire import Bus
from appsim.workshop.course import MASTER_FIRMWARE, SOLUTIONS
from appsim.bus.link import BusLink
from appsim.firmware.loader import load_firmware
from appsim.bus.realtime import WallClock
from appsim.sim import Simulator

role, group, seconds = sys.argv[1], sys.argv[2], float(sys.argv[3])
sim = Simulator()
bus = Bus(sim, 125_000)
if role == "instructor":
    board = APP023(bus, "master", potentiometer=777)
    board.run(load_firmware(MASTER_FIRMWARE))
elif role == "student-ex6":
    board = APP023(bus, "station1", potentiometer=321)
    board.run(load_firmware(SOLUTIONS / "ex6.py", {"MESSAGE_ID1": 0x100}))
else:
    board = APP023(bus, "station2", potentiometer=654)
    board.run(load_firmware(SOLUTIONS / "ex5.py", {"RTR_ID": 0x82}))
with BusLink(bus, interface="udp_multicast", channel=group) as link:
    clock = WallClock(sim)
    clock.add_poller(link.poll)
    print("ready", flush=True)
    clock.run(seconds)
print(json.dumps({"frames": [[e.sender, str(e.frame)] for e in bus.frames()], "lcd": board.glcd.lines,
                  "rejected": sum(link.rejected.values()), "failures": board.mcu.process.failure_text}))
"""


def result(process) -> dict:
    assert process.finish(timeout=30) == 0, process.output
    return json.loads(process.lines[-1])


def test_master_on_one_pc_and_students_on_two_others_share_one_bus(namespaces):
    instructor_pc, pc_a, pc_b = namespaces(3)
    with HostWatch(PORT) as watch:
        students = [pc_a.start_python(PC, "student-ex6", GROUP, "2.5"),
                    pc_b.start_python(PC, "student-ex5", GROUP, "2.5")]
        for student in students:
            student.wait_for_line("ready")
        master = instructor_pc.start_python(PC, "instructor", GROUP, "1.5")
        master_run, ex6_run, ex5_run = result(master), *map(result, students)
    for run in (master_run, ex6_run, ex5_run):
        assert run["failures"] == "" and run["rejected"] == 0

    master_frames = [tuple(f) for f in master_run["frames"]]
    assert ("outside", "100 [5] 01 02 03 01 41") in master_frames, "student A's Ex6 answer to the poll (A/D 321)"
    assert ("outside", "082 [0] remote request") in master_frames, "student B's Ex5 request"
    assert ("master", "082 [5] 01 02 03 03 09") in master_frames, "the master answers with its A/D 777"

    assert ("station1", "100 [5] 01 02 03 01 41") in [tuple(f) for f in ex6_run["frames"]]
    assert "777" in ex5_run["lcd"][2], f"student B's LCD shows the master's A/D: {ex5_run['lcd']}"
    own = [f for f in ex5_run["frames"] if f[0] == "station2"]
    assert own and all(f[1] == "082 [0] remote request" for f in own), "each frame once: no echo loops"
    assert watch.dropped == 0 and watch.seen == [], "nothing of it left through the host's interfaces"
