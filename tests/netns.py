"""Network namespaces ("PCs") joined by a bridge of their own, for python-can's udp_multicast between machines
that never touch this host's interfaces; and a watch on the host's interfaces proving nothing left.

    from netns import namespaces          # the fixture: skips unless root with `ip netns`
    def test_x(namespaces):
        pcs = namespaces(3)               # torn down after the test, even when it fails
        out = pcs[0].python("import can; ...", timeout=20)
"""
from __future__ import annotations

import itertools
import os
import shutil
import socket
import struct
import subprocess
import sys
import threading
from collections.abc import Callable, Iterator, Sequence
from contextlib import ExitStack, contextmanager
from dataclasses import dataclass, field
from functools import cache
from pathlib import Path

import pytest

KIT = Path(__file__).resolve().parent.parent
INTERFACE = "eth0"
# Documentation ranges (RFC 5737, RFC 3849): never routed anywhere, and here they exist only inside the namespaces.
IPV4_PREFIX, IPV6_PREFIX = "192.0.2.", "2001:db8:7468::"
_networks = itertools.count()


def ip(*args: str, namespace: str | None = None) -> None:
    """Run `ip [-n NAMESPACE] ARGS...`; fails with ip's own message."""
    command = ["ip", *(["-n", namespace] if namespace else []), *args]
    result = subprocess.run(command, capture_output=True, text=True, timeout=10, check=False)
    if result.returncode != 0:
        raise RuntimeError(f"{' '.join(command)} failed: {result.stderr.strip()}")


@cache
def unavailable() -> str | None:
    """Why network namespaces cannot be made here, or None if they can."""
    if os.geteuid() != 0:
        return "network namespaces need root (ip netns add)"
    if shutil.which("ip") is None:
        return "network namespaces need iproute2 (apt-get install iproute2)"
    probe = f"appsim-{os.getpid()}-probe"
    try:
        ip("netns", "add", probe)
    except RuntimeError as error:
        return f"cannot create a network namespace here: {error}"
    ip("netns", "del", probe)
    return None


class Process:
    """A program running in a namespace; its stdout lines are collected as they come."""

    def __init__(self, namespace: str, command: Sequence[str]) -> None:
        self.command = " ".join(command)
        self.lines: list[str] = []
        self._changed = threading.Condition()
        self._popen = subprocess.Popen(
            ["ip", "netns", "exec", namespace, *command], cwd=KIT, stdin=subprocess.DEVNULL,
            stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True,
        )
        self._reader = threading.Thread(target=self._read, daemon=True)
        self._reader.start()

    def _read(self) -> None:
        assert self._popen.stdout is not None
        for line in self._popen.stdout:
            with self._changed:
                self.lines.append(line.rstrip("\n"))
                self._changed.notify_all()
        with self._changed:
            self._changed.notify_all()

    @property
    def output(self) -> str:
        return "\n".join(self.lines)

    def wait_for_line(self, text: str, timeout: float = 20.0) -> None:
        """Return once a line equal to `text` has been printed (e.g. "ready"); fail with the output if not."""
        with self._changed:
            if not self._changed.wait_for(lambda: text in self.lines or self._popen.poll() is not None, timeout):
                raise AssertionError(f"{self.command} did not print {text!r} within {timeout:g} s:\n{self.output}")
            if text not in self.lines:
                raise AssertionError(f"{self.command} ended without printing {text!r}:\n{self.output}")

    def finish(self, timeout: float = 20.0) -> int:
        """Wait for the program to end (killed after `timeout`) and return its exit status."""
        try:
            self._popen.wait(timeout=timeout)
        except subprocess.TimeoutExpired:
            self.kill()
            raise AssertionError(f"{self.command} did not finish within {timeout:g} s:\n{self.output}") from None
        self._reader.join(timeout=5)
        return self._popen.returncode

    def kill(self) -> None:
        if self._popen.poll() is None:
            self._popen.kill()
            self._popen.wait()
        self._reader.join(timeout=5)


@dataclass
class Namespace:
    """One "PC": a network namespace with `lo` and eth0 (on the bridge) up, and multicast routed out of eth0."""

    name: str
    ipv4: str
    ipv6: str
    processes: list[Process] = field(default_factory=list, repr=False)

    def start(self, *command: str) -> Process:
        """Start `ip netns exec NAME COMMAND...` in the background, in the kit's directory."""
        self.processes.append(Process(self.name, command))
        return self.processes[-1]

    def start_python(self, code: str, *args: str) -> Process:
        """Start this test run's Python on `code` in the namespace; `sys.argv[1:]` are `args`."""
        return self.start(sys.executable, "-c", code, *args)

    def python(self, code: str, *args: str, timeout: float = 20.0) -> subprocess.CompletedProcess[str]:
        """Run Python `code` in the namespace to the end; its output (stdout and stderr) and status come back."""
        return subprocess.run(
            ["ip", "netns", "exec", self.name, sys.executable, "-c", code, *args], cwd=KIT,
            stdin=subprocess.DEVNULL, stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True, timeout=timeout,
            check=False,
        )


