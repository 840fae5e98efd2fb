"""Errors injected on the bus, armed until they fire: which a frame offers each node (its injections in the order
given, several in one frame only at later and later bits), which fired, and why one never did, in a few words.
"""
from __future__ import annotations

from collections import Counter
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field

from appsim.bus.bitlevel import AT_THEIR_PLACE, Injection, Outcome
from appsim.can.bits import INTERMISSION_BITS, TAIL_BITS, frame_bits
from appsim.can.frame import CanFrame

IDENTIFIERS_TOLD = 8            # identifiers a node saw, named in why its injection never fired


@dataclass(frozen=True, slots=True)
class Taking:
    """A node as a frame finds it at SOF: on the bus in Normal mode (else Listen-only), and whether it sends."""

    name: str
    normal: bool
    sending: bool


@dataclass(eq=False, slots=True)
class _Armed:
    """An injection still to fire `left` times, and what the frames did with it."""

    injection: Injection
    left: int
    fired: int = 0
    matched: int = 0                # frames its node took part in, in Normal mode, with its identifier (if any)
    offered: int = 0                # of them, those it was offered in
    waited: int = 0                 # of them, those it waited in behind its node's earlier injections
    longest: int = 0                # the longest of them, in its node's bits to the end of the intermission


@dataclass(slots=True)
class _Seen:
    """What a node with an injection armed did on the bus meanwhile."""

    frames: int = 0                 # frames it took part in
    normal: int = 0                 # of them, in Normal mode (the others: Listen-only)
    sent: int = 0                   # of them, frames it sent
    identifiers: set[int] = field(default_factory=set)


def _name(injection: Injection) -> str:
    """The injection as --inject gives it: NODE:KIND:BIT[:ID]."""
    ident = "" if injection.can_id is None else f":0x{injection.can_id:X}"
    frames = f" (frames={injection.frames})" if injection.frames > 1 else ""
    return f"{injection.node}:{injection.kind}:{injection.bit}{ident}{frames}"


class Injections:
    """The injections armed on one bus (`Bus.inject`), in the order given."""

    def __init__(self) -> None:
        self._armed: list[_Armed] = []
        self._seen: dict[str, _Seen] = {}

    def __bool__(self) -> bool:
        return bool(self._armed)

    @property
    def nodes(self) -> Mapping[str, object]:
        """The nodes any injection was ever armed for (only they need be offered a frame: `offer`)."""
        return self._seen

    def arm(self, injection: Injection) -> None:
        self._armed.append(_Armed(injection, injection.frames))
        self._seen.setdefault(injection.node, _Seen())

    def offer(self, frame: CanFrame, nodes: Sequence[Taking], *, plain: bool) -> dict[str, tuple[Injection, ...]]:
        """The injections this frame (`frame` wins arbitration; `nodes` take part) offers, by node: a node in Normal
        mode gets its first armed injection for this identifier, and after it those at later bits, until one is not;
        the others wait for the next frames. `plain`: the frame goes through unless an injection fires, so one at a
        bit past its end cannot fire in it. A node in Listen-only mode sends no error flag: its injections wait."""
        taking = {node.name: node for node in nodes if node.name in self._seen}     # (`nodes` may hold only those)
        for one in taking.values():
            seen = self._seen[one.name]
            seen.frames += 1
            seen.normal += one.normal
            seen.sent += one.sending
            if len(seen.identifiers) < 4 * IDENTIFIERS_TOLD:
                seen.identifiers.add(frame.can_id)
        length = frame_bits(frame) + INTERMISSION_BITS
        stuffed = frame_bits(frame) - TAIL_BITS
        offered: dict[str, tuple[Injection, ...]] = {}
        waiting: set[str] = set()
        for armed in self._armed:
            injection = armed.injection
            node = taking.get(injection.node)
            if node is None or not node.normal or injection.can_id not in (None, frame.can_id):
                continue
            armed.matched += 1
            armed.longest = max(armed.longest, length)
            if injection.node in waiting:
                armed.waited += 1
                continue
            if plain and injection.kind not in AT_THEIR_PLACE and \
                    injection.bit >= (stuffed if injection.kind == "stuff" else length):
                continue
            before = offered.get(injection.node, ())
            if before and injection.bit <= before[-1].bit:
                waiting.add(injection.node)
                armed.waited += 1
                continue
            offered[injection.node] = (*before, injection)
            armed.offered += 1
        return offered

    def fired(self, offered: Mapping[str, tuple[Injection, ...]], outcomes: Mapping[str, Outcome]) -> None:
        """The frame ran: each offered injection that took effect fired once more; those done are disarmed."""
        if not offered:
            return
        for armed in self._armed:
            outcome = outcomes.get(armed.injection.node)
            if outcome is None or not any(armed.injection is i for i in offered.get(armed.injection.node, ())):
                continue
            armed.longest = max(armed.longest, outcome.sampled)
            if any(armed.injection is fired for fired in outcome.fired):
                armed.fired += 1
                armed.left -= 1
        self._armed = [armed for armed in self._armed if armed.left > 0]

    def not_fired(self) -> list[str]:
        """Each injection still armed, in a line: what it is, how often it fired, and why not more (injections alike
        counted together)."""
        said: Counter[str] = Counter()
        for armed in self._armed:
            fired = f"fired in {armed.fired} of its {armed.injection.frames} frames" if armed.fired else "never fired"
            said[f"{_name(armed.injection)} {fired}: {self._why(armed)}"] += 1
        return [line if count == 1 else f"{count:,} x {line}" for line, count in said.items()]

    def _why(self, armed: _Armed) -> str:
        injection, seen = armed.injection, self._seen[armed.injection.node]
        node = injection.node
        if not seen.frames:
            return (f"{node} took part in no frame on the bus (off it: Configuration, Loopback or Disable mode, or "
                    "bus-off)")
        if not seen.normal:
            return (f"{node} was in Listen-only mode in all {seen.frames} frames it heard, and a Listen-only node "
                    "sends no error flag: its injection waits for Normal mode")
        if not armed.matched:
            ids = ", ".join(f"0x{i:03X}" for i in sorted(seen.identifiers)[:IDENTIFIERS_TOLD])
            return (f"no frame with identifier 0x{injection.can_id:X} went by {node} in Normal mode (it saw "
                    f"{ids}{' ...' if len(seen.identifiers) > IDENTIFIERS_TOLD else ''})")
        if injection.kind == "ack" and not seen.sent:
            return f"{node} sent no frame, and only a transmitter sees an ACK error"
        if armed.waited and not armed.offered:
            return (f"it waited for {node}'s earlier injections, which fire in turn, one frame each, and the run ended "
                    "first")
        if injection.kind not in AT_THEIR_PLACE and injection.bit >= armed.longest:
            return (f"bit {injection.bit} is past the end of every frame {node} took part in (the longest, with its "
                    f"error frames and intermission: {armed.longest} bits)")
        where = "its ACK slot as a transmitter" if injection.kind == "ack" else \
            "its ACK delimiter as a receiver" if injection.kind == "crc" else f"bit {injection.bit}"
        return f"in the {armed.matched} frames it could have fired in, {node} never reached {where}"
