"""Pictures for the notebooks: a frame's bits on the wire, arbitration, one bit's time segments and a
resynchronisation, the bus over time, the error states, a register's bits.

Each function draws on `ax` (a new figure when None) and returns the Figure, as `GLCD.picture` does.
"""
from __future__ import annotations

from collections.abc import Callable, Mapping, Sequence
from itertools import groupby
from typing import TYPE_CHECKING, Any, cast

from appsim.bus import monitor
from appsim.bus.bitlevel import ERROR_DELIMITER_BITS, ERROR_FLAG_BITS
from appsim.bus.wire import BUS_IDLE_BITS, BusEvent
from appsim.can import physical
from appsim.can.bits import WireBit, encode_annotated
from appsim.can.bittiming import SYNC_SEG_TQ, BitTiming
from appsim.can.frame import CanFrame
from appsim.chip.ecan.registers import BITFIELDS
from appsim.sim import PS_PER_SECOND

if TYPE_CHECKING:
    from matplotlib.axes import Axes
    from matplotlib.figure import Figure

FIELD_COLOURS = {
    "SOF": "#f4cccc", "ID": "#fce5cd", "SRR": "#fff2cc", "IDE": "#fff2cc", "RTR": "#fff2cc", "r0": "#d9ead3",
    "r1": "#d9ead3", "DLC": "#d9ead3", "DATA": "#cfe2f3", "CRC": "#d9d2e9", "CRC delimiter": "#eeeeee",
    "ACK slot": "#b6d7a8", "ACK delimiter": "#eeeeee", "EOF": "#eeeeee", "error flag": "#ea9999",
    "error delimiter": "#eeeeee", "overload flag": "#f9cb9c", "overload delimiter": "#eeeeee",
}
FIELD_LABELS = {"CRC delimiter": "DEL", "ACK delimiter": "DEL", "ACK slot": "ACK", "error flag": "error\nflag",
                "error delimiter": "error\ndelimiter", "overload flag": "overload\nflag(s)",
                "overload delimiter": "overload\ndelimiter"}
ARBITRATION_FIELDS = frozenset({"SOF", "ID", "SRR", "IDE", "RTR"})
SEGMENT_COLOURS = {"Sync": "#999999", "Prop": "#f6b26b", "Phase1": "#93c47d", "Phase2": "#6fa8dc"}
ERROR_THRESHOLDS = ((96, "warning (96)"), (128, "error-passive (128)"), (256, "bus-off (TEC 256)"))
WARNING, PASSIVE, BUS_OFF = (level for level, _ in ERROR_THRESHOLDS)
RECOVERY_SEQUENCES = 128                  # occurrences of 11 recessive bits that bring a bus-off node back
STATE_COLOURS = {"error-active": "#d9ead3", "error-passive": "#fff2cc", "bus-off": "#f4cccc"}
MS = PS_PER_SECOND / 1000
SIGNAL_LABELS = 12             # frames in a timeline few enough for each label to carry its signals


def _axes(ax: Axes | None, size: tuple[float, float]) -> Axes:
    if ax is not None:
        return ax
    import matplotlib.pyplot as plt

    return plt.figure(figsize=size).add_subplot()


def _figure(ax: Axes) -> Figure:
    """The figure `ax` draws in (a subfigure when the caller's axes sit in one)."""
    return cast("Figure", ax.figure)


def _levels(ax: Axes, levels: Sequence[int], y: float = 0.0, x0: int = 0, **style: Any) -> None:
    """A wire's levels as a step line from bit `x0`, recessive (1) high and dominant (0) low."""
    xs = range(x0, x0 + len(levels) + 1)
    ax.step(xs, [y + level for level in levels] + [y + levels[-1]], where="post", **style)


def _stuff_bits(ax: Axes, bits: Sequence[WireBit], y: float = 0.0) -> None:
    """Outline the stuff bits of `bits` (drawn from bit 0 at height `y`) in red."""
    from matplotlib.patches import Rectangle

    for index, bit in enumerate(bits):
        if bit.stuff:
            ax.add_patch(Rectangle((index, y - 0.1), 1, 1.2, fill=False, edgecolor="red", linewidth=1.5, gid="stuff"))


