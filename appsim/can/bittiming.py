"""Bit timing of the PIC18 CAN module: BRGCON1..3 <-> BRP and segments in TQ, exact bit rate and sample point.

Checks the datasheet rules in plain sentences, lists the settings for a bit rate, and replays the Workshop 202 recipe.
"""
from __future__ import annotations

import math
from collections.abc import Iterable, Mapping
from dataclasses import dataclass
from fractions import Fraction

from appsim.errors import BitTimingError

SYNC_SEG_TQ = 1
IPT_TQ = 2
MIN_TQ_PER_BIT = 8
MAX_TQ_PER_BIT = 25
SJW_MAX_TQ = 4
SEGMENT_MAX_TQ = 8
BRP_MAX = 64
CLASSIC_CAN_MAX_BIT_RATE = 1_000_000
"""Classic CAN's fastest bit rate, bit/s (ISO 11898-1; only CAN FD's data phase goes faster, and the ECAN has none)."""
FOSC_MAX_HZ = 40_000_000
"""The PIC18F8680's fastest clock (its data sheet: DC to 40 MHz)."""
TOLERATED_RATE_ERROR = Fraction(158, 10_000)
"""The largest oscillator tolerance any classic CAN bit timing allows, 1.58 % (Hartwich and Bassemir, "The
Configuration of the CAN Bit Timing", Bosch, 1999): a node whose rate is further off cannot keep in step."""
BRGCON3_IMPLEMENTED = 0x47
"""BRGCON3 bits this model implements (WAKFIL, SEG2PH<2:0>); bits 7 and 5..3 are unimplemented and read 0."""

SEED_PROP_SEG_TQ = 2
SEED_PS2_SHARE = Fraction(3, 10)


def _exact(value: int | float | Fraction) -> Fraction:
    """`value` as an exact fraction; a float is read as the decimal it prints as (0.7 -> 7/10)."""
    return Fraction(repr(value)) if isinstance(value, float) else Fraction(value)


def _percent(value: Fraction) -> str:
    """A fraction as a percentage with at most two decimals: 11/16 -> '68.75'."""
    return f"{float(value * 100):.2f}".rstrip("0").rstrip(".")


def error_percent(error: Fraction) -> str:
    """A rate error in percent, signed, with two decimals or as many as its first two digits need: '+0.18',
    '-0.0000025'; exactly '0' when the rate is exact."""
    if error == 0:
        return "0"
    value = float(error * 100)
    return f"{value:+.{max(2, 1 - math.floor(math.log10(abs(value))))}f}"


def _range_problems(*, brp: int, sjw: int, prseg: int, seg1ph: int, seg2ph: int) -> list[str]:
    """Every field that its register bits cannot hold, each as a sentence."""
    problems = []
    if not 1 <= brp <= BRP_MAX:
        problems.append(
            f"BRP = {brp} cannot be programmed: BRP here is the prescaler divider 1..{BRP_MAX} "
            f"(the AN738 CANInitialize argument); the register BRP<5:0> (BRGCON1<5:0>) holds BRP - 1 = 0..63, "
            f"and TQ = 2 x BRP / Fosc"
        )
    if not 1 <= sjw <= SJW_MAX_TQ:
        extra = f" (SJW = {sjw} TQ would need register value {sjw - 1})" if sjw > SJW_MAX_TQ else ""
        problems.append(
            f"SJW = {sjw} TQ cannot be programmed: SJW<1:0> (BRGCON1<7:6>) is 2 bits, register value 0..3 "
            f"= 1..4 TQ, so SJW holds at most {SJW_MAX_TQ} TQ{extra}"
        )
    for name, value, field in (
        ("Propagation Segment", prseg, "PRSEG<2:0> (BRGCON2<2:0>)"),
        ("Phase Segment 1", seg1ph, "SEG1PH<2:0> (BRGCON2<5:3>)"),
        ("Phase Segment 2", seg2ph, "SEG2PH<2:0> (BRGCON3<2:0>)"),
    ):
        if not 1 <= value <= SEGMENT_MAX_TQ:
            problems.append(
                f"{name} = {value} TQ cannot be programmed: {field} is 3 bits, register value 0..7 "
                f"= 1..{SEGMENT_MAX_TQ} TQ"
            )
    return problems


