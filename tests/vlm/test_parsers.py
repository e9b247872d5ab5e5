"""Parsers accept what small VLMs emit, classify the rest, and never raise."""

from __future__ import annotations

import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from tests.mountain_car_helpers import parse_box, parse_float, parse_mcq
from vlmrl_cli.tasks.mountain_car.geometry import Zone
from vlmrl_cli.vlm.parsers import ParseStatus

PARSERS = (parse_float, parse_box, parse_mcq)


@pytest.mark.parametrize(
    ("text", "status", "value"),
    [
        ("0.378", ParseStatus.OK, 0.378),
        ("The car is at approximately -0.52.", ParseStatus.OK, -0.52),
        ("x = -0.5", ParseStatus.OK, -0.5),
        ("Between x = -1.2 and x = 0.6 ... I think x ≈ -0.3", ParseStatus.AMBIGUOUS, None),
        ("The position is -0.4 (range -1.2 to 0.6)", ParseStatus.OK, -0.4),
        ("\u22120.25", ParseStatus.OK, -0.25),
        ("3.7", ParseStatus.OUT_OF_RANGE, 3.7),
        ("1e999", ParseStatus.OUT_OF_RANGE, float("inf")),
        ("-0.2 or maybe -0.3", ParseStatus.AMBIGUOUS, None),
        ("I cannot tell.", ParseStatus.FORMAT_COLLAPSE, None),
        ("   ", ParseStatus.EMPTY, None),
        (None, ParseStatus.NO_ANSWER, None),
    ],
)
def test_parse_float_examples(text: str | None, status: ParseStatus, value: float | None) -> None:
    result = parse_float(text)
    assert result.status is status
    assert result.value == value


@pytest.mark.parametrize(
    ("text", "status", "box"),
    [
        ("[450, 210, 480, 230]", ParseStatus.OK, (450, 210, 480, 230)),
        ("Box [450, 210, 480, 230]", ParseStatus.OK, (450, 210, 480, 230)),
        ("(10.5, 20, 30, 40.5)", ParseStatus.OK, (10.5, 20, 30, 40.5)),
        ('{"x_min": 10, "y_min": 20, "x_max": 30, "y_max": 40}', ParseStatus.OK, (10, 20, 30, 40)),
        ("The box is 10, 20, 30, 40", ParseStatus.OK, (10, 20, 30, 40)),
        ("[0.1, 0.5, 0.2, 0.75]", ParseStatus.OK, (60, 200, 120, 300)),
        ("Error [0, 0, 0, 0]", ParseStatus.FORMAT_COLLAPSE, None),
        ("[10, 20, 700, 40]", ParseStatus.OUT_OF_RANGE, (10, 20, 700, 40)),
        ("[30, 20, 10, 40]", ParseStatus.OUT_OF_RANGE, (30, 20, 10, 40)),
        ("[1, 2, 3, 4] or [5, 6, 7, 8]", ParseStatus.AMBIGUOUS, None),
        ("no car", ParseStatus.FORMAT_COLLAPSE, None),
        ("", ParseStatus.EMPTY, None),
        (None, ParseStatus.NO_ANSWER, None),
    ],
)
def test_parse_box_examples(text: str | None, status: ParseStatus, box: tuple[float, ...] | None) -> None:
    result = parse_box(text)
    assert result.status is status
    assert result.box == (None if box is None else tuple(float(v) for v in box))


def test_normalised_boxes_are_flagged() -> None:
    assert parse_box("[0.1, 0.5, 0.2, 0.75]").normalised
    assert not parse_box("[10, 50, 20, 75]").normalised


@pytest.mark.parametrize(
    ("text", "status", "label"),
    [
        ("BOTTOM", ParseStatus.OK, Zone.BOTTOM),
        ("Choice = BOTTOM", ParseStatus.OK, Zone.BOTTOM),
        ("bottom.", ParseStatus.OK, Zone.BOTTOM),
        ("left slope", ParseStatus.OK, Zone.LEFT_SLOPE),
        ("Left-Peak!", ParseStatus.OK, Zone.LEFT_PEAK),
        ("NEAR_GOAL", ParseStatus.OK, Zone.NEAR_GOAL),
        ("**GOAL**", ParseStatus.OK, Zone.GOAL),
        ("Answer: RIGHT_SLOPE (not BOTTOM)", ParseStatus.OK, Zone.RIGHT_SLOPE),
        ("BOTTOM or LEFT_SLOPE", ParseStatus.AMBIGUOUS, None),
        ("LEFT_PEAK, LEFT_SLOPE, BOTTOM, RIGHT_SLOPE, NEAR_GOAL, GOAL", ParseStatus.AMBIGUOUS, None),
        ("the valley", ParseStatus.FORMAT_COLLAPSE, None),
        ("\n", ParseStatus.EMPTY, None),
        (None, ParseStatus.NO_ANSWER, None),
    ],
)
def test_parse_mcq_examples(text: str | None, status: ParseStatus, label: Zone | None) -> None:
    result = parse_mcq(text)
    assert result.status is status
    assert result.label == label


