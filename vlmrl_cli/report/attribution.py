"""Attribution: which reward term does the work? Pairwise comparisons of arms over seeds (speedups,
reliability, detached success, learning-curve area, probability of improvement), the seed as unit.
See docs/commands/report.md."""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np
import pandas as pd

from vlmrl_cli.analysis import censored, stats
from vlmrl_cli.analysis.multiplicity import DEFAULT_ADJUST
from vlmrl_cli.analysis.proportions import compare_proportions
from vlmrl_cli.analysis.ranks import DEFAULT_N_PERM, probability_of_improvement, rank_sum_p
from vlmrl_cli.core import tables
from vlmrl_cli.report.table2 import judge_steps, threshold_key
from vlmrl_cli.shaping.arms import ARMS, ArmSpec
from vlmrl_cli.shaping.arms import comparisons as registry_comparisons


@dataclass(frozen=True)
class Pair:
    """Arm ``a`` compared with arm ``b``; ``meaning``: what the difference isolates."""

    a: str
    b: str
    meaning: str

    @property
    def name(self) -> str:
        return f"{self.a} vs {self.b}"


def registry_pairs(registry: Mapping[str, ArmSpec] = ARMS) -> tuple[Pair, ...]:
    """Every comparison of ``registry`` (each arm's ``compared_with``) as a pair, in the report's order.

    Example:
        >>> registry_pairs()[0]
        Pair(a='hybrid', b='baseline', meaning='the whole method')
    """
    return tuple(Pair(a, b, meaning) for a, b, meaning in registry_comparisons(registry))


#: ``p_value``: the raw p of the row's test; ``p_adj``: for speedups, adjusted within the family of
#: every speedup of the table (NaN for other metrics, and for a speedup not measured);
#: ``logrank_p``/``logrank_p_adj``: the log-rank test beside the rank test; ``tests_disagree``: which
#: test alone rejects after adjustment ("" when they agree); ``direction``: P(a faster) - 0.5;
#: ``equivalence_ok``: each arm finished on enough seeds for an equivalence verdict.
COLUMNS = ["pair", "meaning", "metric", "label", "unit", "value", "ci_low", "ci_high", "p_value", "p_adj",
           "logrank_p", "logrank_p_adj", "tests_disagree", "test", "n_a", "n_b", "note", "verdict", "tost_low",
           "tost_high", "direction", "equivalence_ok"]
#: Equivalence margin of the learning-curve area, in return units (a mean return within +-5 of the other arm's).
DEFAULT_AUC_DELTA = 5.0


def present_pairs(arms: Sequence[str], registry: Mapping[str, ArmSpec] = ARMS) -> list[Pair]:
    """The pairs of ``registry`` whose two arms both ran.

    Example:
        >>> [p.name for p in present_pairs(["baseline", "hybrid", "kinematic"])]
        ['hybrid vs baseline', 'hybrid vs kinematic', 'kinematic vs baseline']
    """
    have = set(arms)
    return [p for p in registry_pairs(registry) if p.a in have and p.b in have]


def _row(pair: Pair, metric: str, label: str, unit: str, est: stats.Estimate, p_value: float, test: str,
         n_a: int, n_b: int, note: str = "", verdict: str = "", tost: tuple[float, float] = (np.nan, np.nan),
         **steps: Any) -> dict[str, Any]:
    return {"pair": pair.name, "meaning": pair.meaning, "metric": metric, "label": label, "unit": unit,
            "value": est.value, "ci_low": est.low, "ci_high": est.high, "p_value": p_value, "p_adj": np.nan,
            "logrank_p": np.nan, "logrank_p_adj": np.nan, "tests_disagree": "", "test": test,
            "n_a": n_a, "n_b": n_b, "note": "; ".join(filter(None, [est.note, note])), "verdict": verdict,
            "tost_low": tost[0], "tost_high": tost[1], "direction": np.nan, "equivalence_ok": False} | steps


def _proportion_verdict(diff: float, p_value: float, alpha: float) -> str:
    if np.isfinite(p_value) and p_value < alpha and np.isfinite(diff) and diff != 0:
        return censored.HIGHER if diff > 0 else censored.LOWER
    return censored.INCONCLUSIVE


def compare_auc(da: pd.DataFrame, db: pd.DataFrame, rng: np.random.Generator, n_boot: int, ci: float,
                alpha: float, delta: float, n_perm: int = DEFAULT_N_PERM
                ) -> tuple[stats.Estimate, float, str, tuple[float, float], str]:
    """Learning-curve area of arm a minus arm b (return units) with a bootstrap CI, a two-sided
    Mann-Whitney p, the verdict, the ``1 - 2 alpha`` interval of its equivalence test and the p's method."""
    a, b = da["auc"].to_numpy(dtype=float), db["auc"].to_numpy(dtype=float)
    a, b = a[np.isfinite(a)], b[np.isfinite(b)]
    est = stats.difference_of_means(a, b, rng, n_boot, ci)
    tost = stats.difference_of_means(a, b, rng, n_boot, 1 - 2 * alpha)
    p, method = rank_sum_p(a, b, n_perm) if a.size >= 2 and b.size >= 2 else (np.nan, "no test")
    verdict = censored.difference_verdict(est, (tost.low, tost.high), p, alpha, delta)
    return est, p, verdict, (tost.low, tost.high), method