def _rule_problems(*, prseg: int, seg1ph: int, seg2ph: int, sjw: int, seg2ph_origin: str = "") -> list[str]:
    """Every datasheet bit-timing rule the segment lengths (in TQ) break, each as a sentence."""
    problems = []
    n = SYNC_SEG_TQ + prseg + seg1ph + seg2ph
    if not MIN_TQ_PER_BIT <= n <= MAX_TQ_PER_BIT:
        problems.append(
            f"Nominal bit time: a bit must be {MIN_TQ_PER_BIT} to {MAX_TQ_PER_BIT} TQ, but this one is {n} TQ "
            f"(1 Sync + {prseg} Prop + {seg1ph} PS1 + {seg2ph} PS2): fewer than 8 TQ per bit is not "
            f"guaranteed to work, so use a smaller BRP and longer segments"
        )
    if seg2ph < sjw:
        problems.append(
            f"Phase Segment 2 ({seg2ph} TQ{seg2ph_origin}) must be at least SJW ({sjw} TQ): a resynchronisation "
            f"shortens Phase Segment 2 by up to SJW, which must not eat the whole segment"
        )
    if prseg + seg1ph < seg2ph:
        problems.append(
            f"Prop Segment + Phase Segment 1 ({prseg} + {seg1ph} = {prseg + seg1ph} TQ) must be at least "
            f"Phase Segment 2 ({seg2ph} TQ{seg2ph_origin}): otherwise the sample point is at or before "
            f"the middle of the bit"
        )
    if seg2ph < IPT_TQ:
        problems.append(
            f"Phase Segment 2 ({seg2ph} TQ) must be at least the Information Processing Time (IPT = {IPT_TQ} TQ): "
            f"the module needs {IPT_TQ} TQ after the sample point to process the bit"
        )
    return problems


