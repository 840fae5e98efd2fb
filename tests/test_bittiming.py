"""Bit timing: register layout, exact rates, the datasheet rules, the calculator and the seed's recipe."""
from __future__ import annotations

from fractions import Fraction

import pytest
from hypothesis import given
from hypothesis import strategies as st

from appsim.can.bittiming import (
    BRGCON3_IMPLEMENTED,
    BitTiming,
    BitTimingError,
    Solution,
    calculate,
    error_percent,
    format_table,
    nearest,
    seed_recipe,
)

MHZ = 1_000_000

CLASSROOM = BitTiming(sjw=4, brp=10, seg1ph=8, seg2ph=4, prseg=3)  # CANInitialize(4, 10, 8, 4, 3, ...)
EXAMPLE_9_2 = BitTiming(brp=4 + 1, prseg=2, seg1ph=7, seg2ph=6, sjw=1)  # chapter BRP = register value 4
EXAMPLE_9_3 = BitTiming(brp=4 + 1, prseg=5, seg1ph=5, seg2ph=5, sjw=1)

timings = st.builds(
    BitTiming,
    brp=st.integers(1, 64),
    prseg=st.integers(1, 8),
    seg1ph=st.integers(1, 8),
    seg2ph=st.integers(1, 8),
    sjw=st.integers(1, 4),
    sam=st.booleans(),
    seg2phts=st.booleans(),
    wakfil=st.booleans(),
)
bytes_ = st.integers(0, 0xFF)


# --- register layout -------------------------------------------------------------------------------------


@given(timings)
def test_registers_round_trip_from_timing(timing: BitTiming) -> None:
    assert BitTiming.from_registers(*timing.to_registers()) == timing


@given(bytes_, bytes_, bytes_)
def test_registers_round_trip_and_unimplemented_brgcon3_bits_read_0(b1: int, b2: int, b3: int) -> None:
    assert BitTiming.from_registers(b1, b2, b3).to_registers() == (b1, b2, b3 & BRGCON3_IMPLEMENTED)


def test_register_fields_hold_tq_minus_1_in_the_datasheet_bit_positions() -> None:
    timing = BitTiming.from_registers(0b10_000101, 0b1_1_011_110, 0b1_1_000_010)
    assert (timing.sjw, timing.brp, timing.brp_register) == (3, 6, 5)
    assert (timing.seg2phts, timing.sam, timing.seg1ph, timing.prseg) == (True, True, 4, 7)
    assert (timing.wakfil, timing.seg2ph) == (True, 3)


def test_reset_registers_decode_to_an_invalid_5_tq_bit() -> None:
    timing = BitTiming.from_registers(0x00, 0x00, 0x00)
    assert timing.tq_per_bit == 5  # 1 + 1 + 1 + max(PS1 = 1, IPT = 2)
    assert len(timing.problems()) == 1
    assert "8 to 25 TQ" in timing.problems()[0]


@pytest.mark.parametrize("value", [-1, 0x100])
def test_from_registers_rejects_values_that_are_not_a_byte(value: int) -> None:
    with pytest.raises(BitTimingError, match="8-bit register"):
        BitTiming.from_registers(0, value, 0)


def test_seg2phts_clear_makes_ps2_the_larger_of_ps1_and_ipt() -> None:
    short = BitTiming(brp=1, prseg=5, seg1ph=1, seg2ph=8, seg2phts=False)
    long = BitTiming(brp=1, prseg=5, seg1ph=6, seg2ph=1, seg2phts=False)
    assert short.effective_seg2ph == 2 and short.tq_per_bit == 9
    assert long.effective_seg2ph == 6 and long.tq_per_bit == 18
    assert BitTiming(brp=1, prseg=5, seg1ph=6, seg2ph=3).effective_seg2ph == 3


# --- worked examples ----------------------------------------------------------------------------------


