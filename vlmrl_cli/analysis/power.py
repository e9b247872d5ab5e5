"""Power of the study's verdict on censored steps, by simulation rather than a t-approximation.

A study's steps to a threshold are right-censored: a seed that never reaches it is a DNF at the
budget, and the verdict's test (``ranks.censored_rank_test``: Mann-Whitney U with DNF censored)
loses power as DNFs tie, which a normal approximation on log steps ignores. Here the data are
simulated as the analysis sees them:

* the reference arm's steps are log-normal with spread ``sd_log`` and a median placed so that a
  fraction ``reliability`` of seeds reach the threshold by the ``budget`` (``reference_median``);
* the other arm's steps are log-normal with its own spread ``sd_log_arm`` (default: the
  reference's) and the reference's median divided by the ``speedup``;
* a seed past the budget is a DNF (NaN);
* "faster" needs what the verdict rule needs (``censored.judge_speedup``): the rank test rejects
  at ``alpha / family`` (Holm's first step, so a lower bound on the power inside a family; Holm's
  later steps are less strict) and, with ``interval=True``, the verdict's interval of the ratio of
  restricted means (a DNF at the budget; ``censored.log_ratio_bounds``) lies above 1. The rank
  test here is its normal approximation (the verdict's is exact): a simulation of thousands of
  studies cannot afford the exact count at every step of a bisection.

All functions are pure; randomness comes in as an explicit generator; shapes are stated.
"""

from __future__ import annotations

import math
import warnings

import numpy as np
from scipy import stats as sps

from vlmrl_cli.analysis.censored import log_ratio_bounds
from vlmrl_cli.analysis.defaults import DEFAULT_POWER_N_BOOT

#: Simulated studies per power figure (Monte Carlo standard error at 80% power: about 0.013).
DEFAULT_N_SIMS = 1_000


def reference_median(reliability: float, sd_log: float, budget: float, n: int) -> float:
    """The median steps of a log-normal whose fraction ``reliability`` lies below ``budget``.

    A reliability of 1 (or 0) has no finite quantile: it is taken as ``1 - 0.5 / n`` (``0.5 / n``),
    half a seed short of all (none), the closest a sample of ``n`` seeds can tell apart.

    Example:
        >>> round(reference_median(0.5, 0.3, 100_000, 20))
        100000
        >>> reference_median(1.0, 0.3, 100_000, 20) < reference_median(0.9, 0.3, 100_000, 20)
        True
    """
    r = min(max(reliability, 0.5 / n), 1 - 0.5 / n)
    return float(budget * math.exp(-sd_log * sps.norm.ppf(r)))


def simulate_steps(rng: np.random.Generator, n_sims: int, n: int, median: float, sd_log: float,
                   budget: float) -> np.ndarray:
    """Steps to a threshold of ``n_sims`` simulated arms of ``n`` seeds: shape ``(n_sims, n)``,
    log-normal around ``median`` with spread ``sd_log``, NaN (a DNF) past ``budget``."""
    steps = median * np.exp(sd_log * rng.standard_normal((n_sims, n)))
    return np.where(steps <= budget, steps, np.nan)


def _rank_p(ref: np.ndarray, arm: np.ndarray) -> np.ndarray:
    """Two-sided Mann-Whitney p per row (shapes ``(n_sims, n)``), a DNF ranked above every finish
    and tied with the other DNFs, normal approximation with tie correction (as the verdict's test
    beyond its exact range)."""
    big = np.finfo(float).max
    a, b = np.where(np.isnan(arm), big, arm), np.where(np.isnan(ref), big, ref)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", RuntimeWarning)  # rows whose values all tie
        p = sps.mannwhitneyu(a, b, axis=1, alternative="two-sided", method="asymptotic").pvalue
    return np.where(np.isfinite(p), p, 1.0)


def _interval_above_one(ref: np.ndarray, arm: np.ndarray, budget: float, ci: float) -> np.ndarray:
    """Whether each row's interval of mean(ref) / mean(arm), DNF at the budget, lies above 1 (shape
    ``(n_sims,)``): the verdict's own interval (``censored.log_ratio_bounds``)."""
    low, _ = log_ratio_bounds(np.nan_to_num(ref, nan=budget), np.nan_to_num(arm, nan=budget), ci)
    return np.asarray(low > 1.0)


