"""Shared test harness: a simulated bus with boards, and firmware to run on them."""
from __future__ import annotations

import signal
from collections.abc import Callable

import pytest

from appsim.bus.wire import Bus
from appsim.chip.mcu import PIC18F8680
from appsim.sim import Simulator

# The tests press Ctrl-C on the kit's commands, as a user at a terminal does. A test run started in the background of a
# script (`cmd &` without job control) inherits SIGINT ignored, and would hand it ignored to every command it starts:
# they get it as a terminal gives it (an ignored signal is inherited across exec, a handler is not).
if signal.getsignal(signal.SIGINT) == signal.SIG_IGN:
    signal.signal(signal.SIGINT, signal.default_int_handler)


class World:
    """A bus at 125 kbit/s (the classroom's) and the nodes on it."""

    def __init__(self, bit_rate: int = 125_000):
        self.sim = Simulator()
        self.bus = Bus(self.sim, bit_rate)

    def node(self, name: str, main: Callable[[], object] | None = None) -> PIC18F8680:
        mcu = self.bus.attach(PIC18F8680(self.sim, name))
        if main is not None:
            mcu.run(main)
        return mcu

    def run(self, seconds: float = 0.1) -> None:
        self.sim.run_for(seconds)
        for process in self.sim.processes:
            if process.failure is not None:
                raise AssertionError(f"firmware {process.name} crashed:\n{process.failure_text}")


@pytest.fixture
def world() -> World:
    return World()