@pytest.mark.parametrize(
    ("fosc", "brp_register", "segments", "tq", "rate"),
    [
        (16 * MHZ, 0x00, (1, 4, 2), Fraction(125, 10**9), 1_000_000),
        (32 * MHZ, 0x01, (1, 4, 2), Fraction(125, 10**9), 1_000_000),
        (32 * MHZ, 0x3F, (8, 8, 8), Fraction(4, 10**6), 10_000),
    ],
)
def test_ds39500_6_2_prescaler_examples(
    fosc: int, brp_register: int, segments: tuple[int, int, int], tq: Fraction, rate: int
) -> None:
    prseg, seg1ph, seg2ph = segments
    timing = BitTiming(brp=brp_register + 1, prseg=prseg, seg1ph=seg1ph, seg2ph=seg2ph)
    assert timing.tq_seconds(fosc) == tq
    assert timing.bit_rate(fosc) == rate
    assert timing.bit_time_ps(fosc) == 10**12 // rate


def test_ds39500_6_7_and_chapter_example_9_2_at_20_mhz() -> None:
    timing = EXAMPLE_9_2
    assert timing.brp_register == 4
    assert timing.tq_seconds(20 * MHZ) == Fraction(500, 10**9)
    assert timing.tq_per_bit == 16
    assert timing.bit_rate(20 * MHZ) == 125_000
    assert timing.sample_point == Fraction(5, 8)
    assert timing.to_registers() == (0x04, 0xB1, 0x05)
    assert BitTiming.from_registers(0x04, 0xB1, 0x05) == timing
    assert timing.is_valid


def test_chapter_example_9_1_brp_register_1_with_8_tq_is_625_kbit() -> None:
    timing = BitTiming(brp=1 + 1, prseg=1, seg1ph=4, seg2ph=2)
    assert timing.tq_seconds(20 * MHZ) == Fraction(2, 10**7)
    assert timing.bit_rate(20 * MHZ) == 625_000


def test_chapter_example_9_3_sample_point_is_68_75_not_the_printed_68() -> None:
    assert EXAMPLE_9_3.tq_per_bit == 16
    assert EXAMPLE_9_3.bit_rate(20 * MHZ) == 125_000
    assert EXAMPLE_9_3.sample_point == Fraction(11, 16)
    assert "68.75 %" in str(EXAMPLE_9_3)
    assert EXAMPLE_9_3.is_valid


def test_an738_example_canintialize_2_8_3_3_1_is_312k5_at_40_mhz_and_125k_at_16_mhz() -> None:
    timing = BitTiming(sjw=2, brp=8, seg1ph=3, seg2ph=3, prseg=1)
    assert timing.brp_register == 7
    assert timing.tq_seconds(40 * MHZ) == Fraction(4, 10**7)
    assert timing.tq_per_bit == 8
    assert timing.bit_rate(40 * MHZ) == Fraction(312_500)
    assert timing.sample_point == Fraction(5, 8)
    assert timing.bit_rate(16 * MHZ) == 125_000
    assert timing.bit_rate(20 * MHZ) == Fraction(156_250)


def test_classroom_convention_is_125k_with_16_tq_and_75_percent_at_40_mhz() -> None:
    assert CLASSROOM.tq_seconds(40 * MHZ) == Fraction(1, 2 * 10**6)
    assert CLASSROOM.tq_per_bit == 16
    assert CLASSROOM.bit_rate(40 * MHZ) == 125_000
    assert CLASSROOM.bit_time_ps(40 * MHZ) == 8_000_000
    assert CLASSROOM.sample_point == Fraction(3, 4)
    assert CLASSROOM.to_registers() == (0xC9, 0xBA, 0x03)
    CLASSROOM.validate()


def test_project_9_1_brp_1_is_100k_as_register_but_200k_as_an738_divider() -> None:
    as_register = BitTiming(brp=1 + 1, prseg=6, seg1ph=6, seg2ph=7, sjw=1)
    as_divider = BitTiming(brp=1, prseg=6, seg1ph=6, seg2ph=7, sjw=1)  # CANInitialize(1, 1, 6, 7, 6, ...)
    assert as_register.bit_rate(8 * MHZ) == 100_000
    assert as_divider.bit_rate(8 * MHZ) == 200_000
    assert as_register.sample_point == Fraction(13, 20)


def test_bit_time_ps_is_exact_then_rounded_once() -> None:
    timing = BitTiming(brp=1, prseg=1, seg1ph=4, seg2ph=2)
    assert timing.bit_time_ps(30 * MHZ) == 533_333  # 8 * 2 / 30 MHz = 533 333.33 ps
    assert timing.bit_rate(30 * MHZ) == Fraction(30 * MHZ, 16)


