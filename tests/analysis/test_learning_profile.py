"""The calibration distance on hand-built episode tables."""

from __future__ import annotations

import math

import numpy as np
import pandas as pd
import pytest
from hypothesis import given
from hypothesis import strategies as st

from vlmrl_cli.analysis.learning_profile import (
    TargetProfile,
    distance,
    distance_ci,
    paper_baseline,
    regime_profile,
    scaled_target,
    seed_steps,
)
from vlmrl_cli.paper import REPORTED

THRESHOLDS = (-190.0, -160.0, -130.0)


def _seed(seed: int, crossings: tuple[int | None, ...], end: int = 1000) -> pd.DataFrame:
    """One seed's episodes with window 1: -200 at step 10, then each threshold's return at its crossing
    (None: never), and a last -200 episode at ``end`` if nothing was reached."""
    rows = [(10, -200.0)]
    rows += [(step, t) for step, t in zip(crossings, THRESHOLDS, strict=True) if step is not None]
    if all(c is None for c in crossings):
        rows.append((end, -200.0))
    return pd.DataFrame({"seed": seed, "timestep": [r[0] for r in rows], "native_return": [r[1] for r in rows]})


def _table(*seeds: tuple[int | None, ...]) -> pd.DataFrame:
    return pd.concat([_seed(i, c) for i, c in enumerate(seeds)], ignore_index=True)


TARGET = TargetProfile(THRESHOLDS, (100.0, 200.0, 300.0), reliability=1.0)


def test_a_regime_that_learns_exactly_like_the_target_is_at_distance_zero() -> None:
    episodes = _table((100, 200, 300), (100, 200, 300), (100, 200, 300))
    profile = regime_profile(episodes, TARGET, budget=1000, rng=np.random.default_rng(0), window=1, n_boot=200)
    assert profile.distance.value == pytest.approx(0.0)
    assert profile.distance.low == pytest.approx(0.0) and profile.distance.high == pytest.approx(0.0)
    assert profile.reliability.value == 1.0 and profile.n_reached == (3, 3, 3)
    assert [e.value for e in profile.steps] == [100.0, 200.0, 300.0]


def test_dnf_seeds_count_at_the_budget_not_dropped() -> None:
    episodes = _table((100, 200, 300), (100, None, None))
    steps, reached = seed_steps(episodes, THRESHOLDS, budget=1000, window=1)
    np.testing.assert_array_equal(steps, [[100, 200, 300], [100, 1000, 1000]])
    np.testing.assert_array_equal(reached, [[True, True, True], [True, False, False]])
    target = TargetProfile(THRESHOLDS, (100.0, 200.0, 300.0), reliability=0.5)
    expected = (0 + math.log(600 / 200) + math.log(650 / 300)) / 3  # means 100, 600, 650; reliability 1/2 matches
    assert distance(steps, reached[:, -1], target) == pytest.approx(expected)


def test_a_seed_without_a_completed_episode_is_a_dnf_not_dropped() -> None:
    steps, reached = seed_steps(_table((100, 200, 300)), THRESHOLDS, budget=1000, window=1, seeds=[0, 1])
    np.testing.assert_array_equal(steps, [[100, 200, 300], [1000, 1000, 1000]])
    assert not reached[1].any()


def test_a_crossing_after_the_budget_is_a_dnf() -> None:
    steps, reached = seed_steps(_table((100, 200, 1500)), THRESHOLDS, budget=1000, window=1)
    assert steps[0, -1] == 1000 and not reached[0, -1]


@given(factor=st.floats(0.1, 10.0), rel=st.floats(0.0, 1.0))
def test_the_log_term_is_symmetric_and_the_reliability_term_is_additive(factor: float, rel: float) -> None:
    target = TargetProfile(THRESHOLDS, (100.0, 200.0, 300.0), reliability=rel)
    steps = np.array([[100.0, 200.0, 300.0]] * 4) * factor
    reached = np.array([True, True, False, False])
    got = distance(steps, reached, target)
    assert got == pytest.approx(abs(math.log(factor)) + abs(0.5 - rel))
    assert distance(steps / factor**2, reached, target) == pytest.approx(got)  # 1/f as far as f


@given(
    st.lists(
        st.tuples(st.integers(1, 999), st.integers(1, 999), st.integers(1, 999), st.booleans()), min_size=2, max_size=8
    )
)
def test_the_bootstrap_ci_is_an_interval_over_seeds(rows: list[tuple[int, int, int, bool]]) -> None:
    steps = np.array([r[:3] for r in rows], dtype=float)
    reached = np.array([r[3] for r in rows])
    est = distance_ci(steps, reached, TARGET, np.random.default_rng(0), n_boot=200)
    assert est.has_ci and est.n == len(rows) and 0 <= est.low <= est.high
    same = distance_ci(
        np.repeat(steps[:1], len(rows), axis=0),
        np.repeat(reached[:1], len(rows)),
        TARGET,
        np.random.default_rng(0),
        n_boot=200,
    )
    assert same.low == pytest.approx(same.value) == pytest.approx(same.high)  # seeds alike: no spread


def test_one_seed_has_no_ci() -> None:
    est = distance_ci([[100.0, 200.0, 300.0]], [True], TARGET, np.random.default_rng(0))
    assert est.value == pytest.approx(0.0) and not est.has_ci and "fewer than 2" in est.note


def test_the_papers_reported_baseline_is_read_from_its_table2() -> None:
    t = paper_baseline(REPORTED)
    assert t.thresholds == THRESHOLDS and t.steps == (196_717.0, 219_679.0, 272_448.0) and t.reliability == 0.6


def test_a_target_needs_one_step_per_threshold() -> None:
    with pytest.raises(ValueError, match="one step count per threshold"):
        TargetProfile(THRESHOLDS, (1.0,), 0.5)


@given(k=st.integers(1, 6), budget=st.integers(1_000, 10_000_000))
def test_a_scaled_target_keeps_the_paper_profile_shape_within_the_budget(k: int, budget: int) -> None:
    paper = paper_baseline(REPORTED)
    t = scaled_target(tuple(float(i) for i in range(k)), budget, paper, 300_000)
    assert len(t.steps) == k and t.reliability == paper.reliability
    assert list(t.steps) == sorted(t.steps) and all(0 < s < budget for s in t.steps)
    # the last threshold sits where the paper's last one does, as a fraction of the budget
    assert t.steps[-1] / budget == pytest.approx(paper.steps[-1] / 300_000)