def censored_power(rng: np.random.Generator, speedup: float, n: int, sd_log: float, reliability: float,
                   budget: float, alpha: float = 0.05, family: int = 1, interval: bool = True,
                   n_sims: int = DEFAULT_N_SIMS, n_boot: int = DEFAULT_POWER_N_BOOT, ci: float = 0.95,
                   sd_log_arm: float | None = None) -> float:
    """The probability that a study of ``n`` seeds per arm calls an arm ``speedup`` times faster than
    the reference "faster" (module docstring), by ``n_sims`` simulated studies; ``sd_log`` is the
    reference's spread, ``sd_log_arm`` the arm's (None: the same). ``n_boot`` is unused (kept for callers).

    Example:
        >>> rng = np.random.default_rng(0)
        >>> weak = censored_power(rng, 1.1, 10, 0.3, 0.6, 300_000, n_sims=300)
        >>> strong = censored_power(np.random.default_rng(0), 2.0, 10, 0.3, 0.6, 300_000, n_sims=300)
        >>> weak < 0.5 < strong
        True
    """
    median = reference_median(reliability, sd_log, budget, n)
    ref = simulate_steps(rng, n_sims, n, median, sd_log, budget)
    arm = simulate_steps(rng, n_sims, n, median / speedup, sd_log if sd_log_arm is None else sd_log_arm, budget)
    called = _rank_p(ref, arm) < alpha / max(1, family)
    called &= np.nanmean(np.nan_to_num(ref, nan=budget), axis=1) > np.nanmean(np.nan_to_num(arm, nan=budget), axis=1)
    if interval:
        called &= _interval_above_one(ref, arm, budget, ci)
    return float(called.mean())


def detectable_speedup(seed: int, n: int, sd_log: float, reliability: float, budget: float, alpha: float = 0.05,
                       family: int = 1, power: float = 0.8, n_sims: int = DEFAULT_N_SIMS,
                       high: float = 4.0, sd_log_arm: float | None = None) -> float:
    """The smallest speedup that ``n`` seeds per arm call "faster" with ``power``, by bisection over
    ``[1, high]`` with the same simulated noise at every step (``seed``); ``inf`` when even ``high``
    is not detected (the budget censors too much to tell).

    Example:
        >>> few = detectable_speedup(0, 5, 0.3, 0.6, 300_000, n_sims=300)
        >>> many = detectable_speedup(0, 20, 0.3, 0.6, 300_000, n_sims=300)
        >>> 1 < many < few
        True
    """
    def power_at(s: float) -> float:
        return censored_power(np.random.default_rng(seed), s, n, sd_log, reliability, budget, alpha, family,
                              n_sims=n_sims, sd_log_arm=sd_log_arm)

    if power_at(high) < power:
        return math.inf
    lo, hi = 1.0, high
    while hi - lo > 0.01:
        mid = (lo + hi) / 2
        lo, hi = (lo, mid) if power_at(mid) >= power else (mid, hi)
    return hi


# --- reliability: Fisher's exact test, enumerated -------------------------------------------------

def fisher_power(p_a: float, p_b: float, n: int, alpha: float = 0.05) -> float:
    """Power of a two-sided Fisher exact test at ``alpha`` telling success rates ``p_a`` and ``p_b``
    apart with ``n`` seeds per arm (exact: every outcome pair enumerated).

    Example:
        >>> round(fisher_power(1.0, 0.6, 16), 2) >= 0.8 > round(fisher_power(1.0, 0.6, 10), 2)
        True
    """
    if n < 1:
        return math.nan
    ks = np.arange(n + 1)
    pa, pb = sps.binom.pmf(ks, n, p_a), sps.binom.pmf(ks, n, p_b)
    total = 0.0
    for i in ks:
        if pa[i] < 1e-12:
            continue
        for j in ks:
            if pb[j] < 1e-12:
                continue
            if sps.fisher_exact([[i, n - i], [j, n - j]]).pvalue < alpha:
                total += pa[i] * pb[j]
    return float(total)


