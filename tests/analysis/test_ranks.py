from __future__ import annotations

import math
from itertools import combinations

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from vlmrl_cli.analysis.ranks import (
    censored_rank_test,
    exact_rank_sum_p,
    performance_profile,
    probability_of_improvement,
)


def _rng() -> np.random.Generator:
    return np.random.default_rng(0)


def test_dnf_is_kept_as_the_slowest_not_dropped() -> None:
    # a: 3 finished seeds; b: 1 finished (faster than all of a) and 2 DNF. Dropping the DNF would
    # make b look faster; censored, b's DNF seeds are slower than every seed of a.
    a = [200.0, 210.0, 220.0]
    b = [100.0, np.nan, np.nan]
    t = censored_rank_test(a, b, budget_a=1000, budget_b=1000)
    # U counts pairs with a_i > b_j (a slower) plus half the ties: every a is slower than b's 100 only: U = 3
    assert t.u == 3.0 and t.p_faster == pytest.approx(1 - 3 / 9)
    assert (t.n_dnf_a, t.n_dnf_b) == (0, 2) and t.note == ""
    # exact permutation p: of the C(6,3) = 20 splits, those with U <= 3 or U >= 6 (|U - 4.5| >= 1.5)
    values = np.array([200, 210, 220, 100, np.inf, np.inf])
    us = []
    for idx in combinations(range(6), 3):
        x = values[list(idx)]
        y = np.delete(values, list(idx))
        us.append(float(np.sum((x[:, None] > y[None, :]) + 0.5 * (x[:, None] == y[None, :]))))
    expected = np.mean(np.abs(np.array(us) - 4.5) >= 1.5 - 1e-12)
    assert t.p_value == pytest.approx(expected)


def test_all_dnf_on_both_sides_is_no_evidence() -> None:
    t = censored_rank_test([np.nan] * 5, [np.nan] * 5)
    assert t.p_value == 1.0 and t.p_faster == 0.5


def test_complete_separation_of_five_vs_five_is_exact() -> None:
    t = censored_rank_test([1.0, 2, 3, 4, 5], [6.0, 7, 8, 9, np.nan])
    assert t.p_faster == 1.0 and t.p_value == pytest.approx(2 / math.comb(10, 5))


def test_different_budgets_and_single_seeds_are_noted() -> None:
    t = censored_rank_test([1.0], [np.nan, 3.0], budget_a=10, budget_b=20)
    assert "budgets differ" in t.note and "no test" in t.note and np.isnan(t.p_value) and t.p_faster == 1.0


def test_probability_of_improvement_by_hand_and_its_interval() -> None:
    # pairs (x > y): 3>1 yes, 3=3 half, 4>1, 4>3 -> (1 + 0.5 + 1 + 1) / 4
    e = probability_of_improvement([3.0, 4.0, 4.0], [1.0, 3.0, 3.0], _rng(), n_boot=200)
    assert e.value == pytest.approx((1 + 0.5 + 0.5 + 1 + 1 + 1 + 1 + 1 + 1) / 9)
    assert e.low <= e.value <= e.high
    sep = probability_of_improvement([5.0, 6.0], [1.0, 2.0], _rng(), n_boot=100)
    assert sep.value == 1.0 and "degenerate" in sep.note


@settings(max_examples=50, deadline=None)
@given(st.lists(st.floats(-200, -80), min_size=1, max_size=8), st.lists(st.floats(-200, -80), min_size=1,
                                                                         max_size=8))
def test_probability_of_improvement_is_complementary(x: list[float], y: list[float]) -> None:
    a = probability_of_improvement(x, y, _rng(), n_boot=20).value
    b = probability_of_improvement(y, x, _rng(), n_boot=20).value
    assert a + b == pytest.approx(1.0)


