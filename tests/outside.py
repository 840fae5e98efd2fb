"""An outside node on a simulated bus (what a link's far side is: a vcan, another PC), and the frames it can send."""
from __future__ import annotations

import itertools

from appsim.bus.wire import Bus
from appsim.can.frame import CanFrame

# Every identifier some classroom node's filters let in (0x000 is RXB1's filter left at 0 under mask 0x7FF), and 0x7FF.
CLASSROOM_IDS = (0x000, *range(0x080, 0x089), *range(0x100, 0x160, 0x10), 0x1F0, 0x7FF)


def every_frame(ids: tuple[int, ...] = CLASSROOM_IDS) -> list[CanFrame]:
    """Each identifier as standard and extended, data frames with DLC 0..15 and remote frames with DLC 0..15."""
    frames = []
    for can_id, extended, dlc in itertools.product(ids, (False, True), range(16)):
        frames.append(CanFrame(can_id, bytes(range(0xA0, 0xA0 + min(dlc, 8))), extended=extended, dlc=dlc))
        frames.append(CanFrame(can_id, extended=extended, remote=True, dlc=dlc))
    return frames


class Outside:
    """A node outside the simulation: it ACKs every frame, and sends what `send` gives it as any node would."""

    name = "outside"

    def __init__(self, bus: Bus):
        self.bus = bus
        bus.attach_outside(self)

    def frame_from_simulation(self, frame: CanFrame) -> None:
        """The simulated bus carried a frame: out here nobody needs it."""

    def send(self, *frames: CanFrame) -> None:
        for frame in frames:
            self.bus.from_outside(self, frame)
