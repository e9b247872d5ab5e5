from __future__ import annotations

import numpy as np
from hypothesis import given
from hypothesis import strategies as st

from vlmrl_cli.tasks.mountain_car.task import kinematic_dense


def kinematic_reward(x: float, scale: float = 2.0, offset: float = 0.4) -> float:
    """Eq. 1 on a position, as MountainCar's dense term reads it from the observation ``[x, v]``."""
    return kinematic_dense(np.array([x, 0.0]), scale, offset)

positions = st.floats(-1.2, 0.6)
scales = st.floats(0.0, 10.0)
offsets = st.floats(-1.0, 1.5)


@given(positions, scales, offsets)
def test_non_negative(x: float, scale: float, offset: float) -> None:
    assert kinematic_reward(x, scale, offset) >= 0.0


@given(positions, positions, scales, offsets)
def test_monotone_non_decreasing_in_x(a: float, b: float, scale: float, offset: float) -> None:
    lo, hi = sorted((a, b))
    assert kinematic_reward(lo, scale, offset) <= kinematic_reward(hi, scale, offset)


@given(positions, scales, offsets)
def test_zero_left_of_minus_offset(x: float, scale: float, offset: float) -> None:
    if x <= -offset:
        assert kinematic_reward(x, scale, offset) == 0.0


def test_paper_defaults_eq1() -> None:
    assert kinematic_reward(-0.4) == 0.0
    assert kinematic_reward(0.5) == 2.0 * 0.9


@given(st.floats(-1.2, 0.6), st.floats(0.0, 10.0), st.floats(-2.0, 2.0))
def test_the_scene_dense_term_is_eq1_on_the_observed_position(x: float, scale: float, offset: float) -> None:
    """MountainCar's scene term is Eq. 1 on ``obs[0]`` of a float32 observation, bit for bit."""
    obs = np.array([x, 0.01], dtype=np.float32)
    assert kinematic_dense(obs, scale, offset) == max(0.0, scale * (float(obs[0]) + offset))
