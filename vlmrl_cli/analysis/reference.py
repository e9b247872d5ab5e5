"""Whether plain PPO meets a published reference score (rl-baselines3-zoo's): an equivalence test
(TOST, t intervals) within a stated margin, by the rule ``RULE`` (issue 51). Shapes are ``(n_seeds,)``.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
import numpy.typing as npt
from scipy import stats as sps

FRACTION = 0.10
MIN_SEEDS = 10
MET, NOT_MET, CANNOT_TELL = "met", "not met", "cannot tell"
RULE = (f"met when the seed mean is equivalent to the zoo's score within {FRACTION:.0%} of the task's span from a "
        f"random policy's score to the zoo's (two one-sided t tests at 0.05, i.e. the 90% t interval inside the "
        f"band, on at least {MIN_SEEDS} seeds); not met when that interval lies wholly outside the band; otherwise, "
        "or with fewer seeds, cannot tell")


@dataclass(frozen=True)
class ReferenceVerdict:
    """The verdict on one task's baseline against the reference, and what it rests on."""

    verdict: str
    n: int
    mean: float
    low: float  # the 1 - 2 alpha t interval of the seed mean
    high: float
    delta: float  # the margin, in return points
    p_tost: float  # the larger of the two one-sided p-values (NaN: no test)
    note: str = ""


def reference_equivalence(scores: npt.ArrayLike, reference: float, random_score: float, fraction: float = FRACTION,
                          alpha: float = 0.05, min_seeds: int = MIN_SEEDS) -> ReferenceVerdict:
    """Judge the seeds' ``scores`` against ``reference`` by the module's rule."""
    x = np.asarray(scores, dtype=float).reshape(-1)
    x = x[np.isfinite(x)]
    delta = fraction * abs(reference - random_score)
    n = int(x.size)
    if n == 0:
        return ReferenceVerdict(CANNOT_TELL, 0, math.nan, math.nan, math.nan, delta, math.nan, "no seeds")
    mean = float(x.mean())
    if n < 2 or float(x.std()) == 0.0:
        low = high = mean
        p = math.nan
    else:
        se = float(x.std(ddof=1)) / math.sqrt(n)
        q = float(sps.t.ppf(1 - alpha, n - 1))
        low, high = mean - q * se, mean + q * se
        p = max(float(sps.t.sf((mean - (reference - delta)) / se, n - 1)),
                float(sps.t.cdf((mean - (reference + delta)) / se, n - 1)))
    band_low, band_high = reference - delta, reference + delta
    if high < band_low or low > band_high:
        verdict = NOT_MET
    elif n >= min_seeds and band_low < low and high < band_high:
        verdict = MET
    else:
        verdict = CANNOT_TELL
    note = f"{n} < {min_seeds} seeds: no equivalence claimed" if n < min_seeds and verdict != NOT_MET else ""
    if n >= 2 and math.isnan(p):
        note = "; ".join(filter(None, [note, "every seed scores the same: no t test, the point is compared"]))
    return ReferenceVerdict(verdict, n, mean, low, high, delta, p, note)
