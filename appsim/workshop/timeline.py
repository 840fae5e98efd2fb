"""The bus over time as an interactive figure: one row per sender, one bar per frame, from its SOF to its end.

Drag to zoom, double-click to see it all, hover a frame for its ID, data, sender and who ACKed it. Plotly draws it (why
Plotly: docs/notebooks.md); `plots.bus_timeline` draws the same as a static matplotlib picture, for files and terminals.
"""
from __future__ import annotations

import html
from collections.abc import Callable, Sequence
from typing import TYPE_CHECKING

from appsim.bus.monitor import acks
from appsim.bus.wire import BusEvent
from appsim.sim import PS_PER_SECOND

if TYPE_CHECKING:
    from plotly.graph_objects import Figure

MS = PS_PER_SECOND / 1000
KINDS = {"data frame": ("#1f77b4", ""), "remote frame (RTR)": ("#9ecae1", "/"), "error frame": ("#d62728", "")}
ROW_PX = 34


def kind(event: BusEvent) -> str:
    """Which of `KINDS` the event is."""
    return "error frame" if event.error else "remote frame (RTR)" if event.frame.remote else "data frame"


def describe(event: BusEvent, nodes: Sequence[str], signals: Callable[[BusEvent], str] | None = None) -> str:
    """What hovering over the event's bar shows (Plotly's HTML subset); with `signals` (a DBC's reading), the frame's
    message and signal values too."""
    frame = event.frame
    ident = f"0x{frame.can_id:08X}" if frame.extended else f"0x{frame.can_id:03X}"
    what = f"RTR, DLC {frame.dlc}" if frame.remote else f"DLC {frame.dlc}: {frame.data.hex(' ').upper()}"
    outcome = f"error: {event.error}" if event.error else f"ACK: {acks(event, nodes)}"
    decoded = signals(event) if signals is not None else ""
    return (f"<b>{ident}</b> {what}<br>from {event.sender} at {event.start_ps / MS:.3f} ms "
            f"({(event.end_ps - event.start_ps) / MS:.3f} ms on the bus)<br>{outcome}"
            + (f"<br>{html.escape(decoded)}" if decoded else ""))


def bus_timeline(trace: Sequence[BusEvent], nodes: Sequence[str],
                 signals: Callable[[BusEvent], str] | None = None) -> Figure:
    """The events of `trace` as bars on one row per sender (`nodes`: the bus's nodes, who could ACK); hovering over a
    frame shows its signals too with `signals` (`appsim.bus.signals.Signals`)."""
    import plotly.graph_objects as go

    senders = list(dict.fromkeys(event.sender for event in trace))
    figure = go.Figure()
    for name, (colour, hatch) in KINDS.items():
        shown = [event for event in trace if kind(event) == name]
        figure.add_bar(
            name=name, orientation="h", y=[event.sender for event in shown],
            base=[event.start_ps / MS for event in shown], x=[(event.end_ps - event.start_ps) / MS for event in shown],
            text=[f"{event.frame.can_id:03X}" for event in shown], textposition="inside", insidetextanchor="middle",
            textangle=0,
            hovertext=[describe(event, nodes, signals) for event in shown], hoverinfo="text",
            marker={"color": colour, "line": {"width": 0}, "pattern": {"shape": hatch}})
    errors = sum(1 for event in trace if event.error)
    figure.update_layout(
        title={"text": f"{len(trace) - errors} frames, {errors} error frames",
               "subtitle": {"text": "drag to zoom (IDs show on bars wide enough), double-click for the whole, "
                                    "hover over a frame"}},
        barmode="overlay", bargap=0.25, uniformtext={"mode": "hide", "minsize": 9}, dragmode="zoom",
        height=140 + ROW_PX * max(1, len(senders)), margin={"l": 10, "r": 10, "t": 70, "b": 40},
        xaxis={"title": "time (ms)"},
        yaxis={"categoryorder": "array", "categoryarray": senders[::-1], "fixedrange": True},
        legend={"orientation": "h", "x": 1, "xanchor": "right", "y": 1.02, "yanchor": "bottom"},
        template="plotly_white")
    return figure