def wire_bits(frame: CanFrame, ax: Axes | None = None, *, acked: bool = True) -> Figure:
    """The frame on the wire, SOF..EOF: fields as coloured bands, stuff bits outlined in red.

    `acked`: the ACK slot is dominant, as the receivers drive it. False draws what a sender alone on the bus does: it
    reads its ACK slot recessive (an ACK error) and from the next bit sends an error flag (6 dominant bits, as an
    error-active node) and the error delimiter (8 recessive) instead of the ACK delimiter and EOF.
    """
    ax = _axes(ax, (14, 2.6))
    bits: list[WireBit] = encode_annotated(frame)
    if acked:
        bits = [WireBit(0, bit.field) if bit.field == "ACK slot" else bit for bit in bits]
    else:
        bits = bits[:next(i for i, bit in enumerate(bits) if bit.field == "ACK slot") + 1]
        bits += [WireBit(0, "error flag")] * ERROR_FLAG_BITS + [WireBit(1, "error delimiter")] * ERROR_DELIMITER_BITS
    _fields(ax, bits)
    stuffed = sum(bit.stuff for bit in bits)
    kind = "remote" if frame.remote else "data"
    if acked:
        ax.set_title(f"{kind} frame {frame}: {len(bits)} bits on the wire, {stuffed} of them stuff bits (red)")
    else:
        ax.set_title(f"{kind} frame {frame} that nobody ACKs:\nits ACK slot stays recessive, so from the next bit "
                     "the sender sends an error flag (6 dominant bits), then the error delimiter (8 recessive)")
    return _figure(ax)


def _fields(ax: Axes, bits: Sequence[WireBit]) -> None:
    """Bits on the wire from bit 0: their levels, each field a coloured band with its name, stuff bits in red."""
    position, narrow = 0, 0
    for field, run in groupby(bits, key=lambda bit: bit.field):
        width = len(list(run))
        ax.axvspan(position, position + width, color=FIELD_COLOURS[field], zorder=0)
        narrow = narrow + 1 if width < 3 else 0          # stagger the labels of one- and two-bit fields: DEL ACK DEL
        ax.text(position + width / 2, 1.2 + 0.22 * (narrow % 3 if narrow else 1), FIELD_LABELS.get(field, field),
                ha="center", va="bottom", fontsize=8)
        position += width
    _stuff_bits(ax, bits)
    _levels(ax, [bit.level for bit in bits], color="black", linewidth=1.5)
    ax.set_xlim(0, len(bits))
    ax.set_ylim(-0.3, 2.0)
    ax.set_yticks([0, 1], ["dominant 0", "recessive 1"])
    ax.set_xlabel("bit")


def recorded_wire(event: BusEvent, bit_rate: int, ax: Axes | None = None) -> Figure:
    """A frame that went through as the bus ran it bit by bit (`BusEvent.wire`, sampled in the middle of each bit):
    its fields to the end of EOF, then what the wire carried until the event ended, the overload frames (flags,
    superposed, and the 8-bit delimiter) when a node read a dominant bit where it expected EOF or intermission."""
    if not event.wire or event.error:
        raise ValueError("recorded_wire draws a frame that went through and was run bit by bit (its BusEvent.wire)")
    bit_ps = PS_PER_SECOND // bit_rate
    count = (event.end_ps - event.start_ps) // bit_ps
    changes = event.wire_changes()
    times = [time - event.start_ps for time, _ in changes]

    def level(bit: int) -> int:
        middle = bit * bit_ps + bit_ps // 2
        index = max(i for i, time in enumerate(times) if time <= middle)
        return changes[index][1]

    frame = encode_annotated(event.frame)
    bits = [WireBit(level(i), bit.field, bit.stuff) for i, bit in enumerate(frame)]
    after = [level(i) for i in range(len(frame), count)]
    for value, run in groupby(after):
        field = "overload flag" if value == 0 else "overload delimiter"
        bits += [WireBit(value, field)] * len(list(run))
    ax = _axes(ax, (14, 2.6))
    _fields(ax, bits)
    overload = sum(bit.field.startswith("overload") for bit in bits)
    ax.set_title(f"{event.frame} from {event.sender}, as the wire carried it: {len(frame)} bits to the end of EOF"
                 + (f", then {overload} bits of overload frame" if overload else ""))
    return _figure(ax)


