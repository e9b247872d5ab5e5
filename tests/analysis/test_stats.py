from __future__ import annotations

import math

import numpy as np
from hypothesis import given, settings
from hypothesis import strategies as st

from vlmrl_cli.analysis import stats

N_BOOT = 200
values = st.lists(st.floats(1e3, 1e6), min_size=2, max_size=8)


def rng() -> np.random.Generator:
    return np.random.default_rng(0)


@settings(max_examples=40, deadline=None)
@given(values)
def test_mean_ci_contains_mean_and_is_reproducible(xs):
    a = stats.mean_ci(xs, rng(), N_BOOT)
    b = stats.mean_ci(xs, rng(), N_BOOT)
    assert a == b
    assert a.low - 1e-6 <= a.value <= a.high + 1e-6
    assert min(xs) - 1e-6 <= a.low and a.high <= max(xs) + 1e-6


def test_summarize_steps_counts_and_censoring():
    s = stats.summarize_steps([100.0, np.nan, 300.0, np.nan], [1000, 1000, 1000, 500], rng(), N_BOOT)
    assert (s.n, s.n_reached) == (4, 2)
    assert s.mean.value == 200.0 and s.median == 200.0
    assert s.censored_mean == (100 + 1000 + 300 + 500) / 4
    assert s.censored_mean >= s.mean.value or s.n == s.n_reached


@settings(max_examples=40, deadline=None)
@given(st.integers(0, 20), st.integers(1, 20))
def test_wilson_interval_contains_proportion(k, extra):
    n = k + extra - 1 if k + extra - 1 >= max(k, 1) else max(k, 1)
    e = stats.wilson_ci(k, n)
    assert 0.0 <= e.low <= e.value <= e.high <= 1.0


def test_reliability_counts_true():
    e = stats.reliability([True, True, False])
    assert math.isclose(e.value, 2 / 3) and e.n == 3


@settings(max_examples=40, deadline=None)
@given(st.lists(st.floats(-200, 0), min_size=1, max_size=12))
def test_iqm_between_min_and_max_and_robust_to_one_outlier(xs):
    v = stats.iqm(xs)
    assert min(xs) - 1e-9 <= v <= max(xs) + 1e-9
    if len(xs) >= 8:
        assert stats.iqm([*xs[:-1], 1e9]) <= max(xs) + 1e-6


@settings(max_examples=30, deadline=None)
@given(st.lists(st.floats(-200, 0), min_size=3, max_size=8), st.floats(1.5, 5))
def test_spread_measures_detect_a_wider_arm(xs, scale):
    if np.std(xs) < 1e-3:
        return
    wide = np.asarray(xs) * scale
    assert stats.std_difference(xs, wide, rng(), N_BOOT).value < 0
    assert math.isclose(stats.std_difference(wide, xs, rng(), N_BOOT).value, (scale - 1) * float(np.std(xs, ddof=1)),
                        rel_tol=1e-9)


def test_final_return_uses_last_window():
    assert stats.final_return(np.r_[np.full(50, -200.0), np.full(100, -100.0)], 100) == -100.0
    assert stats.final_return([-200.0, -100.0], 100) == -150.0


def test_mean_band_shapes_and_nan_where_seeds_missing():
    curves = np.array([[np.nan, -200, -150, -100], [-200, -200, -100, -100]], dtype=float)
    mean, low, high = stats.mean_band(curves, rng(), N_BOOT)
    assert mean.shape == low.shape == high.shape == (4,)
    assert mean[0] == -200 and np.isnan(low[0])
    assert low[1] == high[1] == -200
    assert low[2] <= mean[2] <= high[2]
