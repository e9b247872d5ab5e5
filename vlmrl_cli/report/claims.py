"""The paper's quantitative claims, each with our measured value, CI and a verdict under ``VERDICT_RULE``
(printed in every ``claims.md``; see docs/commands/report.md)."""

from __future__ import annotations

import math
from dataclasses import dataclass, field, replace
from pathlib import Path
from typing import Any

import numpy as np
import pandas as pd

from vlmrl_cli.analysis import stats
from vlmrl_cli.core import tables
from vlmrl_cli.report.attribution import compare_arms, lookup, lookup_verdict
from vlmrl_cli.report.table2 import Table2, threshold_key
from vlmrl_cli.shaping.arms import BASELINE, METHOD, PURE_VISION

MIN_SEEDS = 3
APPROX_TOLERANCE = 0.10
REPRODUCED, NOT_REPRODUCED, INCONCLUSIVE, NOT_TESTED = "reproduced", "not reproduced", "inconclusive", "not tested"

VERDICT_RULE = (
    f"Fewer than {MIN_SEEDS} seeds behind an estimate, or no computable CI: inconclusive; an arm the claim needs is "
    "absent: not tested. Comparative claims (effect vs a null: speedup vs 1x, reliability gap vs 0, spread "
    "difference vs 0): reproduced if our whole 95% CI lies strictly on the paper's side of the null; not "
    "reproduced if it lies entirely on the other side (null included) or excludes the paper's value while "
    "containing the null; otherwise inconclusive. Absolute claims (one arm's value): not reproduced if our 95% CI "
    f"excludes the paper's value (+-{100 * APPROX_TOLERANCE:.0f}% where the paper says '~'); reproduced if it holds "
    f"it and our estimate is within {100 * APPROX_TOLERANCE:.0f}% of it (or of the '~' tolerance); otherwise "
    "inconclusive (the CI is too wide to tell). A comparative claim with a test p-value (Fisher exact for "
    "proportions of seeds, Mann-Whitney U with DNF censored for steps) is reproduced only if that p-value is also "
    "below 1 - the CI level; otherwise inconclusive. For a speedup that p is the one adjusted within the report's "
    "family of speedups (every pair and threshold of the attribution table; Holm unless --adjust says otherwise). "
    "Proportions of seeds get score intervals (Wilson for one arm, "
    "Newcombe's hybrid score interval for a difference), never a bootstrap that collapses to a point. A claim that "
    "credits the VLM itself is judged on hybrid vs kinematic (same dense term, with and without the VLM); "
    "without the kinematic arm it is not tested. A speedup claim that would be inconclusive is not reproduced "
    "when the two arms are equivalent within the margin by two one-sided tests on the ratio of restricted means "
    "(the 90% interval inside [1/1.15, 1.15] by default): 'no difference' is judged by an equivalence test, "
    "never by a large p."
)


