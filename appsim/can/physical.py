"""High-speed CAN's physical layer as the workshop teaches it: the two wires' levels, the termination, bus length.

Nominal numbers, with their sources (spec extracts): the levels and the ISO 11898-2 receiver thresholds are the CAN
projects chapter's [SUPP] values (section 1.3), the 1.0 V threshold, the 25 ns transceiver delay, the 17 cm/ns and
the length tables are the workshop's (section 1.4, 1.5). The kit's bus is logical (dominant or recessive, see
`appsim.bus.wire`): nothing here changes what it does; this module is for the lessons' pictures and sums.
"""
from __future__ import annotations

from fractions import Fraction

DOMINANT, RECESSIVE = 0, 1

CANH_CANL_VOLTS = {RECESSIVE: (2.5, 2.5), DOMINANT: (3.5, 1.5)}
"""Nominal (CANH, CANL) of each bus level: recessive both at about 2.5 V, dominant CANH up and CANL down by 1 V."""

RECESSIVE_BELOW_VOLTS = 0.5
"""A receiver reads recessive below this differential voltage (ISO 11898-2, and the workshop's 82C251 slide)."""
DOMINANT_ABOVE_VOLTS = 0.9
"""A receiver reads dominant above this differential voltage (ISO 11898-2)."""
WORKSHOP_DOMINANT_ABOVE_VOLTS = 1.0
"""The workshop's transceiver slide says dominant above 1.0 V: stricter than the standard's 0.9 V."""

TERMINATION_OHMS = 120
"""One terminating resistor at each end of the bus, equal to the cable's characteristic impedance (ISO 11898)."""

TRANSCEIVER_DELAY_SECONDS = Fraction(25, 10**9)
"""The workshop's average transceiver propagation delay, 25 ns."""
CABLE_METRES_PER_SECOND = Fraction(17, 100) * 10**9
"""The workshop's signal speed in the cable, 17 cm/ns (its '2/3 x 30 cm/ns' would be 20: the slide prints 17)."""

WORKSHOP_LENGTH_TABLES = {
    "table": ((40, 1_000_000), (500, 125_000), (1000, 50_000)),
    "rule of thumb": ((40, 1_000_000), (400, 100_000), (1000, 40_000)),
}
"""The workshop's two slides of bus length (m) against bit rate (bit/s); they disagree at 1000 m."""


def differential_volts(level: int) -> float:
    """CANH - CANL of a bus level, nominal: 0 V recessive, 2 V dominant."""
    canh, canl = CANH_CANL_VOLTS[level]
    return canh - canl


def bus_resistance_ohms() -> Fraction:
    """What an ohmmeter reads between CANH and CANL of a powered-off bus: the two terminators in parallel."""
    return Fraction(TERMINATION_OHMS * TERMINATION_OHMS, 2 * TERMINATION_OHMS)


def max_bus_length_metres(round_trip_seconds: Fraction | int) -> Fraction:
    """The longest bus whose round trip fits in `round_trip_seconds`.

    A bit must go from one end to the other and the far node's answer (its dominant ACK or arbitration bit) come
    back within the time the bit allows: two transceivers each way and the cable twice,
    4 x 25 ns + 2 x length / (17 cm/ns) <= the budget (the workshop's first-step approximation).
    """
    cable_seconds = (Fraction(round_trip_seconds) - 4 * TRANSCEIVER_DELAY_SECONDS) / 2
    return max(Fraction(0), cable_seconds * CABLE_METRES_PER_SECOND)


def workshop_max_bus_length_metres(bit_rate: int) -> Fraction:
    """The workshop's rule: the round trip may take 2/3 of the bit, the last third is for arbitration."""
    return max_bus_length_metres(Fraction(2, 3) / bit_rate)