@contextmanager
def network(count: int = 3) -> Iterator[list[Namespace]]:
    """`count` namespaces appsim-PID-N-1.. on a bridge in namespace appsim-PID-N-br; all removed on the way out."""
    if not 1 <= count <= 200:
        raise ValueError(f"a test network has 1..200 namespaces; asked for {count}")
    prefix = f"appsim-{os.getpid()}-{next(_networks)}"
    bridge = f"{prefix}-br"
    made: list[str] = []
    pcs = [Namespace(f"{prefix}-{k}", f"{IPV4_PREFIX}{k}", f"{IPV6_PREFIX}{k}") for k in range(1, count + 1)]
    try:
        for name in [bridge, *(pc.name for pc in pcs)]:
            ip("netns", "add", name)
            made.append(name)
            ip("link", "set", "lo", "up", namespace=name)
        ip("link", "add", "br0", "type", "bridge", "mcast_snooping", "0", namespace=bridge)
        ip("link", "set", "br0", "up", namespace=bridge)
        for k, pc in enumerate(pcs, start=1):
            port = f"port{k}"
            # Both ends are made inside namespaces: the host's own namespace never sees them.
            ip("link", "add", port, "type", "veth", "peer", "name", INTERFACE, "netns", pc.name, namespace=bridge)
            ip("link", "set", port, "master", "br0", "up", namespace=bridge)
            ip("addr", "add", f"{pc.ipv4}/24", "dev", INTERFACE, namespace=pc.name)
            ip("-6", "addr", "add", f"{pc.ipv6}/64", "dev", INTERFACE, "nodad", namespace=pc.name)
            ip("link", "set", INTERFACE, "up", namespace=pc.name)
            ip("route", "add", "224.0.0.0/4", "dev", INTERFACE, namespace=pc.name)
        yield pcs
    finally:
        for pc in pcs:
            for process in pc.processes:
                process.kill()
        for name in made:
            subprocess.run(["ip", "netns", "del", name], capture_output=True, timeout=10, check=False)


@pytest.fixture
def namespaces() -> Iterator[Callable[[int], list[Namespace]]]:
    """Make N "PCs": `pcs = namespaces(3)`; skipped with the reason when not root or without `ip netns`."""
    if reason := unavailable():
        pytest.skip(reason)
    with ExitStack() as stack:
        yield lambda count=3: stack.enter_context(network(count))


ETH_P_ALL, SOL_PACKET, PACKET_STATISTICS, SO_RCVBUFFORCE = 0x0003, 263, 6, 33
ETH_P_IP, ETH_P_IPV6, IPPROTO_UDP = 0x0800, 0x86DD, 17


def _udp_destination_port(protocol: int, packet: bytes) -> int | None:
    if protocol == ETH_P_IP and len(packet) >= 20 and packet[9] == IPPROTO_UDP:
        header = (packet[0] & 0x0F) * 4
        return int.from_bytes(packet[header + 2:header + 4], "big") if len(packet) >= header + 4 else None
    if protocol == ETH_P_IPV6 and len(packet) >= 44 and packet[6] == IPPROTO_UDP:
        return int.from_bytes(packet[42:44], "big")
    return None


class HostWatch:
    """Every UDP packet to `port` on any of this host's own interfaces (eth0, lo, ...), seen with a packet socket
    in the host's namespace while the watch is open: `with HostWatch(43113) as watch: ...; watch.seen`."""

    def __init__(self, port: int) -> None:
        self.port = port
        self.seen: list[str] = []
        self.dropped = 0
        self._socket = socket.socket(socket.AF_PACKET, socket.SOCK_DGRAM, socket.htons(ETH_P_ALL))
        self._socket.setsockopt(socket.SOL_SOCKET, SO_RCVBUFFORCE, 8 << 20)  # root may exceed rmem_max
        self._socket.settimeout(0.05)
        self._stop = threading.Event()
        self._reader = threading.Thread(target=self._read, daemon=True)

    def _read(self) -> None:
        while not self._stop.is_set():
            try:
                self._note(*self._socket.recvfrom(65536))
            except TimeoutError:
                continue

    def _note(self, packet: bytes, address: tuple) -> None:
        interface, protocol = address[:2]
        if _udp_destination_port(protocol, packet) == self.port:
            self.seen.append(f"UDP to port {self.port} on the host's {interface}")

    def __enter__(self) -> HostWatch:
        self._reader.start()
        return self

    def __exit__(self, *exc: object) -> None:
        self._stop.set()
        self._reader.join()
        self._socket.setblocking(False)
        while True:  # a packet is queued here as it is sent: what was sent before now is all in the queue
            try:
                self._note(*self._socket.recvfrom(65536))
            except BlockingIOError:
                break
        _, self.dropped = struct.unpack("II", self._socket.getsockopt(SOL_PACKET, PACKET_STATISTICS, 8))
        self._socket.close()