def arbitration(frames: Mapping[str, CanFrame], ax: Axes | None = None) -> Figure:
    """Nodes starting frames at the same SOF: each one's bits through the arbitration field, and the bus.

    The bus is the wired-AND of what is driven (dominant 0 wins). A node that sends recessive and reads
    dominant has lost: it stops sending (grey from there) and becomes a receiver. The lowest ID wins.
    """
    if len(frames) < 2:
        raise ValueError("arbitration needs at least two nodes starting a frame at the same time")
    annotated = {name: [bit for bit in encode_annotated(frame) if bit.field in ARBITRATION_FIELDS]
                 for name, frame in frames.items()}
    sent = {name: [bit.level for bit in bits] for name, bits in annotated.items()}
    ax = _axes(ax, (12, 1.2 + 0.9 * (len(frames) + 1)))
    sending = set(frames)
    lost_at: dict[str, int] = {}
    bus: list[int] = []
    while driven := [sent[name][len(bus)] for name in sending if len(bus) < len(sent[name])]:
        level = min(driven)
        for name in sorted(sending):
            if len(bus) < len(sent[name]) and sent[name][len(bus)] > level:
                lost_at[name] = len(bus)
                sending.discard(name)
        bus.append(level)
    length = len(bus)
    rows = list(frames)
    for row, name in enumerate(rows):
        y = 2 * (len(rows) - row)
        stop = lost_at.get(name, len(sent[name]) - 1) + 1
        _levels(ax, sent[name][:stop], y, color="black", linewidth=1.5)
        _stuff_bits(ax, annotated[name][:stop], y)
        if name in lost_at:
            if stop < length:
                _levels(ax, bus[stop:], y, stop, color="#bbbbbb", linewidth=1)    # it only listens now
            lost = lost_at[name]
            ax.plot(lost + 0.5, y + 1.3, "rx", markersize=10)
            left = lost > length / 2                    # the label on the side with room for it
            ax.text(lost - 0.1 if left else lost + 1.1, y + 1.3, f"lost at bit {lost}", color="red", fontsize=9,
                    ha="right" if left else "left", va="center")
    _levels(ax, bus, 0, color="tab:blue", linewidth=2)
    winner = next(name for name in rows if name not in lost_at)
    _stuff_bits(ax, annotated[winner], 0)
    labels = [f"{name}  0x{frames[name].can_id:03X}" for name in rows] + ["bus (wired-AND)"]
    ax.set_yticks([2 * (len(rows) - row) + 0.5 for row in range(len(rows))] + [0.5], labels)
    ax.set_xticks(range(length + 1))
    ax.set_xlim(0, length)
    ax.set_ylim(-0.5, 2 * len(rows) + 1.8)
    ax.set_xlabel("bit from SOF (identifier MSB first, then RTR; extended: SRR, IDE, 18 more ID bits); "
                  "red boxes: stuff bits")
    same_id = any(frames[name].base_id == frames[winner].base_id for name in lost_at)
    why = ("same identifier: RTR (data beats remote) or IDE (standard beats extended) decides" if same_id
           else "the lowest identifier wins")
    ax.set_title(f"{winner} wins arbitration: at the first bit that differs it sends dominant 0\n{why}")
    return _figure(ax)