_number = st.one_of(st.integers(-2000, 2000).map(str), st.floats(allow_nan=True, allow_infinity=True).map(repr))
_near_miss = st.one_of(
    st.text(),
    st.builds(lambda a, b, c, d, o, cl: f"{o}{a}, {b}, {c}, {d}{cl}", _number, _number, _number, _number,
              st.sampled_from(["[", "(", "{", "Box [", ""]), st.sampled_from(["]", ")", "}", ""])),
    st.builds(lambda n, pre: f"{pre}{n}", _number, st.sampled_from(["x = ", "x:", "about ", "", "position is "])),
    st.builds(lambda z, pre, post: f"{pre}{z}{post}", st.sampled_from([z.value for z in Zone] + ["BOTTOMLESS"]),
              st.sampled_from(["Choice = ", "", "answer: ", "**"]), st.sampled_from(["", ".", " or GOAL", "**"])),
    st.dictionaries(st.sampled_from(["x_min", "y_min", "x_max", "y_max", "xmin"]),
                    st.one_of(st.floats(), st.text(max_size=3), st.none(), st.integers())).map(
        lambda d: __import__("json").dumps(d)),
)


@settings(max_examples=300, deadline=None)
@given(_near_miss)
def test_parsers_never_raise(text: str) -> None:
    for parser in PARSERS:
        result = parser(text)
        assert isinstance(result.status, ParseStatus)
        assert result.ok == (result.status is ParseStatus.OK)


@settings(max_examples=200, deadline=None)
@given(st.floats(-1.2, 0.6))
def test_in_range_floats_round_trip(x: float) -> None:
    result = parse_float(f"{x:.4f}")
    assert result.status is ParseStatus.OK
    assert result.value == pytest.approx(x, abs=1e-4)


@settings(max_examples=200, deadline=None)
@given(st.integers(0, 598), st.integers(0, 398), st.integers(1, 100), st.integers(1, 100))
def test_in_frame_pixel_boxes_round_trip(x0: int, y0: int, w: int, h: int) -> None:
    x1, y1 = min(600, x0 + w), min(400, y0 + h)
    result = parse_box(f"[{x0}, {y0}, {x1}, {y1}]")
    if max(x0, y0, x1, y1) <= 1:  # read as normalised by design
        return
    assert result.status is ParseStatus.OK
    assert result.box == (x0, y0, x1, y1)


@given(st.sampled_from(list(Zone)), st.sampled_from(["{}", "Choice = {}", "{}.", "the car is at {}"]),
       st.booleans())
def test_every_label_parses_in_every_form(zone: Zone, template: str, lower: bool) -> None:
    text = template.format(zone.value.lower() if lower else zone.value)
    assert parse_mcq(text).label == zone


@pytest.mark.parametrize(("text", "label"), [
    ("HIGH_SWING", "HIGH_SWING"), ("Answer: high swing.", "HIGH_SWING"), ("The image shows ABOVE-BAR", "ABOVE_BAR"),
    ("Choice = low_swing", "LOW_SWING"),
])
def test_another_tasks_vocabulary_parses_into_its_labels(text: str, label: str) -> None:
    labels = ("HANGING", "LOW_SWING", "HIGH_SWING", "ABOVE_BAR")
    assert parse_mcq(text, labels).label == label


def test_another_tasks_vocabulary_keeps_the_ambiguity_and_collapse_rules() -> None:
    labels = ("NEAR", "NEAR_GOAL")  # a label inside another: the longer one wins where it fits
    assert parse_mcq("NEAR GOAL", labels).label == "NEAR_GOAL"
    assert parse_mcq("NEAR or NEAR_GOAL", labels).status is ParseStatus.AMBIGUOUS
    assert parse_mcq("BOTTOM", labels).status is ParseStatus.FORMAT_COLLAPSE  # MountainCar's zone is not a label here
