"""Properties of the probe's statistics."""

from __future__ import annotations

import math

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from vlmrl_cli.probe import metrics
from vlmrl_cli.tasks.mountain_car import MOUNTAIN_CAR
from vlmrl_cli.tasks.mountain_car.geometry import Zone, zone_of
from vlmrl_cli.tasks.mountain_car.probe import NUMBER_PROBE
from vlmrl_cli.vlm.parsers import ParseStatus

# MountainCar's potentials of Table 1: its label map
LABEL_MAP = dict(MOUNTAIN_CAR.label_potentials)

_coord = st.floats(-50, 700, allow_nan=False)
_box = st.tuples(_coord, _coord, _coord, _coord)
_valid_box = st.tuples(st.floats(0, 500), st.floats(0, 300), st.floats(1, 100), st.floats(1, 100)).map(
    lambda t: (t[0], t[1], t[0] + t[2], t[1] + t[3]))


@given(_box, _box)
def test_iou_is_bounded_and_symmetric(a: tuple[float, ...], b: tuple[float, ...]) -> None:
    v = metrics.iou(a, b)  # type: ignore[arg-type]
    assert 0.0 <= v <= 1.0
    assert v == pytest.approx(metrics.iou(b, a))  # type: ignore[arg-type]


@given(_valid_box)
def test_iou_of_a_box_with_itself_is_one(b: tuple[float, float, float, float]) -> None:
    assert metrics.iou(b, b) == pytest.approx(1.0)
    assert metrics.centre_error_px(b, b) == 0.0


@given(_valid_box, st.floats(-100, 100), st.floats(-100, 100))
def test_centre_error_is_the_shift(b: tuple[float, float, float, float], dx: float, dy: float) -> None:
    shifted = (b[0] + dx, b[1] + dy, b[2] + dx, b[3] + dy)
    assert metrics.centre_error_px(b, shifted) == pytest.approx(math.hypot(dx, dy), abs=1e-6)


def test_spearman_handles_constant_and_nan() -> None:
    assert math.isnan(metrics.spearman([0.1, 0.1, 0.1], [1, 2, 3]))
    assert math.isnan(metrics.spearman([1.0], [1.0]))
    assert metrics.spearman([1, np.nan, 3, 4], [1, 2, 3, 4]) == pytest.approx(1.0)
    assert metrics.spearman([3, 2, 1], [1, 2, 3]) == pytest.approx(-1.0)


def test_spearman_ci_by_hand() -> None:
    # rho = 0.5 over 28 pairs: z = atanh(0.5) = 0.5493, se = sqrt(1.125 / 25) = 0.2121,
    # z +- 1.96 se = (0.1335, 0.9651), tanh -> (0.1327, 0.7465)
    assert metrics.spearman_ci(0.5, 28) == pytest.approx((0.13274690, 0.74653306), abs=1e-7)
    # no correlation over 103 pairs: +- tanh(1.96 / 10) = +- 0.1935
    assert metrics.spearman_ci(0.0, 103) == pytest.approx((-0.19352466, 0.19352466), abs=1e-7)


def test_spearman_ci_is_undefined_where_fisher_z_is() -> None:
    for rho, n in ((math.nan, 50), (0.3, 3), (1.0, 50), (-1.0, 50)):
        assert all(math.isnan(v) for v in metrics.spearman_ci(rho, n))
    with pytest.raises(ValueError, match="level"):
        metrics.spearman_ci(0.1, 50, level=1.0)


@given(st.floats(-0.999, 0.999), st.integers(4, 10_000))
def test_spearman_ci_holds_rho_inside_the_open_interval(rho: float, n: int) -> None:
    lo, hi = metrics.spearman_ci(rho, n)
    assert -1.0 <= lo <= rho <= hi <= 1.0
    wider = metrics.spearman_ci(rho, n, level=0.99)
    assert wider[0] <= lo and hi <= wider[1]


