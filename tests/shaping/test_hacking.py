from __future__ import annotations

import numpy as np
import pytest
from hypothesis import given
from hypothesis import strategies as st

from tests.tasks.mountain_car.test_kinematic import kinematic_reward
from vlmrl_cli.shaping.hacking import HOVER_HORIZON, hover_steps, summarize_hovering
from vlmrl_cli.tasks.mountain_car import MOUNTAIN_CAR
from vlmrl_cli.training.evaluation import evaluate_detached

HOVER_X = 0.3  # MountainCar's hovering starts here (its Task.hover_from)


def _energy_pumping(obs: np.ndarray) -> int:
    """Push in the direction of motion: drives straight to the flag."""
    return 2 if obs[1] >= 0 else 0


def _energy(x: float, v: float) -> float:
    """MountainCar's mechanical energy per unit mass (its gravity term is 0.0025 cos(3x))."""
    return 0.5 * v * v + 0.0025 / 3 * np.sin(3 * x)


def _hovering(obs: np.ndarray) -> int:
    """Pump energy only up to what reaches x ~ 0.44, then hold the car there, short of the flag (0.5).

    Right of x ~ 0.39 the engine (0.001) beats gravity, so pushing right holds the car; it pushes
    left only to stop an overshoot.
    """
    x, v = float(obs[0]), float(obs[1])
    if x < 0.39:
        pump = _energy(x, v) < _energy(0.44, 0.0)
        return (2 if v >= 0 else 0) if pump else (0 if v > 0 else 2)
    return 0 if v > 0 and x > 0.43 else 2


def test_a_hovering_policy_is_flagged_and_earns_more_kinematic_reward_than_it_would_finishing() -> None:
    r = evaluate_detached(_hovering, episodes=3, seed=0, task=MOUNTAIN_CAR)
    assert r.success_rate == 0.0 and np.all(r.lengths == 200)  # it never reaches the flag
    assert all(xs[-50:].min() > 0.4 and xs.max() < 0.5 for xs in r.positions)  # parked short of the flag
    hover = r.hovering
    assert hover.flagged and hover.hover_fraction > 0.2 and hover.dwell_right_steps > 50
    # why it is a hack: parked at x ~ 0.44 the kinematic term pays more per step than the -1 native cost
    assert kinematic_reward(0.44) - 1.0 > 0


def test_driving_straight_to_the_flag_is_not_flagged() -> None:
    r = evaluate_detached(_energy_pumping, episodes=5, seed=0, task=MOUNTAIN_CAR)
    assert r.success_rate == 1.0
    assert [xs.size for xs in r.positions] == r.lengths.tolist()
    hover = r.hovering
    assert hover.hover_fraction == 0.0 and not hover.flagged
    assert 0 < hover.dwell_right_steps <= HOVER_HORIZON  # it does pass x > 0.3, on its way in


def test_an_idle_policy_is_not_flagged() -> None:
    hover = evaluate_detached(lambda obs: 1, episodes=2, seed=0, task=MOUNTAIN_CAR).hovering
    assert hover.hover_fraction == 0.0 and hover.dwell_right_steps == 0.0


@given(st.lists(st.floats(-1.2, 0.6), min_size=1, max_size=60), st.booleans(), st.integers(0, 30))
def test_hover_steps_are_right_of_the_cut_and_a_timeout_hovers_wherever_it_is_right(xs, reached, horizon) -> None:
    h = hover_steps(xs, reached, HOVER_X, horizon=horizon)
    x = np.asarray(xs)
    assert h.shape == x.shape and not np.any(h & (x <= HOVER_X))
    if not reached:
        assert np.array_equal(h, x > HOVER_X)
    else:  # the last horizon+1 steps are the approach to the flag
        assert not h[max(0, x.size - 1 - horizon):].any()


def test_summary_pools_steps_over_episodes_and_checks_its_inputs() -> None:
    s = summarize_hovering([np.full(10, 0.4), np.full(30, 0.0)], [False, False], HOVER_X)
    assert s.hover_fraction == pytest.approx(10 / 40) and s.dwell_right_steps == 5.0 and s.episodes == 2
    with pytest.raises(ValueError, match="reached_flag"):
        summarize_hovering([np.zeros(3)], [True, False], HOVER_X)
    assert np.isnan(summarize_hovering([], [], HOVER_X).hover_fraction)
