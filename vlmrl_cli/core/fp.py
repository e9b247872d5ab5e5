"""A float64 ``exp`` that gives the same bits on every x86-64 CPU, for whatever feeds a reward
(numpy's SIMD ``exp`` rounds differently per CPU). See docs/development.md, "History"."""

from __future__ import annotations

import math

import numpy as np

# fdlibm's split of ln 2: LN2_HI has 32 trailing zero bits, so k * LN2_HI is exact for |k| < 2**20.
_LN2_HI = 6.93147180369123816490e-01
_LN2_LO = 1.90821492927058770002e-10
_INV_LN2 = 1.44269504088896338700e00
_LOWEST = -708.0  # exp(-708) ~ 3.3e-308 is still a normal float64
_HIGHEST = 709.0
# Taylor coefficients 1/n!, n = 13 .. 2, for Horner's rule on |r| <= ln(2)/2: truncation error < 1e-18.
_COEFFS = tuple(1.0 / math.factorial(n) for n in range(13, 1, -1))


def exp(x: np.ndarray) -> np.ndarray:
    """``e ** x`` elementwise, float64, bit-identical on every CPU: above 709 a ``ValueError``, below -708 0.0.

    Example:
        >>> float(exp(np.array([0.0]))[0]), float(exp(np.array([-1000.0]))[0])
        (1.0, 0.0)
        >>> abs(float(exp(np.array([-2.5]))[0]) / math.exp(-2.5) - 1) < 1e-15
        True
    """
    x = np.asarray(x, dtype=np.float64)
    if x.size and not float(np.max(x)) <= _HIGHEST:
        raise ValueError(f"exp argument above {_HIGHEST} (or NaN): {float(np.max(x))}")
    under = x < _LOWEST
    xc = np.where(under, 0.0, x)
    k = np.rint(xc * _INV_LN2)
    r = (xc - k * _LN2_HI) - k * _LN2_LO
    p = np.full_like(r, _COEFFS[0])
    for c in _COEFFS[1:]:
        p = p * r + c
    p = (p * r + 1.0) * r + 1.0
    out = np.ldexp(p, k.astype(np.int32))
    return np.where(under, 0.0, out)


def exp_scalar(x: float) -> float:
    """``exp`` for one Python float, the same operations in the same order (a reference).

    Example:
        >>> exp_scalar(-2.5) == float(exp(np.array([-2.5]))[0])
        True
    """
    if not x <= _HIGHEST:
        raise ValueError(f"exp argument above {_HIGHEST} (or NaN): {x}")
    if x < _LOWEST:
        return 0.0
    k = float(round(x * _INV_LN2))  # round-half-even, as np.rint
    r = (x - k * _LN2_HI) - k * _LN2_LO
    p = _COEFFS[0]
    for c in _COEFFS[1:]:
        p = p * r + c
    p = (p * r + 1.0) * r + 1.0
    return math.ldexp(p, int(k))
