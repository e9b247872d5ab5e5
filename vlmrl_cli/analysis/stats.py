"""Statistics over seeds: percentile bootstrap intervals (``scipy.stats.bootstrap``; BCa is often
undefined at 3-10 seeds), each arm's seeds resampled independently; Wilson intervals for proportions.
An interval that cannot be computed has NaN bounds and ``Estimate.note`` says why.
"""

from __future__ import annotations

import hashlib
import warnings
from collections.abc import Callable
from dataclasses import dataclass

import numpy as np
import numpy.typing as npt
from scipy import stats as sps

from vlmrl_cli.analysis.defaults import DEFAULT_N_BOOT


@dataclass(frozen=True)
class Streams:
    """Independent random streams keyed by name: ``Streams(seed)(key)`` depends only on the seed
    and the key, so adding a metric changes no other metric's interval.

    Example:
        >>> s = Streams(0)
        >>> bool(s("a").random() == s("a").random()), bool(s("a").random() == s("b").random())
        (True, False)
    """

    seed: int

    def __call__(self, key: str) -> np.random.Generator:
        words = np.frombuffer(hashlib.sha256(key.encode("utf-8")).digest()[:16], dtype=np.uint32)
        return np.random.default_rng(np.random.SeedSequence([int(self.seed), *map(int, words)]))


def stream(rng: np.random.Generator | Streams, key: str) -> np.random.Generator:
    """The generator for ``key``: the keyed stream of ``Streams``, or ``rng`` itself when one generator is shared."""
    return rng(key) if isinstance(rng, Streams) else rng


@dataclass(frozen=True)
class Estimate:
    """A point estimate with a two-sided confidence interval (NaN bounds when not computable)."""

    value: float
    low: float = float("nan")
    high: float = float("nan")
    n: int = 0
    note: str = ""

    @property
    def has_ci(self) -> bool:
        return bool(np.isfinite(self.low) and np.isfinite(self.high))


@dataclass(frozen=True)
class StepsSummary:
    """Steps to one threshold over one arm's seeds: ``mean``/``median`` over the seeds that reached
    it (the paper's convention); ``censored_mean`` counts a DNF at its budget."""

    n: int
    n_reached: int
    mean: Estimate
    median: float
    censored_mean: float
    std: float
    iqr: float


def _finite(values: npt.ArrayLike) -> np.ndarray:
    arr = np.asarray(values, dtype=float).reshape(-1)
    return arr[np.isfinite(arr)]


def bootstrap_ci(
    samples: tuple[np.ndarray, ...],
    statistic: Callable[..., np.ndarray],
    rng: np.random.Generator,
    n_boot: int = DEFAULT_N_BOOT,
    ci: float = 0.95,
    paired: bool = False,
) -> tuple[float, float]:
    """Percentile bootstrap ``(low, high)`` of ``statistic(*samples)`` (vectorised, ``axis=-1``), each
    sample (shape ``(n_i,)``, ``n_i >= 2``) resampled independently unless ``paired``; NaN where undefined."""
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")  # degenerate samples (all equal) warn but are fine here
        res = sps.bootstrap(samples, statistic, n_resamples=n_boot, confidence_level=ci, method="percentile",
                            vectorized=True, paired=paired, axis=-1, rng=rng)
    return float(res.confidence_interval.low), float(res.confidence_interval.high)


def mean_ci(values: npt.ArrayLike, rng: np.random.Generator, n_boot: int = DEFAULT_N_BOOT, ci: float = 0.95
            ) -> Estimate:
    """Mean of ``values`` (shape ``(n,)``, NaN ignored) with a bootstrap CI."""
    x = _finite(values)
    if x.size == 0:
        return Estimate(float("nan"), n=0, note="no values")
    if x.size < 2:
        return Estimate(float(x.mean()), n=1, note="n=1: no CI")
    low, high = bootstrap_ci((x,), np.mean, rng, n_boot, ci)
    return Estimate(float(x.mean()), low, high, n=int(x.size))


def summarize_steps(
    steps: npt.ArrayLike, budget: npt.ArrayLike, rng: np.random.Generator, n_boot: int = DEFAULT_N_BOOT,
    ci: float = 0.95,
) -> StepsSummary:
    """Summary of one arm's ``steps`` (shape ``(n_seeds,)``, NaN = DNF) to one threshold."""
    x = np.asarray(steps, dtype=float).reshape(-1)
    b = np.broadcast_to(np.asarray(budget, dtype=float), x.shape)
    reached = x[np.isfinite(x)]
    mean = mean_ci(reached, rng, n_boot, ci)
    if x.size and reached.size < x.size:
        note = f"mean over the {reached.size} of {x.size} seeds that reached it"
        mean = Estimate(mean.value, mean.low, mean.high, mean.n, "; ".join(filter(None, [mean.note, note])))
    censored = np.where(np.isfinite(x), x, b)
    nan = float("nan")
    return StepsSummary(
        n=int(x.size),
        n_reached=int(reached.size),
        mean=mean,
        median=float(np.median(reached)) if reached.size else nan,
        censored_mean=float(censored.mean()) if x.size else nan,
        std=float(reached.std(ddof=1)) if reached.size >= 2 else nan,
        iqr=float(np.subtract(*np.percentile(reached, [75, 25]))) if reached.size else nan,
    )


def wilson_ci(successes: int, n: int, ci: float = 0.95) -> Estimate:
    """A proportion ``successes / n`` with its Wilson score interval."""
    if n <= 0:
        return Estimate(float("nan"), n=0, note="no seeds")
    interval = sps.binomtest(int(successes), int(n)).proportion_ci(confidence_level=ci, method="wilson")
    return Estimate(successes / n, float(interval.low), float(interval.high), n=int(n))