@dataclass(frozen=True, slots=True, kw_only=True)
class BitTiming:
    """One BRGCON1..3 setting in the units the data sheet counts: the BRP divider and segments in TQ.

    Two conventions exist for the baud rate prescaler, and mixing them up changes the bit rate:

    * `brp` is the *divider* 1..64: TQ = 2 * brp / Fosc. AN738's `CANInitialize(SJW, BRP, PHSEG1, PHSEG2,
      PROPSEG, ...)` takes this and writes BRP - 1 into the register, so the classroom's
      `CANInitialize(4, 10, 8, 4, 3, ...)` is `BitTiming(sjw=4, brp=10, seg1ph=8, seg2ph=4, prseg=3)`;
    * `brp_register` is the *register value* BRP<5:0> = brp - 1 = 0..63 of the data sheet and of the CAN
      chapter's equation 9.3: TQ = 2 * (BRP<5:0> + 1) / Fosc. Write `brp=reg + 1` for a chapter example.

    `sjw` is 1..4 TQ; `prseg`, `seg1ph`, `seg2ph` are 1..8 TQ (their register fields hold TQ - 1).
    `sam` = sample three times; `seg2phts` = Phase Segment 2 freely programmable (when False the module uses
    max(Phase Segment 1, IPT = 2 TQ) and ignores `seg2ph`); `wakfil` = CAN bus line filter used for wake-up.

    Like the hardware, construction accepts any value the register fields can hold, even one that breaks the
    timing rules: `problems()` lists those and `validate()` raises. A value no register field can hold
    (e.g. SJW = 5 TQ) raises `BitTimingError` at once.
    """

    brp: int
    prseg: int
    seg1ph: int
    seg2ph: int
    sjw: int = 1
    sam: bool = False
    seg2phts: bool = True
    wakfil: bool = False

    def __post_init__(self) -> None:
        for name in ("brp", "prseg", "seg1ph", "seg2ph", "sjw"):
            value = getattr(self, name)
            if not isinstance(value, int) or isinstance(value, bool):
                raise TypeError(f"{name} must be an int (a count of TQ, or the BRP divider), got {value!r}")
        for name in ("sam", "seg2phts", "wakfil"):
            if not isinstance(getattr(self, name), bool):
                raise TypeError(f"{name} must be a bool, got {getattr(self, name)!r}")
        problems = _range_problems(
            brp=self.brp, sjw=self.sjw, prseg=self.prseg, seg1ph=self.seg1ph, seg2ph=self.seg2ph
        )
        if problems:
            raise BitTimingError("; ".join(problems))

    @classmethod
    def from_registers(cls, brgcon1: int, brgcon2: int, brgcon3: int) -> BitTiming:
        """Decode BRGCON1..3 (each a byte); unimplemented BRGCON3 bits are ignored."""
        for name, value in (("BRGCON1", brgcon1), ("BRGCON2", brgcon2), ("BRGCON3", brgcon3)):
            if not 0 <= value <= 0xFF:
                raise BitTimingError(f"{name} is an 8-bit register (0x00..0xFF), got {value!r}")
        return cls(
            brp=(brgcon1 & 0x3F) + 1,
            sjw=(brgcon1 >> 6) + 1,
            seg2phts=bool(brgcon2 & 0x80),
            sam=bool(brgcon2 & 0x40),
            seg1ph=((brgcon2 >> 3) & 0x07) + 1,
            prseg=(brgcon2 & 0x07) + 1,
            wakfil=bool(brgcon3 & 0x40),
            seg2ph=(brgcon3 & 0x07) + 1,
        )

    def to_registers(self) -> tuple[int, int, int]:
        """(BRGCON1, BRGCON2, BRGCON3): SJW<1:0>|BRP<5:0>; SEG2PHTS|SAM|SEG1PH<2:0>|PRSEG<2:0>; WAKFIL|SEG2PH<2:0>."""
        brgcon1 = (self.sjw - 1) << 6 | self.brp_register
        brgcon2 = self.seg2phts << 7 | self.sam << 6 | (self.seg1ph - 1) << 3 | (self.prseg - 1)
        brgcon3 = self.wakfil << 6 | (self.seg2ph - 1)
        return brgcon1, brgcon2, brgcon3

    @property
    def brp_register(self) -> int:
        """The register value BRP<5:0> = brp - 1 (0..63), the "BRP" of the data sheet's TQ formula."""
        return self.brp - 1

    @property
    def an738_arguments(self) -> tuple[int, int, int, int, int]:
        """(SJW, BRP, PHSEG1, PHSEG2, PROPSEG), the first five arguments of AN738's `CANInitialize`, in its order."""
        return self.sjw, self.brp, self.seg1ph, self.effective_seg2ph, self.prseg

    @property
    def effective_seg2ph(self) -> int:
        """Phase Segment 2 in TQ as the module uses it: SEG2PH if SEG2PHTS, else max(Phase Segment 1, IPT)."""
        return self.seg2ph if self.seg2phts else max(self.seg1ph, IPT_TQ)

    @property
    def tq_per_bit(self) -> int:
        """N = 1 Sync + Prop + Phase Segment 1 + effective Phase Segment 2, in TQ."""
        return SYNC_SEG_TQ + self.prseg + self.seg1ph + self.effective_seg2ph

    @property
    def sample_point(self) -> Fraction:
        """Where the bit is sampled, as a fraction of the bit: (1 + Prop + PS1) / N."""
        return Fraction(SYNC_SEG_TQ + self.prseg + self.seg1ph, self.tq_per_bit)

    def tq_seconds(self, fosc: int) -> Fraction:
        """One time quantum in seconds, exactly: 2 * brp / Fosc (Fosc in Hz)."""
        if fosc <= 0:
            raise ValueError(f"Fosc must be a positive frequency in Hz, got {fosc!r}")
        return Fraction(2 * self.brp, fosc)

    def bit_rate(self, fosc: int) -> Fraction:
        """Nominal bit rate in bit/s, exactly: Fosc / (2 * brp * N)."""
        return 1 / (self.tq_seconds(fosc) * self.tq_per_bit)

    def bit_time_ps(self, fosc: int) -> int:
        """Nominal bit time in picoseconds, rounded once at the end (to nearest, ties to even)."""
        return round(self.tq_seconds(fosc) * self.tq_per_bit * 10**12)

    @property
    def iso_sjw(self) -> bool:
        """Whether SJW <= min(Phase Segment 1, Phase Segment 2), ISO 11898-1's rule (the data sheet asks only
        SJW <= Phase Segment 2): a resynchronisation may then neither eat Phase Segment 2 nor lengthen Phase Segment
        1 past its own length."""
        return self.sjw <= min(self.seg1ph, self.effective_seg2ph)

    def problems(self) -> list[str]:
        """Every datasheet timing rule this setting breaks, as sentences naming the rule and the numbers.

        Rules: 8 <= N <= 25 TQ; PS2 >= SJW; Prop + PS1 >= PS2; PS2 >= IPT (2 TQ), all with the effective PS2.
        (The DS39500 translation prints "Phase segment 2 > SJW"; the data sheet's rule is >=.)
        """
        origin = "" if self.seg2phts else ", = max(Phase Segment 1, IPT) because SEG2PHTS = 0"
        return _rule_problems(
            prseg=self.prseg, seg1ph=self.seg1ph, seg2ph=self.effective_seg2ph, sjw=self.sjw, seg2ph_origin=origin
        )

    @property
    def is_valid(self) -> bool:
        """True when `problems()` is empty."""
        return not self.problems()

    def validate(self) -> None:
        """Raise `BitTimingError` listing every broken rule, or return if the setting is valid."""
        problems = self.problems()
        if problems:
            raise BitTimingError("invalid bit timing: " + "; ".join(problems))

    def __str__(self) -> str:
        ps2 = f"{self.effective_seg2ph} PS2" + ("" if self.seg2phts else " (SEG2PHTS = 0)")
        samples = ", 3 samples" if self.sam else ""
        return (
            f"BRP {self.brp} (BRP<5:0> = {self.brp_register}), {self.tq_per_bit} TQ = 1 Sync + {self.prseg} Prop"
            f" + {self.seg1ph} PS1 + {ps2}, SJW {self.sjw}, sample point {_percent(self.sample_point)} %{samples}"
        )


