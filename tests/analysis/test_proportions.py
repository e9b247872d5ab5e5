from __future__ import annotations

import math

import numpy as np
import pytest
from hypothesis import given
from hypothesis import strategies as st

from vlmrl_cli.analysis.proportions import (
    compare_proportions,
    detached_successes,
    exact_test,
    newcombe_difference,
)
from vlmrl_cli.analysis.stats import wilson_ci

Z = 1.959963984540054  # the 97.5% normal quantile


def _wilson_by_hand(k: int, n: int) -> tuple[float, float]:
    p = k / n
    centre = (p + Z**2 / (2 * n)) / (1 + Z**2 / n)
    half = Z / (1 + Z**2 / n) * math.sqrt(p * (1 - p) / n + Z**2 / (4 * n**2))
    return centre - half, centre + half


def test_wilson_for_0_of_5_and_5_of_5() -> None:
    e = wilson_ci(0, 5)
    assert e.value == 0.0 and e.low == pytest.approx(0.0, abs=1e-12) and e.high == pytest.approx(0.4345, abs=1e-4)
    assert (e.low, e.high) == pytest.approx(_wilson_by_hand(0, 5))
    assert wilson_ci(5, 5).low == pytest.approx(1 - 0.4345, abs=1e-4)


def test_newcombe_5_of_5_vs_5_of_5_is_about_plus_minus_0_43() -> None:
    e = newcombe_difference(5, 5, 5, 5)
    assert e.value == 0.0
    assert e.low == pytest.approx(-0.4345, abs=1e-4) and e.high == pytest.approx(0.4345, abs=1e-4)
    assert e.low < -0.4 and e.high > 0.4 and e.has_ci  # never the point [0, 0]


def test_newcombe_5_of_5_vs_3_of_5_from_the_wilson_limits() -> None:
    la, ua = _wilson_by_hand(5, 5)  # (0.5655, 1.0)
    lb, ub = _wilson_by_hand(3, 5)  # (0.2307, 0.8824)
    d = 1.0 - 0.6
    low = d - math.sqrt((1.0 - la) ** 2 + (ub - 0.6) ** 2)
    high = d + math.sqrt((ua - 1.0) ** 2 + (0.6 - lb) ** 2)
    e = newcombe_difference(5, 5, 3, 5)
    assert e.value == pytest.approx(0.4)
    assert (e.low, e.high) == pytest.approx((low, high), abs=1e-9)
    assert (e.low, e.high) == pytest.approx((-0.1182, 0.7693), abs=1e-3)


@given(st.integers(1, 30), st.integers(1, 30), st.data())
def test_newcombe_holds_the_difference_and_is_antisymmetric(n_a: int, n_b: int, data: st.DataObject) -> None:
    k_a, k_b = data.draw(st.integers(0, n_a)), data.draw(st.integers(0, n_b))
    e, r = newcombe_difference(k_a, n_a, k_b, n_b), newcombe_difference(k_b, n_b, k_a, n_a)
    assert -1.0 <= e.low < e.value + 1e-12 and e.value - 1e-12 < e.high <= 1.0
    assert e.high - e.low > 0.0
    assert (e.low, e.high) == pytest.approx((-r.high, -r.low))


def test_fisher_exact_by_hand() -> None:
    # 5/5 vs 0/5: only the observed table is as extreme in each tail: 2 / C(10, 5)
    assert exact_test(5, 5, 0, 5) == pytest.approx(2 / math.comb(10, 5))
    assert exact_test(5, 5, 5, 5) == 1.0
    # 5/5 vs 3/5 (8 successes in 10): P(table) = C(5,5)C(5,3)/C(10,8) = 10/45; the other tail 3/5 vs 5/5 too
    assert exact_test(5, 5, 3, 5) == pytest.approx(20 / 45)


def test_compare_proportions_counts_seeds_and_drops_nan() -> None:
    c = compare_proportions([1.0, 1.0, 1.0, np.nan], [1.0, 0.0, 0.0])
    assert (c.k_a, c.n_a, c.k_b, c.n_b) == (3, 3, 1, 3)
    assert c.difference.value == pytest.approx(2 / 3) and 0 < c.p_value <= 1


def test_detached_success_cut_is_inclusive() -> None:
    assert detached_successes([0.9, 0.89], cut=0.9).tolist() == [1.0, 0.0]