def reliability(reached: npt.ArrayLike, ci: float = 0.95) -> Estimate:
    """Fraction of seeds that reached the threshold, shape ``(n_seeds,)`` of bools, with a Wilson CI."""
    r = np.asarray(reached, dtype=bool).reshape(-1)
    return wilson_ci(int(r.sum()), int(r.size), ci)


def _diff_of_means(a: np.ndarray, b: np.ndarray, axis: int = -1) -> np.ndarray:
    return np.asarray(np.mean(a, axis=axis) - np.mean(b, axis=axis))


def difference_of_means(
    a: npt.ArrayLike, b: npt.ArrayLike, rng: np.random.Generator, n_boot: int = DEFAULT_N_BOOT, ci: float = 0.95
) -> Estimate:
    """``mean(a) - mean(b)`` (shapes ``(n_a,)``, ``(n_b,)``) with an independent-resampling bootstrap CI.

    Example:
        >>> difference_of_means([1.0, 1.0], [0.0, 1.0], np.random.default_rng(0), n_boot=100).value
        0.5
    """
    x, y = _finite(a), _finite(b)
    if x.size == 0 or y.size == 0:
        return Estimate(float("nan"), note="an arm has no values")
    value = float(x.mean() - y.mean())
    if x.size < 2 or y.size < 2:
        return Estimate(value, n=int(min(x.size, y.size)), note="fewer than 2 seeds: no CI")
    low, high = bootstrap_ci((x, y), _diff_of_means, rng, n_boot, ci)
    return Estimate(value, low, high, n=int(min(x.size, y.size)))


def _std_diff(a: np.ndarray, b: np.ndarray, axis: int = -1) -> np.ndarray:
    return np.asarray(np.std(a, axis=axis, ddof=1) - np.std(b, axis=axis, ddof=1))


def std_difference(
    a: npt.ArrayLike, b: npt.ArrayLike, rng: np.random.Generator, n_boot: int = DEFAULT_N_BOOT, ci: float = 0.95
) -> Estimate:
    """``std(a) - std(b)`` across seeds (ddof=1; below 0: ``a`` is narrower) with a bootstrap CI."""
    x, y = _finite(a), _finite(b)
    if x.size < 2 or y.size < 2:
        return Estimate(float("nan"), n=int(min(x.size, y.size)), note="fewer than 2 seeds: no spread")
    value = float(x.std(ddof=1) - y.std(ddof=1))
    low, high = bootstrap_ci((x, y), _std_diff, rng, n_boot, ci)
    return Estimate(value, low, high, n=int(min(x.size, y.size)))


def iqm(values: npt.ArrayLike) -> float:
    """Interquartile mean of ``values`` (shape ``(n,)``): the mean of the middle 50% (``trim_mean`` 0.25)."""
    x = _finite(values)
    return float(sps.trim_mean(x, 0.25)) if x.size else float("nan")


def _iqm_axis(a: np.ndarray, axis: int = -1) -> np.ndarray:
    return np.asarray(sps.trim_mean(a, 0.25, axis=axis))


def iqm_ci(values: npt.ArrayLike, rng: np.random.Generator, n_boot: int = DEFAULT_N_BOOT, ci: float = 0.95
           ) -> Estimate:
    """IQM of ``values`` (shape ``(n_seeds,)``) with a bootstrap CI over seeds."""
    x = _finite(values)
    if x.size < 2:
        return Estimate(iqm(x), n=int(x.size), note="fewer than 2 seeds: no CI")
    low, high = bootstrap_ci((x,), _iqm_axis, rng, n_boot, ci)
    return Estimate(iqm(x), low, high, n=int(x.size))


def final_return(returns: npt.ArrayLike, window: int = 100) -> float:
    """Mean native return of the last ``window`` training episodes (shape ``(E,)``, time order)."""
    r = np.asarray(returns, dtype=float).reshape(-1)
    return float(r[-window:].mean()) if r.size else float("nan")


def mean_band(
    curves: npt.ArrayLike, rng: np.random.Generator, n_boot: int = DEFAULT_N_BOOT, ci: float = 0.95
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Mean over seeds of ``curves`` (shape ``(n_seeds, G)``, NaN: no value yet) and a pointwise
    bootstrap band, each shape ``(G,)``; the band only where every seed (at least 2) has a value."""
    c = np.asarray(curves, dtype=float)
    if c.ndim != 2:
        raise ValueError(f"curves must have shape (n_seeds, G), got {c.shape}.")
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", RuntimeWarning)  # all-NaN columns
        mean = np.nanmean(c, axis=0) if c.shape[0] else np.full(c.shape[1], np.nan)
    low = np.full(c.shape[1], np.nan)
    high = np.full(c.shape[1], np.nan)
    full = np.all(np.isfinite(c), axis=0)
    if c.shape[0] >= 2 and full.any():
        lo, hi = _band(c[:, full], rng, n_boot, ci)
        low[full], high[full] = lo, hi
    return mean, low, high


def _band(c: np.ndarray, rng: np.random.Generator, n_boot: int, ci: float) -> tuple[np.ndarray, np.ndarray]:
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        res = sps.bootstrap((c,), np.mean, n_resamples=n_boot, confidence_level=ci, method="percentile",
                            vectorized=True, axis=0, rng=rng)
    lo = np.asarray(res.confidence_interval.low, dtype=float)
    hi = np.asarray(res.confidence_interval.high, dtype=float)
    # a column where all seeds agree has a zero-width band; scipy may return NaN there
    same = np.all(c == c[0], axis=0)
    lo[same], hi[same] = c[0, same], c[0, same]
    return lo, hi
