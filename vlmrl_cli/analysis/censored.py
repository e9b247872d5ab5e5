"""The DNF rule for steps to a threshold (restricted mean, a DNF at the budget) and the verdicts
built on it (``judge_speedup``, ``judge_family``). See docs/method.md.

Shapes are ``(n_seeds,)`` with NaN for a DNF; randomness comes in as an explicit generator.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
import numpy.typing as npt
from scipy import stats as sps

from vlmrl_cli.analysis.defaults import DEFAULT_MARGIN
from vlmrl_cli.analysis.multiplicity import DEFAULT_ADJUST, adjust
from vlmrl_cli.analysis.stats import DEFAULT_N_BOOT, Estimate, bootstrap_ci

MIN_FINISHED_FOR_EQUIVALENCE = 0.5
FASTER, SLOWER, INCONCLUSIVE = "faster", "slower", "inconclusive"
HIGHER, LOWER = "higher", "lower"
#: How a speedup's interval is computed, for the Method sections.
RATIO_INTERVAL = ("the delta method on the log of the ratio of restricted means, each arm's own spread, Student's t "
                  "on min(n_a, n_b) - 1 degrees of freedom (a percentile bootstrap covered about 90% at nominal 95% "
                  "at 10 seeds per arm; this covers at least 94% in the simulation test)")
RULE = ("steps to a threshold are censored at the budget: a seed that never reaches it counts at the budget "
        "(restricted mean, i.e. the RMST up to the budget); a seed reached it when its rolling mean crossed it "
        "within the budget")


def equivalent(margin: float) -> str:
    """The verdict text of an equivalence, naming its margin."""
    return f"equivalent within {margin:g}x"


def restricted(steps: npt.ArrayLike, budget: npt.ArrayLike) -> np.ndarray:
    """``min(steps, budget)`` per seed, a DNF (NaN) at the budget: shape ``(n,)``, in env steps."""
    x = np.asarray(steps, dtype=float).reshape(-1)
    b = np.broadcast_to(np.asarray(budget, dtype=float), x.shape)
    return np.where(np.isfinite(x), np.minimum(x, b), b)


def reached(steps: npt.ArrayLike, budget: npt.ArrayLike) -> np.ndarray:
    """Whether each seed reached the threshold within its budget: shape ``(n,)`` of bools."""
    x = np.asarray(steps, dtype=float).reshape(-1)
    b = np.broadcast_to(np.asarray(budget, dtype=float), x.shape)
    return np.isfinite(x) & (x <= b)


def restricted_mean(steps: npt.ArrayLike, budget: npt.ArrayLike, rng: np.random.Generator | None = None,
                    n_boot: int = DEFAULT_N_BOOT, ci: float = 0.95) -> Estimate:
    """The restricted mean of steps (env steps) with a bootstrap CI over seeds when ``rng`` is given."""
    r = restricted(steps, budget)
    if r.size == 0:
        return Estimate(math.nan, n=0, note="no seeds")
    n_dnf = int((~reached(steps, budget)).sum())
    note = f"DNF {n_dnf}/{r.size} counted at the budget" if n_dnf else ""
    if rng is None or r.size < 2:
        return Estimate(float(r.mean()), n=int(r.size), note=note or ("n=1: no CI" if r.size < 2 else ""))
    low, high = bootstrap_ci((r,), np.mean, rng, n_boot, ci)
    return Estimate(float(r.mean()), low, high, n=int(r.size), note=note)


def log_ratio_interval(b: npt.ArrayLike, a: npt.ArrayLike, ci: float = 0.95) -> tuple[float, float]:
    """An interval for ``mean(b) / mean(a)`` (shapes ``(n_b,)``, ``(n_a,)``, positive values):
    ``exp(log(m_b / m_a) +- t se)``, ``se^2 = s_b^2 / (n_b m_b^2) + s_a^2 / (n_a m_a^2)``, Student's
    t on ``min(n_a, n_b) - 1`` df (``RATIO_INTERVAL`` says why not a bootstrap).
    """
    x_b, x_a = np.asarray(b, dtype=float).reshape(-1), np.asarray(a, dtype=float).reshape(-1)
    if min(x_a.size, x_b.size) < 2:
        return math.nan, math.nan
    low, high = log_ratio_bounds(x_b, x_a, ci)
    return float(low), float(high)


def log_ratio_bounds(b: np.ndarray, a: np.ndarray, ci: float = 0.95) -> tuple[np.ndarray, np.ndarray]:
    """``log_ratio_interval`` of every row (shapes ``(..., n)``, ``n >= 2``): bounds of shape ``(...)``.

    Example:
        >>> low, high = log_ratio_bounds(np.array([[110.0, 120.0, 130.0]]), np.array([[100.0, 100.0, 100.0]]))
        >>> low.round(3).tolist(), high.round(3).tolist()
        ([0.976], [1.476])
    """
    n_b, n_a = b.shape[-1], a.shape[-1]
    m_b, m_a = b.mean(axis=-1), a.mean(axis=-1)
    se = np.sqrt(b.var(axis=-1, ddof=1) / (n_b * m_b**2) + a.var(axis=-1, ddof=1) / (n_a * m_a**2))
    q = float(sps.t.ppf(0.5 + ci / 2, min(n_a, n_b) - 1))
    centre = np.log(m_b / m_a)
    return np.exp(centre - q * se), np.exp(centre + q * se)


def speedup(ref_steps: npt.ArrayLike, arm_steps: npt.ArrayLike, ref_budget: npt.ArrayLike,
            arm_budget: npt.ArrayLike, ci: float = 0.95) -> Estimate:
    """Restricted mean steps of the reference over the arm's (above 1: the arm is faster), ``ci`` interval."""
    b, a = restricted(ref_steps, ref_budget), restricted(arm_steps, arm_budget)
    if a.size == 0 or b.size == 0:
        return Estimate(math.nan, n=0, note="an arm has no seeds")
    if not (reached(ref_steps, ref_budget).any() or reached(arm_steps, arm_budget).any()):
        # budget / budget = 1 would read as "no difference"; nothing is known but that both exceed it
        return Estimate(math.nan, n=int(min(a.size, b.size)), note="neither arm reached the threshold")
    value = float(b.mean() / a.mean())
    n = int(min(a.size, b.size))
    if n < 2:
        return Estimate(value, n=n, note="fewer than 2 seeds: no CI")
    low, high = log_ratio_interval(b, a, ci)
    return Estimate(value, low, high, n=n)


