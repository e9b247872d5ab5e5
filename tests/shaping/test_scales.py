from __future__ import annotations

import math

import pytest
from hypothesis import given
from hypothesis import strategies as st

from vlmrl_cli.shaping.scales import DENSE_SHARE, POTENTIAL_SHARE, TaskScales, task_scales

positive = st.floats(min_value=1e-3, max_value=1e4, allow_nan=False, allow_infinity=False)


@given(goal=positive, span=positive, peak=positive, horizon=st.integers(1, 10_000))
def test_each_term_pays_its_share_of_the_goal(goal: float, span: float, peak: float, horizon: int) -> None:
    s = task_scales(goal, span, peak, horizon)
    assert math.isclose(s.alpha * span, POTENTIAL_SHARE * goal, rel_tol=5e-3)
    assert math.isclose(s.kin_scale * peak * horizon, DENSE_SHARE * goal, rel_tol=5e-3)
    assert s.alpha * span + s.kin_scale * peak * horizon < goal  # lingering cannot out-earn finishing


@given(goal=positive, k=st.floats(min_value=0.1, max_value=10))
def test_scales_grow_with_the_goal(goal: float, k: float) -> None:
    a, b = task_scales(goal, 1.0, 1.0, 100), task_scales(goal * k, 1.0, 1.0, 100)
    assert math.isclose(b.alpha, k * a.alpha, rel_tol=1e-2) and math.isclose(b.kin_scale, k * a.kin_scale, rel_tol=1e-2)


@pytest.mark.parametrize("bad", [0.0, -1.0, math.inf, math.nan])
def test_a_degenerate_input_is_refused(bad: float) -> None:
    with pytest.raises(ValueError, match="goal_return"):
        task_scales(bad, 1.0, 1.0, 100)
    with pytest.raises(ValueError, match="alpha"):
        TaskScales(bad if bad != 0.0 else -1.0, 1.0, "x")
