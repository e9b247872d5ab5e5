"""Cross-task aggregates (``analysis.aggregate``): properties, and rliable's own reference values.

Reference values come from google-research/rliable (commit 3ccd9f4, Apache-2.0), read, not
imported (rliable does not import beside pandas 3):

- ``tests/rliable/metrics_test.py``: ``x = [[1, 2], [2, 2], [1, 1], [2, 1]]`` and
  ``y = [[1, 1], [2, 2], [3, 3]]`` (runs x tasks) have ``aggregate_iqm`` 1.5 and 2,
  ``aggregate_mean`` 1.5 and 2, and ``probability_of_improvement(x, y)`` 1/3.
- ``tests/rliable/library_test.py``: ``x = arange(80).reshape(5, 16)``, ``y = flip(x, axis=0)``;
  the percentile intervals of the IQM and mean hold the point estimate strictly inside, and so
  does the interval of the probability of improvement of x over y.
- ``rliable/metrics.py`` and ``rliable/library.py`` for the definitions: ``aggregate_iqm`` is
  ``scipy.stats.trim_mean(scores, 0.25, axis=None)``; the probability of improvement on a task is
  ``scipy.stats.mannwhitneyu(x, y, alternative="greater")`` U over ``n_x n_y`` (0.5 for equal
  columns), averaged over tasks; ``StratifiedBootstrap`` draws run indices of shape
  ``(n_runs, n_tasks)`` and takes ``scores[index, task]``, i.e. resamples the runs of each task on
  their own; ``run_score_deviation`` is ``np.mean(scores > tau)``.
"""

from __future__ import annotations

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from hypothesis.extra import numpy as hnp
from scipy import stats as sps

from vlmrl_cli.analysis import aggregate as agg

RLIABLE_X = np.array([[1, 2], [2, 2], [1, 1], [2, 1]])
RLIABLE_Y = np.array([[1, 1], [2, 2], [3, 3]])
LIBRARY_X = np.arange(5 * 16).reshape(5, 16)
LIBRARY_Y = np.flip(LIBRARY_X, axis=0)

# small matrices (runs x tasks) of small integers, so ties are common
matrices = hnp.arrays(np.float64, st.tuples(st.integers(2, 6), st.integers(1, 4)),
                      elements=st.integers(-5, 5).map(float))
ragged = st.lists(st.lists(st.integers(-5, 5).map(float), min_size=2, max_size=6), min_size=1, max_size=4)


def _rng(seed: int = 0) -> np.random.Generator:
    return np.random.default_rng(seed)


# --- rliable's reference values ------------------------------------------------------------------

def test_iqm_mean_and_probability_of_improvement_match_rliables_metrics_test() -> None:
    assert agg.iqm(RLIABLE_X) == 1.5 and agg.mean(RLIABLE_X) == 1.5
    assert agg.iqm(RLIABLE_Y) == 2.0 and agg.mean(RLIABLE_Y) == 2.0
    assert agg.probability_of_improvement(RLIABLE_X, RLIABLE_Y) == pytest.approx(1 / 3)


def test_intervals_hold_the_point_strictly_inside_as_in_rliables_library_test() -> None:
    for scores in (LIBRARY_X, LIBRARY_Y):
        for estimate in (agg.iqm_interval(scores, _rng(), n_boot=100), agg.mean_interval(scores, _rng(), n_boot=100)):
            assert estimate.low < estimate.value < estimate.high
    assert agg.iqm(LIBRARY_X) == sps.trim_mean(LIBRARY_X, 0.25, axis=None) == 39.5
    poi = agg.probability_of_improvement_interval(LIBRARY_X, LIBRARY_Y, _rng(), n_boot=100)
    assert poi.value == 0.5  # y holds the same runs as x on every task
    assert poi.low < poi.value < poi.high


def _rliable_stratified_iqm_interval(scores: np.ndarray, rng: np.random.Generator, reps: int) -> tuple[float, float]:
    """rliable's StratifiedBootstrap by its definition: run indices of shape (n_runs, n_tasks),
    ``scores[index, task]``, the IQM of each resample, the 2.5 and 97.5 percentiles."""
    n_runs, n_tasks = scores.shape
    stats = [sps.trim_mean(scores[rng.integers(0, n_runs, scores.shape), np.arange(n_tasks)], 0.25, axis=None)
             for _ in range(reps)]
    low, high = np.percentile(stats, [2.5, 97.5])
    return float(low), float(high)


def test_iqm_interval_agrees_with_rliables_stratified_bootstrap_definition() -> None:
    ref_low, ref_high = _rliable_stratified_iqm_interval(LIBRARY_X.astype(float), _rng(1), reps=4000)
    ours = agg.iqm_interval(LIBRARY_X, _rng(2), n_boot=4000)
    # two Monte Carlo estimates of the same percentiles; the interval is about 15 wide
    assert ours.low == pytest.approx(ref_low, abs=1.0) and ours.high == pytest.approx(ref_high, abs=1.0)


@settings(max_examples=40, deadline=None)
@given(matrices, matrices)
def test_probability_of_improvement_is_rliables_mann_whitney_definition(x, y) -> None:
    tasks = min(x.shape[1], y.shape[1])
    x, y = x[:, :tasks], y[:, :tasks]
    expected = np.mean([0.5 if np.array_equal(x[:, m], y[:, m]) else
                        sps.mannwhitneyu(x[:, m], y[:, m], alternative="greater").statistic / (len(x) * len(y))
                        for m in range(tasks)])
    assert agg.probability_of_improvement(x, y) == pytest.approx(expected)


# --- properties ----------------------------------------------------------------------------------