def test_tq_needs_a_positive_fosc() -> None:
    with pytest.raises(ValueError, match="Fosc"):
        CLASSROOM.tq_seconds(0)


@given(timings)
def test_valid_timing_samples_after_the_middle_of_the_bit(timing: BitTiming) -> None:
    if timing.is_valid:
        assert Fraction(1, 2) < timing.sample_point < 1
        assert 8 <= timing.tq_per_bit <= 25


# --- the datasheet rules -------------------------------------------------------------------------------


def test_rule_bit_must_be_8_to_25_tq() -> None:
    timing = BitTiming(brp=1, prseg=1, seg1ph=2, seg2ph=2)
    assert timing.problems() == [
        "Nominal bit time: a bit must be 8 to 25 TQ, but this one is 6 TQ (1 Sync + 1 Prop + 2 PS1 + 2 PS2): "
        "fewer than 8 TQ per bit is not guaranteed to work, so use a smaller BRP and longer segments"
    ]


def test_rule_phase_segment_2_at_least_sjw() -> None:
    (problem,) = BitTiming(brp=1, prseg=3, seg1ph=8, seg2ph=3, sjw=4).problems()
    assert problem.startswith("Phase Segment 2 (3 TQ) must be at least SJW (4 TQ): ")


def test_rule_phase_segment_2_at_least_sjw_names_seg2phts_when_ps2_is_derived() -> None:
    (problem,) = BitTiming(brp=1, prseg=5, seg1ph=2, seg2ph=8, sjw=4, seg2phts=False).problems()
    assert "Phase Segment 2 (2 TQ, = max(Phase Segment 1, IPT) because SEG2PHTS = 0) must be at least SJW" in problem


def test_rule_prop_plus_phase_segment_1_at_least_phase_segment_2() -> None:
    (problem,) = BitTiming(brp=1, prseg=1, seg1ph=1, seg2ph=8).problems()
    assert problem.startswith(
        "Prop Segment + Phase Segment 1 (1 + 1 = 2 TQ) must be at least Phase Segment 2 (8 TQ): "
    )


def test_rule_phase_segment_2_at_least_ipt() -> None:
    (problem,) = BitTiming(brp=1, prseg=3, seg1ph=3, seg2ph=1).problems()
    assert "Information Processing Time (IPT = 2 TQ)" in problem


def test_validate_raises_a_value_error_listing_every_broken_rule() -> None:
    timing = BitTiming(brp=1, prseg=1, seg1ph=1, seg2ph=1, sjw=2)
    with pytest.raises(ValueError) as caught:
        timing.validate()
    assert isinstance(caught.value, BitTimingError)
    message = str(caught.value)
    for rule in ("8 to 25 TQ", "at least SJW", "Information Processing Time"):
        assert rule in message


@pytest.mark.parametrize(
    ("fields", "names"),
    [
        ({"sjw": 5}, ("SJW = 5 TQ", "SJW<1:0>", "at most 4 TQ")),
        ({"sjw": 0}, ("SJW = 0 TQ", "SJW<1:0>")),
        ({"brp": 0}, ("BRP = 0", "divider", "BRP<5:0>")),
        ({"brp": 65}, ("BRP = 65", "divider", "BRP<5:0>")),
        ({"prseg": 9}, ("Propagation Segment = 9 TQ", "PRSEG<2:0>")),
        ({"seg1ph": 0}, ("Phase Segment 1 = 0 TQ", "SEG1PH<2:0>")),
        ({"seg2ph": 9}, ("Phase Segment 2 = 9 TQ", "SEG2PH<2:0>")),
    ],
)
def test_values_no_register_field_can_hold_raise_at_construction(
    fields: dict[str, int], names: tuple[str, ...]
) -> None:
    with pytest.raises(BitTimingError) as caught:
        BitTiming(**{"brp": 4, "prseg": 2, "seg1ph": 8, "seg2ph": 5, "sjw": 1, **fields})
    for name in names:
        assert name in str(caught.value)


def test_fields_must_be_ints_and_flags_bools() -> None:
    with pytest.raises(TypeError, match="sam"):
        BitTiming(brp=1, prseg=1, seg1ph=4, seg2ph=2, sam=1)  # type: ignore[arg-type]
    with pytest.raises(TypeError, match="brp"):
        BitTiming(brp=True, prseg=1, seg1ph=4, seg2ph=2)


