"""Proportions over seeds: Wilson and Newcombe score intervals and Fisher's exact test, never a
bootstrap (it collapses to [1, 1] when every seed succeeds).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
import numpy.typing as npt
from scipy import stats as sps

from vlmrl_cli.analysis.defaults import DETACHED_SUCCESS_CUT
from vlmrl_cli.analysis.stats import Estimate, wilson_ci


@dataclass(frozen=True)
class ProportionComparison:
    """``k_a/n_a - k_b/n_b`` over seeds: the difference with its Newcombe interval and an exact p-value."""

    k_a: int
    n_a: int
    k_b: int
    n_b: int
    difference: Estimate
    p_value: float
    test: str = "Fisher exact, two-sided"


def newcombe_difference(k_a: int, n_a: int, k_b: int, n_b: int, ci: float = 0.95) -> Estimate:
    """``k_a/n_a - k_b/n_b`` with Newcombe's hybrid score interval (method 10 of Newcombe 1998, from
    the two Wilson intervals; it never collapses to a point).
    """
    if n_a <= 0 or n_b <= 0:
        return Estimate(float("nan"), n=int(min(n_a, n_b, 0)), note="an arm has no seeds")
    a, b = wilson_ci(k_a, n_a, ci), wilson_ci(k_b, n_b, ci)
    d = a.value - b.value
    low = d - math.hypot(a.value - a.low, b.high - b.value)
    high = d + math.hypot(a.high - a.value, b.value - b.low)
    return Estimate(float(d), float(max(-1.0, low)), float(min(1.0, high)), n=int(min(n_a, n_b)),
                    note=f"{k_a}/{n_a} vs {k_b}/{n_b} seeds; Newcombe hybrid score interval")


def exact_test(k_a: int, n_a: int, k_b: int, n_b: int) -> float:
    """Two-sided Fisher exact p-value for ``k_a/n_a`` vs ``k_b/n_b`` (1.0 when both arms agree entirely)."""
    if n_a <= 0 or n_b <= 0:
        return float("nan")
    table = [[int(k_a), int(n_a - k_a)], [int(k_b), int(n_b - k_b)]]
    return float(sps.fisher_exact(table, alternative="two-sided").pvalue)


def compare_proportions(a: npt.ArrayLike, b: npt.ArrayLike, ci: float = 0.95) -> ProportionComparison:
    """Compare two arms' per-seed successes (bool arrays of shape ``(n_a,)``, ``(n_b,)``; NaN dropped)."""
    xa, xb = _bools(a), _bools(b)
    ka, na, kb, nb = int(xa.sum()), int(xa.size), int(xb.sum()), int(xb.size)
    return ProportionComparison(ka, na, kb, nb, newcombe_difference(ka, na, kb, nb, ci), exact_test(ka, na, kb, nb))


def _bools(values: npt.ArrayLike) -> np.ndarray:
    x = np.asarray(values, dtype=float).reshape(-1)
    return x[np.isfinite(x)] > 0.5


def detached_successes(success_rates: npt.ArrayLike, cut: float = DETACHED_SUCCESS_CUT) -> np.ndarray:
    """Per seed, 1.0 when its share of successful detached episodes is at least ``cut``, else 0.0 (NaN kept)."""
    r = np.asarray(success_rates, dtype=float).reshape(-1)
    return np.where(np.isfinite(r), (r >= cut).astype(float), np.nan)