@dataclass(frozen=True, slots=True)
class Solution:
    """One calculator result: the setting, the bit rate it really gives and its error relative to the target."""

    timing: BitTiming
    bit_rate: Fraction
    error: Fraction


def _valid_splits(brp: int, n: int, sjw: int | None) -> list[BitTiming]:
    """Every valid setting (SEG2PHTS = 1) with this BRP divider and N TQ; SJW = `sjw`, or min(4, PS1, PS2) if None."""
    splits = []
    for seg2ph in range(IPT_TQ, SEGMENT_MAX_TQ + 1):
        for prseg in range(1, SEGMENT_MAX_TQ + 1):
            seg1ph = n - SYNC_SEG_TQ - prseg - seg2ph
            if 1 <= seg1ph <= SEGMENT_MAX_TQ:
                jump = min(SJW_MAX_TQ, seg1ph, seg2ph) if sjw is None else sjw
                timing = BitTiming(brp=brp, prseg=prseg, seg1ph=seg1ph, seg2ph=seg2ph, sjw=jump)
                if timing.is_valid:
                    splits.append(timing)
    return splits


def calculate(
    bit_rate: int | float | Fraction,
    fosc: int,
    *,
    sample_point: float | Fraction = Fraction(7, 8),
    tolerance: float | Fraction = 0,
    sjw: int | None = None,
) -> list[Solution]:
    """Every valid setting that gives `bit_rate` (bit/s) at `fosc` (Hz), best first.

    Listed: each BRP divider 1..64 and N = 8..25 TQ whose rate is within `tolerance` (relative, 0.01 = 1 %;
    default exact), and each split of N into Prop, PS1 and PS2 (SEG2PHTS = 1) that passes every rule.
    SJW is not varied: by default it is min(4, PS1, PS2), the largest jump width ISO 11898-1 allows (SJW <=
    min(PS1, PS2); the data sheet asks only SJW <= PS2) and so the most tolerant of oscillator drift; pass `sjw`
    (1..4) to fix it instead (settings whose PS2 is shorter are then left out, those whose PS1 is shorter are
    kept and `format_table` flags them).

    Order (deterministic): smallest |rate error|; then sample point closest to `sample_point` (default
    87.5 %, CiA's recommendation); then more TQ per bit; then larger min(PS1, PS2) (oscillator tolerance
    by ISO 11898-1); then longer Prop segment (longer bus); then smaller BRP and signed error.
    """
    target = _exact(bit_rate)
    wanted_sp = _exact(sample_point)
    allowed = _exact(tolerance)
    if target <= 0 or fosc <= 0:
        raise ValueError(f"bit rate and Fosc must be positive, got {bit_rate!r} bit/s at {fosc!r} Hz")
    if not 0 < wanted_sp < 1:
        raise ValueError(f"the target sample point is a fraction of the bit (e.g. 0.875), got {sample_point!r}")
    if allowed < 0:
        raise ValueError(f"tolerance is a relative error (0.01 = 1 %), got {tolerance!r}")
    if sjw is not None and not 1 <= sjw <= SJW_MAX_TQ:
        raise BitTimingError(_range_problems(brp=1, sjw=sjw, prseg=1, seg1ph=1, seg2ph=1)[0])

    solutions = []
    for brp in range(1, BRP_MAX + 1):
        for n in range(MIN_TQ_PER_BIT, MAX_TQ_PER_BIT + 1):
            rate = Fraction(fosc, 2 * brp * n)
            error = rate / target - 1
            if abs(error) > allowed:
                continue
            solutions += [Solution(timing, rate, error) for timing in _valid_splits(brp, n, sjw)]

    def rank(s: Solution) -> tuple[Fraction | int, ...]:
        t = s.timing
        return (
            abs(s.error),
            abs(t.sample_point - wanted_sp),
            -t.tq_per_bit,
            -min(t.seg1ph, t.seg2ph),
            -t.prseg,
            t.brp,
            s.error,
        )

    return sorted(solutions, key=rank)