def compare_arms(
    per_seed: pd.DataFrame, thresholds: Sequence[float], rng: np.random.Generator | stats.Streams,
    n_boot: int = stats.DEFAULT_N_BOOT, ci: float = 0.95, n_perm: int = DEFAULT_N_PERM,
    alpha: float = 0.05, margin: float = censored.DEFAULT_MARGIN, auc_delta: float = DEFAULT_AUC_DELTA,
    pairs: Sequence[Pair] | None = None, adjust: str = DEFAULT_ADJUST, registry: Mapping[str, ArmSpec] = ARMS,
) -> pd.DataFrame:
    """Every comparison of every present pair (columns ``COLUMNS``), from ``per_seed`` (see ``per_seed_table``).

    The speedups form one family, adjusted by ``adjust`` (``adjust_family``); a caller whose family
    spans several frames (the study) passes ``"none"`` and adjusts it itself. ``pairs``: default,
    those of ``registry`` whose two arms are present.
    """
    rows: list[dict[str, Any]] = []
    top = max(thresholds)
    chosen = present_pairs(per_seed["arm"].unique().tolist(), registry) if pairs is None else pairs
    for pair in chosen:
        da, db = per_seed[per_seed["arm"] == pair.a], per_seed[per_seed["arm"] == pair.b]
        for t in thresholds:
            judged, test, logrank = judge_steps(per_seed, pair.a, pair.b, t, ci, n_perm, alpha, margin)
            rows.append(_row(pair, f"speedup_{t:g}", f"Speedup to {t:g} ({pair.a} over {pair.b})", "x",
                             judged.speedup, test.p_value,
                             f"Mann-Whitney U on steps, DNF censored ({test.method} p)", test.n_a, test.n_b,
                             "; ".join(filter(None, [f"P({pair.a} faster) = {test.p_faster:.2f}", test.note])),
                             judged.text, (judged.tost_low, judged.tost_high), logrank_p=logrank.p_value,
                             direction=judged.direction, equivalence_ok=judged.equivalence_allowed))
        key = threshold_key(top)
        rel = compare_proportions(censored.reached(da[key].to_numpy(dtype=float), da["budget"].to_numpy(dtype=float)),
                                  censored.reached(db[key].to_numpy(dtype=float), db["budget"].to_numpy(dtype=float)),
                                  ci)
        rows.append(_row(pair, "reliability_diff", f"Reliability difference (seeds reaching {top:g})", "%",
                         rel.difference, rel.p_value, rel.test, rel.n_a, rel.n_b,
                         verdict=_proportion_verdict(rel.difference.value, rel.p_value, alpha)))
        det = compare_proportions(da["detached_success"].to_numpy(dtype=float),
                                  db["detached_success"].to_numpy(dtype=float), ci)
        rows.append(_row(pair, "detached_success_diff", "Detached success difference (seeds)", "%",
                         det.difference, det.p_value, det.test, det.n_a, det.n_b,
                         verdict=_proportion_verdict(det.difference.value, det.p_value, alpha)))
        if "auc" in per_seed:
            auc, p_auc, v_auc, tost, how = compare_auc(da, db, stats.stream(rng, f"attribution/auc/{pair.name}"),
                                                       n_boot, ci, alpha, auc_delta, n_perm)
            rows.append(_row(pair, "auc_diff", "Learning-curve area difference (mean native return over the "
                             "budget, a minus b)", "return", auc, p_auc, f"Mann-Whitney U on per-seed areas ({how} p)",
                             int(da["auc"].notna().sum()), int(db["auc"].notna().sum()), verdict=v_auc, tost=tost))
        poi = probability_of_improvement(da["final_return"], db["final_return"],
                                         stats.stream(rng, f"attribution/poi/{pair.name}"), n_boot, ci)
        rows.append(_row(pair, "poi_final_return", "P(final return higher)", "p", poi, float("nan"),
                         "bootstrap over seeds (descriptive)", int(da["final_return"].notna().sum()),
                         int(db["final_return"].notna().sum())))
    return adjust_family(pd.DataFrame(rows, columns=COLUMNS), adjust, alpha, margin)


def is_family(comparisons: pd.DataFrame) -> pd.Series:
    """The rows of the steps family: every speedup that was measured (a finite ratio)."""
    return comparisons["metric"].str.startswith("speedup_") & np.isfinite(comparisons["value"].astype(float))


