"""Power of the study's verdict on censored steps, by simulating studies as the analysis sees
them: log-normal steps, a DNF past the budget, "faster" when the rank test (its normal
approximation) rejects at Holm's first step and the verdict's interval lies above 1.
See docs/commands/study.md.
"""

from __future__ import annotations

import math
import warnings

import numpy as np
from scipy import stats as sps

from vlmrl_cli.analysis.censored import log_ratio_bounds

#: Simulated studies per power figure (Monte Carlo standard error at 80% power: about 0.013).
DEFAULT_N_SIMS = 1_000


def reference_median(reliability: float, sd_log: float, budget: float, n: int) -> float:
    """The median steps of a log-normal whose fraction ``reliability`` lies below ``budget``; a
    reliability of 1 (0) is taken as ``1 - 0.5 / n`` (``0.5 / n``), half a seed short of all (none).
    """
    r = min(max(reliability, 0.5 / n), 1 - 0.5 / n)
    return float(budget * math.exp(-sd_log * sps.norm.ppf(r)))


def simulate_steps(rng: np.random.Generator, n_sims: int, n: int, median: float, sd_log: float,
                   budget: float) -> np.ndarray:
    """Log-normal steps of ``n_sims`` simulated arms of ``n`` seeds, shape ``(n_sims, n)``, NaN past ``budget``."""
    steps = median * np.exp(sd_log * rng.standard_normal((n_sims, n)))
    return np.where(steps <= budget, steps, np.nan)


def _rank_p(ref: np.ndarray, arm: np.ndarray) -> np.ndarray:
    """Two-sided Mann-Whitney p per row, a DNF (NaN) tied above every finish, normal approximation."""
    big = np.finfo(float).max
    a, b = np.where(np.isnan(arm), big, arm), np.where(np.isnan(ref), big, ref)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", RuntimeWarning)  # rows whose values all tie
        p = sps.mannwhitneyu(a, b, axis=1, alternative="two-sided", method="asymptotic").pvalue
    return np.where(np.isfinite(p), p, 1.0)


def _interval_above_one(ref: np.ndarray, arm: np.ndarray, budget: float, ci: float) -> np.ndarray:
    """Whether each row's verdict interval of mean(ref) / mean(arm), a DNF at the budget, lies above 1."""
    low, _ = log_ratio_bounds(np.nan_to_num(ref, nan=budget), np.nan_to_num(arm, nan=budget), ci)
    return np.asarray(low > 1.0)


def censored_power(rng: np.random.Generator, speedup: float, n: int, sd_log: float, reliability: float,
                   budget: float, alpha: float = 0.05, family: int = 1, interval: bool = True,
                   n_sims: int = DEFAULT_N_SIMS, ci: float = 0.95, sd_log_arm: float | None = None) -> float:
    """The probability that a study of ``n`` seeds per arm calls an arm ``speedup`` times faster than
    the reference "faster", by ``n_sims`` simulated studies; ``sd_log_arm``: the arm's spread (None:
    the reference's ``sd_log``).
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
    """The smallest speedup that ``n`` seeds per arm call "faster" with ``power`` (bisection over
    ``[1, high]``, the same noise at every step); ``inf`` when even ``high`` is not detected.
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


def fisher_power(p_a: float, p_b: float, n: int, alpha: float = 0.05) -> float:
    """Power of a two-sided Fisher exact test telling rates ``p_a`` and ``p_b`` apart at ``n`` seeds per arm."""
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
    """The smallest reliability (1% grid, by bisection) that Fisher's exact test tells from ``p_b``
    with ``power`` at ``n`` seeds per arm; None when not even 100% is detected.
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


def fit_censored_lognormal(steps: np.ndarray, budgets: np.ndarray) -> tuple[float, float] | None:
    """Maximum-likelihood ``(mu, sd)`` of log steps, DNFs right-censored; None with < 2 distinct finishes.

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
    """The fraction of log-normal steps (log mean ``mu``, sd ``sd``) within ``budget``.

    Example:
        >>> round(lognormal_reliability(math.log(reference_median(0.7, 0.3, 1e5, 20)), 0.3, 1e5), 6)
        0.7
    """
    return float(sps.norm.cdf((math.log(budget) - mu) / sd))


def restricted_mean_steps(mu: float, sd: float, budget: float) -> float:
    """``E[min(T, budget)]`` of log-normal steps ``T``: the tables' restricted mean.

    Example:
        >>> round(restricted_mean_steps(math.log(1000.0), 1e-9, 10_000.0)), round(restricted_mean_steps(20.0, 0.3, 5.0))
        (1000, 5)
    """
    z = (math.log(budget) - mu) / sd
    below = math.exp(mu + sd * sd / 2) * float(sps.norm.cdf(z - sd))
    return below + budget * float(sps.norm.sf(z))


def restricted_ratio(mu: float, sd: float, budget: float, speedup: float, sd_arm: float | None = None) -> float:
    """The ratio of restricted means, reference over arm, for a median ratio ``speedup`` (the arm's
    spread ``sd_arm``, None: ``sd``): what the tables would show for that effect.
    """
    arm_sd = sd if sd_arm is None else sd_arm
    return restricted_mean_steps(mu, sd, budget) / restricted_mean_steps(mu - math.log(speedup), arm_sd, budget)
