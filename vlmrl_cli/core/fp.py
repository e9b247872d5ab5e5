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
_FSUM_MAX_TERMS = 1 << 26  # fsum's per-exponent float64 sums of 27-bit integers stay below 2**53


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
    # the operations of exp_scalar, in place (no temporary per step; an FMA never fuses them)
    r = np.subtract(xc, k * _LN2_HI, out=xc)
    r -= k * _LN2_LO
    p = np.full_like(r, _COEFFS[0])
    for c in (*_COEFFS[1:], 1.0, 1.0):
        p *= r
        p += c
    out = np.ldexp(p, k.astype(np.int32), out=p)
    out[under] = 0.0
    return out


def fsum(x: np.ndarray) -> float:
    """``math.fsum`` of a float64 array, the same bits (the exactly rounded sum), without a Python
    float per entry: each entry is an integer times a power of two, the integers are summed exactly
    per exponent, the exponents combined in one Python int, and that rounded once.

    Example:
        >>> fsum(np.array([1.0, 1e100, 1.0, -1e100]))
        2.0
    """
    v = np.asarray(x, dtype=np.float64).ravel()
    if not 0 < v.size < _FSUM_MAX_TERMS or not bool(np.isfinite(v).all()):
        return math.fsum(v.tolist())
    mantissa, exponent = np.frexp(v)  # v = mantissa * 2**exponent, |mantissa| in [0.5, 1) or 0
    whole = mantissa * 2.0**53  # an integer below 2**53: v = whole * 2**(exponent - 53), exactly
    high = np.floor(whole * 2.0**-26)
    low = whole - high * 2.0**26  # whole = high * 2**26 + low, 0 <= low < 2**26, |high| <= 2**27
    lowest = int(exponent.min())
    bins = exponent - lowest
    # per-exponent sums of < 2**26 terms of at most 27 bits: float64's partial sums stay exact
    highs = np.bincount(bins, weights=high).tolist()
    lows = np.bincount(bins, weights=low).tolist()
    total = 0
    for h, lo in zip(reversed(highs), reversed(lows), strict=True):
        total = (total << 1) + (int(h) << 26) + int(lo)
    if total == 0:  # zero's sign as math.fsum gives it
        return math.fsum(v.tolist())
    shift = lowest - 53
    # int -> float and int / int round exactly once in CPython (half-even, subnormals included)
    return float(total << shift) if shift >= 0 else total / (1 << -shift)


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
