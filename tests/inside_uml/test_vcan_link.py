"""The link on a real Linux vcan0 under outside pressure: cangen at full rate, CAN FD frames, DLC above 8, and the
interface going down or away in the middle of a run. Every frame is accounted for and the classroom goes on.
"""
from __future__ import annotations

import subprocess
import time
from collections.abc import Callable, Iterator
from pathlib import Path

import can
import pytest

from appsim.bus.link import DLC_ABOVE_8, ERROR_FRAME, FD_FRAME, REOPEN_EVERY_S, BusLink
from appsim.bus.realtime import WallClock
from appsim.bus.wire import Bus
from appsim.sim import Simulator, ps
from appsim.workshop.classroom import Classroom
from appsim.workshop.course import STATIONS, station_ids

CANGEN_FRAMES = 50_000      # about 5 s of `cangen -g 0` inside UML while the classroom runs
FLOOD_ID = "7F0"            # the lowest priority, used by no classroom node: the classroom goes on under the flood


class LinkedClassroom:
    """The classroom at Ex6 (the master polls each station with an RTR) linked to vcan0, paced to the wall clock."""

    def __init__(self) -> None:
        self.sim = Simulator()
        self.bus = Bus(self.sim, 125_000)
        self.classroom = Classroom(self.bus, 6, seed=7, monitor=False)
        self.link = BusLink(self.bus, interface="socketcan", channel="vcan0")
        self.clock = WallClock(self.sim)
        self.clock.add_poller(self.link.poll)

    def at(self, seconds: float, action: Callable[[], object]) -> None:
        """Do `action` once the simulated clock reaches `seconds`, between two slices of a run."""
        due = ps(seconds)

        def poll() -> None:
            if self.sim.now >= due and poll in self.clock.pollers:
                self.clock.pollers.remove(poll)
                action()

        self.clock.add_poller(poll)

    def assert_every_station_answers_the_master(self, since_ps: int) -> None:
        answered = {e.sender for e in self.bus.frames() if e.start_ps >= since_ps and e.sender.startswith("station")
                    and e.frame.can_id == station_ids(int(e.sender[7:]))["MESSAGE_ID1"] and not e.frame.remote}
        assert answered == {f"station{k}" for k in range(1, STATIONS + 1)}, f"only {sorted(answered)} answered"

    def assert_report_adds_up(self) -> str:
        link, report = self.link, self.link.report()
        rejected = sum(link.rejected.values())
        assert link.received == link.delivered + rejected + link.dropped + link.queued
        assert link.delivered == sum(e.sender == link.name for e in self.bus.frames())
        assert f"{link.received} received = {link.delivered} delivered + {rejected} rejected" in report
        return report


@pytest.fixture
def room() -> Iterator[LinkedClassroom]:
    linked = LinkedClassroom()
    yield linked
    linked.link.close()


def ip(*args: str) -> None:
    subprocess.run(["ip", "link", *args], check=True, capture_output=True, timeout=10)


def test_cangen_at_full_rate_every_frame_is_accounted_for_and_the_classroom_goes_on(room, caplog):
    started = time.monotonic()
    cangen = subprocess.Popen(["cangen", "vcan0", "-g", "0", "-I", FLOOD_ID, "-n", str(CANGEN_FRAMES)])
    room.clock.run(stop=lambda: cangen.poll() is not None)
    cangen_seconds = time.monotonic() - started
    assert cangen.returncode == 0
    assert any("faster than the simulated 125 kbit/s bus" in r.message for r in caplog.records), \
        "drops are told while the flood goes on"
    room.clock.run(0.2)                     # what is left in the socket's buffer is read
    quiet = room.sim.now
    room.clock.run(0.8)

    link = room.link
    assert link.received + link.kernel_dropped == CANGEN_FRAMES, "every frame cangen sent is accounted for"
    assert not link.rejected and link.dropped > 0 and link.kernel_dropped > 0
    report = room.assert_report_adds_up()
    assert f"the kernel dropped {link.kernel_dropped} more" in report
    room.assert_every_station_answers_the_master(since_ps=quiet)
    print(f"cangen sent {CANGEN_FRAMES} frames in {cangen_seconds:.1f} s: {link.delivered} delivered, "
          f"{link.dropped} dropped (queue full), {link.kernel_dropped} dropped by the kernel, {link.queued} queued; "
          f"largest lag {room.clock.max_lag_s:.2f} s")


def test_fd_frames_dlc_above_8_and_error_frames_from_outside_are_counted(room):
    assert Path("/sys/class/net/vcan0/mtu").read_text().strip() == "72", "tools/vcan-uml sets up vcan0 for CAN FD"
    with can.Bus(interface="socketcan", channel="vcan0", fd=True) as peer:
        for dlc in range(9, 16):
            peer.send(can.Message(arbitration_id=0x123, data=bytes(8), dlc=dlc, is_extended_id=False))
        peer.send(can.Message(arbitration_id=0x20000080, is_error_frame=True, is_extended_id=True))
    cangen = subprocess.Popen(["cangen", "vcan0", "-m", "-g", "1", "-n", "300", "-v"],   # -m: FD, RTR, EFF mixed
                              stdout=subprocess.PIPE, text=True)
    room.clock.run(stop=lambda: cangen.poll() is not None)
    room.clock.run(0.2)
    fd_sent = sum("##" in line for line in cangen.stdout)

    link = room.link
    assert link.kernel_dropped == 0, "at one frame a millisecond nothing should overflow the socket's buffer"
    assert link.received == 300 + 7 + 1
    assert (link.rejected[FD_FRAME], link.rejected[DLC_ABOVE_8], link.rejected[ERROR_FRAME]) == (fd_sent, 7, 1) \
        and fd_sent > 0
    room.assert_report_adds_up()


def answers_a_poll_from_cansend(room: LinkedClassroom) -> bool:
    subprocess.run(["cansend", "vcan0", "130#R"], check=True, timeout=10)
    asked = room.sim.now
    room.clock.run(0.05)
    return any(e.sender == "station4" and e.frame.can_id == 0x130 and e.start_ps > asked for e in room.bus.frames())


def test_the_interface_taken_down_and_brought_back_the_run_goes_on_and_reports_it(room, caplog):
    room.at(0.3, lambda: ip("set", "vcan0", "down"))
    room.at(0.6, lambda: ip("set", "vcan0", "up"))
    room.clock.run(1.0)
    assert answers_a_poll_from_cansend(room), "station 4 answers an RTR from cansend once vcan0 is up again"
    report = room.assert_report_adds_up()
    assert "Network is down" in report and "the interface is down" in report
    assert sum(room.link.send_failures.values()) > 0, "the frames sent while it was down are counted"
    assert any("the interface is down" in r.message for r in caplog.records), "told when it happened"


def test_an_interface_deleted_and_created_again_is_opened_again(room, caplog):
    room.at(0.3, lambda: ip("del", "vcan0"))
    room.at(0.6, lambda: (ip("add", "vcan0", "type", "vcan"), ip("set", "vcan0", "mtu", "72", "up")))
    room.clock.run(0.6 + 2 * REOPEN_EVERY_S)
    assert room.link.reopened == 1 and answers_a_poll_from_cansend(room)
    report = room.assert_report_adds_up()
    assert "No such device" in report and "opened again 1 time" in report
    assert any("is back, opened again" in r.message for r in caplog.records)
