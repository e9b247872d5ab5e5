"""Table 2 of the paper (steps to reward thresholds, final reliability), ours beside the paper's:
``per_seed_table`` (one row per run) -> ``build_table2`` (per arm). See docs/commands/report.md."""

from __future__ import annotations

import math
from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np
import pandas as pd

from vlmrl_cli.analysis import censored, stats
from vlmrl_cli.analysis.load import ExperimentData
from vlmrl_cli.analysis.proportions import DETACHED_SUCCESS_CUT, detached_successes
from vlmrl_cli.analysis.ranks import DEFAULT_N_PERM, RankTest, censored_rank_test
from vlmrl_cli.analysis.survival import LogRank, censored_logrank
from vlmrl_cli.analysis.thresholds import full_window_steps_to_threshold, steps_to_threshold
from vlmrl_cli.shaping.arms import ARMS, BASELINE, METHOD, ArmSpec, report_order

NEEDS_BASELINE = "needs baseline arm"


def order_arms(arms: Sequence[str], registry: Mapping[str, ArmSpec] = ARMS) -> list[str]:
    """The registry's report order (the paper's hybrid, baseline first), then any others alphabetically.

    Example:
        >>> order_arms(["kinematic", "zeta", "baseline", "hybrid"])
        ['hybrid', 'baseline', 'kinematic', 'zeta']
    """
    known = report_order(registry)
    present = set(arms)
    return [a for a in known if a in present] + sorted(present - set(known))


def threshold_key(threshold: float) -> str:
    """Column/metric name of a threshold, e.g. ``steps_-130``."""
    return f"steps_{threshold:g}"


def full_window_key(threshold: float) -> str:
    """Column/metric name of a threshold reached by a full window of episodes, e.g. ``full_steps_-130``."""
    return f"full_{threshold_key(threshold)}"


def finishers_key(threshold: float) -> str:
    """Row of the paper's convention (mean over the seeds that finished), e.g. ``finishers_steps_-130``."""
    return f"finishers_{threshold_key(threshold)}"


def per_seed_table(data: ExperimentData, thresholds: Sequence[float], window: int = 100,
                   min_episodes: int = 1, detached_cut: float = DETACHED_SUCCESS_CUT) -> pd.DataFrame:
    """One row per run: steps to each threshold (NaN = DNF; ``full_steps_*``: full windows only), final
    return (last ``window`` episodes), ``auc`` (mean native return over the budget), eval metrics and
    ``detached_success`` (1 when the eval success rate is at least ``detached_cut``)."""
    rows = []
    by_run = dict(tuple(data.episodes.groupby("run_id", sort=False)))
    for run in data.runs.itertuples(index=False):
        ep = by_run.get(run.run_id, data.episodes.iloc[0:0]).sort_values("timestep", kind="stable")
        ts, ret = ep["timestep"].to_numpy(dtype=np.int64), ep["native_return"].to_numpy(dtype=float)
        row: dict[str, Any] = {"arm": run.arm, "seed": run.seed, "run_id": run.run_id,
                               "config_hash": run.config_hash, "preset": run.preset, "budget": run.budget}
        for t in thresholds:
            s = steps_to_threshold(ts, ret, t, window, min_episodes)
            row[threshold_key(t)] = float("nan") if s is None else float(s)
            full = full_window_steps_to_threshold(ts, ret, t, window)
            row[full_window_key(t)] = float("nan") if full is None else float(full)
        row["final_return"] = stats.final_return(ret, window)
        budget = float(run.budget) if pd.notna(run.budget) else math.inf
        lengths = ep["length"].to_numpy(dtype=float) if "length" in ep else np.full(len(ep), np.nan)
        row["auc"] = censored.learning_curve_area(ts, ret, lengths, int(budget) if math.isfinite(budget) else 2**62)
        row["first_window_step"] = float(ts[window - 1]) if len(ts) >= window else float("nan")
        shaped = ep["shaped_return"].to_numpy(dtype=float) if "shaped_return" in ep else np.full(len(ep), np.nan)
        row["shaped_gap"] = stats.final_return(shaped - ret, window)
        row["episodes"] = len(ep)
        row |= {k: getattr(run, k) for k in ("eval_success_rate", "eval_mean_length", "eval_mean_return")}
        row["detached_success"] = float(detached_successes([run.eval_success_rate], detached_cut)[0])
        row["hover_fraction"] = getattr(run, "eval_hover_fraction", float("nan"))
        row["dwell_right_steps"] = getattr(run, "eval_dwell_right_steps", float("nan"))
        rows.append(row)
    return pd.DataFrame(rows)


