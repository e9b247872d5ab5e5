"""The paper's quantitative claims, each with our measured value, CI and a verdict.

Verdict rule (``VERDICT_RULE`` is printed in the report):

* fewer than ``MIN_SEEDS`` (3) seeds behind our estimate in an arm it uses, or no computable CI
  -> **inconclusive**; an arm the claim needs is absent -> **not tested**.
* comparative claims (an effect against a null: speedup vs 1, reliability gap vs 0, spread
  difference vs 0): **reproduced** if our whole CI lies strictly on the paper's side of the null;
  **not reproduced** if it lies entirely on the other side (null included), or if it excludes the
  paper's value while still containing the null; otherwise (it contains both the null and the
  paper's value) **inconclusive**.
* absolute claims (a value of one arm: 100% reliability, ~125 steps): **not reproduced** if our CI
  excludes the paper's value (widened by +-10% when the paper says "~"); **reproduced** if it
  contains it and our estimate is within 10% of it (or within the "~" tolerance); otherwise
  (a CI wide enough to hold the paper's value around an estimate far from it, e.g. 5/5 seeds
  succeeding against a claimed 60%) **inconclusive**.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np
import pandas as pd

from vlmrl_cli.analysis import stats
from vlmrl_cli.report.table2 import BASELINE, Table2, threshold_key

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
    "inconclusive (the CI is too wide to tell)."
)


def verdict(
    estimate: stats.Estimate,
    paper: float | None,
    null: float | None = None,
    direction: str = ">",
    approximate: bool = False,
    n_seeds: int | None = None,
) -> tuple[str, str]:
    """The verdict and its reason for one claim (see ``VERDICT_RULE``).

    Args:
        estimate: our value with its CI.
        paper: the paper's value (``None`` for a purely directional claim).
        null: the no-effect value of a comparative claim; ``None`` for an absolute claim.
        direction: ``">"`` if the paper's effect is above the null, ``"<"`` if below.
        approximate: the paper's value is "~" (widen it by ``APPROX_TOLERANCE``).
        n_seeds: the fewest seeds behind the estimate in any arm (default ``estimate.n``).

    Example:
        >>> verdict(stats.Estimate(1.5, 1.2, 1.9, n=5), 1.4, null=1.0)
        ('reproduced', 'CI [1.2, 1.9] lies above 1; the paper value 1.4 is inside it')
        >>> verdict(stats.Estimate(1.5, 1.2, 1.9, n=2), 1.4, null=1.0)[0]
        'inconclusive'
    """
    n = estimate.n if n_seeds is None else n_seeds
    if n < MIN_SEEDS:
        return INCONCLUSIVE, f"only {n} seed(s) behind the estimate (need >= {MIN_SEEDS})"
    if not estimate.has_ci:
        return INCONCLUSIVE, "no CI: " + (estimate.note or "not computable")
    lo, hi = estimate.low, estimate.high
    ci_text = f"CI [{lo:.3g}, {hi:.3g}]"
    if null is None:
        if paper is None:
            return INCONCLUSIVE, "the paper gives no value"
        tol = abs(paper) * APPROX_TOLERANCE if approximate else 0.0
        shown = f"{paper:g}" + (f" +-{tol:g}" if tol else "")
        if not (lo <= paper + tol and hi >= paper - tol):
            return NOT_REPRODUCED, f"{ci_text} excludes the paper value {shown}"
        if abs(estimate.value - paper) <= max(tol, abs(paper) * APPROX_TOLERANCE):
            return REPRODUCED, f"{ci_text} holds the paper value {shown}; our estimate {estimate.value:.3g} is close"
        return INCONCLUSIVE, (f"{ci_text} holds the paper value {shown}, but our estimate {estimate.value:.3g} is far "
                              "from it: too few seeds to tell")
    above = direction == ">"
    on_side = lo > null if above else hi < null
    against = hi <= null if above else lo >= null
    side = "above" if above else "below"
    inside = paper is not None and lo <= paper <= hi
    if on_side:
        tail = "" if paper is None else (f"; the paper value {paper:g} is inside it" if inside
                                         else f"; the paper value {paper:g} is outside it (magnitude differs)")
        return REPRODUCED, f"{ci_text} lies {side} {null:g}{tail}"
    if against:
        return NOT_REPRODUCED, f"{ci_text} is not {side} {null:g}: no effect in the paper's direction"
    if paper is not None and not inside:
        return NOT_REPRODUCED, f"{ci_text} contains {null:g} and excludes the paper value {paper:g}"
    return INCONCLUSIVE, f"{ci_text} contains the null {null:g}" + ("" if paper is None else f" and {paper:g}")


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


def _est_from_cell(cell: dict[str, Any] | None) -> stats.Estimate:
    if cell is None:
        return stats.Estimate(float("nan"))
    return stats.Estimate(float(cell["value"]), float(cell["ci_low"]), float(cell["ci_high"]), int(cell["n"] or 0),
                          str(cell["note"] or ""))


def evaluate_claims(
    table: Table2, per_seed: pd.DataFrame, reported: dict[str, Any], rng: np.random.Generator,
    n_boot: int = stats.DEFAULT_N_BOOT, ci: float = 0.95,
) -> list[ClaimResult]:
    """Every claim in ``reported["claims"]`` measured on our runs, with its verdict."""
    arms = set(table.arms)
    top = max(table.thresholds)
    results = []
    for spec in reported.get("claims", []):
        cid, paper = spec["id"], spec.get("value")
        paper_f = None if paper is None else float(paper)
        need: set[str] = set()
        est = stats.Estimate(float("nan"))
        null: float | None = None
        direction, unit, n_seeds = ">", "", None
        if cid.startswith("speedup_"):
            t = float(cid.removeprefix("speedup_"))
            need, unit, null = {"hybrid", BASELINE}, "x", 1.0
            if t not in table.thresholds:
                results.append(ClaimResult(cid, spec["section"], spec["text"], paper_f, est, unit, NOT_TESTED,
                                           f"threshold {t:g} not in this report's thresholds"))
                continue
            if need <= arms:
                s = table.speedup(t, "hybrid")
                est = _est_from_cell(s)
                n_seeds = min(_n_reached(table, t, "hybrid"), _n_reached(table, t, BASELINE))
        elif cid in ("reliability_hybrid", "reliability_baseline"):
            arm = cid.removeprefix("reliability_")
            need, unit = {arm}, "%"
            est = _est_from_cell(table.cell("reliability", arm))
        elif cid == "reliability_gap":
            need, unit, null = {"hybrid", BASELINE}, "%", 0.0
            if need <= arms:
                key = threshold_key(top)
                a = np.isfinite(per_seed.loc[per_seed["arm"] == "hybrid", key].to_numpy(dtype=float))
                b = np.isfinite(per_seed.loc[per_seed["arm"] == BASELINE, key].to_numpy(dtype=float))
                est = stats.difference_of_means(a.astype(float), b.astype(float), rng, n_boot, ci)
        elif cid.startswith("detached_success_"):
            arm = cid.removeprefix("detached_success_")
            need, unit = {arm}, "%"
            est = _est_from_cell(table.cell("eval_success", arm))
        elif cid == "detached_length_hybrid":
            need, unit = {"hybrid"}, " steps"
            est = _est_from_cell(table.cell("eval_length", "hybrid"))
            n_seeds = int((per_seed["arm"] == "hybrid").sum())
        elif cid == "narrower_variance":
            need, null, direction, unit = {"hybrid", BASELINE}, 0.0, "<", ""
            if need <= arms:
                a = per_seed.loc[per_seed["arm"] == "hybrid", "final_return"].to_numpy(dtype=float)
                b = per_seed.loc[per_seed["arm"] == BASELINE, "final_return"].to_numpy(dtype=float)
                est = stats.std_difference(a, b, rng, n_boot, ci)
        elif cid == "zero_convergence":
            need, unit = {"vision-float"}, "%"
            est = _est_from_cell(table.cell("reliability", "vision-float"))
        missing = need - arms
        if missing:
            reason = f"arm {', '.join(sorted(missing))} not in this experiment"
            if cid == "zero_convergence":
                reason += "; see `vlmrl taxonomy` for the pure-vision failure modes"
            results.append(ClaimResult(cid, spec["section"], spec["text"], paper_f, est, unit, NOT_TESTED, reason))
            continue
        if n_seeds is None:
            n_seeds = min(int((per_seed["arm"] == a).sum()) for a in need)
        v, reason = verdict(est, paper_f, null, direction, bool(spec.get("approximate")), n_seeds)
        if cid == "narrower_variance":
            reason = "measure: std across seeds of the final return, hybrid minus baseline; " + reason
        results.append(ClaimResult(cid, spec["section"], spec["text"], paper_f, est, unit, v, reason))
    return results


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
        "ci_low": r.estimate.low, "ci_high": r.estimate.high, "n": r.estimate.n, "verdict": r.verdict,
        "reason": r.reason, "note": r.estimate.note,
    } for r in results])


def claims_markdown(results: list[ClaimResult]) -> str:
    """Markdown table: claim, section, paper, ours [CI], verdict, reason."""
    lines = ["| Claim | Section | Paper | Ours [95% CI] | Verdict | Why |", "| --- | --- | --- | --- | --- | --- |"]
    for r in results:
        ours = _fmt(r.estimate.value, r.unit)
        if r.estimate.has_ci:
            ours += f" [{_fmt(r.estimate.low, r.unit)}, {_fmt(r.estimate.high, r.unit)}]"
        paper = "narrower" if r.id == "narrower_variance" else _fmt(r.paper, r.unit)
        if r.id == "detached_length_hybrid" and r.paper is not None:
            paper = "~" + paper
        cells = [r.claim, r.section, paper, ours, f"**{r.verdict}**", r.reason]
        lines.append("| " + " | ".join(c.replace("|", "\\|") for c in cells) + " |")
    return "\n".join(lines) + "\n"


def write_claims(results: list[ClaimResult], out: Path, vlm_note: str) -> list[Path]:
    """Write ``claims.md`` (with the verdict rule and ``vlm_note``, the VLM behind the shaped arms)
    and ``claims.csv`` (``vlm_note`` as a ``vlm`` column); returns their paths."""
    md, csv = out / "claims.md", out / "claims.csv"
    md.write_text("# Claims of the paper vs our runs\n\n" + vlm_note + ".\n\nVerdict rule: " + VERDICT_RULE + "\n\n"
                  + claims_markdown(results), encoding="utf-8")
    claims_frame(results).assign(vlm=vlm_note).to_csv(csv, index=False)
    return [md, csv]