def bus_levels(levels: Sequence[int], axes: Sequence[Axes] | None = None) -> Figure:
    """The two wires under a run of bits: CANH and CANL, their difference, and what a receiver reads.

    Nominal ISO 11898-2 levels (`appsim.can.physical`): recessive, both wires at 2.5 V (nobody drives); dominant,
    CANH 3.5 V and CANL 1.5 V. Below it the bus as the termination sees it: 120 ohm at each end, nodes on stubs.
    """
    import matplotlib.pyplot as plt
    from matplotlib.patches import Rectangle

    if axes is None:
        figure, axes = plt.subplots(3, 1, figsize=(12, 7), height_ratios=(2, 1.4, 1.3))
    wires, difference, bus = axes
    canh = [physical.CANH_CANL_VOLTS[level][0] for level in levels]
    canl = [physical.CANH_CANL_VOLTS[level][1] for level in levels]
    xs = range(len(levels) + 1)
    wires.step(xs, canh + canh[-1:], where="post", color="tab:orange", linewidth=2, label="CANH")
    wires.step(xs, canl + canl[-1:], where="post", color="tab:blue", linewidth=2, label="CANL")
    for index, level in enumerate(levels):
        wires.text(index + 0.5, 3.8, "D" if level == physical.DOMINANT else "R", ha="center", fontsize=8)
    wires.set_ylim(0.4, 4.1)                         # room under CANL's 1.5 V for the legend, clear of both lines
    wires.set_ylabel("volts")
    wires.set_xlim(0, len(levels))
    wires.legend(loc="lower right", fontsize=8, ncols=2)
    wires.set_title("dominant (D, logic 0): CANH pulled up, CANL down; recessive (R, logic 1): nobody drives, "
                    "both rest at 2.5 V")
    vdiff = [physical.differential_volts(level) for level in levels]
    difference.step(xs, vdiff + vdiff[-1:], where="post", color="black", linewidth=2)
    difference.axhspan(physical.DOMINANT_ABOVE_VOLTS, 3, color="#f4cccc", zorder=0)
    difference.axhspan(-0.5, physical.RECESSIVE_BELOW_VOLTS, color="#d9ead3", zorder=0)
    difference.axhline(physical.WORKSHOP_DOMINANT_ABOVE_VOLTS, color="grey", linestyle="--", linewidth=1)
    difference.set_title(f"a receiver reads dominant above {physical.DOMINANT_ABOVE_VOLTS} V (red; ISO 11898-2, "
                         f"the workshop's transceiver slide says {physical.WORKSHOP_DOMINANT_ABOVE_VOLTS} V, dashed), "
                         f"recessive below {physical.RECESSIVE_BELOW_VOLTS} V (green)", fontsize=10)
    difference.set_xlim(0, len(levels))
    for ax in (wires, difference):
        ax.set_xticks(range(len(levels) + 1))
    difference.set_ylim(-0.5, 2.6)
    difference.set_ylabel("CANH - CANL (V)")
    difference.set_xlabel("bit")
    for y, name, colour in ((1, "CANH", "tab:orange"), (0, "CANL", "tab:blue")):
        bus.plot([0.5, 9.5], [y, y], color=colour, linewidth=2)
        bus.text(0.4, y, name, ha="right", va="center", fontsize=9)
    for x in (0.8, 9.2):
        bus.add_patch(Rectangle((x - 0.12, 0.2), 0.24, 0.6, facecolor="white", edgecolor="black", gid="terminator"))
        bus.text(x + 0.2, 0.5, f"{physical.TERMINATION_OHMS} Ω", va="center", fontsize=9)
        bus.plot([x, x], [0, 0.2], [x, x], [0.8, 1], color="black", linewidth=1)
    for x, name in ((3, "node"), (5, "node"), (7, "node")):
        bus.plot([x - 0.1, x - 0.1], [1, 1.6], [x + 0.1, x + 0.1], [0, 1.6], color="grey", linewidth=1)
        bus.add_patch(Rectangle((x - 0.6, 1.6), 1.2, 0.5, facecolor="#cfe2f3", edgecolor="black", gid="node"))
        bus.text(x, 1.85, f"{name}\n(transceiver)", ha="center", va="center", fontsize=8)
    bus.set_xlim(0, 10)
    bus.set_ylim(-0.3, 2.3)
    bus.axis("off")
    bus.set_title(f"one pair of wires, {physical.TERMINATION_OHMS} Ω at each end: "
                  f"{float(physical.bus_resistance_ohms()):g} Ω between CANH and CANL", fontsize=10)
    figure = _figure(wires)
    figure.tight_layout()
    return figure


