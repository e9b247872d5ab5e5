"""Rank-based comparisons of two arms over seeds: the censored rank test (a DNF tied with every
other DNF and above every finish, by ``censored.reached``), probability of improvement, profile.
"""

from __future__ import annotations

import math
import warnings
from dataclasses import dataclass

import numpy as np
import numpy.typing as npt
from scipy import stats as sps

from vlmrl_cli.analysis.aggregate import p_greater
from vlmrl_cli.analysis.censored import reached
from vlmrl_cli.analysis.defaults import DEFAULT_N_PERM
from vlmrl_cli.analysis.stats import DEFAULT_N_BOOT, Estimate, bootstrap_ci


@dataclass(frozen=True)
class RankTest:
    """A two-sided Mann-Whitney U test of arm ``a`` vs arm ``b`` on censored steps; ``p_faster`` =
    ``1 - U/(n_a n_b)``, above 0.5 favours ``a``."""

    u: float
    p_value: float
    p_faster: float
    n_a: int
    n_b: int
    n_dnf_a: int
    n_dnf_b: int
    note: str = ""
    method: str = "exact"  # "exact" (every split counted) or "asymptotic" (normal, tie-corrected)


def censor(steps: npt.ArrayLike, budget: npt.ArrayLike | None = None) -> np.ndarray:
    """Steps (shape ``(n,)``) with each DNF by ``censored.reached`` (None: no budget known) as ``+inf``.

    Example:
        >>> censor([100.0, float("nan"), 1200.0], 1000)
        array([100.,  inf,  inf])
    """
    x = np.asarray(steps, dtype=float).reshape(-1)
    return np.where(reached(x, np.inf if budget is None else budget), x, np.inf)


def _single_budget(budget: npt.ArrayLike | None) -> float | None:
    """The one budget of an arm's seeds, or None when unknown or not shared."""
    if budget is None:
        return None
    values = set(np.asarray(budget, dtype=float).reshape(-1).tolist())
    return values.pop() if len(values) == 1 else None


def censored_rank_test(
    steps_a: npt.ArrayLike, steps_b: npt.ArrayLike, n_perm: int = DEFAULT_N_PERM,
    budget_a: npt.ArrayLike | None = None, budget_b: npt.ArrayLike | None = None,
) -> RankTest:
    """Mann-Whitney U test on steps (shapes ``(n_a,)``, ``(n_b,)``, NaN = DNF) with each DNF censored
    at its budget (``censor``), the p exact up to ``n_perm`` splits (``rank_sum_p``). The note
    says when the budgets differ (a DNF only exceeds its own budget).
    """
    a, b = censor(steps_a, budget_a), censor(steps_b, budget_b)
    dnf_a, dnf_b = int(np.isinf(a).sum()), int(np.isinf(b).sum())
    if a.size == 0 or b.size == 0:
        return RankTest(float("nan"), float("nan"), float("nan"), int(a.size), int(b.size), dnf_a, dnf_b,
                        "an arm has no seeds")
    notes = []
    one_a, one_b = _single_budget(budget_a), _single_budget(budget_b)
    if budget_a is not None and budget_b is not None and (one_a is None or one_b is None or one_a != one_b):
        shown = f" ({one_a:g} vs {one_b:g})" if one_a is not None and one_b is not None else ""
        notes.append(f"budgets differ{shown}: a DNF is only known to exceed its own budget")
    note = "; ".join(notes)
    # U of a: pairs where a needs more steps, ties (DNF with DNF) counted half
    u = float(np.sum((a[:, None] > b[None, :]) + 0.5 * (a[:, None] == b[None, :])))
    if a.size < 2 or b.size < 2:
        return RankTest(u, float("nan"), 1.0 - u / (a.size * b.size), int(a.size), int(b.size), dnf_a, dnf_b,
                        "; ".join([*notes, "fewer than 2 seeds in an arm: no test"]))
    p, method = rank_sum_p(a, b, n_perm)
    return RankTest(u, p, 1.0 - u / (a.size * b.size), int(a.size), int(b.size), dnf_a, dnf_b, note, method)


