from __future__ import annotations

import itertools

import pytest
from hypothesis import given
from hypothesis import strategies as st

from vlmrl_cli.shaping.hysteresis import LockState, lock_step

labels = st.lists(st.sampled_from([0.0, 0.1, 0.3, 0.6, 1.0]), max_size=80)
confirms = st.integers(1, 4)


def run(seq: list[float], confirm: int) -> list[LockState]:
    states, s = [], LockState()
    for p in seq:
        s = lock_step(s, p, confirm)
        states.append(s)
    return states


@given(labels, confirms)
def test_level_is_monotone_non_decreasing(seq: list[float], confirm: int) -> None:
    levels = [0.0] + [s.level for s in run(seq, confirm)]
    assert all(a <= b for a, b in itertools.pairwise(levels))


@given(labels, confirms)
def test_level_is_a_confirmed_potential_or_zero(seq: list[float], confirm: int) -> None:
    confirmed = {seq[i] for i in range(confirm - 1, len(seq)) if len(set(seq[i - confirm + 1: i + 1])) == 1}
    for s in run(seq, confirm):
        assert s.level == 0.0 or s.level in confirmed


@given(labels)
def test_with_confirm_one_the_level_is_the_running_max(seq: list[float]) -> None:
    running = 0.0
    for p, s in zip(seq, run(seq, 1), strict=True):
        running = max(running, p)
        assert s.level == running


def test_a_single_flicker_does_not_lock_and_a_confirmed_milestone_survives_flicker() -> None:
    states = run([0.0, 0.6, 0.0, 0.3, 0.3, 0.0, 0.1, 0.0], confirm=2)
    assert [s.level for s in states] == [0.0, 0.0, 0.0, 0.0, 0.3, 0.3, 0.3, 0.3]


def test_confirm_must_be_positive() -> None:
    with pytest.raises(ValueError, match="confirm"):
        lock_step(LockState(), 0.3, 0)
