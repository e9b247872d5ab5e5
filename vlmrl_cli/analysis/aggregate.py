"""Aggregates across tasks after rliable (Agarwal et al. 2021) over one arm's finite scores: a
``(n_runs, n_tasks)`` matrix or one ``(n_runs_m,)`` array per task, usually ``normalise``d. Intervals
are stratified percentile bootstraps: each task's runs resampled on their own, the tasks kept.
See docs/commands/compare.md.
"""

from __future__ import annotations

import warnings
from collections.abc import Callable, Sequence

import numpy as np
import numpy.typing as npt
from scipy import stats as sps

from vlmrl_cli.analysis.stats import DEFAULT_N_BOOT, Estimate

#: One arm's scores: a ``(n_runs, n_tasks)`` matrix, or one ``(n_runs_m,)`` array per task.
TaskScores = npt.ArrayLike | Sequence[npt.ArrayLike]


def per_task(scores: TaskScores) -> list[np.ndarray]:
    """The scores as one checked float array per task (2-D: ``(n_runs, n_tasks)``): finite, none empty.

    Example:
        >>> [a.tolist() for a in per_task(np.array([[1, 2], [3, 4], [5, 6]]))]
        [[1.0, 3.0, 5.0], [2.0, 4.0, 6.0]]
        >>> [a.tolist() for a in per_task([[1.0], [2.0, 3.0]])]
        [[1.0], [2.0, 3.0]]
    """
    if isinstance(scores, np.ndarray) and scores.ndim == 2:
        tasks = [np.asarray(scores[:, m], dtype=float) for m in range(scores.shape[1])]
    else:
        tasks = [np.asarray(t, dtype=float).reshape(-1) for t in scores]  # type: ignore[union-attr]
    if not tasks:
        raise ValueError("no tasks: give scores of shape (n_runs, n_tasks) with n_tasks >= 1")
    for m, t in enumerate(tasks):
        if t.size == 0:
            raise ValueError(f"task {m} has no runs")
        if not np.all(np.isfinite(t)):
            raise ValueError(f"task {m} has a NaN or infinite score; drop or fill it before aggregating")
    return tasks


def normalise(scores: TaskScores, lo: npt.ArrayLike, hi: npt.ArrayLike) -> list[np.ndarray]:
    """Min-max normalised scores per task, 0 at ``lo`` and 1 at ``hi`` (shapes ``(n_tasks,)``)."""
    tasks = per_task(scores)
    low, high = np.asarray(lo, dtype=float).reshape(-1), np.asarray(hi, dtype=float).reshape(-1)
    if low.size != len(tasks) or high.size != len(tasks):
        raise ValueError(f"give one lo and one hi per task ({len(tasks)}), got {low.size} and {high.size}")
    if np.any(high == low) or not np.all(np.isfinite(high - low)):
        raise ValueError("every task needs a finite reference pair with hi != lo")
    return [(t - a) / (b - a) for t, a, b in zip(tasks, low, high, strict=True)]


def _iqm_axis(*tasks: np.ndarray, axis: int = -1) -> np.ndarray:
    """The IQM of the mixture of the tasks' runs (a task weighs ``1 / n_tasks``, each of its ``n_m``
    runs ``1 / (n_tasks n_m)``): the weighted quantile function's mean over (0.25, 0.75)."""
    values = np.concatenate([np.moveaxis(t, axis, -1) for t in tasks], axis=-1)
    weights = np.concatenate([np.full(t.shape[axis], 1.0 / (len(tasks) * t.shape[axis])) for t in tasks])
    order = np.argsort(values, axis=-1, kind="stable")
    x = np.take_along_axis(values, order, axis=-1)
    w = weights[order]
    upper = np.cumsum(w, axis=-1)
    overlap = np.clip(np.minimum(upper, 0.75) - np.maximum(upper - w, 0.25), 0.0, None)
    mean = np.sum(x * overlap, axis=-1) / np.sum(overlap, axis=-1)  # the overlaps sum to 0.5, up to rounding
    return np.asarray(np.clip(mean, x[..., 0], x[..., -1]))


def _mean_axis(*tasks: np.ndarray, axis: int = -1) -> np.ndarray:
    return np.mean(np.stack([t.mean(axis=axis) for t in tasks]), axis=0)


def iqm(scores: TaskScores) -> float:
    """Interquartile mean over all tasks' runs, each task weighing the same (rliable's ``aggregate_iqm``)."""
    return float(_iqm_axis(*per_task(scores)))


def mean(scores: TaskScores) -> float:
    """Mean over tasks of each task's mean score, as rliable's ``aggregate_mean``."""
    return float(_mean_axis(*per_task(scores)))


def stratified_bootstrap(
    statistic: Callable[..., np.ndarray],
    samples: Sequence[np.ndarray],
    rng: np.random.Generator,
    n_boot: int = DEFAULT_N_BOOT,
    ci: float = 0.95,
) -> tuple[np.ndarray, np.ndarray]:
    """Percentile ``(low, high)`` of ``statistic(*samples, axis=-1)`` (vectorised; one or ``k`` values),
    each sample (a stratum of at least 2 runs) resampled on its own; shapes ``()`` or ``(k,)``."""
    if any(s.size < 2 for s in samples):
        raise ValueError("a stratified bootstrap needs at least 2 runs in every stratum (task)")
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")  # degenerate strata (all runs equal) warn but are fine here
        res = sps.bootstrap(tuple(samples), statistic, n_resamples=n_boot, confidence_level=ci,
                            method="percentile", vectorized=True, paired=False, axis=-1, rng=rng)
    return np.asarray(res.confidence_interval.low), np.asarray(res.confidence_interval.high)