@dataclass(frozen=True)
class Table2:
    """Per-arm results. ``cells``: one row per (metric, arm) with value, CI, counts, paper value.
    ``speedups``: one row per (threshold, arm != baseline). ``labels``: metric -> row label."""

    arms: tuple[str, ...]
    thresholds: tuple[float, ...]
    cells: pd.DataFrame
    speedups: pd.DataFrame
    labels: dict[str, str]
    ci: float
    paper: dict[str, dict[str, Any]]

    @property
    def has_baseline(self) -> bool:
        return BASELINE in self.arms

    def cell(self, metric: str, arm: str) -> dict[str, Any] | None:
        hit = self.cells[(self.cells["metric"] == metric) & (self.cells["arm"] == arm)]
        return None if hit.empty else dict(hit.iloc[0])

    def speedup(self, threshold: float, arm: str) -> dict[str, Any] | None:
        hit = self.speedups[(self.speedups["metric"] == threshold_key(threshold)) & (self.speedups["arm"] == arm)]
        return None if hit.empty else dict(hit.iloc[0])


def _paper_steps(reported: dict[str, Any], threshold: float) -> dict[str, Any]:
    for row in reported.get("table2", {}).get("steps_to_threshold", []):
        if float(row["threshold"]) == float(threshold):
            return dict(row)
    return {}


def _paper_values(reported: dict[str, Any], metric: str, thresholds: Sequence[float]) -> dict[str, Any]:
    """{arm: value, "speedup": value} the paper reports for ``metric``."""
    for t in thresholds:
        if metric == finishers_key(t):  # the paper's steps are means over the seeds that finished
            return {k: v for k, v in _paper_steps(reported, t).items() if k != "speedup"}
        if metric == threshold_key(t):  # its speedup is shown beside ours, on our headline row
            return {k: v for k, v in _paper_steps(reported, t).items() if k == "speedup"}
    if metric == "reliability":
        return dict(reported.get("table2", {}).get("final_reliability", {}))
    if metric == "eval_success":
        return dict(reported.get("detached_evaluation", {}).get("success_rate", {}))
    if metric == "eval_length":
        return dict(reported.get("detached_evaluation", {}).get("mean_episode_length", {}))
    return {}


def _cell(metric: str, arm: str, est: stats.Estimate, paper: Any, n: int, n_reached: int | None = None) -> dict:
    return {"metric": metric, "arm": arm, "value": est.value, "ci_low": est.low, "ci_high": est.high, "n": n,
            "n_reached": n_reached, "paper": float(paper) if paper is not None else float("nan"), "note": est.note}


def floor_thresholds(per_seed: pd.DataFrame, thresholds: Sequence[float]) -> list[float]:
    """The thresholds every seed of every arm crosses at its first complete window (floors: steps
    there measure how fast episodes end, not learning).

    Example:
        >>> df = pd.DataFrame({"full_steps_-190": [500.0, 510.0], "full_steps_-130": [500.0, 900.0],
        ...                    "first_window_step": [500.0, 510.0]})
        >>> floor_thresholds(df, [-190.0, -130.0])
        [-190.0]
    """
    if "first_window_step" not in per_seed or per_seed.empty:
        return []
    first = per_seed["first_window_step"].to_numpy(dtype=float)
    out = []
    for t in thresholds:
        full = per_seed.get(full_window_key(t))
        if full is not None and np.all(np.isfinite(first)) and np.array_equal(full.to_numpy(dtype=float), first):
            out.append(float(t))
    return out


def build_table2(
    per_seed: pd.DataFrame,
    eval_episodes: pd.DataFrame,
    reported: dict[str, Any],
    thresholds: Sequence[float],
    rng: np.random.Generator | stats.Streams,
    window: int = 100,
    ci: float = 0.95,
    n_boot: int = stats.DEFAULT_N_BOOT,
    detached_cut: float = DETACHED_SUCCESS_CUT,
    n_perm: int = DEFAULT_N_PERM,
    registry: Mapping[str, ArmSpec] = ARMS,
) -> Table2:
    """Table 2 from ``per_seed`` (see ``per_seed_table``) and per-episode eval lengths (may be empty).

    ``rng``: one shared generator, or ``Streams`` for one stream per (metric, arm) so that no cell's
    interval depends on which other cells exist; ``registry``: the arms whose order the columns follow.
    """
    arms = tuple(order_arms(per_seed["arm"].unique().tolist(), registry))
    labels = table2_labels(thresholds, window, detached_cut)
    cells: list[dict[str, Any]] = []
    for arm in arms:  # one arm's cells in the order they draw from a shared generator
        d = per_seed[per_seed["arm"] == arm]
        ev = eval_episodes[eval_episodes["arm"] == arm] if len(eval_episodes) else eval_episodes
        cells += _steps_cells(d, arm, reported, thresholds, rng, n_boot, ci)
        cells += _success_cells(d, arm, reported, thresholds, ci, detached_cut)
        cells.append(_length_cell(d, ev, arm, reported, thresholds, rng, n_boot, ci))
        cells += _final_cells(d, arm, window, rng, n_boot, ci)
    speed_rows = _speedup_rows(per_seed, arms, reported, thresholds, ci, n_perm)
    paper_values = {m: _paper_values(reported, m, thresholds) for m in labels}
    return Table2(arms, tuple(thresholds), pd.DataFrame(cells), pd.DataFrame(speed_rows, columns=list(SPEED_COLUMNS)),
                  labels, ci, paper_values)


