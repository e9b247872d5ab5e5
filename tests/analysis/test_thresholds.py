from __future__ import annotations

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from vlmrl_cli.analysis.censored import restricted
from vlmrl_cli.analysis.thresholds import (
    full_window_steps_to_threshold,
    rolling_mean_return,
    steps_to_threshold,
)


def test_reached_exactly_counts():
    # window 2: means -200, -150, -130 -> -130 reached exactly at step 300
    assert steps_to_threshold([100, 200, 300], [-200, -100, -160], -130, window=2) == 300


def test_dnf_is_none_and_censored_at_budget():
    ts, ret = [100, 200, 300], [-200, -200, -150]
    assert steps_to_threshold(ts, ret, -130, window=2) is None
    assert restricted([np.nan], 1000).tolist() == [1000.0]  # the DNF counts at the budget
    assert steps_to_threshold(ts, ret, -190, window=2) == 300


def test_window_longer_than_run_uses_partial_mean_by_default():
    ts, ret = [10, 20, 30], [-200, -100, -120]  # running means -200, -150, -140
    assert steps_to_threshold(ts, ret, -150, window=100) == 20
    assert steps_to_threshold(ts, ret, -150, window=100, min_episodes=100) is None
    assert steps_to_threshold(ts, ret, -150, window=3, min_episodes=3) == 30


def test_ties_use_window_after_all_episodes_at_that_step():
    # at step 20 two episodes end: after the first the mean (window 2) would be -100, after both -150
    ts, ret = [10, 20, 20], [-100, -100, -200]
    assert steps_to_threshold(ts, ret, -100, window=2) == 10
    # window 1: the middle episode alone (-100) would pass -120, but the last one at step 20 (-200) decides
    assert steps_to_threshold([10, 20, 20], [-200, -100, -200], -120, window=1) is None
    steps, mean = rolling_mean_return(ts, ret, window=2)
    assert steps.tolist() == [10, 20] and mean.tolist() == [-100.0, -150.0]


def test_unsorted_input_is_sorted_by_timestep():
    assert steps_to_threshold([300, 100, 200], [-100, -200, -200], -150, window=2) == 300


def test_empty_run_and_bad_arguments():
    assert steps_to_threshold([], [], -130) is None
    with pytest.raises(ValueError):
        steps_to_threshold([1, 2], [1.0], -130)
    with pytest.raises(ValueError):
        steps_to_threshold([1], [1.0], -130, window=0)
    with pytest.raises(ValueError):
        steps_to_threshold([1], [1.0], -130, window=5, min_episodes=6)


@st.composite
def runs(draw: st.DrawFn) -> tuple[np.ndarray, np.ndarray]:
    n = draw(st.integers(1, 60))
    gaps = draw(st.lists(st.integers(0, 300), min_size=n, max_size=n))  # 0 gaps make ties
    returns = draw(st.lists(st.integers(-200, -80), min_size=n, max_size=n))
    return np.cumsum(np.asarray(gaps) + 0) + 1, np.asarray(returns, dtype=float)


def _key(s: int | None) -> float:
    return float("inf") if s is None else float(s)


@settings(max_examples=150, deadline=None)
@given(runs(), st.integers(-200, -80), st.integers(0, 60), st.integers(1, 20))
def test_lower_threshold_is_never_reached_later(run, threshold, delta, window):
    ts, ret = run
    high = steps_to_threshold(ts, ret, threshold, window)
    low = steps_to_threshold(ts, ret, threshold - delta, window)
    assert _key(low) <= _key(high)


@settings(max_examples=150, deadline=None)
@given(runs(), st.integers(-200, -80), st.integers(0, 50), st.integers(1, 20))
def test_shifting_returns_up_never_delays(run, threshold, shift, window):
    ts, ret = run
    assert _key(steps_to_threshold(ts, ret + shift, threshold, window)) <= _key(
        steps_to_threshold(ts, ret, threshold, window))


@settings(max_examples=100, deadline=None)
@given(runs(), st.integers(-200, -80), st.integers(1, 20))
def test_result_is_an_episode_end_and_censoring_bounds(run, threshold, window):
    ts, ret = run
    s = steps_to_threshold(ts, ret, threshold, window)
    budget = int(ts.max()) + 1
    c = restricted([np.nan if s is None else s], budget)[0]
    if s is None:
        assert c == budget
    else:
        assert s in set(ts.tolist()) and c == s


def test_full_window_ignores_a_lucky_start():
    # window 3: the partial window of the first episode alone (-100) meets -150 at step 10; the first
    # complete window (-100, -200, -150) has mean -150 at step 30, the next (-200, -150, -40) -130 at 40
    ts, ret = [10, 20, 30, 40], [-100, -200, -150, -40]
    assert steps_to_threshold(ts, ret, -150, window=3) == 10
    assert full_window_steps_to_threshold(ts, ret, -150, window=3) == 30
    assert steps_to_threshold(ts, ret, -140, window=3) == 10
    assert full_window_steps_to_threshold(ts, ret, -140, window=3) == 40
    assert full_window_steps_to_threshold(ts[:2], ret[:2], -100, window=3) is None  # never a complete window
