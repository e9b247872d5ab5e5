"""Adjusting p-values for multiplicity within a declared family of comparisons.

A table that judges many comparisons at ``alpha`` each will call some of them significant by
chance alone; the adjusted p-values here let each verdict be judged at ``alpha`` while the whole
family keeps its error rate:

* ``holm`` (default): Holm's step-down procedure, controls the family-wise error rate (the chance
  of any false "faster"/"slower" in the family) under any dependence between the tests.
* ``bh``: Benjamini-Hochberg, controls the false discovery rate (the expected share of false
  rejections among the rejections); valid for independent or positively dependent tests.
* ``none``: the raw p-values (each comparison on its own).

A comparison that was not made (NaN) stays NaN and does not count in the family size. All
functions are pure.
"""

from __future__ import annotations

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
    """``method`` as an ``Adjust`` value; ``ValueError`` naming the choices otherwise.

    Example:
        >>> check_method("bh")
        'bh'
    """
    if method not in METHODS:
        raise ValueError(f"unknown multiplicity adjustment '{method}'; choose one of {', '.join(METHODS)}")
    return method  # type: ignore[return-value]


def adjust(p_values: npt.ArrayLike, method: str = DEFAULT_ADJUST) -> np.ndarray:
    """Adjusted p-values of one family, in the order given.

    Args:
        p_values: shape ``(m,)``, raw p-values in [0, 1]; NaN for a comparison not made (kept NaN,
            not counted in the family size).
        method: ``"holm"``, ``"bh"`` or ``"none"``.

    Returns:
        Shape ``(m,)``: each adjusted p is at least its raw p, at most 1, and the adjusted values
        keep the order of the raw ones (a smaller raw p never gets a larger adjusted p).

    Example:
        >>> adjust([0.01, 0.04, float("nan"), 0.03]).round(3).tolist()
        [0.03, 0.06, nan, 0.06]
        >>> adjust([0.01, 0.04, 0.03], "bh").round(3).tolist()
        [0.03, 0.04, 0.04]
    """
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