@settings(max_examples=40, deadline=None)
@given(matrices, st.floats(0.1, 10.0), st.floats(-10.0, 10.0))
def test_iqm_is_the_pooled_trimmed_mean_and_affine_equivariant(x, a, b) -> None:
    if x.size % 4 == 0:  # whole runs at the quartiles: rliable's trimmed mean exactly
        assert agg.iqm(x) == pytest.approx(float(sps.trim_mean(x, 0.25, axis=None)))
    assert x.min() <= agg.iqm(x) <= x.max()
    assert agg.iqm(a * x + b) == pytest.approx(a * agg.iqm(x) + b, abs=1e-9)
    assert agg.mean(a * x + b) == pytest.approx(a * agg.mean(x) + b, abs=1e-9)


@settings(max_examples=40, deadline=None)
@given(ragged, st.integers(2, 4))
def test_every_task_weighs_the_same_whatever_its_run_count(tasks, k) -> None:
    """Repeating each run of one task k times (k times its runs, the same distribution) moves no aggregate."""
    more = [list(np.repeat(tasks[0], k)), *tasks[1:]]
    assert agg.iqm(more) == pytest.approx(agg.iqm(tasks), abs=1e-9)
    assert agg.mean(more) == pytest.approx(agg.mean(tasks), abs=1e-9)


@settings(max_examples=30, deadline=None)
@given(ragged)
def test_ragged_tasks_equal_the_matrix_when_runs_are_equal(tasks) -> None:
    n = min(len(t) for t in tasks)
    matrix = np.array([t[:n] for t in tasks]).T
    cut = [t[:n] for t in tasks]
    assert agg.iqm(cut) == pytest.approx(agg.iqm(matrix)) and agg.mean(cut) == pytest.approx(agg.mean(matrix))
    assert agg.mean(tasks) == pytest.approx(np.mean([np.mean(t) for t in tasks]))  # each task weighs the same


@settings(max_examples=40, deadline=None)
@given(ragged, ragged)
def test_probability_of_improvement_is_antisymmetric_and_bounded(x, y) -> None:
    k = min(len(x), len(y))
    x, y = x[:k], y[:k]
    p = agg.probability_of_improvement(x, y)
    assert 0.0 <= p <= 1.0
    assert p + agg.probability_of_improvement(y, x) == pytest.approx(1.0)
    assert agg.probability_of_improvement(x, x) == pytest.approx(0.5)


@settings(max_examples=20, deadline=None)
@given(ragged, st.integers(0, 2**32 - 1))
def test_intervals_are_ordered_inside_the_scores_and_reproducible(tasks, seed) -> None:
    lo, hi = min(min(t) for t in tasks), max(max(t) for t in tasks)
    for interval in (agg.iqm_interval, agg.mean_interval):
        e = interval(tasks, _rng(seed), n_boot=60)
        assert lo <= e.low <= e.high <= hi
        assert e == interval(tasks, _rng(seed), n_boot=60)  # the generator is the only randomness


@settings(max_examples=20, deadline=None)
@given(st.lists(st.tuples(st.integers(-5, 5).map(float), st.integers(2, 5)), min_size=2, max_size=4))
def test_the_bootstrap_is_stratified_constant_tasks_give_no_width(levels) -> None:
    # each task's runs are all equal: resampling within tasks changes nothing (pooling runs across
    # tasks would mix the levels and give a wide interval)
    tasks = [[level] * n for level, n in levels]
    for interval in (agg.iqm_interval, agg.mean_interval):
        e = interval(tasks, _rng(), n_boot=60)
        assert e.low == pytest.approx(e.value) and e.high == pytest.approx(e.value)


@settings(max_examples=30, deadline=None)
@given(ragged)
def test_performance_profile_falls_from_one_to_zero(tasks) -> None:
    every = np.concatenate([np.asarray(t) for t in tasks])
    taus = np.linspace(every.min() - 1, every.max(), 25)
    profile = agg.performance_profile(tasks, taus)
    assert profile[0] == 1.0 and profile[-1] == 0.0  # strictly above tau, as rliable's
    assert np.all(np.diff(profile) <= 1e-12) and np.all((profile >= 0) & (profile <= 1))
    curve, low, high = agg.performance_profile_band(tasks, taus, _rng(), n_boot=60)
    assert np.array_equal(curve, profile) and np.all(low <= high + 1e-12)
    assert np.all((low >= 0) & (high <= 1))


def test_performance_profile_is_rliables_run_score_distribution_for_a_matrix() -> None:
    taus = np.array([0.0, 0.25, 0.5, 1.0, 40.0])
    x = LIBRARY_X
    expected = [np.mean(x > t) for t in taus]
    assert agg.performance_profile(x, taus) == pytest.approx(expected)


def test_normalise_maps_the_pair_to_zero_and_one() -> None:
    out = agg.normalise([[-200.0, -110.0], [0.0, 90.0]], lo=[-200.0, 0.0], hi=[-110.0, 90.0])
    assert [a.tolist() for a in out] == [[0.0, 1.0], [0.0, 1.0]]
    with pytest.raises(ValueError, match="hi != lo"):
        agg.normalise([[1.0, 2.0]], lo=[1.0], hi=[1.0])


def test_bad_scores_are_refused() -> None:
    with pytest.raises(ValueError, match="NaN"):
        agg.iqm([[1.0, np.nan]])
    with pytest.raises(ValueError, match="no runs"):
        agg.mean([[1.0], []])
    with pytest.raises(ValueError, match="same tasks"):
        agg.probability_of_improvement([[1.0, 2.0]], [[1.0], [2.0]])
    assert agg.iqm_interval([[1.0], [2.0, 3.0]], _rng()).note.startswith("a task has fewer than 2 runs")
