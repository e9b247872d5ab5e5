"""How far one regime's baseline learning profile (censored steps to each threshold, and the
reliability at the last) is from a target profile: the distance ``D`` of docs/commands/calibrate.md,
``(1/K) sum_k |ln(S_k / T_k)| + |rho - rho*|``, with a paired bootstrap CI over seeds. Inputs are
episode tables (``seed``, ``timestep``, ``native_return``).
"""

from __future__ import annotations

import json
import math
from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path

import numpy as np
import numpy.typing as npt
import pandas as pd

from vlmrl_cli.analysis import censored
from vlmrl_cli.analysis.stats import DEFAULT_N_BOOT, Estimate, bootstrap_ci, reliability
from vlmrl_cli.analysis.thresholds import steps_to_threshold
from vlmrl_cli.core.errors import BadInput


@dataclass(frozen=True)
class TargetProfile:
    """A learning profile to match: steps to each threshold, and the reliability at the last."""

    thresholds: tuple[float, ...]  # native return targets, ascending difficulty, e.g. (-190, -160, -130)
    steps: tuple[float, ...]  # target steps to each threshold, shape (K,)
    reliability: float  # fraction of seeds reaching thresholds[-1] within the budget
    source: str = ""

    def __post_init__(self) -> None:
        if not self.thresholds or len(self.thresholds) != len(self.steps):
            raise ValueError("a target profile needs one step count per threshold, and at least one threshold.")
        if any(s <= 0 for s in self.steps) or not 0 <= self.reliability <= 1:
            raise ValueError("target steps must be > 0 and the target reliability in [0, 1].")


def paper_baseline(path: Path) -> TargetProfile:
    """The baseline of a paper's reported Table 2 (``path``, the paper's task's ``PaperTask.reported``):
    steps to each threshold and its final reliability.
    """
    try:
        table2 = json.loads(path.read_text(encoding="utf-8"))["table2"]
        rows = sorted(table2["steps_to_threshold"], key=lambda r: float(r["threshold"]))
        return TargetProfile(
            thresholds=tuple(float(r["threshold"]) for r in rows),
            steps=tuple(float(r["baseline"]) for r in rows),
            reliability=float(table2["final_reliability"]["baseline"]),
            source=f"the paper's baseline ({path.name}, Table 2)",
        )
    except (OSError, ValueError, KeyError, TypeError) as exc:
        raise BadInput(f"cannot read the paper's baseline profile from {path}; check the file ({exc}).") from exc


def scaled_target(thresholds: Sequence[float], budget: int, paper: TargetProfile, paper_budget: int) -> TargetProfile:
    """The paper's baseline profile (trained for ``paper_budget`` steps) carried to ``thresholds`` and
    ``budget``: each threshold at the paper's fraction of the budget (interpolated), the same reliability.
    """
    fractions = np.asarray(paper.steps, dtype=float) / paper_budget
    k = len(thresholds)
    if k == 0:
        raise BadInput("a scaled target needs at least one threshold.")
    where = np.linspace(0, len(fractions) - 1, k) if k > 1 else np.asarray([len(fractions) - 1.0])
    steps = np.interp(where, np.arange(len(fractions)), fractions) * budget
    return TargetProfile(
        thresholds=tuple(float(t) for t in thresholds),
        steps=tuple(float(s) for s in steps),
        reliability=paper.reliability,
        source=f"the paper's baseline profile scaled to this task (each threshold at the paper's fraction of the "
               f"budget, {', '.join(f'{f:.0%}' for f in fractions)}; reliability {paper.reliability:.0%})",
    )