def table2_labels(thresholds: Sequence[float], window: int = 100, detached_cut: float = DETACHED_SUCCESS_CUT
                  ) -> dict[str, str]:
    """The row label of every metric of Table 2, in its rows' order.

    Example:
        >>> table2_labels([-130.0])["steps_-130"]
        'Steps to reach -130 (restricted mean, DNF at the budget)'
    """
    top = max(thresholds)
    labels = {threshold_key(t): f"Steps to reach {t:g} (restricted mean, DNF at the budget)" for t in thresholds}
    labels |= {full_window_key(t): f"Steps to reach {t:g}, full {window}-episode window (restricted mean)"
               for t in thresholds}
    labels |= {finishers_key(t): f"Steps to reach {t:g}, mean over the seeds that finished (the paper's "
                                 "convention; no verdict rests on it)" for t in thresholds}
    return labels | {
        "reliability": f"Final reliability (seeds reaching {top:g})",
        "eval_success": f"Detached eval: seeds succeeding (success rate >= {100 * detached_cut:g}%)",
        "eval_success_mean": "Detached eval success rate (mean over seeds, no CI)",
        "eval_length": "Detached eval mean episode length",
        "final_iqm": f"Final return IQM (last {window} episodes)",
        "final_std": "Final return std across seeds",
    }


def _steps_cells(d: pd.DataFrame, arm: str, reported: dict[str, Any], thresholds: Sequence[float],
                 rng: np.random.Generator | stats.Streams, n_boot: int, ci: float) -> list[dict[str, Any]]:
    """One arm's restricted mean steps (DNF at the budget) to each threshold, partial and full window,
    and the paper's mean over the seeds that finished."""
    cells = []
    budget = d["budget"].to_numpy(dtype=float)
    for t in thresholds:
        for key in (threshold_key(t), full_window_key(t)):
            if key not in d:
                continue
            s = d[key].to_numpy(dtype=float)
            est = censored.restricted_mean(s, budget, stats.stream(rng, f"table2/{key}/{arm}"), n_boot, ci)
            c = _cell(key, arm, est, None, len(d), int(censored.reached(s, budget).sum()))
            summ = stats.summarize_steps(s, budget, stats.stream(rng, f"table2/finishers/{key}/{arm}"), n_boot, ci)
            cells.append(c | {"median": summ.median, "censored_mean": summ.censored_mean, "std": summ.std,
                              "iqr": summ.iqr})
            if key == threshold_key(t):  # the paper's own convention, beside ours, for its table
                cells.append(_cell(finishers_key(t), arm, summ.mean,
                                   _paper_values(reported, key, thresholds).get(arm), len(d), summ.n_reached))
    return cells


def _success_cells(d: pd.DataFrame, arm: str, reported: dict[str, Any], thresholds: Sequence[float], ci: float,
                   detached_cut: float) -> list[dict[str, Any]]:
    """One arm's reliability and detached success (seeds; Wilson intervals), and its mean success rate."""
    budget = d["budget"].to_numpy(dtype=float)
    reached = censored.reached(d[threshold_key(max(thresholds))].to_numpy(dtype=float), budget)
    rel = stats.reliability(reached, ci)
    rates = d["eval_success_rate"].to_numpy(dtype=float)
    per_seed_ok = detached_successes(rates, detached_cut)
    per_seed_ok = per_seed_ok[np.isfinite(per_seed_ok)]
    succ = stats.reliability(per_seed_ok > 0.5, ci)
    finite_rates = rates[np.isfinite(rates)]
    mean_rate = stats.Estimate(float(finite_rates.mean()) if finite_rates.size else float("nan"),
                               n=int(finite_rates.size), note="per-episode rates averaged over seeds")
    return [
        _cell("reliability", arm, rel, _paper_values(reported, "reliability", thresholds).get(arm), len(d),
              int(reached.sum())),
        _cell("eval_success", arm, succ, _paper_values(reported, "eval_success", thresholds).get(arm), succ.n,
              int(per_seed_ok.sum())),
        _cell("eval_success_mean", arm, mean_rate, None, mean_rate.n),
    ]