def _interval(statistic: Callable[..., np.ndarray], tasks: list[np.ndarray], rng: np.random.Generator,
              n_boot: int, ci: float) -> Estimate:
    value = float(statistic(*tasks))
    n = sum(t.size for t in tasks)
    if min(t.size for t in tasks) < 2:
        return Estimate(value, n=n, note="a task has fewer than 2 runs: no interval")
    low, high = stratified_bootstrap(statistic, tasks, rng, n_boot, ci)
    return Estimate(value, float(low), float(high), n=n)


def iqm_interval(scores: TaskScores, rng: np.random.Generator, n_boot: int = DEFAULT_N_BOOT, ci: float = 0.95
                 ) -> Estimate:
    """``iqm`` with its stratified bootstrap percentile interval (``n``: runs over all tasks)."""
    return _interval(_iqm_axis, per_task(scores), rng, n_boot, ci)


def mean_interval(scores: TaskScores, rng: np.random.Generator, n_boot: int = DEFAULT_N_BOOT, ci: float = 0.95
                  ) -> Estimate:
    """``mean`` with its stratified bootstrap percentile interval (``n``: runs over all tasks)."""
    return _interval(_mean_axis, per_task(scores), rng, n_boot, ci)


def p_greater(x: np.ndarray, y: np.ndarray, axis: int = -1) -> np.ndarray:
    """P(X > Y) + P(X = Y)/2 over all pairs, i.e. the Mann-Whitney U of ``x`` over ``n_x n_y``."""
    a, b = np.moveaxis(x, axis, -1)[..., :, None], np.moveaxis(y, axis, -1)[..., None, :]
    return np.mean((a > b) + 0.5 * (a == b), axis=(-2, -1))


def _poi_of(n_tasks: int) -> Callable[..., np.ndarray]:
    def poi(*samples: np.ndarray, axis: int = -1) -> np.ndarray:
        xs, ys = samples[:n_tasks], samples[n_tasks:]
        return np.mean(np.stack([p_greater(x, y, axis) for x, y in zip(xs, ys, strict=True)]), axis=0)

    return poi


def _pair(x: TaskScores, y: TaskScores) -> tuple[list[np.ndarray], list[np.ndarray]]:
    xs, ys = per_task(x), per_task(y)
    if len(xs) != len(ys):
        raise ValueError(f"X has {len(xs)} tasks and Y {len(ys)}: compare arms on the same tasks")
    return xs, ys


def probability_of_improvement(x: TaskScores, y: TaskScores) -> float:
    """rliable's probability of improvement of arm X over Y: the mean over tasks of P(X > Y) + P(X = Y)/2."""
    xs, ys = _pair(x, y)
    return float(_poi_of(len(xs))(*xs, *ys))


def probability_of_improvement_interval(x: TaskScores, y: TaskScores, rng: np.random.Generator,
                                        n_boot: int = DEFAULT_N_BOOT, ci: float = 0.95) -> Estimate:
    """``probability_of_improvement`` with a stratified bootstrap interval (``n``: both arms' runs)."""
    xs, ys = _pair(x, y)
    return _interval(_poi_of(len(xs)), [*xs, *ys], rng, n_boot, ci)


def _profile_of(taus: np.ndarray) -> Callable[..., np.ndarray]:
    def profile(*tasks: np.ndarray, axis: int = -1) -> np.ndarray:
        # (n_taus, ...) per task: the fraction of its runs above each tau; then the mean over tasks
        fractions = [np.mean(np.moveaxis(t, axis, -1)[None, ...] > taus.reshape(-1, *([1] * t.ndim)), axis=-1)
                     for t in tasks]
        return np.mean(np.stack(fractions), axis=0)

    return profile


def performance_profile(scores: TaskScores, taus: npt.ArrayLike) -> np.ndarray:
    """rliable's score distribution: the mean over tasks of the share of runs strictly above each ``tau``."""
    t = np.asarray(taus, dtype=float).reshape(-1)
    return np.asarray(_profile_of(t)(*per_task(scores)), dtype=float)


def performance_profile_band(scores: TaskScores, taus: npt.ArrayLike, rng: np.random.Generator,
                             n_boot: int = DEFAULT_N_BOOT, ci: float = 0.95
                             ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """``performance_profile`` and its pointwise stratified bootstrap band, each shape ``(n_taus,)``."""
    t = np.asarray(taus, dtype=float).reshape(-1)
    tasks = per_task(scores)
    profile = np.asarray(_profile_of(t)(*tasks), dtype=float)
    low, high = stratified_bootstrap(_profile_of(t), tasks, rng, n_boot, ci)
    return profile, low.reshape(-1), high.reshape(-1)