def nearest(
    bit_rate: int | float | Fraction,
    fosc: int,
    *,
    sample_point: float | Fraction = Fraction(7, 8),
    sjw: int | None = None,
) -> list[Solution]:
    """The settings of the bit rate nearest `bit_rate` that `fosc` can make (both, if two are as near), ordered as
    `calculate` orders them: what to use where no setting gives `bit_rate` exactly."""
    target = _exact(bit_rate)
    if target <= 0 or fosc <= 0:
        raise ValueError(f"bit rate and Fosc must be positive, got {bit_rate!r} bit/s at {fosc!r} Hz")
    error = min(abs(Fraction(fosc, 2 * brp * n) / target - 1)
                for brp in range(1, BRP_MAX + 1) for n in range(MIN_TQ_PER_BIT, MAX_TQ_PER_BIT + 1))
    return calculate(target, fosc, sample_point=sample_point, tolerance=error, sjw=sjw)


COLUMNS = ("SJW", "BRP", "PHSEG1", "PHSEG2", "PROPSEG")
"""The table's first columns: `CANInitialize`'s first five arguments, in its order."""


def format_table(solutions: Iterable[Solution], marks: Mapping[BitTiming, str] | None = None) -> str:
    """A calculator-style table, one row per solution: `CANInitialize`'s five timing arguments in its order, then
    N, sample point, rate error and the BRGCON1..3 values; a row whose SJW breaks ISO 11898-1's SJW <= min(PS1, PS2)
    says so, and a row of a timing in `marks` ends with its mark."""
    marks = marks or {}
    lines = [
        "CANInitialize(SJW, BRP, PHSEG1, PHSEG2, PROPSEG, ...) takes the first five columns, in this order (BRP the "
        "divider: BRGCON1's BRP<5:0> holds BRP - 1); SJW <= min(PS1, PS2) (ISO 11898-1)",
        " ".join(COLUMNS) + f" {'N':>3} {'SP %':>6} {'Error %':>7}  BRGCON1 BRGCON2 BRGCON3",
    ]
    for s in solutions:
        t = s.timing
        arguments = " ".join(f"{value:>{len(name)}}" for name, value in zip(COLUMNS, t.an738_arguments, strict=True))
        regs = "    ".join(f"0x{r:02X}" for r in t.to_registers())
        notes = [note for note in (marks.get(t), None if t.iso_sjw else
                                   "SJW > PS1: breaks ISO 11898-1 (the PIC accepts it)") if note]
        lines.append(f"{arguments} {t.tq_per_bit:>3} {_percent(t.sample_point):>6} {error_percent(s.error):>7}     "
                     + regs + "".join(f"   {note}" for note in notes))
    if len(lines) == 2:
        lines.append("(no setting gives this bit rate)")
    return "\n".join(lines)


@dataclass(frozen=True, slots=True)
class SeedRecipe:
    """The Workshop 202 recipe's numbers as the workshop computes them, what is wrong with them, and a fix.

    `brp`, `prseg`, `seg1ph`, `seg2ph` and `sjw` are the recipe's values (BRP as the divider, segments in TQ);
    they may not be programmable, which is why they are plain ints. `notes` explain every inconsistency;
    `corrected` is the valid setting closest to the recipe at the same BRP and N (so the same bit rate).
    """

    bit_rate: Fraction
    fosc: int
    tq_per_bit: int
    brp: int
    prseg: int
    seg1ph: int
    seg2ph: int
    sjw: int
    notes: tuple[str, ...]
    corrected: BitTiming

    @property
    def brp_register(self) -> int:
        """The register value BRP<5:0> = brp - 1, the workshop recipe's "BRP = ((Fosc/N)/(2B)) - 1"."""
        return self.brp - 1

    @property
    def consistent(self) -> bool:
        """True when the recipe's own numbers are a valid, programmable setting."""
        corrected = self.corrected
        return (corrected.prseg, corrected.seg1ph, corrected.seg2ph, corrected.sjw) == (
            self.prseg, self.seg1ph, self.seg2ph, self.sjw
        )


