"""Nodes on a bus with the full model (APP023 boards, ECAN, AN738 firmware reading what its filters accept), timed.

Each node sends 8-byte standard frames: as fast as its TX buffers allow (100 % load), or every Timer1 period.
Its masks and filters accept every frame, or (`one_sender`) only the next node's, as a classroom station
accepts only the identifiers it needs.
"""
from __future__ import annotations

import time
from dataclasses import dataclass
from statistics import mean

from appsim.board.app023 import APP023
from appsim.bus.wire import Bus
from appsim.can.bits import INTERMISSION_BITS, frame_bits
from appsim.can.bittiming import calculate
from appsim.chip.clock import FOSC_HZ
from appsim.firmware import *
from appsim.sim import Simulator, ps

BIT_RATE = 1_000_000
WARM_UP_S = 0.005               # CANInitialize and the first frames, not timed
TIMER1_TICK_S = 8 * 4 / FOSC_HZ  # Timer1 at Fosc/4 with a 1:8 prescaler: 0.8 us a count
NODE_BITS = 5                   # the low identifier bits name the sender: up to 32 nodes


def can_initialize_arguments(bit_rate: int) -> tuple[int, int, int, int, int]:
    """CANInitialize's first five arguments (SJW, BRP, PHSEG1, PHSEG2, PROPSEG) for `bit_rate` at 40 MHz."""
    timing = calculate(bit_rate, FOSC_HZ)[0].timing
    return timing.sjw, timing.brp, timing.seg1ph, timing.seg2ph, timing.prseg


MBIT = can_initialize_arguments(BIT_RATE)


def _frame_id(node: int, sent: int) -> int:
    """Node k's n-th identifier: the count in the high bits climbs, so the nodes take turns winning
    arbitration; the low bits are the node."""
    return 0x100 + ((sent % 48) << NODE_BITS | node)


def node_firmware(node: int, nodes: int, received: list[int], period_counts: int | None = None, *,
                  bit_rate: int = BIT_RATE, one_sender: bool = False):
    """A node's main(): reads every frame its filters accept with CANReceiveMessage (all of them, or with
    `one_sender` the next node's); sends whenever a TX buffer is free (`period_counts` None) or on every
    Timer1 overflow, `period_counts` Timer1 counts apart."""
    def main() -> None:
        CANInitialize(*can_initialize_arguments(bit_rate), CAN_CONFIG_VALID_STD_MSG)
        if one_sender:
            CANSetOperationMode(CAN_OP_MODE_CONFIG)
            for mask in CAN_MASK:
                CANSetMask(mask, (1 << NODE_BITS) - 1, CAN_CONFIG_STD_MSG)
            for filter_ in CAN_FILTER:
                CANSetFilter(filter_, (node + 1) % nodes, CAN_CONFIG_STD_MSG)
            CANSetOperationMode(CAN_OP_MODE_NORMAL)
        data = [node & 0xFF, 0, 0x55, 0xAA, 0x0F, 0xF0, 0x33, 0xCC]
        sent = 0
        if period_counts is not None:
            preload = 0x10000 - period_counts
            OpenTimer1(TIMER_INT_OFF & T1_16BIT_RW & T1_SOURCE_INT & T1_PS_1_8 & T1_OSC1EN_OFF & T1_SYNC_EXT_OFF)
            WriteTimer1(preload + node * period_counts // nodes)      # the nodes start staggered
        while True:
            if period_counts is None:
                due = CANIsTxReady()
            elif PIR1bits.TMR1IF:
                PIR1bits.TMR1IF = 0
                WriteTimer1(ReadTimer1() + preload)
                due = True
            else:
                due = False
            if due:
                data[1] = sent & 0xFF
                CANSendMessage(_frame_id(node, sent), data, 8, CAN_TX_PRIORITY_0 & CAN_TX_STD_FRAME)
                sent += 1
            if CANIsRxReady():
                CANReceiveMessage()
                received[node] += 1
    return main


@dataclass(frozen=True)
class Run:
    """What one timed run did: simulated and wall time, the frames, what the firmware read."""

    nodes: int
    bit_rate: int
    wall_s: float
    simulated_s: float
    frames: int
    mean_frame_bits: float       # stuffed SOF..EOF plus intermission, over the frames that went through
    bus_busy: float              # fraction of the simulated time the wire carried frames (load)
    read_by_firmware: float      # frames read with CANReceiveMessage / frames x (nodes - 1)

    @property
    def real_time_factor(self) -> float:
        return self.simulated_s / self.wall_s

    @property
    def frames_per_wall_second(self) -> float:
        return self.frames / self.wall_s

    @property
    def bus_limit_fps(self) -> float:
        """Frames per second the bus carries back to back for this frame mix."""
        return self.bit_rate / self.mean_frame_bits


def run(nodes: int = 7, load: float = 1.0, simulated_s: float = 0.1, *, bit_rate: int = BIT_RATE,
        one_sender: bool = False) -> Run:
    """`nodes` boards on a bus at `load` (1.0: every node always has a frame queued), timed; every node
    reads every frame, or with `one_sender` only the next node's."""
    if not 2 <= nodes <= 1 << NODE_BITS:
        raise ValueError(f"the benchmark names senders in {NODE_BITS} identifier bits: 2 to {1 << NODE_BITS} "
                         f"nodes, not {nodes}")
    sim = Simulator()
    bus = Bus(sim, bit_rate)
    received = [0] * nodes
    period = None
    if load < 1.0:
        frame_s = (111 + INTERMISSION_BITS) / bit_rate              # a typical 8-byte frame, for pacing only
        period = round(nodes * frame_s / load / TIMER1_TICK_S)
    for k in range(nodes):
        firmware = node_firmware(k, nodes, received, period, bit_rate=bit_rate, one_sender=one_sender)
        APP023(bus, f"node{k}").run(firmware)
    sim.run(until=ps(WARM_UP_S))
    start_ps, first_frame, read_before = sim.now, len(bus.trace), sum(received)
    end_ps = start_ps + ps(simulated_s)
    started = time.perf_counter()
    sim.run(until=end_ps)
    wall = time.perf_counter() - started
    for process in sim.processes:
        if process.failure is not None:
            raise RuntimeError(f"benchmark firmware {process.name} crashed:\n{process.failure_text}")
    events = bus.trace[first_frame:]
    frames = [e for e in events if e.ok]
    bits = [frame_bits(e.frame) + INTERMISSION_BITS for e in frames]
    busy_ps = sum(e.end_ps - e.start_ps for e in events) + len(events) * INTERMISSION_BITS * bus.bit_ps
    read = sum(received) - read_before
    return Run(nodes, bit_rate, wall, simulated_s, len(frames), mean(bits) if bits else float("nan"),
               busy_ps / (end_ps - start_ps), read / max(len(frames) * (nodes - 1), 1))