def tost_equivalent(interval: tuple[float, float], margin: float = DEFAULT_MARGIN) -> bool:
    """TOST on a ratio: whether the ``1 - 2 alpha`` interval lies inside ``[1/margin, margin]``.

    Example:
        >>> tost_equivalent((0.92, 1.10)), tost_equivalent((0.80, 1.10)), tost_equivalent((float("nan"), 1.0))
        (True, False, False)
    """
    if not margin > 1:
        raise ValueError(f"the equivalence margin is a ratio > 1, got {margin}")
    low, high = interval
    return bool(math.isfinite(low) and math.isfinite(high) and 1 / margin < low and high < margin)


def leans(direction: str) -> str:
    """The verdict text of an inconclusive comparison whose evidence points one way."""
    return f"{INCONCLUSIVE}, leans {direction}"


def _side(interval: tuple[float, float]) -> int:
    """+1 when the interval lies above 1, -1 below, 0 when it holds 1 or is not finite."""
    low, high = interval
    if math.isfinite(low) and math.isfinite(high):
        return 1 if low > 1 else (-1 if high < 1 else 0)
    return 0


def judge_speedup(p_adjusted: float, direction: float, interval: tuple[float, float],
                  tost_interval: tuple[float, float], margin: float = DEFAULT_MARGIN, alpha: float = 0.05,
                  equivalence_allowed: bool = True) -> str:
    """The verdict on a speedup (above 1: the arm is faster): "faster"/"slower" needs the adjusted
    test to reject AND the 95% ``interval`` to exclude 1 on the test's side; "equivalent" needs the
    90% ``tost_interval`` inside [1/margin, margin]; otherwise "inconclusive", saying which way it
    leans. ``direction`` > 0: the test favours the arm (0 or NaN: the interval's side decides).
    """
    side = _side(interval)
    rejects = math.isfinite(p_adjusted) and p_adjusted < alpha
    test_side = int(np.sign(direction)) if math.isfinite(direction) else 0
    if rejects and side != 0 and test_side in (0, side):
        return FASTER if side > 0 else SLOWER
    if equivalence_allowed and tost_equivalent(tost_interval, margin):
        return equivalent(margin)
    pointers = {side} - {0} | ({test_side} - {0} if rejects else set())
    if len(pointers) == 1:
        return leans(FASTER if pointers.pop() > 0 else SLOWER)
    return INCONCLUSIVE


@dataclass(frozen=True)
class Verdict:
    """A comparison's verdict and what it rests on (``tost_*``: the ``1 - 2 alpha`` interval)."""

    text: str
    speedup: Estimate
    tost_low: float
    tost_high: float
    p_value: float
    margin: float
    direction: float = math.nan
    equivalence_allowed: bool = True


def steps_verdict(ref_steps: npt.ArrayLike, arm_steps: npt.ArrayLike, ref_budget: npt.ArrayLike,
                  arm_budget: npt.ArrayLike, p_value: float, ci: float = 0.95, alpha: float = 0.05,
                  margin: float = DEFAULT_MARGIN, direction: float = math.nan) -> Verdict:
    """The verdict of arm vs reference on one threshold's steps, on ``p_value`` as given (``judge_speedup``)."""
    est = speedup(ref_steps, arm_steps, ref_budget, arm_budget, ci)
    tost = speedup(ref_steps, arm_steps, ref_budget, arm_budget, 1 - 2 * alpha)
    finished = min(float(reached(ref_steps, ref_budget).mean()) if np.size(ref_steps) else 0.0,
                   float(reached(arm_steps, arm_budget).mean()) if np.size(arm_steps) else 0.0)
    allowed = finished >= MIN_FINISHED_FOR_EQUIVALENCE
    text = judge_speedup(p_value, direction, (est.low, est.high), (tost.low, tost.high), margin, alpha, allowed)
    return Verdict(text, est, tost.low, tost.high, p_value, margin, direction, allowed)