def verdict(estimate: stats.Estimate, paper: float | None, null: float | None = None, direction: str = ">",
            approximate: bool = False, n_seeds: int | None = None, p_value: float | None = None,
            alpha: float = 0.05) -> tuple[str, str]:
    """The verdict and its reason for one claim (see ``VERDICT_RULE``).

    ``paper``: None for a purely directional claim; ``null``: the no-effect value of a comparative
    claim (None: an absolute claim), ``direction`` the paper's side of it; ``approximate``: the paper
    says "~"; ``n_seeds``: the fewest seeds in any arm (default ``estimate.n``); ``p_value``: the
    claim's test p (NaN or None: no test).

    Example:
        >>> verdict(stats.Estimate(1.5, 1.2, 1.9, n=5), 1.4, null=1.0)
        ('reproduced', 'CI [1.2, 1.9] lies above 1; the paper value 1.4 is inside it')
        >>> verdict(stats.Estimate(1.5, 1.2, 1.9, n=2), 1.4, null=1.0)[0]
        'inconclusive'
        >>> verdict(stats.Estimate(1.5, 1.2, 1.9, n=5), 1.4, null=1.0, p_value=0.2)[0]
        'inconclusive'
    """
    n = estimate.n if n_seeds is None else n_seeds
    if n < MIN_SEEDS:
        return INCONCLUSIVE, f"only {n} seed(s) behind the estimate (need >= {MIN_SEEDS})"
    if not estimate.has_ci:
        return INCONCLUSIVE, "no CI: " + (estimate.note or "not computable")
    if null is None:
        return _absolute_verdict(estimate, paper, approximate)
    lo, hi = estimate.low, estimate.high
    ci_text = f"CI [{lo:.3g}, {hi:.3g}]"
    above = direction == ">"
    on_side = lo > null if above else hi < null
    against = hi <= null if above else lo >= null
    side = "above" if above else "below"
    inside = paper is not None and lo <= paper <= hi
    tested = p_value is not None and math.isfinite(p_value)
    p_text = f"; test p={p_value:.2g}" if tested else ""
    if on_side:
        tail = "" if paper is None else (f"; the paper value {paper:g} is inside it" if inside
                                         else f"; the paper value {paper:g} is outside it (magnitude differs)")
        if tested and p_value is not None and p_value >= alpha:
            return INCONCLUSIVE, f"{ci_text} lies {side} {null:g}{tail}, but the test p={p_value:.2g} >= {alpha:g}"
        return REPRODUCED, f"{ci_text} lies {side} {null:g}{tail}{p_text}"
    if against:
        return NOT_REPRODUCED, f"{ci_text} is not {side} {null:g}: no effect in the paper's direction{p_text}"
    if paper is not None and not inside:
        return NOT_REPRODUCED, f"{ci_text} contains {null:g} and excludes the paper value {paper:g}{p_text}"
    return INCONCLUSIVE, (f"{ci_text} contains the null {null:g}" + ("" if paper is None else f" and {paper:g}")
                          + p_text)


def _absolute_verdict(estimate: stats.Estimate, paper: float | None, approximate: bool) -> tuple[str, str]:
    """``verdict`` of an absolute claim: does our CI hold the paper's value, and our estimate lie near it?"""
    if paper is None:
        return INCONCLUSIVE, "the paper gives no value"
    ci_text = f"CI [{estimate.low:.3g}, {estimate.high:.3g}]"
    tol = abs(paper) * APPROX_TOLERANCE if approximate else 0.0
    shown = f"{paper:g}" + (f" +-{tol:g}" if tol else "")
    if not (estimate.low <= paper + tol and estimate.high >= paper - tol):
        return NOT_REPRODUCED, f"{ci_text} excludes the paper value {shown}"
    if abs(estimate.value - paper) <= max(tol, abs(paper) * APPROX_TOLERANCE):
        return REPRODUCED, f"{ci_text} holds the paper value {shown}; our estimate {estimate.value:.3g} is close"
    return INCONCLUSIVE, (f"{ci_text} holds the paper value {shown}, but our estimate {estimate.value:.3g} is far "
                          "from it: too few seeds to tell")


@dataclass(frozen=True)
class ClaimResult:
    id: str
    section: str
    claim: str
    paper: float | None
    estimate: stats.Estimate
    unit: str
    verdict: str
    reason: str
    p_value: float = float("nan")  # the p the verdict used: for a speedup, adjusted within the report's family
    arms: str = ""  # the comparison judged, e.g. "hybrid vs kinematic"
    p_raw: float = float("nan")  # the test's own p, before any adjustment


def _est_from_cell(cell: dict[str, Any] | None) -> stats.Estimate:
    if cell is None:
        return stats.Estimate(float("nan"))
    return stats.Estimate(float(cell["value"]), float(cell["ci_low"]), float(cell["ci_high"]), int(cell["n"] or 0),
                          str(cell["note"] or ""))