def adjust_family(comparisons: pd.DataFrame, method: str = DEFAULT_ADJUST, alpha: float = 0.05,
                  margin: float = censored.DEFAULT_MARGIN) -> pd.DataFrame:
    """``comparisons`` with its measured speedups adjusted as one family and re-judged
    (``censored.judge_family``); other metrics keep their verdicts on their raw p."""
    out = comparisons.copy()
    fam = is_family(out).to_numpy()
    if not fam.any():
        return out
    rows = out[fam]
    judged = censored.judge_family(rows["p_value"], rows["logrank_p"], rows["direction"],
                                   rows[["ci_low", "ci_high"]], rows[["tost_low", "tost_high"]],
                                   rows["equivalence_ok"].astype(bool), method, alpha, margin)
    out.loc[fam, "p_adj"] = judged.p_adjusted
    out.loc[fam, "logrank_p_adj"] = judged.logrank_adjusted
    out.loc[fam, "verdict"] = list(judged.verdicts)
    out.loc[fam, "tests_disagree"] = list(judged.disagreement)
    return out


def _find(comparisons: pd.DataFrame, a: str, b: str, metric: str) -> pd.Series | None:
    hit = comparisons[(comparisons["pair"] == f"{a} vs {b}") & (comparisons["metric"] == metric)]
    return None if hit.empty else hit.iloc[0]


def lookup(comparisons: pd.DataFrame, a: str, b: str, metric: str) -> tuple[stats.Estimate, float, float] | None:
    """The estimate, raw p-value and the p its verdict uses (adjusted within the family for a
    speedup, the raw one otherwise) of one comparison, or None when that pair or metric is absent."""
    r = _find(comparisons, a, b, metric)
    if r is None:
        return None
    est = stats.Estimate(float(r["value"]), float(r["ci_low"]), float(r["ci_high"]),
                         int(min(r["n_a"], r["n_b"])), str(r["note"]))
    adjusted = float(r["p_adj"])
    return est, float(r["p_value"]), adjusted if np.isfinite(adjusted) else float(r["p_value"])


def lookup_verdict(comparisons: pd.DataFrame, a: str, b: str, metric: str) -> tuple[str, float, float]:
    """The verdict of one comparison and the ``1 - 2 alpha`` interval its equivalence test used
    (``("", nan, nan)`` when absent)."""
    r = _find(comparisons, a, b, metric)
    if r is None:
        return "", float("nan"), float("nan")
    return str(r["verdict"]), float(r["tost_low"]), float(r["tost_high"])


def _fmt(x: float, unit: str) -> str:
    if not np.isfinite(x):
        return "—"
    if unit == "%":
        return f"{100 * x:+.0f} pts"
    if unit == "x":
        return f"{x:.2f}x"
    if unit == "return":
        return f"{x:+.1f}"
    return f"{x:.2f}"


def _p(x: float) -> str:
    return censored.format_p(x).removeprefix("p = ") if np.isfinite(x) else "—"


def logrank_cell(p_raw: float, p_adj: float, disagree: str) -> str:
    """The log-rank column: raw p, adjusted p, and a warning when it and the rank test disagree.

    Example:
        >>> logrank_cell(0.003, 0.03, "log-rank only")
        '0.003 (adj. 0.03); **disagrees**: only the log-rank rejects'
    """
    if not np.isfinite(p_raw):
        return "—"
    text = f"{_p(p_raw)} (adj. {_p(p_adj)})" if np.isfinite(p_adj) else _p(p_raw)
    if disagree:
        text += "; **disagrees**: only the " + ("log-rank" if disagree == "log-rank only" else "rank test") + \
            " rejects"
    return text


def attribution_markdown(comparisons: pd.DataFrame, ci: float = 0.95, adjust: str = DEFAULT_ADJUST) -> str:
    """Markdown table of ``compare_arms``' rows."""
    rows = []
    for r in comparisons.itertuples(index=False):
        value = _fmt(r.value, r.unit)
        if np.isfinite(r.ci_low) and np.isfinite(r.ci_high):
            value += f" [{_fmt(r.ci_low, r.unit)}, {_fmt(r.ci_high, r.unit)}]"
        rows.append([r.pair, r.meaning, r.label, value, _p(r.p_value), _p(r.p_adj),
                     logrank_cell(r.logrank_p, r.logrank_p_adj, r.tests_disagree), r.test, r.verdict or "—",
                     f"{r.n_a}/{r.n_b}"])
    header = ["Pair", "Isolates", "Metric", f"Ours [{100 * ci:g}% CI]", "p", f"p adjusted ({adjust})",
              f"Log-rank p ({adjust}-adjusted)", "Test", "Verdict", "Seeds (a/b)"]
    return "\n".join(tables.markdown_rows(header, rows)) + "\n"