def seed_steps(
    episodes: pd.DataFrame,
    thresholds: tuple[float, ...],
    budget: int,
    window: int = 100,
    seeds: Sequence[int] | None = None,
) -> tuple[np.ndarray, np.ndarray]:
    """Per seed (ascending), censored steps to each threshold (a DNF at ``budget``) and whether it
    was reached, both shape ``(n_seeds, K)``; a seed of ``seeds`` without episodes is a DNF everywhere."""
    steps, reached = [], []
    for seed in sorted(set(episodes["seed"]) if seeds is None else seeds):
        ep = episodes[episodes["seed"] == seed]
        ts, ret = ep["timestep"].to_numpy(), ep["native_return"].to_numpy()
        hits = [steps_to_threshold(ts, ret, t, window) for t in thresholds]
        raw = np.asarray([math.nan if h is None else float(h) for h in hits])
        steps.append(censored.restricted(raw, budget))  # the one DNF rule (analysis/censored.py)
        reached.append(censored.reached(raw, budget))
    k = len(thresholds)
    return np.asarray(steps, dtype=float).reshape(-1, k), np.asarray(reached, dtype=bool).reshape(-1, k)


def distance(steps: npt.ArrayLike, reached: npt.ArrayLike, target: TargetProfile) -> float:
    """``D`` for censored ``steps`` (``(n_seeds, K)``) and ``reached`` (``(n_seeds,)``)."""
    s = np.asarray(steps, dtype=float)
    r = np.asarray(reached, dtype=float)
    return float(_distance_stat(*s.T, r, target=target))


def _distance_stat(*columns: np.ndarray, target: TargetProfile, axis: int = -1) -> np.ndarray:
    """Vectorised ``D``: ``columns`` are K censored-step arrays and one reached array, seeds on ``axis``."""
    *step_cols, reached = columns
    log_term = np.mean(
        [np.abs(np.log(np.mean(c, axis=axis) / t)) for c, t in zip(step_cols, target.steps, strict=True)], axis=0
    )
    return np.asarray(log_term + np.abs(np.mean(reached, axis=axis) - target.reliability))


def distance_ci(
    steps: npt.ArrayLike,
    reached: npt.ArrayLike,
    target: TargetProfile,
    rng: np.random.Generator,
    n_boot: int = DEFAULT_N_BOOT,
    ci: float = 0.95,
) -> Estimate:
    """``D`` with a paired percentile bootstrap CI over seeds (NaN bounds and a note below 2 seeds)."""
    s = np.asarray(steps, dtype=float)
    r = np.asarray(reached, dtype=float).reshape(-1)
    value = distance(s, r, target)
    if r.size < 2:
        return Estimate(value, n=int(r.size), note="fewer than 2 seeds: no CI")
    low, high = bootstrap_ci((*s.T, r), lambda *cols, axis=-1: _distance_stat(*cols, target=target, axis=axis),
                             rng, n_boot, ci, paired=True)
    if not (np.isfinite(low) and np.isfinite(high)):  # every resample equal: the interval is the point
        low = high = value
    if low > high:  # seeds alike up to rounding: interpolated percentiles can cross by an ulp
        low, high = high, low
    return Estimate(value, low, high, n=int(r.size))


@dataclass(frozen=True)
class RegimeProfile:
    """One regime's measured profile next to the target: what ``calibration.csv`` holds per row."""

    n_seeds: int
    budget: int
    reliability: Estimate  # fraction reaching the last threshold, Wilson CI
    steps: tuple[Estimate, ...]  # censored mean steps to each threshold, bootstrap CI
    n_reached: tuple[int, ...]  # seeds that reached each threshold within the budget
    distance: Estimate


def regime_profile(
    episodes: pd.DataFrame,
    target: TargetProfile,
    budget: int,
    rng: np.random.Generator,
    window: int = 100,
    n_boot: int = DEFAULT_N_BOOT,
    ci: float = 0.95,
    seeds: Sequence[int] | None = None,
) -> RegimeProfile:
    """The profile of one regime's episode table against ``target``; ``seeds`` as in ``seed_steps``."""
    steps, reached = seed_steps(episodes, target.thresholds, budget, window, seeds)
    return RegimeProfile(
        n_seeds=int(reached.shape[0]),
        budget=int(budget),
        reliability=reliability(reached[:, -1], ci),
        steps=tuple(censored.restricted_mean(steps[:, k], budget, rng, n_boot, ci) for k in range(steps.shape[1])),
        n_reached=tuple(int(n) for n in reached.sum(axis=0)),
        distance=distance_ci(steps, reached[:, -1], target, rng, n_boot, ci),
    )