_NULLS = {"x": 1.0, "%": 0.0}


def evaluate_claims(
    table: Table2, per_seed: pd.DataFrame, reported: dict[str, Any], rng: np.random.Generator | stats.Streams,
    n_boot: int = stats.DEFAULT_N_BOOT, ci: float = 0.95, comparisons: pd.DataFrame | None = None,
) -> list[ClaimResult]:
    """Every claim in ``reported["claims"]`` measured on our runs, with its verdict.

    ``comparisons``: the attribution table (``attribution.compare_arms``), computed here when not
    given. A claim with ``"vs": ARM`` and ``"metric": M`` is judged on hybrid vs ARM's comparison M.
    """
    if comparisons is None:
        comparisons = compare_arms(per_seed, table.thresholds, rng, n_boot, ci)
    arms = set(table.arms)
    results = []
    for spec in reported.get("claims", []):  # in order: a claim's draws come after the one before
        comparison = _comparison_of(spec)
        if comparison is not None:
            measure = _measure_comparison(comparison, table, comparisons, arms)
        else:
            measure = _measure_value(spec["id"], table, per_seed, arms, rng, n_boot, ci)
        results.append(_judge(spec, measure, per_seed, comparisons, arms, ci))
    return results


@dataclass(frozen=True)
class _Measure:
    """What one claim is judged on (``verdict``'s arguments), the arms it needs, the comparison (a, b,
    metric) of a comparative claim, and why it cannot be tested, if known before its arms are looked at."""

    need: frozenset[str] = frozenset()
    est: stats.Estimate = field(default_factory=lambda: stats.Estimate(float("nan")))
    unit: str = ""
    null: float | None = None
    direction: str = ">"
    n_seeds: int | None = None
    p_value: float = float("nan")
    p_raw: float = float("nan")
    comparison: tuple[str, str, str] | None = None
    untestable: str = ""

    @property
    def pair(self) -> str:
        return "" if self.comparison is None else f"{self.comparison[0]} vs {self.comparison[1]}"


def _comparison_of(spec: dict[str, Any]) -> tuple[str, str, str] | None:
    """The (a, b, metric) a comparative claim is judged on; None for a claim about one arm's value.

    Example:
        >>> _comparison_of({"id": "speedup_-130"}), _comparison_of({"id": "x", "vs": "kinematic", "metric": "m"})
        (('hybrid', 'baseline', 'speedup_-130'), ('hybrid', 'kinematic', 'm'))
    """
    if "vs" in spec:
        return METHOD, str(spec["vs"]), str(spec["metric"])
    if spec["id"].startswith("speedup_"):
        return METHOD, BASELINE, spec["id"]
    if spec["id"] == "reliability_gap":
        return METHOD, BASELINE, "reliability_diff"
    return None


def _measure_comparison(comparison: tuple[str, str, str], table: Table2, comparisons: pd.DataFrame,
                        arms: set[str]) -> _Measure:
    """A comparative claim's estimate and p from the attribution table; for a speedup, the fewest
    seeds that reached its threshold in either arm."""
    a, b, metric = comparison
    speedup = metric.startswith("speedup_")
    unit = "x" if speedup else "%"
    measure = _Measure(need=frozenset({a, b}), unit=unit, null=_NULLS[unit], comparison=comparison)
    if speedup and float(metric.removeprefix("speedup_")) not in table.thresholds:
        return replace(measure, untestable=f"threshold {metric.removeprefix('speedup_')} not in this report's "
                                           "thresholds")
    if not measure.need <= arms:
        return measure
    found = lookup(comparisons, a, b, metric)
    if found is not None:
        est, p_raw, p_value = found
        measure = replace(measure, est=est, p_raw=p_raw, p_value=p_value)
    if speedup:
        t = float(metric.removeprefix("speedup_"))
        measure = replace(measure, n_seeds=min(_n_reached(table, t, a), _n_reached(table, t, b)))
    return measure


