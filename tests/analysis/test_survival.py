"""The log-rank test: the textbook example, symmetry, censoring at the budget."""

from __future__ import annotations

import math

import numpy as np
import pytest
from hypothesis import given
from hypothesis import strategies as st

from vlmrl_cli.analysis.survival import censored_logrank, logrank_test

# Freireich et al. (1963), remission weeks of acute leukaemia, 6-MP vs placebo (Gehan 1965's data);
# Kleinbaum & Klein, Survival Analysis (3rd ed.), ch. 2: log-rank chi-square 16.79 (1 df), placebo
# observed 21 vs expected 10.75, variance 6.2570.
SIX_MP = [6, 6, 6, 7, 10, 13, 16, 22, 23, 6, 9, 10, 11, 17, 19, 20, 25, 32, 32, 34, 35]
SIX_MP_EVENT = [True] * 9 + [False] * 12
PLACEBO = [1, 1, 2, 2, 3, 4, 4, 5, 5, 8, 8, 8, 8, 11, 11, 12, 12, 15, 17, 22, 23]


def test_the_freireich_example_gives_the_published_values() -> None:
    t = logrank_test(PLACEBO, [True] * 21, SIX_MP, SIX_MP_EVENT)
    assert t.statistic == pytest.approx(16.79, abs=0.005)
    assert t.observed_a == 21 and t.expected_a == pytest.approx(10.75, abs=0.005)
    assert t.variance == pytest.approx(6.2570, abs=5e-4)
    assert t.p_value == pytest.approx(4.17e-5, rel=0.01) and t.direction == 1  # placebo relapses sooner


STEPS = st.lists(st.one_of(st.integers(1, 1200).map(float), st.just(math.nan)), min_size=1, max_size=12)


@given(STEPS, STEPS)
def test_swapping_the_arms_keeps_the_statistic_and_flips_the_direction(a: list[float], b: list[float]) -> None:
    ab, ba = censored_logrank(a, b, 1000, 1000), censored_logrank(b, a, 1000, 1000)
    if math.isnan(ab.statistic):
        assert math.isnan(ba.statistic)
        return
    assert ab.statistic == pytest.approx(ba.statistic) and ab.p_value == pytest.approx(ba.p_value)
    assert ab.direction == -ba.direction
    assert 0.0 <= ab.p_value <= 1.0


@given(STEPS, STEPS)
def test_a_dnf_is_the_same_as_a_finish_past_the_budget(a: list[float], b: list[float]) -> None:
    late = [1500.0 if math.isnan(x) else x for x in a]
    one, other = censored_logrank(a, b, 1000, 1000), censored_logrank(late, b, 1000, 1000)
    assert one.statistic == pytest.approx(other.statistic, nan_ok=True)


def test_every_seed_finishing_at_one_step_gives_no_evidence() -> None:
    t = censored_logrank([5000.0] * 4, [5000.0] * 6, 300_000, 300_000)
    assert (t.statistic, t.p_value, t.direction) == (0.0, 1.0, 0)


def test_identical_arms_give_no_evidence() -> None:
    t = censored_logrank([100.0, 200.0, np.nan], [100.0, 200.0, np.nan], 1000, 1000)
    assert t.statistic == pytest.approx(0.0) and t.p_value == pytest.approx(1.0) and t.direction == 0


def test_nothing_to_compare_is_nan_with_a_note() -> None:
    assert "no seed reached" in censored_logrank([np.nan] * 3, [np.nan] * 3, 1000, 1000).note
    assert "no seeds" in censored_logrank([], [1.0], 1000, 1000).note
    with pytest.raises(ValueError, match="one event flag"):
        logrank_test([1.0, 2.0], [True], [1.0], [True])


def test_a_dnf_of_a_shorter_budget_is_censored_at_its_own_budget() -> None:
    # arm a ran 500 steps and never finished; b finished at 600-900: a's seeds left the risk set at
    # 500, before any event, so nothing is known against a (the rank test would call a slower)
    t = censored_logrank([np.nan] * 4, [600.0, 700.0, 800.0, 900.0], 500, 1000)
    assert t.p_value == 1.0 and t.direction == 0 and "no variance" in t.note