def detectable_reliability(p_b: float, n: int, alpha: float = 0.05, power: float = 0.8) -> float | None:
    """The smallest reliability (on a 1% grid) that a two-sided Fisher exact test at ``alpha`` tells
    from ``p_b`` with ``power``, at ``n`` seeds per arm; None when not even 100% is detected. Found by
    bisection: above ``p_b`` the power grows with the other arm's reliability.

    Example:
        >>> detectable_reliability(0.0, 10), detectable_reliability(0.6, 10)
        (0.59, None)
    """
    lo, hi = math.floor(100 * p_b) + 1, 100  # percent
    if lo > hi or fisher_power(hi / 100, p_b, n, alpha) < power:
        return None
    while lo < hi:
        mid = (lo + hi) // 2
        if fisher_power(mid / 100, p_b, n, alpha) >= power:
            hi = mid
        else:
            lo = mid + 1
    return hi / 100


# --- one comparison's own reference: fitted with censoring, stated in restricted-mean ratios --------

def fit_censored_lognormal(steps: np.ndarray, budgets: np.ndarray) -> tuple[float, float] | None:
    """Maximum-likelihood ``(mu, sd)`` of log steps, a seed that did not finish (NaN, or past its
    budget) right-censored at its log budget (``scipy.stats.CensoredData``); None with fewer than
    two finished seeds, where the spread cannot be told.

    Example:
        >>> rng = np.random.default_rng(0)
        >>> steps = np.exp(11.0 + 0.3 * rng.standard_normal(4000))
        >>> budget = np.full(4000, np.exp(11.2))  # about 75% finish
        >>> mu, sd = fit_censored_lognormal(np.where(steps <= budget, steps, np.nan), budget)
        >>> round(mu, 1), round(sd, 1)
        (11.0, 0.3)
    """
    x, b = np.asarray(steps, dtype=float).reshape(-1), np.asarray(budgets, dtype=float).reshape(-1)
    done = np.isfinite(x) & (x <= b)
    if int(done.sum()) < 2 or float(np.ptp(np.log(x[done]))) == 0.0:
        return None
    data = sps.CensoredData(uncensored=np.log(x[done]), right=np.log(b[~done]))
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", RuntimeWarning)
        mu, sd = sps.norm.fit(data)
    return float(mu), float(sd)


def lognormal_reliability(mu: float, sd: float, budget: float) -> float:
    """The fraction of log-normal steps (log mean ``mu``, sd ``sd``) within ``budget``: the fitted
    reliability, the inverse of ``reference_median``.

    Example:
        >>> round(lognormal_reliability(math.log(reference_median(0.7, 0.3, 1e5, 20)), 0.3, 1e5), 6)
        0.7
    """
    return float(sps.norm.cdf((math.log(budget) - mu) / sd))


def restricted_mean_steps(mu: float, sd: float, budget: float) -> float:
    """``E[min(T, budget)]`` of log-normal steps ``T`` (log mean ``mu``, sd ``sd``): the tables'
    restricted mean, a DNF counted at the budget.

    Example:
        >>> round(restricted_mean_steps(math.log(1000.0), 1e-9, 10_000.0)), round(restricted_mean_steps(20.0, 0.3, 5.0))
        (1000, 5)
    """
    z = (math.log(budget) - mu) / sd
    below = math.exp(mu + sd * sd / 2) * float(sps.norm.cdf(z - sd))
    return below + budget * float(sps.norm.sf(z))


def restricted_ratio(mu: float, sd: float, budget: float, speedup: float, sd_arm: float | None = None) -> float:
    """The ratio of restricted means, reference over arm, when the arm's median is the reference's
    divided by ``speedup`` (a median ratio) and its spread is ``sd_arm`` (None: the reference's
    ``sd``): what the tables would show for that effect; the budget shrinks it towards 1.

    Example:
        >>> round(restricted_ratio(math.log(1000.0), 0.2, 1e9, 1.5), 3), restricted_ratio(20.0, 0.2, 100.0, 1.5)
        (1.5, 1.0)
    """
    arm_sd = sd if sd_arm is None else sd_arm
    return restricted_mean_steps(mu, sd, budget) / restricted_mean_steps(mu - math.log(speedup), arm_sd, budget)