@given(st.lists(st.floats(-200, -80), min_size=1, max_size=10))
def test_performance_profile_falls_from_one_to_zero(values: list[float]) -> None:
    taus = np.linspace(-201, -79, 30)
    p = performance_profile(values, taus)
    assert p[0] == 1.0 and p[-1] == 0.0 and np.all(np.diff(p) <= 0)


def test_a_crossing_after_the_budget_is_a_dnf_in_the_rank_test() -> None:
    # issue 51: three seeds crossed after the 100,000-step budget (reached = False). They are DNFs,
    # tied with the other DNF, not finishes ranked below it.
    budget = 100_000.0
    over = [100_240.0, 100_416.0, 101_200.0, np.nan]
    same_as_dnf = [np.nan] * 4
    finished = [50_000.0, 60_000.0, 70_000.0, 80_000.0]
    t_over = censored_rank_test(finished, over, budget_a=budget, budget_b=budget)
    t_nan = censored_rank_test(finished, same_as_dnf, budget_a=budget, budget_b=budget)
    assert t_over.n_dnf_b == 4
    assert (t_over.u, t_over.p_value) == (t_nan.u, t_nan.p_value)
    # among the DNFs of b, the over-budget crossings and the NaN are tied: U of b vs a DNF-only arm is 8
    t_b = censored_rank_test(over, [np.nan, np.nan], budget_a=budget, budget_b=budget)
    assert t_b.u == 4.0 and t_b.p_faster == 0.5


def _scipy_exact(x: np.ndarray, y: np.ndarray) -> float:
    from scipy import stats as sps

    def rank_sum(u: np.ndarray, v: np.ndarray, axis: int = -1) -> np.ndarray:
        pooled = np.concatenate([u, v], axis=axis)
        return np.sum(sps.rankdata(pooled, axis=axis)[..., : u.shape[axis]], axis=axis)

    return float(sps.permutation_test((x, y), rank_sum, permutation_type="independent", n_resamples=np.inf,
                                      vectorized=True, alternative="two-sided").pvalue)


@settings(max_examples=40, deadline=None)
@given(st.lists(st.sampled_from([1.0, 2.0, 3.0, 5.0, 8.0, np.inf]), min_size=2, max_size=6),
       st.lists(st.sampled_from([1.0, 2.0, 3.0, 5.0, 8.0, np.inf]), min_size=2, max_size=6))
def test_the_exact_p_is_scipys_full_enumeration(x: list[float], y: list[float]) -> None:
    # ties (DNFs at +inf among them) included: the counted distribution is scipy's enumerated one
    a, b = np.array(x), np.array(y)
    assert exact_rank_sum_p(a, b) == pytest.approx(_scipy_exact(a, b), abs=1e-12)


def test_the_exact_p_is_scipys_exact_mann_whitney_without_ties() -> None:
    from scipy import stats as sps

    rng = np.random.default_rng(5)
    for _ in range(20):
        a, b = rng.normal(size=7), rng.normal(0.8, size=9)
        assert exact_rank_sum_p(a, b) == pytest.approx(sps.mannwhitneyu(a, b, method="exact").pvalue, rel=1e-9)


def test_ten_vs_ten_is_exact_where_the_normal_approximation_is_not() -> None:
    # issue 51: complete separation at 10 vs 10 is 2 / C(20, 10) = 1.1e-5, not the normal 0.00018;
    # heavy DNF ties: 1 finish and 9 DNF against 10 DNF is 1.0 exactly
    sep = censored_rank_test(list(range(1, 11)), [np.nan] * 10)
    assert sep.method == "exact" and sep.p_value == pytest.approx(2 / math.comb(20, 10))
    ties = censored_rank_test([5.0] + [np.nan] * 9, [np.nan] * 10)
    assert ties.method == "exact" and ties.p_value == 1.0


def test_beyond_the_counted_splits_the_test_says_it_is_approximate() -> None:
    t = censored_rank_test(list(range(1, 11)), [np.nan] * 10, n_perm=1000)
    assert t.method == "asymptotic" and t.p_value > 2 / math.comb(20, 10)
