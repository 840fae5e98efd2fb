"""The bus trace: what the bus carried, its latest events kept in memory, counts over the whole run, and listeners
that get every event as it happens (a log keeps what the window lets go).
"""
from __future__ import annotations

import itertools
from collections import deque
from collections.abc import Callable, Iterator, Sequence
from typing import TYPE_CHECKING, overload

if TYPE_CHECKING:
    from appsim.bus.wire import BusEvent

# Events a trace keeps in memory: 2.5 simulated minutes of a classroom, about 4 MB. An event holds about 200 bytes,
# frames and error frames alike: the bus keeps each frame, outcome and wire that events repeat once (about 300 bytes
# where no two are alike; `python -m bench` measures it). A check's whole run (1 s at most) fits many times over: at
# 125 kbit/s even a bus full of error frames carries under 4,000 a second.
TRACE_WINDOW = 20_000


class Trace(Sequence["BusEvent"]):
    """What the bus carried, oldest first: the last `window` events (every one if `window` is None), counts over the
    whole run, and `listeners`, called with each event as it happens (a log keeps what the window lets go)."""

    def __init__(self, window: int | None = TRACE_WINDOW):
        if window is not None and window < 1:
            raise ValueError(f"a trace window holds 1 event or more (None: every event); got {window}")
        self.window = window
        self._events: deque[BusEvent] = deque(maxlen=window)
        self.total = 0                   # events since the start
        self.frames = 0                  # of them, frames that went through
        self.busy_ps = 0                 # the time they held the bus
        self.listeners: list[Callable[[BusEvent], None]] = []

    def append(self, event: BusEvent) -> None:
        self._events.append(event)
        self.total += 1
        self.frames += event.ok
        self.busy_ps += event.end_ps - event.start_ps
        for listener in self.listeners:
            listener(event)

    @property
    def errors(self) -> int:
        """Error frames since the start."""
        return self.total - self.frames

    @property
    def dropped(self) -> int:
        """Events older than the window: no longer in memory."""
        return self.total - len(self._events)

    def since(self, count: int) -> list[BusEvent]:
        """The events after the run's first `count` that are still in memory."""
        kept_before = max(0, count - self.dropped)
        return list(itertools.islice(self._events, kept_before, None))

    def __len__(self) -> int:
        return len(self._events)

    def __iter__(self) -> Iterator[BusEvent]:
        return iter(self._events)

    @overload
    def __getitem__(self, index: int) -> BusEvent: ...
    @overload
    def __getitem__(self, index: slice) -> list[BusEvent]: ...

    def __getitem__(self, index: int | slice) -> BusEvent | list[BusEvent]:
        return list(self._events)[index] if isinstance(index, slice) else self._events[index]

    def __eq__(self, other: object) -> bool:
        return list(self) == list(other) if isinstance(other, Sequence) else NotImplemented

    def __repr__(self) -> str:
        return repr(list(self._events))
