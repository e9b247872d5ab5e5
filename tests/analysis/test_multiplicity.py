"""Multiplicity adjustment: properties of Holm and Benjamini-Hochberg on random families."""

from __future__ import annotations

import math

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from scipy import stats as sps

from vlmrl_cli.analysis.multiplicity import METHODS, adjust, check_method

P = st.floats(min_value=0.0, max_value=1.0, allow_nan=False)
FAMILY = st.lists(st.one_of(P, st.just(math.nan)), min_size=0, max_size=25)
FINITE = st.lists(P, min_size=1, max_size=25)


def holm_reference(p: list[float]) -> list[float]:
    """Holm (1979) as written in the paper: the i-th smallest of the m tests gets
    max over j <= i of min(1, (m - j + 1) p_(j)), with 1-based ranks; loops, no numpy tricks."""
    finite = [(v, i) for i, v in enumerate(p) if not math.isnan(v)]
    m = len(finite)
    ranked = sorted(finite)
    out = [math.nan] * len(p)
    running = 0.0
    for j, (v, i) in enumerate(ranked, start=1):
        running = max(running, min(1.0, (m - j + 1) * v))
        out[i] = running
    return out


@given(FAMILY, st.sampled_from(METHODS))
def test_adjusted_is_at_least_raw_at_most_one_and_nan_stays_nan(p: list[float], method: str) -> None:
    raw = np.array(p, dtype=float)
    adj = adjust(raw, method)
    assert adj.shape == raw.shape
    assert np.array_equal(np.isnan(adj), np.isnan(raw))
    ok = np.isfinite(raw)
    assert np.all(adj[ok] >= raw[ok] - 1e-15) and np.all(adj[ok] <= 1.0)


@given(FAMILY)
def test_none_is_the_identity(p: list[float]) -> None:
    np.testing.assert_array_equal(adjust(p, "none"), np.array(p, dtype=float))


@given(FAMILY)
def test_holm_is_never_below_bh(p: list[float]) -> None:
    holm, bh = adjust(p, "holm"), adjust(p, "bh")
    ok = np.isfinite(holm)
    assert np.all(holm[ok] >= bh[ok] - 1e-12)


@given(FAMILY, st.sampled_from(["holm", "bh"]))
def test_the_order_of_the_raw_p_values_is_kept(p: list[float], method: str) -> None:
    raw = np.array(p, dtype=float)
    adj = adjust(raw, method)
    ok = np.flatnonzero(np.isfinite(raw))
    for i in ok:
        for j in ok:
            if raw[i] <= raw[j]:
                assert adj[i] <= adj[j] + 1e-12


@given(FAMILY)
def test_nan_does_not_count_in_the_family_size(p: list[float]) -> None:
    raw = np.array(p, dtype=float)
    ok = np.isfinite(raw)
    for method in METHODS:
        np.testing.assert_allclose(adjust(raw, method)[ok], adjust(raw[ok], method))


@settings(max_examples=200)
@given(FINITE)
def test_bh_agrees_with_scipy(p: list[float]) -> None:
    np.testing.assert_allclose(adjust(p, "bh"), sps.false_discovery_control(p, method="bh"), rtol=1e-12, atol=1e-15)


@settings(max_examples=200)
@given(FAMILY)
def test_holm_agrees_with_the_reference(p: list[float]) -> None:
    np.testing.assert_allclose(adjust(p, "holm"), holm_reference(p), rtol=1e-12, atol=1e-15)


@given(st.lists(P, min_size=1, max_size=1), st.sampled_from(METHODS))
def test_a_family_of_one_is_not_adjusted(p: list[float], method: str) -> None:
    np.testing.assert_array_equal(adjust(p, method), p)


def test_holm_on_a_hand_worked_family() -> None:
    # m = 4: 4 x 0.01, 3 x 0.02 = 0.06, 2 x 0.03 = 0.06, 1 x 0.5
    np.testing.assert_allclose(adjust([0.5, 0.03, 0.01, 0.02]), [0.5, 0.06, 0.04, 0.06])
    # BH on the same: 0.04, 0.04, 0.04, 0.5
    np.testing.assert_allclose(adjust([0.5, 0.03, 0.01, 0.02], "bh"), [0.5, 0.04, 0.04, 0.04])


def test_bad_input_says_what_is_allowed() -> None:
    with pytest.raises(ValueError, match="holm, bh, none"):
        check_method("bonferroni")
    with pytest.raises(ValueError, match=r"\[0, 1\]"):
        adjust([0.2, 1.5])


def test_a_family_too_large_for_its_seeds_is_said_to_be_unreachable() -> None:
    from math import comb

    from vlmrl_cli.analysis.multiplicity import reach_line, seeds_to_reach, smallest_exact_p

    assert smallest_exact_p(5, 5) == 2 / comb(10, 5) == 2 / 252
    line = reach_line("holm", 12, 5, 5)
    assert line is not None and "2/252" in line and "0.05/12" in line and "at least 6 seeds" in line
    assert reach_line("holm", 12, 10, 10) is None  # 2/184756 passes 0.05/12
    assert reach_line("holm", 1, 5, 5) is None  # 0.0079 < 0.05 on its own
    n = seeds_to_reach(12)
    assert n is not None and smallest_exact_p(n, n) < 0.05 / 12 <= smallest_exact_p(n - 1, n - 1)