def bit_segments(timing: BitTiming, fosc: int, ax: Axes | None = None) -> Figure:
    """One bit time in TQ: Sync, Prop, Phase1 and Phase2 segments, the sample point and the SJW window."""
    from matplotlib.patches import Rectangle

    ax = _axes(ax, (10, 2.4))
    segments = (("Sync", SYNC_SEG_TQ), ("Prop", timing.prseg), ("Phase1", timing.seg1ph),
                ("Phase2", timing.effective_seg2ph))
    start = 0
    for name, width in segments:
        ax.add_patch(Rectangle((start, 0), width, 1, facecolor=SEGMENT_COLOURS[name], edgecolor="black", gid="segment"))
        ax.text(start + width / 2, 0.5, f"{name}\n{width} TQ", ha="center", va="center", fontsize=9)
        start += width
    sample = SYNC_SEG_TQ + timing.prseg + timing.seg1ph
    ax.add_patch(Rectangle((sample - timing.sjw, 1.05), 2 * timing.sjw, 0.15, facecolor="#cccccc", gid="sjw"))
    ax.text(sample, 1.25, f"SJW {timing.sjw} TQ: resynchronisation may lengthen Phase1 or shorten Phase2 by this much",
            ha="center", fontsize=8)
    ax.axvline(sample, color="red", linewidth=2)
    ax.text(sample, -0.25, f"sample point {float(timing.sample_point):.1%}", color="red", ha="center", fontsize=9)
    tq_us = float(timing.tq_seconds(fosc)) * 1e6
    ax.set_xlim(0, timing.tq_per_bit)
    ax.set_ylim(-0.4, 1.5)
    ax.set_xticks(range(timing.tq_per_bit + 1))
    ax.set_yticks([])
    ax.set_xlabel(f"time quanta (1 TQ = 2 x (BRP<5:0> + 1) / Fosc = 2 x {timing.brp} / Fosc = {tq_us:g} µs)")
    ax.set_title(f"one bit = {timing.tq_per_bit} TQ = {timing.tq_per_bit * tq_us:g} µs: "
                 f"{float(timing.bit_rate(fosc)) / 1000:g} kbit/s")
    return _figure(ax)