def _length_cell(d: pd.DataFrame, ev: pd.DataFrame, arm: str, reported: dict[str, Any], thresholds: Sequence[float],
                 rng: np.random.Generator | stats.Streams, n_boot: int, ci: float) -> dict[str, Any]:
    """One arm's detached mean episode length: its episodes ``ev`` pooled over seeds, else its seeds' means."""
    length_rng = stats.stream(rng, f"table2/eval_length/{arm}")
    if len(ev):
        length = stats.mean_ci(ev["length"].to_numpy(dtype=float), length_rng, n_boot, ci)
        length = stats.Estimate(length.value, length.low, length.high, length.n,
                                f"{len(ev)} episodes pooled over {ev['seed'].nunique()} seeds")
    else:
        length = stats.mean_ci(d["eval_mean_length"].to_numpy(dtype=float), length_rng, n_boot, ci)
    return _cell("eval_length", arm, length, _paper_values(reported, "eval_length", thresholds).get(arm), length.n)


def _final_cells(d: pd.DataFrame, arm: str, window: int, rng: np.random.Generator | stats.Streams, n_boot: int,
                 ci: float) -> list[dict[str, Any]]:
    """One arm's final return over seeds: its IQM with a bootstrap CI, and its standard deviation."""
    final = d["final_return"].to_numpy(dtype=float)
    iqm = stats.iqm_ci(final, stats.stream(rng, f"table2/final_iqm/{arm}"), n_boot, ci)
    fin = final[np.isfinite(final)]
    std = float(fin.std(ddof=1)) if fin.size >= 2 else float("nan")
    return [_cell("final_iqm", arm, iqm, None, len(d)), _cell("final_std", arm, stats.Estimate(std, n=int(fin.size)),
                                                              None, len(d))]


#: The columns of ``Table2.speedups``.
SPEED_COLUMNS = ("metric", "arm", "value", "ci_low", "ci_high", "n", "paper", "note", "p_value", "p_faster")


def _speedup_rows(per_seed: pd.DataFrame, arms: Sequence[str], reported: dict[str, Any], thresholds: Sequence[float],
                  ci: float, n_perm: int) -> list[dict[str, Any]]:
    """Every other arm's speedup over the baseline to each threshold with its censored rank test (NaN
    without a baseline); the paper's speedup beside the hybrid's."""
    rows: list[dict[str, Any]] = []
    for t in thresholds:
        paper = _paper_steps(reported, t).get("speedup")
        for arm in arms:
            if arm == BASELINE:
                continue
            if BASELINE in arms:
                est, test = compare_steps(per_seed, arm, BASELINE, t, ci, n_perm)
            else:
                est, test = stats.Estimate(float("nan"), note=NEEDS_BASELINE), None
            rows.append({"metric": threshold_key(t), "arm": arm, "value": est.value, "ci_low": est.low,
                         "ci_high": est.high, "n": est.n,
                         "paper": float(paper) if paper is not None and arm == METHOD else float("nan"),
                         "note": est.note, "p_value": test.p_value if test else float("nan"),
                         "p_faster": test.p_faster if test else float("nan")})
    return rows


def compare_steps(
    per_seed: pd.DataFrame, arm: str, ref: str, threshold: float, ci: float = 0.95, n_perm: int = DEFAULT_N_PERM,
) -> tuple[stats.Estimate, RankTest]:
    """Speedup of ``arm`` over ``ref`` to ``threshold`` (ratio of restricted mean steps, delta-method
    interval on its log: ``censored.speedup``) and the censored rank test: ``judge_steps`` without its verdict."""
    judged, test, _ = judge_steps(per_seed, arm, ref, threshold, ci, n_perm)
    return judged.speedup, test


def judge_steps(
    per_seed: pd.DataFrame, arm: str, ref: str, threshold: float, ci: float = 0.95, n_perm: int = DEFAULT_N_PERM,
    alpha: float = 0.05, margin: float = censored.DEFAULT_MARGIN,
) -> tuple[censored.Verdict, RankTest, LogRank]:
    """``compare_steps``, its verdict on the raw rank-test p (``censored.steps_verdict``; a family's
    adjustment re-judges it later) and the log-rank test beside it."""
    key = threshold_key(threshold)
    mine, theirs = per_seed["arm"] == arm, per_seed["arm"] == ref
    a, r = per_seed.loc[mine, key].to_numpy(dtype=float), per_seed.loc[theirs, key].to_numpy(dtype=float)
    budget_a = per_seed.loc[mine, "budget"].to_numpy(dtype=float)
    budget_r = per_seed.loc[theirs, "budget"].to_numpy(dtype=float)
    test = censored_rank_test(a, r, n_perm, budget_a, budget_r)
    judged = censored.steps_verdict(r, a, budget_r, budget_a, test.p_value, ci, alpha, margin,
                                    direction=test.p_faster - 0.5)
    return judged, test, censored_logrank(a, r, budget_a, budget_r)
