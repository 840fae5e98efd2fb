"""python-can's udp_multicast between three "PCs" (network namespaces on a bridge of their own): a frame sent on
one arrives on the other two, and no packet of it appears on any of the host's own interfaces.
"""
from __future__ import annotations

import inspect
import socket

import pytest
from can.interfaces.udp_multicast import UdpMulticastBus
from netns import HostWatch, namespaces, unavailable  # noqa: F401 - namespaces is a fixture

pytestmark = pytest.mark.netns
PORT = inspect.signature(UdpMulticastBus).parameters["port"].default

RECEIVER = """
import sys, can
with can.Bus(interface="udp_multicast", channel=sys.argv[1]) as bus:
    print("ready", flush=True)
    message = bus.recv(timeout=10)
    print("nothing in 10 s" if message is None else
          f"{message.arbitration_id:03X}#{message.data.hex().upper()} extended={message.is_extended_id}")
"""

SENDER = """
import sys, can
with can.Bus(interface="udp_multicast", channel=sys.argv[1]) as bus:
    bus.send(can.Message(arbitration_id=0x123, data=bytes.fromhex("DEADBEEF"), is_extended_id=False))
"""


@pytest.mark.parametrize("group", [UdpMulticastBus.DEFAULT_GROUP_IPv4, UdpMulticastBus.DEFAULT_GROUP_IPv6],
                         ids=["ipv4", "ipv6"])
def test_a_frame_sent_on_one_pc_arrives_on_the_other_two_and_never_on_the_host(namespaces, group):
    sender, *others = namespaces(3)
    with HostWatch(PORT) as watch:
        receivers = [pc.start_python(RECEIVER, group) for pc in others]
        for receiver in receivers:
            receiver.wait_for_line("ready")
        sent = sender.python(SENDER, group)
        assert sent.returncode == 0, sent.stdout
        for receiver in receivers:
            assert receiver.finish() == 0, receiver.output
    assert [receiver.lines[-1] for receiver in receivers] == ["123#DEADBEEF extended=False"] * 2
    assert watch.dropped == 0, "the host watch dropped packets: it cannot tell whether any left the host"
    assert watch.seen == []


def test_the_host_watch_sees_a_packet_on_the_hosts_own_interfaces():
    if reason := unavailable():
        pytest.skip(reason)
    control = PORT + 1          # not python-can's port, so a test running beside this one is not disturbed
    with HostWatch(control) as watch, socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as udp:
        udp.sendto(b"appsim", ("127.0.0.1", control))
    assert f"UDP to port {control} on the host's lo" in watch.seen