# --- the calculator ------------------------------------------------------------------------------------


def test_calculator_at_40_mhz_125k_lists_the_classroom_setting() -> None:
    solutions = calculate(125_000, 40 * MHZ)
    assert CLASSROOM in [s.timing for s in solutions]
    assert all(s.timing.is_valid and s.bit_rate == 125_000 and s.error == 0 for s in solutions)
    best = solutions[0].timing
    assert best.sample_point == Fraction(7, 8) and best.tq_per_bit == 16


def test_calculator_at_20_mhz_125k_with_sjw_1_lists_examples_9_2_and_9_3() -> None:
    timings = [s.timing for s in calculate(125_000, 20 * MHZ, sjw=1)]
    assert EXAMPLE_9_2 in timings and EXAMPLE_9_3 in timings
    assert {t.sjw for t in timings} == {1}


def test_calculator_default_sjw_is_the_largest_iso_11898_allows_min_4_ps1_ps2() -> None:
    solutions = calculate(125_000, 20 * MHZ)
    assert all(s.timing.sjw == min(4, s.timing.seg1ph, s.timing.seg2ph) for s in solutions)
    assert any(s.timing.seg1ph < min(4, s.timing.seg2ph) for s in solutions), \
        "rows where the data sheet alone allows more"
    assert all(s.timing.iso_sjw for s in solutions)


def test_a_fixed_sjw_above_phase_segment_1_is_listed_with_the_iso_rule_it_breaks() -> None:
    solutions = calculate(1_000_000, 40 * MHZ, sjw=2)
    table = format_table(solutions).splitlines()
    assert "SJW <= min(PS1, PS2) (ISO 11898-1)" in table[0]
    short_ps1 = [row for s, row in zip(solutions, table[2:], strict=True) if s.timing.seg1ph < 2]
    assert short_ps1 and all(row.endswith("SJW > PS1: breaks ISO 11898-1 (the PIC accepts it)") for row in short_ps1)
    assert all("ISO" not in row for s, row in zip(solutions, table[2:], strict=True) if s.timing.seg1ph >= 2)


def test_calculator_order_is_error_then_sample_point_then_more_tq() -> None:
    target = Fraction(7, 10)
    solutions = calculate(33_000, 40 * MHZ, sample_point=0.7, tolerance=0.01)
    assert solutions and not calculate(33_000, 40 * MHZ)
    keys = [(abs(s.error), abs(s.timing.sample_point - target), -s.timing.tq_per_bit) for s in solutions]
    assert keys == sorted(keys)
    assert all(abs(s.error) <= Fraction(1, 100) for s in solutions)
    assert all(s.bit_rate == s.timing.bit_rate(40 * MHZ) for s in solutions)
    assert solutions == calculate(33_000, 40 * MHZ, sample_point=0.7, tolerance=0.01)


@pytest.mark.parametrize(
    "kwargs",
    [{"sample_point": 1.0}, {"sample_point": 0}, {"tolerance": -0.1}, {"sjw": 5}],
)
def test_calculator_rejects_impossible_requests(kwargs: dict[str, float]) -> None:
    with pytest.raises(ValueError):
        calculate(125_000, 40 * MHZ, **kwargs)


def test_format_table_reads_like_a_bit_timing_calculator_in_caninitialize_s_argument_order() -> None:
    table = format_table([Solution(CLASSROOM, Fraction(125_000), Fraction(0))], {CLASSROOM: "the workshop's"})
    legend, header, row = table.splitlines()
    assert legend.startswith("CANInitialize(SJW, BRP, PHSEG1, PHSEG2, PROPSEG, ...) takes the first five columns")
    assert header.split() == [
        "SJW", "BRP", "PHSEG1", "PHSEG2", "PROPSEG", "N", "SP", "%", "Error", "%", "BRGCON1", "BRGCON2", "BRGCON3"
    ]
    assert row.split() == ["4", "10", "8", "4", "3", "16", "75", "0", "0xC9", "0xBA", "0x03", "the", "workshop's"]
    assert CLASSROOM.an738_arguments == (4, 10, 8, 4, 3), "CANInitialize(4, 10, 8, 4, 3, ...)"
    assert "no setting" in format_table([])