def _measure_value(cid: str, table: Table2, per_seed: pd.DataFrame, arms: set[str],
                   rng: np.random.Generator | stats.Streams, n_boot: int, ci: float) -> _Measure:
    """A claim about one arm's value (reliability, detached success or length), or the spread of
    the hybrid's final returns against the baseline's (``narrower_variance``)."""
    if cid in ("reliability_hybrid", "reliability_baseline"):
        arm = cid.removeprefix("reliability_")
        return _Measure(frozenset({arm}), _est_from_cell(table.cell("reliability", arm)), "%")
    if cid.startswith("detached_success_"):
        arm = cid.removeprefix("detached_success_")
        return _Measure(frozenset({arm}), _est_from_cell(table.cell("eval_success", arm)), "%")
    if cid == "detached_length_hybrid":
        return _Measure(frozenset({METHOD}), _est_from_cell(table.cell("eval_length", METHOD)), " steps",
                        n_seeds=int((per_seed["arm"] == METHOD).sum()))
    if cid == "narrower_variance":
        need = frozenset({METHOD, BASELINE})
        est = stats.Estimate(float("nan"))
        if need <= arms:
            a_ret = per_seed.loc[per_seed["arm"] == METHOD, "final_return"].to_numpy(dtype=float)
            b_ret = per_seed.loc[per_seed["arm"] == BASELINE, "final_return"].to_numpy(dtype=float)
            est = stats.std_difference(a_ret, b_ret, stats.stream(rng, "claims/narrower_variance"), n_boot, ci)
        return _Measure(need, est, "", null=0.0, direction="<")
    if cid == "zero_convergence":
        return _Measure(frozenset({PURE_VISION}), _est_from_cell(table.cell("reliability", PURE_VISION)), "%")
    return _Measure()


def _judge(spec: dict[str, Any], m: _Measure, per_seed: pd.DataFrame, comparisons: pd.DataFrame, arms: set[str],
           ci: float) -> ClaimResult:
    """One claim's result: not tested (an arm missing, or a threshold this report has not), else
    ``verdict`` on its measure, an inconclusive speedup re-judged by the equivalence test."""
    cid, paper = spec["id"], spec.get("value")
    paper_f = None if paper is None else float(paper)
    missing = m.need - arms
    if m.untestable or missing:
        reason = m.untestable or _missing_reason(cid, missing)
        return ClaimResult(cid, spec["section"], spec["text"], paper_f, m.est, m.unit, NOT_TESTED, reason,
                           arms=m.pair)
    n_seeds = m.n_seeds if m.n_seeds is not None else min(int((per_seed["arm"] == a).sum()) for a in m.need)
    v, reason = verdict(m.est, paper_f, m.null, m.direction, bool(spec.get("approximate")), n_seeds, m.p_value,
                        1.0 - ci)
    v, reason = _by_equivalence(v, reason, m.comparison, comparisons)
    return ClaimResult(cid, spec["section"], spec["text"], paper_f, m.est, m.unit, v, _explained(reason, cid, m),
                       m.p_value, m.pair, m.p_raw)


def _missing_reason(cid: str, missing: set[str] | frozenset[str]) -> str:
    reason = f"arm {', '.join(sorted(missing))} not in this experiment"
    if cid == "zero_convergence":
        reason += "; see `vlmrl taxonomy` for the pure-vision failure modes"
    return reason


def _by_equivalence(v: str, reason: str, comparison: tuple[str, str, str] | None, comparisons: pd.DataFrame
                    ) -> tuple[str, str]:
    """An inconclusive speedup claim whose arms are equivalent within the margin (two one-sided
    tests) is not reproduced: "no effect" is a claim too, judged by TOST, not by a large p."""
    if comparison is None or not comparison[2].startswith("speedup_") or v != INCONCLUSIVE:
        return v, reason
    judged, low, high = lookup_verdict(comparisons, *comparison)
    if not judged.startswith("equivalent"):
        return v, reason
    return NOT_REPRODUCED, (f"{judged} by two one-sided tests (interval [{low:.3g}, {high:.3g}]): no speedup as "
                            f"large as the margin; {reason}")