def resynchronisation(timing: BitTiming, late_tq: int, early_tq: int, ax: Axes | None = None) -> Figure:
    """What one resynchronisation does, in TQ (ISO 11898-1 bit timing): above, the edge comes `late_tq` after the
    node's Sync segment (its clock runs early), and Phase1 is lengthened by min(late, SJW), so the sample point moves
    that much later; below, it comes `early_tq` before the node's bit ends (in Phase2: its clock runs late), and Phase2
    is shortened by min(early, SJW), so the next bit starts that much sooner."""
    from matplotlib.patches import Rectangle

    ax = _axes(ax, (12, 3.6))
    sjw, n = timing.sjw, timing.tq_per_bit
    sample = SYNC_SEG_TQ + timing.prseg + timing.seg1ph
    lengthen, shorten = min(late_tq, sjw), min(early_tq, sjw)
    rows = ((2.2, "edge late: Phase1 + " + f"{lengthen} TQ", (("Sync", SYNC_SEG_TQ), ("Prop", timing.prseg),
                                                          ("Phase1", timing.seg1ph + lengthen),
                                                          ("Phase2", timing.effective_seg2ph)), late_tq),
            (0.4, "edge early: Phase2 - " + f"{shorten} TQ", (("Sync", SYNC_SEG_TQ), ("Prop", timing.prseg),
                                                              ("Phase1", timing.seg1ph),
                                                              ("Phase2", timing.effective_seg2ph - shorten)),
             n - early_tq))
    for y, title, segments, edge in rows:
        ax.add_patch(Rectangle((0, y + 1.0), n, 0.12, facecolor="none", edgecolor="grey", linestyle=":",
                               gid="nominal"))
        ax.text(0.1, y + 1.2, f"nominal bit, {n} TQ", fontsize=7, va="bottom", color="grey")
        start = 0
        for name, width in segments:
            ax.add_patch(Rectangle((start, y), width, 0.9, facecolor=SEGMENT_COLOURS[name], edgecolor="black",
                                   gid="segment"))
            ax.text(start + width / 2, y + 0.45, f"{name}\n{width} TQ", ha="center", va="center", fontsize=8)
            start += width
        ax.plot([edge, edge], [y - 0.15, y + 1.2], color="black", linestyle="--", linewidth=1.5, gid="edge")
        ax.text(edge, y - 0.3, "edge", ha="center", fontsize=8)
        moved = sample + (lengthen if segments[2][1] > timing.seg1ph else 0)
        ax.plot([sample, sample], [y, y + 0.9], color="red", linestyle=":", linewidth=1.5, gid="nominal sample")
        ax.plot([moved, moved], [y, y + 0.9], color="red", linewidth=2.5, gid="sample point")
        ax.text(-0.3, y + 0.45, title, ha="right", va="center", fontsize=9)
    ax.annotate("", xy=(sample + lengthen, 3.45), xytext=(sample, 3.45),
                arrowprops={"arrowstyle": "->", "color": "red"})
    ax.text(sample + lengthen / 2, 3.55, f"sample point moved {lengthen} TQ (at most SJW = {sjw})", ha="center",
            fontsize=8, color="red")
    ax.annotate("", xy=(n - shorten, 1.75), xytext=(n, 1.75), arrowprops={"arrowstyle": "->", "color": "tab:blue"})
    ax.text(n - shorten / 2, 1.85, f"next bit {shorten} TQ sooner", ha="center", fontsize=8, color="tab:blue")
    ax.set_xlim(-0.5, n + lengthen + 0.5)
    ax.set_ylim(-0.1, 3.8)
    ax.set_xticks(range(n + lengthen + 1))
    ax.set_yticks([])
    ax.set_xlabel("time quanta from the node's own Sync segment")
    ax.set_title(f"resynchronisation with SJW {sjw} TQ: edge {late_tq} TQ late (above), {early_tq} TQ early (below); "
                 f"dotted red: where the node would have sampled")
    return _figure(ax)


def bus_timeline(trace: Sequence[BusEvent], ax: Axes | None = None, *,
                 start_ps: int | None = None, end_ps: int | None = None,
                 signals: Callable[[BusEvent], str] | None = None) -> Figure:
    """Frames on the bus over time, one row per sender: data frames blue, RTR frames hatched, error frames red; with
    `signals` (a DBC's reading), a frame's label is its message and signal values when there are few."""
    from matplotlib.patches import Rectangle

    start_ps = min((e.start_ps for e in trace), default=0) if start_ps is None else start_ps
    end_ps = max((e.end_ps for e in trace), default=start_ps + 1) if end_ps is None else end_ps
    shown = [e for e in trace if e.end_ps > start_ps and e.start_ps < end_ps]
    senders = list(dict.fromkeys(e.sender for e in shown))
    ax = _axes(ax, (12, 1 + 0.45 * max(1, len(senders))))
    for event in shown:
        row = len(senders) - 1 - senders.index(event.sender)
        colour = "tab:red" if event.error else "tab:blue"
        ax.add_patch(Rectangle((event.start_ps / MS, row + 0.1), (event.end_ps - event.start_ps) / MS, 0.8,
                               facecolor=colour, edgecolor=colour, hatch="///" if event.frame.remote else None,
                               alpha=0.5 if event.frame.remote else 0.9, gid="error" if event.error else "frame"))
        if len(shown) <= 40:
            decoded = signals(event) if signals is not None and len(shown) <= SIGNAL_LABELS else ""
            ax.text(event.end_ps / MS, row + 0.5, f" {event.frame.can_id:03X} {decoded}".rstrip(), va="center",
                    fontsize=7)
    ax.set_yticks([len(senders) - 0.5 - row for row in range(len(senders))], senders)
    ax.set_xlim(start_ps / MS, end_ps / MS)
    ax.set_ylim(0, max(1, len(senders)))
    ax.set_xlabel("time (ms)")
    errors = sum(1 for e in shown if e.error)
    ax.set_title(f"{len(shown) - errors} frames, {errors} error frames (red); RTR frames hatched")
    return _figure(ax)