def rank_sum_p(x: npt.ArrayLike, y: npt.ArrayLike, n_perm: int = DEFAULT_N_PERM) -> tuple[float, str]:
    """The two-sided Wilcoxon-Mann-Whitney p of ``x`` vs ``y`` (at least 2 each; ``+inf`` allowed)
    and its method: ``"exact"`` up to ``n_perm`` splits, else ``"asymptotic"`` (normal, tie-corrected).

    Example:
        >>> rank_sum_p([1.0, 2.0], [3.0, 4.0])
        (0.3333333333333333, 'exact')
    """
    a, b = np.asarray(x, dtype=float).reshape(-1), np.asarray(y, dtype=float).reshape(-1)
    if math.comb(int(a.size + b.size), int(a.size)) <= n_perm:
        return min(1.0, exact_rank_sum_p(a, b)), "exact"
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", RuntimeWarning)  # all values tied
        # an infinite DNF is a rank above every finish either way; the normal approximation needs finite values
        finite_a, finite_b = (np.where(np.isinf(v), np.finfo(float).max, v) for v in (a, b))
        res = sps.mannwhitneyu(finite_a, finite_b, alternative="two-sided", method="asymptotic")
    return (min(1.0, float(res.pvalue)) if np.isfinite(res.pvalue) else 1.0), "asymptotic"


def exact_rank_sum_p(x: npt.ArrayLike, y: npt.ArrayLike) -> float:
    """The exact two-sided permutation p of the Wilcoxon-Mann-Whitney test (midranks), conditional
    on the ties: ``min(1, 2 min(P(R <= r), P(R >= r)))`` for the rank sum ``R`` of ``x`` over every
    split, counted by dynamic programming over the doubled midranks (``C(n_x + n_y, n_x)`` must fit
    int64). ``+inf`` allowed, NaN not.
    """
    a, b = np.asarray(x, dtype=float).reshape(-1), np.asarray(y, dtype=float).reshape(-1)
    if np.isnan(a).any() or np.isnan(b).any():
        raise ValueError("censor the steps first: NaN has no rank")
    n_a, n = int(a.size), int(a.size + b.size)
    if n_a == 0 or n_a == n:
        return float("nan")
    ranks2 = np.rint(2 * sps.rankdata(np.concatenate([a, b]))).astype(np.int64)  # midranks are halves
    top = int(ranks2.sum())
    # counts[k, s]: subsets of size k of the values seen so far whose doubled ranks sum to s
    counts = np.zeros((n_a + 1, top + 1), dtype=np.int64)
    counts[0, 0] = 1
    for r in ranks2.tolist():
        shifted = np.zeros_like(counts)
        shifted[1:, r:] = counts[:-1, : top + 1 - r]
        counts += shifted
    dist = counts[n_a]
    total = float(dist.sum())
    observed = int(ranks2[:n_a].sum())
    lower, upper = float(dist[: observed + 1].sum()) / total, float(dist[observed:].sum()) / total
    return float(min(1.0, 2 * min(lower, upper)))


def probability_of_improvement(
    x: npt.ArrayLike, y: npt.ArrayLike, rng: np.random.Generator, n_boot: int = DEFAULT_N_BOOT, ci: float = 0.95
) -> Estimate:
    """P(X > Y) + P(X = Y)/2 for a random seed of each arm (NaN dropped), with a descriptive bootstrap CI."""
    a, b = np.asarray(x, dtype=float).reshape(-1), np.asarray(y, dtype=float).reshape(-1)
    a, b = a[np.isfinite(a)], b[np.isfinite(b)]
    if a.size == 0 or b.size == 0:
        return Estimate(float("nan"), note="an arm has no values")
    value = float(p_greater(a, b))
    n = int(min(a.size, b.size))
    if n < 2:
        return Estimate(value, n=n, note="fewer than 2 seeds: no CI")
    low, high = bootstrap_ci((a, b), p_greater, rng, n_boot, ci)
    note = "every resample gives the same value (degenerate bootstrap)" if low == high else ""
    return Estimate(value, low, high, n=n, note=note)


def performance_profile(values: npt.ArrayLike, taus: npt.ArrayLike) -> np.ndarray:
    """Fraction of seeds (NaN dropped) whose score is at least each ``tau``: shape ``(n_taus,)``."""
    v = np.asarray(values, dtype=float).reshape(-1)
    v = v[np.isfinite(v)]
    t = np.asarray(taus, dtype=float).reshape(-1)
    if v.size == 0:
        return np.full(t.shape, np.nan)
    return np.asarray(np.mean(v[None, :] >= t[:, None], axis=1), dtype=float)