def _explained(reason: str, cid: str, m: _Measure) -> str:
    """``reason`` with what the claim measures, the adjustment of its p and the comparison judged."""
    if cid == "narrower_variance":
        reason = "measure: std across seeds of the final return, hybrid minus baseline; " + reason
    if math.isfinite(m.p_raw) and m.p_raw != m.p_value:
        reason += f" (p adjusted within the report's family of speedups; raw p={m.p_raw:.2g})"
    if m.pair:
        reason = f"judged on {m.pair}; " + reason
    return reason


def _n_reached(table: Table2, threshold: float, arm: str) -> int:
    c = table.cell(threshold_key(threshold), arm)
    return int(c["n_reached"]) if c is not None else 0


def _fmt(x: float | None, unit: str) -> str:
    if x is None or (isinstance(x, float) and math.isnan(x)):
        return "—"
    if unit == "%":
        return f"{100 * x:.0f}%"
    if unit == "x":
        return f"{x:.2f}x"
    return f"{x:.3g}{unit}"


def claims_frame(results: list[ClaimResult]) -> pd.DataFrame:
    """Numeric table (CSV): one row per claim."""
    return pd.DataFrame([{
        "id": r.id, "section": r.section, "claim": r.claim, "paper": r.paper, "ours": r.estimate.value,
        "ci_low": r.estimate.low, "ci_high": r.estimate.high, "n": r.estimate.n, "p_raw": r.p_raw, "p_value": r.p_value,
        "arms": r.arms, "verdict": r.verdict, "reason": r.reason, "note": r.estimate.note,
    } for r in results])


def claims_markdown(results: list[ClaimResult]) -> str:
    """Markdown table: claim, section, arms compared, paper, ours [CI], p-value, verdict, reason."""
    rows = []
    for r in results:
        ours = _fmt(r.estimate.value, r.unit)
        if r.estimate.has_ci:
            ours += f" [{_fmt(r.estimate.low, r.unit)}, {_fmt(r.estimate.high, r.unit)}]"
        paper = "narrower" if r.id == "narrower_variance" else _fmt(r.paper, r.unit)
        if r.paper is None and r.unit in _NULLS and r.arms:  # a directional comparison: an effect beyond the null
            paper = f"> {_fmt(_NULLS[r.unit], r.unit)}"
        if r.id == "detached_length_hybrid" and r.paper is not None:
            paper = "~" + paper
        raw = f"{r.p_raw:.2g}" if math.isfinite(r.p_raw) else "—"
        used = f"{r.p_value:.2g}" if math.isfinite(r.p_value) else "—"
        rows.append([r.claim, r.section, r.arms or "—", paper, ours, raw, used, f"**{r.verdict}**", r.reason])
    header = ["Claim", "Section", "Arms", "Paper", "Ours [95% CI]", "p", "p judged (speedups: adjusted)", "Verdict",
              "Why"]
    return "\n".join(tables.markdown_rows(header, rows)) + "\n"


def write_claims(results: list[ClaimResult], out: Path, vlm_note: str) -> list[Path]:
    """Write ``claims.md`` (with the verdict rule and ``vlm_note``, the VLM behind the shaped arms)
    and ``claims.csv`` (``vlm_note`` as a ``vlm`` column); returns their paths."""
    md, csv = out / "claims.md", out / "claims.csv"
    md.write_text("# Claims of the paper vs our runs\n\n" + vlm_note + ".\n\nVerdict rule: " + VERDICT_RULE + "\n\n"
                  + claims_markdown(results), encoding="utf-8")
    claims_frame(results).assign(vlm=vlm_note).to_csv(csv, index=False)
    return [md, csv]
