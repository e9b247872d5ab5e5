from __future__ import annotations

import math

from hypothesis import given
from hypothesis import strategies as st

from vlmrl_cli.shaping.hysteresis import LockState, lock_step
from vlmrl_cli.shaping.pbrs import pbrs_term

potentials = st.floats(-10.0, 10.0)
gammas = st.floats(0.5, 1.0)
alphas = st.floats(0.0, 10.0)


def discounted_shaping(phis: list[float], gamma: float, alpha: float, terminated: bool) -> float:
    """sum_t gamma^t term_t for the episode phi_0 .. phi_T (terminated at its last step or not)."""
    steps = len(phis) - 1
    return sum(
        gamma**t * pbrs_term(phis[t], phis[t + 1], gamma, alpha, terminated and t == steps - 1)
        for t in range(steps)
    )


@given(st.lists(potentials, min_size=2, max_size=60), gammas, alphas, st.booleans())
def test_telescoping_for_any_potential_sequence(phis: list[float], gamma: float, alpha: float,
                                                terminated: bool) -> None:
    """For ANY sequence phi_0..phi_T: sum_t gamma^t term_t == alpha (gamma^T phi_T - phi_0),
    with phi_T = 0 when the episode terminated (and phi_T kept when it was only truncated)."""
    steps = len(phis) - 1
    phi_last = 0.0 if terminated else phis[-1]
    expected = alpha * (gamma**steps * phi_last - phis[0])
    assert math.isclose(discounted_shaping(phis, gamma, alpha, terminated), expected, rel_tol=1e-9, abs_tol=1e-9)


@given(st.lists(st.sampled_from([0.0, 0.1, 0.3, 0.6, 1.0]), min_size=2, max_size=60),
       st.lists(st.floats(0.0, 1.0), min_size=60, max_size=60), gammas, alphas, st.booleans())
def test_telescoping_with_the_history_dependent_lock(labels: list[float], rbf: list[float], gamma: float,
                                                      alpha: float, terminated: bool) -> None:
    """The same identity holds for Phi = max(lock level, Phi_rbf), which depends on the history."""
    state, phis = LockState(), []
    for label, smooth in zip(labels, rbf, strict=False):
        state = lock_step(state, label, confirm=2)
        phis.append(max(state.level, smooth))
    phi_last = 0.0 if terminated else phis[-1]
    expected = alpha * (gamma ** (len(phis) - 1) * phi_last - phis[0])
    assert math.isclose(discounted_shaping(phis, gamma, alpha, terminated), expected, rel_tol=1e-9, abs_tol=1e-9)


@given(st.lists(st.floats(0.0, 10.0), min_size=1, max_size=40), st.floats(0.0, 10.0), gammas, alphas)
def test_a_loop_back_to_the_same_potential_never_pays(middle: list[float], phi0: float, gamma: float,
                                                       alpha: float) -> None:
    """Cycling s_0 -> ... -> s_0 earns alpha (gamma^T - 1) phi_0 <= 0 for phi_0 >= 0: no reward hacking."""
    phis = [phi0, *middle, phi0]
    total = discounted_shaping(phis, gamma, alpha, terminated=False)
    steps = len(phis) - 1
    assert math.isclose(total, alpha * (gamma**steps - 1.0) * phi0, rel_tol=1e-9, abs_tol=1e-9)
    assert total <= 1e-9


@given(st.lists(potentials, min_size=1, max_size=40), potentials, alphas)
def test_a_loop_is_exactly_zero_without_discount(middle: list[float], phi0: float, alpha: float) -> None:
    phis = [phi0, *middle, phi0]
    assert math.isclose(discounted_shaping(phis, 1.0, alpha, terminated=False), 0.0, abs_tol=1e-9)


@given(potentials, potentials, gammas, alphas)
def test_terminal_next_potential_is_zero_and_truncation_keeps_it(phi: float, phi_next: float, gamma: float,
                                                                  alpha: float) -> None:
    assert pbrs_term(phi, phi_next, gamma, alpha, terminated=True) == alpha * (gamma * 0.0 - phi)
    assert pbrs_term(phi, phi_next, gamma, alpha, terminated=False) == alpha * (gamma * phi_next - phi)