def bus_load_over_time(trace: Sequence[BusEvent], start_ps: int, end_ps: int, window_ps: int,
                       ax: Axes | None = None) -> Figure:
    """Bus load (`monitor.bus_load`) in consecutive windows of `window_ps`, as bars in percent."""
    if window_ps <= 0 or end_ps <= start_ps:
        raise ValueError("give a positive window and a time span with end after start")
    ax = _axes(ax, (10, 2.5))
    starts = range(start_ps, end_ps, window_ps)
    loads = [100 * monitor.bus_load(trace, s, min(s + window_ps, end_ps)) for s in starts]
    ax.bar([s / MS for s in starts], loads, width=window_ps / MS, align="edge", color="tab:blue", edgecolor="white")
    ax.set_xlabel("time (ms)")
    ax.set_ylabel("bus load (%)")
    ax.set_ylim(0, 100)
    ax.set_title(f"bus load per {window_ps / MS:g} ms")
    return _figure(ax)


def error_counter_history(samples: Sequence[tuple[float, int, int]], ax: Axes | None = None, *,
                          node: str = "") -> Figure:
    """TEC and REC against time from (seconds, TEC, REC) samples, with the error-state thresholds."""
    ax = _axes(ax, (10, 3))
    times = [s[0] * 1000 for s in samples]
    ax.step(times, [s[1] for s in samples], where="post", label="TEC", color="tab:red", linewidth=2)
    ax.step(times, [s[2] for s in samples], where="post", label="REC", color="tab:blue", linewidth=2)
    top = max([s[1] for s in samples] + [s[2] for s in samples] + [140])
    shown = [(level, name) for level, name in ERROR_THRESHOLDS if level <= top + 20]
    for level, name in shown:
        ax.axhline(level, color="grey", linestyle="--", linewidth=1)
        ax.annotate(name, (0, level), xycoords=("axes fraction", "data"), xytext=(4, 2), textcoords="offset points",
                    color="grey", fontsize=8, va="bottom", backgroundcolor="white")
    ax.set_ylim(-5, max(top, shown[-1][0]) * 1.2)       # room above the top line for its label
    ax.set_xlabel("time (ms)")
    ax.set_ylabel("error counter")
    ax.set_title(f"error counters{' of ' + node if node else ''}")
    ax.legend(loc="lower right")
    return _figure(ax)