def seed_recipe(bit_rate: int | float | Fraction, fosc: int) -> SeedRecipe:
    """Run the Workshop 202 recipe (workshop extract §2.5) and report where it goes wrong.

    N = the largest of 8..25 for which (Fosc / N) / (2 * B) is a whole divider 1..64; BRP<5:0> = that - 1;
    Phase Segment 2 = SJW = N * 0.30 rounded to the nearest TQ (halves up), as the workshop's worked example
    does (16 * 0.30 = 4.8 -> 5; the recipe text's "integer operation" would truncate, and a note says so when
    that differs); Prop = 2; Phase Segment 1 = N - 1 - 2 - Phase Segment 2.
    Raises `BitTimingError` if no N gives a whole divider.
    """
    target = _exact(bit_rate)
    if target <= 0 or fosc <= 0:
        raise ValueError(f"bit rate and Fosc must be positive, got {bit_rate!r} bit/s at {fosc!r} Hz")
    for n in range(MAX_TQ_PER_BIT, MIN_TQ_PER_BIT - 1, -1):
        divider = Fraction(fosc, n) / (2 * target)
        if divider.denominator == 1 and 1 <= divider <= BRP_MAX:
            brp = int(divider)
            break
    else:
        raise BitTimingError(
            f"the recipe finds no N in {MIN_TQ_PER_BIT}..{MAX_TQ_PER_BIT} for which (Fosc / N) / (2 x {target} bit/s) "
            f"at Fosc = {fosc} Hz is a whole prescaler divider 1..{BRP_MAX}: this bit rate cannot be made exactly; "
            f"try calculate(..., tolerance=...)"
        )

    exact_ps2 = n * SEED_PS2_SHARE
    ps2 = math.floor(exact_ps2 + Fraction(1, 2))
    ps1 = n - SYNC_SEG_TQ - SEED_PROP_SEG_TQ - ps2
    notes = []
    truncated = math.floor(exact_ps2)
    if truncated != ps2:
        truncated_ps1 = n - SYNC_SEG_TQ - SEED_PROP_SEG_TQ - truncated
        consequence = (
            f" (and then Phase Segment 1 = {n} - 1 - 2 - {truncated} = {truncated_ps1} TQ, more than the "
            f"{SEGMENT_MAX_TQ} TQ SEG1PH<2:0> can hold)"
            if truncated_ps1 > SEGMENT_MAX_TQ
            else ""
        )
        notes.append(
            f"Phase Segment 2 = SJW = N x 0.30 = {n} x 0.30 = {float(exact_ps2):g} TQ is not a whole number: the "
            f"recipe's \"integer operation\" truncates it to {truncated} TQ{consequence}, while the workshop's worked "
            f"example rounds it to {ps2} TQ; this kit follows the worked example"
        )
    broken = _range_problems(brp=brp, sjw=ps2, prseg=SEED_PROP_SEG_TQ, seg1ph=ps1, seg2ph=ps2)
    broken += _rule_problems(prseg=SEED_PROP_SEG_TQ, seg1ph=ps1, seg2ph=ps2, sjw=ps2)
    notes += broken

    corrected = min(
        _valid_splits(brp, n, None),
        key=lambda t: (abs(t.seg2ph - ps2), abs(t.prseg - SEED_PROP_SEG_TQ), -t.prseg),
    )
    if broken:
        changes = ", ".join(
            f"{label} {old} -> {new} TQ"
            for label, old, new in (
                ("Prop", SEED_PROP_SEG_TQ, corrected.prseg),
                ("PS1", ps1, corrected.seg1ph),
                ("PS2", ps2, corrected.seg2ph),
                ("SJW", ps2, corrected.sjw),
            )
            if old != new
        )
        registers = ", ".join(f"BRGCON{i} = 0x{r:02X}" for i, r in enumerate(corrected.to_registers(), start=1))
        notes.append(
            f"Corrected at the same BRP and N, so the same bit rate ({changes}): {corrected}; {registers}"
        )
    return SeedRecipe(
        bit_rate=target,
        fosc=fosc,
        tq_per_bit=n,
        brp=brp,
        prseg=SEED_PROP_SEG_TQ,
        seg1ph=ps1,
        seg2ph=ps2,
        sjw=ps2,
        notes=tuple(notes),
        corrected=corrected,
    )
