"""Adjusting p-values for multiplicity within a declared family: ``holm`` (family-wise error rate,
any dependence), ``bh`` (Benjamini-Hochberg, false discovery rate) or ``none``. A comparison not
made (NaN) stays NaN and does not count in the family size.
"""

from __future__ import annotations

import math
from typing import Literal, get_args

import numpy as np
import numpy.typing as npt

Adjust = Literal["holm", "bh", "none"]
METHODS: tuple[str, ...] = get_args(Adjust)
DEFAULT_ADJUST: Adjust = "holm"
NAMES = {"holm": "Holm's step-down (family-wise error rate)",
         "bh": "Benjamini-Hochberg (false discovery rate)",
         "none": "no adjustment (each comparison at its own level)"}


def check_method(method: str) -> Adjust:
    """``method`` as an ``Adjust`` value; ``ValueError`` naming the choices otherwise."""
    if method not in METHODS:
        raise ValueError(f"unknown multiplicity adjustment '{method}'; choose one of {', '.join(METHODS)}")
    return method  # type: ignore[return-value]


def adjust(p_values: npt.ArrayLike, method: str = DEFAULT_ADJUST) -> np.ndarray:
    """Adjusted p-values of one family (shape ``(m,)``, NaN: not made), in the order given."""
    method = check_method(method)
    p = np.asarray(p_values, dtype=float).reshape(-1)
    finite = p[np.isfinite(p)]
    if np.any((finite < 0) | (finite > 1)):
        raise ValueError(f"p-values lie in [0, 1], got {finite[(finite < 0) | (finite > 1)][0]}")
    out = p.copy()
    keep = np.flatnonzero(np.isfinite(p))
    m = keep.size
    if method == "none" or m == 0:
        return out
    order = keep[np.argsort(p[keep], kind="stable")]
    ranked = p[order]
    if method == "holm":
        # the i-th smallest (0-based) is compared with alpha / (m - i); a running max keeps it step-down
        adjusted = np.maximum.accumulate((m - np.arange(m)) * ranked)
    else:
        # the i-th smallest (1-based) with alpha i / m; a running min from the largest keeps it step-up
        adjusted = np.minimum.accumulate((m / np.arange(1, m + 1) * ranked)[::-1])[::-1]
    out[order] = np.minimum(adjusted, 1.0)
    return out


def family_line(method: str, size: int, what: str) -> str:
    """The sentence a Method section states about a family and its adjustment.

    Example:
        >>> family_line("bh", 17, "The speedups")
        'The speedups form one family of 17 tests, adjusted by Benjamini-Hochberg (false discovery rate)'
    """
    return f"{what} form one family of {size} test{'s' if size != 1 else ''}, adjusted by {NAMES[check_method(method)]}"


def smallest_exact_p(n_a: int, n_b: int) -> float:
    """The smallest two-sided p an exact rank test of ``n_a`` against ``n_b`` seeds can give."""
    return min(1.0, 2.0 / math.comb(n_a + n_b, n_a))


def seeds_to_reach(size: int, alpha: float = 0.05, most: int = 100) -> int | None:
    """The fewest seeds per arm whose smallest exact p passes Holm's first step; None above ``most``."""
    for n in range(2, most + 1):
        if smallest_exact_p(n, n) < alpha / max(1, size):
            return n
    return None


def reach_line(method: str, size: int, n_a: int, n_b: int, alpha: float = 0.05) -> str | None:
    """The warning that a family of ``size`` exact rank tests at ``n_a`` vs ``n_b`` seeds cannot give
    any adjusted p below ``alpha``; None when it can.
    """
    method = check_method(method)
    p_min = smallest_exact_p(n_a, n_b)
    level = alpha / size if method == "holm" else alpha  # BH's smallest adjusted p can equal the smallest raw p
    if p_min < level or size < 1:
        return None
    need = seeds_to_reach(size if method == "holm" else 1, alpha)
    total = math.comb(n_a + n_b, n_a)
    step = f"Holm's first step compares it with {alpha:g}/{size} = {alpha / size:.2g}" if method == "holm" else (
        f"it is not below {alpha:g} even unadjusted")
    more = (f": that takes at least {need} seeds per arm (2/{math.comb(2 * need, need)} = "
            f"{smallest_exact_p(need, need):.2g})" if need else "")
    return (f"At {n_a} vs {n_b} seeds the rank test's smallest exact two-sided p is 2/{total} = {p_min:.2g}; {step}, "
            f"so no test of this family can reach an adjusted p below {alpha:g} whatever the data, and no speedup "
            f"can be called faster{more}.")