def error_states(ax: Axes | None = None) -> Figure:
    """Fault confinement as a state diagram: error-active, error-passive and bus-off, the counters that move a node
    between them, what it may do in each, and the COMSTAT bits (and PIR3.ERRIF) its firmware reads to see it."""
    from matplotlib.patches import FancyArrowPatch, FancyBboxPatch

    ax = _axes(ax, (13, 5.2))
    boxes = {"error-active": 0.0, "error-passive": 5.6, "bus-off": 11.2}
    says = {
        "error-active": "error flags: 6 dominant bits\n(they destroy the frame for all)\n\n"
                        f"TEC or REC > {WARNING - 1}: warning\nCOMSTAT.TXWARN / RXWARN, EWARN",
        "error-passive": "error flags: 6 recessive bits:\nanother node's frame goes on\n(its own still ends)\n"
                         f"waits 8 more bits after sending\n\nCOMSTAT.TXBP (TEC > {PASSIVE - 1})\n"
                         f"COMSTAT.RXBP (REC > {PASSIVE - 1})",
        "bus-off": "sends nothing, ACKs nothing,\nflags nothing\n\n\n"
                   f"COMSTAT.TXBO (TEC > {BUS_OFF - 1})",
    }
    for state, x in boxes.items():
        ax.add_patch(FancyBboxPatch((x, 0), 3.4, 3.2, boxstyle="round,pad=0.1", facecolor=STATE_COLOURS[state],
                                    edgecolor="black", gid="state"))
        ax.text(x + 1.7, 2.85, state, ha="center", va="center", fontsize=12, fontweight="bold")
        ax.text(x + 1.7, 1.35, says[state], ha="center", va="center", fontsize=8.5)

    def arrow(start: tuple[float, float], end: tuple[float, float], label: str, label_at: tuple[float, float],
              bend: float = 0.0) -> None:
        ax.add_patch(FancyArrowPatch(start, end, arrowstyle="-|>", mutation_scale=18, linewidth=1.5,
                                     connectionstyle=f"arc3,rad={bend}", color="black", gid="transition"))
        ax.text(*label_at, label, ha="center", va="center", fontsize=8.5, backgroundcolor="white", gid="condition")

    arrow((3.6, 2.2), (5.4, 2.2), f"TEC > {PASSIVE - 1}\nor REC > {PASSIVE - 1}", (4.5, 2.75))
    arrow((5.4, 1.0), (3.6, 1.0), f"TEC <= {PASSIVE - 1}\nand REC <= {PASSIVE - 1}", (4.5, 0.45))
    arrow((9.2, 1.6), (11.0, 1.6), f"TEC > {BUS_OFF - 1}", (10.1, 2.0))
    arrow((12.9, -0.2), (1.7, -0.2), f"after {RECOVERY_SEQUENCES} x {BUS_IDLE_BITS} recessive bits: TEC = REC = 0 "
          "(the ECAN comes back by itself)", (7.3, -1.3), bend=-0.2)
    ax.text(7.3, 3.9, "each of TXWARN, RXWARN, TXBP, RXBP, TXBO that rises sets PIR3.ERRIF; REC stops at "
            f"{BUS_OFF - 1} and never takes a node bus-off", ha="center", fontsize=9, color="#444444")
    ax.set_xlim(-0.4, 14.9)
    ax.set_ylim(-2.0, 4.3)
    ax.axis("off")
    ax.set_title("error states: TEC and REC move a node between them (ISO 11898-1 fault confinement)")
    return _figure(ax)


def register_bits(name: str, value: int, ax: Axes | None = None) -> Figure:
    """An 8-bit ECAN register as the data sheet draws it, bit 7 on the left: each bit's name and value, and each
    field of several bits bracketed below with the value it holds (`appsim.chip.ecan.registers.BITFIELDS`)."""
    from matplotlib.patches import Rectangle

    if name not in BITFIELDS:
        raise ValueError(f"no bit names for {name}: the registers with named bits are {', '.join(sorted(BITFIELDS))}")
    if not 0 <= value <= 0xFF:
        raise ValueError(f"{name} is an 8-bit register (0x00..0xFF), got {value!r}")
    fields = BITFIELDS[name]
    wide = {field: (shift, width) for field, (shift, width) in fields.items() if width > 1}
    single = {shift: field for field, (shift, width) in fields.items() if width == 1}
    ax = _axes(ax, (10, 1.9 if wide else 1.4))
    for bit in range(8):
        x = 7 - bit
        level = value >> bit & 1
        ax.add_patch(Rectangle((x, 0), 1, 1, facecolor="#cfe2f3" if level else "white", edgecolor="black", gid="bit"))
        ax.text(x + 0.5, 0.72, single.get(bit, "-"), ha="center", va="center", fontsize=7.5)
        ax.text(x + 0.5, 0.3, str(level), ha="center", va="center", fontsize=13, fontweight="bold")
        ax.text(x + 0.5, 1.12, f"bit {bit}", ha="center", va="bottom", fontsize=7, color="grey")
    for field, (shift, width) in wide.items():
        x0, x1 = 8 - shift - width, 8 - shift
        held = value >> shift & (1 << width) - 1
        ax.plot([x0 + 0.08, x0 + 0.08, x1 - 0.08, x1 - 0.08], [-0.1, -0.25, -0.25, -0.1], color="black", linewidth=1)
        ax.text((x0 + x1) / 2, -0.35, f"{field}<{width - 1}:0> = {held:0{width}b} ({held})", ha="center", va="top",
                fontsize=8.5, gid="field")
    ax.set_xlim(-0.1, 8.1)
    ax.set_ylim(-0.8 if wide else -0.1, 1.5)
    ax.axis("off")
    ax.set_title(f"{name} = 0x{value:02X}", fontsize=11)
    return _figure(ax)