@dataclass(frozen=True)
class FamilyVerdicts:
    """A family's verdicts (shapes ``(m,)``); ``disagreement``: which of the two tests alone rejects, or ""."""

    p_adjusted: np.ndarray
    logrank_adjusted: np.ndarray
    verdicts: tuple[str, ...]
    disagreement: tuple[str, ...]


def judge_family(p_values: npt.ArrayLike, logrank_p: npt.ArrayLike, directions: npt.ArrayLike,
                 intervals: npt.ArrayLike, tost_intervals: npt.ArrayLike, equivalence_allowed: npt.ArrayLike,
                 method: str = DEFAULT_ADJUST, alpha: float = 0.05, margin: float = DEFAULT_MARGIN
                 ) -> FamilyVerdicts:
    """Adjust a family's rank-test and log-rank p-values (``multiplicity.adjust``; shape ``(m,)``,
    NaN: not made) and judge each comparison on its adjusted rank-test p (``judge_speedup``);
    ``intervals``, ``tost_intervals``: shape ``(m, 2)``.
    """
    p = np.asarray(p_values, dtype=float).reshape(-1)
    lr = np.asarray(logrank_p, dtype=float).reshape(-1)
    d = np.asarray(directions, dtype=float).reshape(-1)
    ci = np.asarray(intervals, dtype=float).reshape(-1, 2)
    tost = np.asarray(tost_intervals, dtype=float).reshape(-1, 2)
    allowed = np.asarray(equivalence_allowed, dtype=bool).reshape(-1)
    if not (p.size == lr.size == d.size == len(ci) == len(tost) == allowed.size):
        raise ValueError("every argument of judge_family needs one entry per comparison")
    p_adj, lr_adj = adjust(p, method), adjust(lr, method)
    verdicts = tuple(judge_speedup(float(p_adj[i]), float(d[i]), (float(ci[i, 0]), float(ci[i, 1])),
                                   (float(tost[i, 0]), float(tost[i, 1])), margin, alpha, bool(allowed[i]))
                     for i in range(p.size))
    rank_rejects, lr_rejects = p_adj < alpha, lr_adj < alpha  # NaN compares False
    both = np.isfinite(p_adj) & np.isfinite(lr_adj)
    disagreement = tuple("" if not both[i] or rank_rejects[i] == lr_rejects[i]
                         else ("rank test only" if rank_rejects[i] else "log-rank only") for i in range(p.size))
    return FamilyVerdicts(p_adj, lr_adj, verdicts, disagreement)


def difference_verdict(diff: Estimate, tost: tuple[float, float], p_value: float, alpha: float,
                       delta: float) -> str:
    """Verdict on a difference where higher is better: ``higher``/``lower`` when the test is
    significant *and* the interval excludes 0 on that side, ``equivalent within +-delta`` when the
    ``1 - 2 alpha`` interval ``tost`` lies inside ``(-delta, delta)``, else ``inconclusive``.
    """
    significant = math.isfinite(p_value) and p_value < alpha and math.isfinite(diff.value) and diff.value != 0
    if significant and diff.value > 0 and diff.low > 0:
        return HIGHER
    if significant and diff.value < 0 and diff.high < 0:
        return LOWER
    low, high = tost
    if math.isfinite(low) and math.isfinite(high) and -delta < low and high < delta:
        return f"equivalent within +-{delta:.3g}"
    return INCONCLUSIVE


def format_p(p_value: float, method: str = "", n_perm: int = 0) -> str:
    """A p-value for a table: ``p < 1/(B+1)`` at a permutation p's floor, else two significant digits."""
    if not math.isfinite(p_value):
        return "no test"
    if method == "permutation" and n_perm > 0 and p_value <= 1.0 / (n_perm + 1) * (1 + 1e-9):
        return f"p < {1.0 / (n_perm + 1):.2g}"
    return f"p = {p_value:.2g}"


def learning_curve_area(timesteps: npt.ArrayLike, returns: npt.ArrayLike, lengths: npt.ArrayLike,
                        budget: int) -> float:
    """Area under the learning curve: mean native return per env step within the budget (shapes ``(E,)``)."""
    ts = np.asarray(timesteps, dtype=float).reshape(-1)
    ret = np.asarray(returns, dtype=float).reshape(-1)
    length = np.asarray(lengths, dtype=float).reshape(-1)
    keep = (ts <= budget) & np.isfinite(ret) & np.isfinite(length) & (length > 0)
    if not keep.any():
        return math.nan
    return float(np.sum(ret[keep] * length[keep]) / np.sum(length[keep]))
