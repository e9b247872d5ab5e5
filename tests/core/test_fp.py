from __future__ import annotations

import math

import numpy as np
from hypothesis import given, settings
from hypothesis import strategies as st
from hypothesis.extra.numpy import arrays

from vlmrl_cli.core.fp import exp, exp_scalar, fsum

finite = st.floats(allow_nan=False, allow_infinity=False)


def _same(a: float, b: float) -> bool:
    return a == b and math.copysign(1.0, a) == math.copysign(1.0, b)


@given(arrays(np.float64, st.integers(0, 60), elements=finite))
@settings(max_examples=400)
def test_fsum_is_math_fsum_bit_for_bit(x: np.ndarray) -> None:
    try:
        expected = math.fsum(x.tolist())
    except OverflowError:
        return
    assert _same(fsum(x), expected)


@given(st.integers(1, 400), st.integers(-1100, 850), st.integers(0, 2**32 - 1))
@settings(max_examples=200)
def test_fsum_over_wide_exponents_cancellation_and_ties(n: int, low: int, seed: int) -> None:
    rng = np.random.default_rng(seed)
    spread = np.ldexp(rng.standard_normal(n), rng.integers(low, low + 120, size=n))
    ties = np.array([1.0, 2.0**-53, 2.0**-106, -(2.0**-1074)]) * rng.choice([-1.0, 1.0])  # half-way sums
    for x in (spread, np.concatenate([spread, -spread[: n // 2]]), ties, np.exp(-rng.random(n) * 700)):
        assert _same(fsum(x), math.fsum(x.tolist()))


def test_fsum_of_zeros_and_nothing_is_math_fsums() -> None:
    for x in ([], [0.0], [-0.0], [-0.0, -0.0], [1.0, -1.0], [float("inf"), 1.0]):
        assert _same(fsum(np.array(x, dtype=np.float64)), math.fsum(x))


@given(arrays(np.float64, st.integers(0, 50), elements=st.floats(-800.0, 709.0)))
@settings(max_examples=300)
def test_exp_is_the_scalar_reference_bit_for_bit(x: np.ndarray) -> None:
    before = x.copy()
    got = exp(x)
    assert got.dtype == np.float64 and got.shape == x.shape
    assert [v.hex() for v in got.tolist()] == [exp_scalar(v).hex() for v in x.tolist()]
    assert np.array_equal(x, before)  # the in-place steps work on a copy, never on the argument
