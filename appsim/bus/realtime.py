"""Pacing the simulated clock to the wall clock, for a simulation that talks to the outside world.

Simulated time advances in short slices, never ahead of the wall clock; between slices, pollers
bring in what arrived from outside (CAN frames, serial bytes) at the simulated present.
"""
from __future__ import annotations

import logging
import time
from collections.abc import Callable

from appsim.sim import PS_PER_SECOND, Simulator, ps

log = logging.getLogger(__name__)

SLICE_PS = PS_PER_SECOND // 1000        # 1 ms: the latency an outside frame or byte can see
LATE_S = 0.2                            # a run this far behind the wall clock says so, once


class WallClock:
    """Runs a `Simulator` in real time (or `speed` times real time), polling outside sources as it goes."""

    def __init__(self, sim: Simulator, *, speed: float = 1.0, slice_ps: int = SLICE_PS):
        if not speed > 0:
            raise ValueError(f"speed is simulated seconds per wall second and must be > 0; got {speed}")
        self.sim = sim
        self.speed = speed
        self.slice_ps = slice_ps
        self.pollers: list[Callable[[], None]] = []
        self.max_lag_s = 0.0             # the most the simulation fell behind the wall clock
        self.lag_s = 0.0                 # how far behind it is now
        self.late_since_ps: int | None = None   # when it first fell more than LATE_S behind (simulated time)

    def add_poller(self, poll: Callable[[], None]) -> None:
        """`poll()` is called between slices, with the simulation stopped at its present (`sim.now`)."""
        self.pollers.append(poll)

    def poll(self) -> None:
        for poll in self.pollers:
            poll()

    def run(self, seconds: float | None = None, *, stop: Callable[[], bool] | None = None) -> None:
        """Run for `seconds` of simulated time (None: until `stop()` or Ctrl-C), paced to the wall clock."""
        sim = self.sim
        start_ps, start_wall = sim.now, time.perf_counter()
        end_ps = None if seconds is None else start_ps + ps(seconds)
        while (end_ps is None or sim.now < end_ps) and not (stop is not None and stop()):
            self.poll()
            target = sim.now + self.slice_ps if end_ps is None else min(sim.now + self.slice_ps, end_ps)
            sim.run(until=target)
            due_wall = start_wall + (target - start_ps) / PS_PER_SECOND / self.speed
            ahead = due_wall - time.perf_counter()
            self.lag_s = max(0.0, -ahead)
            if ahead > 0:
                time.sleep(ahead)
            else:
                self.max_lag_s = max(self.max_lag_s, self.lag_s)
                if self.lag_s > LATE_S and self.late_since_ps is None:
                    self.late_since_ps = sim.now
                    log.warning("the simulation has fallen %.1f s behind real time at %.1f s (simulated): what it "
                                "sends and receives outside is that late (the machine is too busy, or the bus carries "
                                "more than it simulates in real time); the summary says how far it fell",
                                self.lag_s, sim.now / PS_PER_SECOND)
        self.poll()

    def lateness(self) -> str:
        """How far the run fell behind real time, and since when, in a line ("" if it kept up within LATE_S)."""
        if self.late_since_ps is None:
            return ""
        return (f"behind real time from {self.late_since_ps / PS_PER_SECOND:.1f} s (simulated) on: at most "
                f"{self.max_lag_s:.1f} s behind, {self.lag_s:.1f} s at the end (frames to and from outside were that "
                "late)")
