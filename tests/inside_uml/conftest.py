"""Tests in this folder need a real Linux vcan0: on a host without one they are skipped, and
tests/test_vcan_uml.py runs them inside User-Mode Linux. Fixtures: `candump`, `cansend`, `vcan_bus`.
"""
from __future__ import annotations

from collections.abc import Callable, Iterator
from pathlib import Path

import can
import pytest
from vcan_harness import Candump, has_vcan, inside_uml
from vcan_harness import cansend as _cansend

HERE = Path(__file__).resolve().parent


def pytest_collection_modifyitems(config: pytest.Config, items: list[pytest.Item]) -> None:
    if not any(HERE in item.path.parents for item in items):
        return
    if inside_uml() and not has_vcan():
        raise pytest.UsageError("running under tools/vcan-uml but there is no vcan0: the UML setup failed")
    skip = pytest.mark.skip(reason="no vcan0 on this machine: tests/test_vcan_uml.py runs these inside User-Mode Linux")
    for item in items:
        if HERE in item.path.parents:
            item.add_marker(pytest.mark.vcan)
            if not has_vcan():
                item.add_marker(skip)


@pytest.fixture
def candump() -> Iterator[Callable[..., Candump]]:
    """Start `candump -L CHANNEL` (vcan0 by default) in the background: `dump = candump(); ...; dump.wait_for(1)`."""
    started: list[Candump] = []

    def start(channel: str = "vcan0") -> Candump:
        started.append(Candump(channel).start())
        return started[-1]

    yield start
    for dump in started:
        dump.stop()


@pytest.fixture
def cansend() -> Callable[..., None]:
    """`cansend("123#DEADBEEF")` on vcan0, or `cansend(frame, "vcan1")`."""
    return _cansend


@pytest.fixture
def vcan_bus() -> Iterator[can.BusABC]:
    """A python-can bus on vcan0, as a user's program would open it."""
    with can.Bus(interface="socketcan", channel="vcan0") as bus:
        yield bus