def test_nearest_gives_the_settings_of_the_nearest_rate_where_none_is_exact() -> None:
    assert not calculate(33_000, 40 * MHZ)
    solutions = nearest(33_000, 40 * MHZ)
    rates = {s.bit_rate for s in solutions}
    assert rates == {Fraction(40 * MHZ, 2 * 55 * 11)}, "33,057.85 bit/s: BRP 55, 11 TQ"
    every = [Fraction(40 * MHZ, 2 * brp * n) for brp in range(1, 65) for n in range(8, 26)]
    assert all(abs(r / 33_000 - 1) >= abs(s.error) for r in every for s in solutions), "none nearer"
    assert solutions == calculate(33_000, 40 * MHZ, tolerance=abs(solutions[0].error))
    assert nearest(125_000, 40 * MHZ) == calculate(125_000, 40 * MHZ), "an exact rate is its own nearest"
    assert [error_percent(e) for e in (Fraction(0), Fraction(18, 10_000), Fraction(-1, 40_000_000))] == \
        ["0", "+0.18", "-0.0000025"]


# --- the seed's recipe ---------------------------------------------------------------------------------


def test_seed_example_sjw_5_is_reported_inconsistent() -> None:
    recipe = seed_recipe(125_000, 16 * MHZ)
    assert (recipe.tq_per_bit, recipe.brp_register) == (16, 3)
    assert (recipe.prseg, recipe.seg1ph, recipe.seg2ph, recipe.sjw) == (2, 8, 5, 5)
    assert not recipe.consistent
    notes = " ".join(recipe.notes)
    assert "16 x 0.30 = 4.8 TQ" in notes and "truncates it to 4 TQ" in notes and "rounds it to 5 TQ" in notes
    assert "SJW = 5 TQ cannot be programmed" in notes and "at most 4 TQ" in notes


def test_seed_example_truncating_4_8_would_overflow_phase_segment_1() -> None:
    notes = " ".join(seed_recipe(125_000, 16 * MHZ).notes)
    assert "Phase Segment 1 = 16 - 1 - 2 - 4 = 9 TQ" in notes


def test_seed_example_is_corrected_to_sjw_4_at_the_same_bit_rate() -> None:
    recipe = seed_recipe(125_000, 16 * MHZ)
    fixed = recipe.corrected
    fixed.validate()
    assert (fixed.brp, fixed.prseg, fixed.seg1ph, fixed.seg2ph, fixed.sjw) == (4, 2, 8, 5, 4)
    assert fixed.bit_rate(16 * MHZ) == 125_000
    # the slide's "Results": BRP<5:0> = 3, SEG1PH = 7, SEG2PH = 4 hold; SJW<1:0> is 3, not the slide's 4
    assert fixed.to_registers() == (0b11_000011, 0b1_0_111_001, 0b0_0_000_100)
    assert "SJW 5 -> 4 TQ" in recipe.notes[-1]


@pytest.mark.parametrize(
    ("rate", "brp_register"), [(125_000, 7), (250_000, 3), (500_000, 1), (1_000_000, 0)]
)
def test_seed_recipe_at_40_mhz_picks_20_tq_whose_sjw_6_and_ps1_11_do_not_fit(rate: int, brp_register: int) -> None:
    recipe = seed_recipe(rate, 40 * MHZ)
    assert (recipe.tq_per_bit, recipe.brp_register, recipe.seg2ph, recipe.seg1ph) == (20, brp_register, 6, 11)
    notes = " ".join(recipe.notes)
    assert "SJW = 6 TQ cannot be programmed" in notes
    assert "Phase Segment 1 = 11 TQ cannot be programmed" in notes
    assert recipe.corrected.is_valid and recipe.corrected.bit_rate(40 * MHZ) == rate
    assert recipe.corrected.tq_per_bit == 20 and recipe.corrected.sjw == 4


def test_seed_recipe_without_problems_has_no_notes_and_keeps_its_numbers() -> None:
    recipe = seed_recipe(1_000_000, 16 * MHZ)
    assert recipe.consistent and recipe.notes == ()
    assert recipe.corrected == BitTiming(brp=1, prseg=2, seg1ph=3, seg2ph=2, sjw=2)


def test_seed_recipe_reports_a_rate_it_cannot_make_exactly() -> None:
    with pytest.raises(BitTimingError, match="no N in 8..25"):
        seed_recipe(10_000, 40 * MHZ)