@given(st.floats(-0.99, 0.99), st.integers(4, 5_000))
def test_spearman_ci_narrows_with_more_pairs(rho: float, n: int) -> None:
    lo, hi = metrics.spearman_ci(rho, n)
    lo2, hi2 = metrics.spearman_ci(rho, 4 * n)
    assert hi2 - lo2 < hi - lo


def test_finite_pairs_drops_a_pair_when_either_side_is_missing() -> None:
    x, y = metrics.finite_pairs([1.0, np.nan, 3.0, 4.0], [1.0, 2.0, np.inf, 5.0])
    assert x.tolist() == [1.0, 4.0] and y.tolist() == [1.0, 5.0]


@given(st.lists(st.sampled_from(list(ParseStatus)), max_size=30))
def test_format_failure_rate_is_a_fraction(statuses: list[ParseStatus]) -> None:
    rate = metrics.format_failure_rate(statuses)
    if all(s is ParseStatus.NO_ANSWER for s in statuses):
        assert math.isnan(rate)
    else:
        assert 0.0 <= rate <= 1.0


@given(st.lists(st.tuples(st.sampled_from(list(Zone)), st.one_of(st.none(), st.sampled_from(list(Zone)))),
                max_size=40))
def test_mcq_accuracy_counts_exact_answers_and_an_unparsed_one_as_wrong(
        pairs: list[tuple[Zone, Zone | None]]) -> None:
    truth = [t for t, _ in pairs]
    pred = [p for _, p in pairs]
    if pairs:
        correct = sum(p is not None and p == t for t, p in pairs)
        assert metrics.mcq_accuracy(pred, truth) == pytest.approx(correct / len(pairs))


_phis = st.lists(st.one_of(st.floats(-2, 2), st.just(math.nan)), min_size=0, max_size=40)


@settings(max_examples=200)
@given(_phis, st.data())
def test_delta_phi_fractions_are_bounded(vlm: list[float], data: st.DataObject) -> None:
    true = data.draw(st.lists(st.floats(-2, 2), min_size=len(vlm), max_size=len(vlm)))
    s = metrics.delta_phi_stats(vlm, true)
    for key in ("dead_zone", "sign_disagreement", "dead_zone_while_truth_moves", "phi_unavailable"):
        assert math.isnan(s[key]) or 0.0 <= s[key] <= 1.0
    assert s["n_pairs"] <= max(0, len(vlm) - 1)
    if s["n_pairs"]:
        assert s["dead_zone_while_truth_moves"] <= s["dead_zone"]


@given(st.lists(st.floats(-1.2, 0.6), min_size=2, max_size=40))
def test_perfect_answers_have_no_dphi_error(xs: list[float]) -> None:
    xs = sorted(xs)
    for phi in ([NUMBER_PROBE.potential(x) for x in xs], [LABEL_MAP[zone_of(x)] for x in xs]):
        s = metrics.delta_phi_stats(phi, phi)
        assert s["sign_disagreement"] == 0.0
        assert s["mean_abs_dphi_error"] == 0.0
        assert s["dead_zone_while_truth_moves"] == 0.0
        assert s["phi_unavailable"] == 0.0


def test_paper_mcq_pair_is_a_dead_zone() -> None:
    vlm = [LABEL_MAP[Zone.BOTTOM], LABEL_MAP[Zone.BOTTOM]]
    true = [LABEL_MAP[zone_of(-0.50)], LABEL_MAP[zone_of(-0.69)]]
    s = metrics.delta_phi_stats(vlm, true)
    assert s["dead_zone"] == 1.0 and s["dead_zone_while_truth_moves"] == 1.0


def test_unparsed_answers_make_phi_unavailable() -> None:
    s = metrics.delta_phi_stats([0.1, math.nan, 0.3, 0.4], [0.1, 0.2, 0.3, 0.4])
    assert s["phi_unavailable"] == 0.25 and s["n_pairs"] == 1
