"""The two-sample log-rank test on right-censored steps to a threshold (Mantel 1966; ties handled
exactly), beside the censored rank test; hand-written because lifelines needs pandas < 3.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
import numpy.typing as npt
from scipy import stats as sps

from vlmrl_cli.analysis.censored import reached, restricted


@dataclass(frozen=True)
class LogRank:
    """A two-sided log-rank test of arm ``a`` vs arm ``b`` (``observed_a``: the finishes of ``a``)."""

    statistic: float  # chi-square, 1 df
    p_value: float
    observed_a: float
    expected_a: float
    variance: float
    note: str = ""

    @property
    def direction(self) -> int:
        """+1 when ``a`` finishes more than expected (faster), -1 when less, 0 when neither."""
        diff = self.observed_a - self.expected_a
        if not math.isfinite(diff) or abs(diff) <= 1e-9 * max(1.0, abs(self.expected_a)):  # rounding, not evidence
            return 0
        return 1 if diff > 0 else -1


def logrank_test(durations_a: npt.ArrayLike, events_a: npt.ArrayLike, durations_b: npt.ArrayLike,
                 events_b: npt.ArrayLike) -> LogRank:
    """The log-rank test of two right-censored samples (``events`` False: censored); NaN when nothing happened."""
    ta, tb = (np.asarray(d, dtype=float).reshape(-1) for d in (durations_a, durations_b))
    ea, eb = (np.asarray(e, dtype=bool).reshape(-1) for e in (events_a, events_b))
    if ta.shape != ea.shape or tb.shape != eb.shape:
        raise ValueError("each arm needs one event flag per duration")
    if ta.size == 0 or tb.size == 0:
        return LogRank(math.nan, math.nan, math.nan, math.nan, math.nan, "an arm has no seeds")
    times = np.unique(np.concatenate([ta[ea], tb[eb]]))
    if times.size == 0:
        return LogRank(math.nan, math.nan, 0.0, 0.0, 0.0, "no seed reached the threshold: nothing to compare")
    at_risk_a = (ta[None, :] >= times[:, None]).sum(axis=1)
    at_risk_b = (tb[None, :] >= times[:, None]).sum(axis=1)
    d_a = ((ta[None, :] == times[:, None]) & ea[None, :]).sum(axis=1)
    d_b = ((tb[None, :] == times[:, None]) & eb[None, :]).sum(axis=1)
    n, d = at_risk_a + at_risk_b, d_a + d_b
    expected = float(np.sum(d * at_risk_a / n))
    # hypergeometric variance with ties; a step with one seed at risk contributes nothing
    ties = np.where(n > 1, (n - d) / np.maximum(n - 1, 1), 0.0)
    variance = float(np.sum(d * (at_risk_a / n) * (at_risk_b / n) * ties))
    observed = float(d_a.sum())
    if not variance > 0:
        # every finish happened with all the seeds at risk finishing together, or with one arm alone
        # at risk: observed equals expected, so nothing tells the arms apart
        return LogRank(0.0, 1.0, observed, expected, variance, "no variance: no finish tells the arms apart")
    stat = (observed - expected) ** 2 / variance
    return LogRank(float(stat), float(sps.chi2.sf(stat, 1)), observed, expected, variance)


def censored_logrank(steps_a: npt.ArrayLike, steps_b: npt.ArrayLike, budget_a: npt.ArrayLike,
                     budget_b: npt.ArrayLike) -> LogRank:
    """The log-rank test on steps to a threshold (shapes ``(n_a,)``, ``(n_b,)``), a DNF censored at its budget."""
    return logrank_test(restricted(steps_a, budget_a), reached(steps_a, budget_a),
                        restricted(steps_b, budget_b), reached(steps_b, budget_b))
