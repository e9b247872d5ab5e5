"""The study's numbers from tracked runs: the regime map, the VLM-quality points, the verdicts and
the plain-language summary. Pure functions of the loaded runs (no training, no MLflow writes).

Every interval reuses the report's statistics: reliability with a Wilson interval and steps to a
threshold with a bootstrap CI over finishing seeds (``report/table2.py``), speedups with a
bootstrap CI and a censored Mann-Whitney test (``report/attribution.py compare_arms``).
"""

from __future__ import annotations

import dataclasses
import math
from collections.abc import Sequence
from typing import Any

import numpy as np
import pandas as pd
from matplotlib.figure import Figure

from vlmrl_cli.analysis import stats
from vlmrl_cli.analysis.load import ExperimentData
from vlmrl_cli.calibration.pipeline import runs_of
from vlmrl_cli.core import tables
from vlmrl_cli.probe.metrics import spearman
from vlmrl_cli.report import attribution, figures
from vlmrl_cli.report.table2 import (
    BASELINE,
    build_table2,
    compare_steps,
    format_cell,
    order_arms,
    per_seed_table,
    threshold_key,
)
from vlmrl_cli.training.config import RunConfig

FASTER, SLOWER, NO_DIFFERENCE, NOT_MEASURED = "faster", "slower", "no detectable difference", "not measurable"
NEITHER = "neither arm reaches the threshold"
#: The comparisons of the regime map: (arm a, arm b, what the difference isolates).
MAP_PAIRS = (("hybrid", BASELINE, "the whole method"), ("hybrid", "kinematic", "what the VLM itself adds"))


def _restrict(data: ExperimentData, runs: pd.DataFrame) -> ExperimentData:
    ids = set(runs["run_id"])
    evals = data.eval_episodes
    return dataclasses.replace(data, runs=runs.reset_index(drop=True),
                               episodes=data.episodes[data.episodes["run_id"].isin(ids)],
                               eval_episodes=evals[evals["run_id"].isin(ids)] if len(evals) else evals)


def subset(data: ExperimentData, run: RunConfig) -> ExperimentData:
    """The runs of ``data`` that are jobs of ``run`` (arm, seed and config hash), with their episodes."""
    return _restrict(data, runs_of(data.runs, run))


def paired(data: ExperimentData, reference: RunConfig, variant: RunConfig) -> ExperimentData:
    """The baseline runs of ``reference`` and the runs of ``variant`` (a VLM variant's hybrid)."""
    ref = runs_of(data.runs, reference)
    runs = pd.concat([ref[ref["arm"] == BASELINE], runs_of(data.runs, variant)]).drop_duplicates("run_id")
    return _restrict(data, runs)


def verdict(speedup: stats.Estimate, p_value: float, reliability_diff: float, alpha: float = 0.05) -> str:
    """``faster``/``slower`` when the censored rank test is significant at ``alpha`` (the direction
    from the speedup, or from the reliability difference when no seed of one arm finished), else
    ``no detectable difference``; ``not measurable`` without a test.

    Example:
        >>> verdict(stats.Estimate(1.4, 1.1, 1.8), 0.01, 0.0), verdict(stats.Estimate(1.4, 0.9, 1.8), 0.2, 0.0)
        ('faster', 'no detectable difference')
        >>> verdict(stats.Estimate(float("nan")), 0.01, 0.6)
        'faster'
    """
    if not math.isfinite(p_value):
        return NOT_MEASURED
    if p_value >= alpha:
        return NO_DIFFERENCE
    direction = speedup.value - 1.0 if math.isfinite(speedup.value) else reliability_diff
    if not math.isfinite(direction) or direction == 0:
        return NO_DIFFERENCE
    return FASTER if direction > 0 else SLOWER


def regime_row(name: str, data: ExperimentData, thresholds: Sequence[float], streams: stats.Streams,
               n_boot: int = stats.DEFAULT_N_BOOT, ci: float = 0.95, alpha: float = 0.05
               ) -> tuple[dict[str, Any], pd.DataFrame]:
    """One regime's row of the map (per arm: reliability and steps to the top threshold with CIs;
    per ``MAP_PAIRS`` pair: speedup, CI, rank-test p and verdict) and its per-seed table."""
    top = max(thresholds)
    per_seed = per_seed_table(data, thresholds)
    table = build_table2(per_seed, data.eval_episodes, {}, thresholds, streams, n_boot=n_boot, ci=ci)
    comparisons = attribution.compare_arms(per_seed, thresholds, streams, n_boot, ci)
    row: dict[str, Any] = {"regime": name, "seeds": int(per_seed.groupby("arm").size().max())}
    for arm in table.arms:
        rel, steps = table.cell("reliability", arm), table.cell(threshold_key(top), arm)
        assert rel is not None and steps is not None
        row |= {f"{arm}.reliability": rel["value"], f"{arm}.reliability_low": rel["ci_low"],
                f"{arm}.reliability_high": rel["ci_high"], f"{arm}.reached": int(rel["n_reached"]),
                f"{arm}.n": int(rel["n"]),
                f"{arm}.steps": steps["value"], f"{arm}.steps_low": steps["ci_low"],
                f"{arm}.steps_high": steps["ci_high"], f"{arm}.reliability_text": format_cell(rel),
                f"{arm}.steps_text": format_cell(steps)}
    for a, b, _ in MAP_PAIRS:
        key = f"{a}_vs_{b}"
        found = attribution.lookup(comparisons, a, b, f"speedup_{top:g}")
        rel_diff = attribution.lookup(comparisons, a, b, "reliability_diff")
        if found is None:
            row |= {f"{key}.speedup": math.nan, f"{key}.low": math.nan, f"{key}.high": math.nan,
                    f"{key}.p": math.nan, f"{key}.verdict": NOT_MEASURED}
            continue
        est, p = found
        diff = rel_diff[0].value if rel_diff is not None else math.nan
        none_reach = row[f"{a}.reached"] == 0 and row[f"{b}.reached"] == 0
        row |= {f"{key}.speedup": est.value, f"{key}.low": est.low, f"{key}.high": est.high, f"{key}.p": p,
                f"{key}.reliability_diff": diff,
                f"{key}.verdict": NEITHER if none_reach else verdict(est, p, diff, alpha)}
    return row, per_seed


def format_speedup(row: dict[str, Any], key: str) -> str:
    """``1.40x [1.10, 1.80], p = 0.01 (faster)`` from a map row."""
    value = row.get(f"{key}.speedup", math.nan)
    text = f"{value:.2f}x" if math.isfinite(value) else "—"
    low, high = row.get(f"{key}.low", math.nan), row.get(f"{key}.high", math.nan)
    if math.isfinite(low) and math.isfinite(high):
        text += f" [{low:.2f}, {high:.2f}]"
    p = row.get(f"{key}.p", math.nan)
    text += f", p = {p:.2g}" if math.isfinite(p) else ", no test"
    return f"{text} ({row.get(f'{key}.verdict', NOT_MEASURED)})"


def map_markdown(rows: Sequence[dict[str, Any]], top: float, ci: float = 0.95) -> str:
    """The regime map: one line per regime, each arm's reliability and steps to ``top``, both speedups."""
    arms = order_arms(sorted({k.split(".")[0] for r in rows for k in r if k.endswith(".reliability")}))
    pct = f"{100 * ci:g}%"
    head = ["Regime", "Seeds"] + [f"{a}: reliability [{pct} Wilson]; steps to {top:g} [{pct} CI]" for a in arms]
    head += [f"Speedup {a} / {b} to {top:g} [{pct} CI], rank p" for a, b, _ in MAP_PAIRS]
    body = []
    for r in rows:
        cells = [f"`{r['regime']}`", str(r["seeds"])]
        cells += [f"{r.get(f'{a}.reliability_text', '—')}; {r.get(f'{a}.steps_text', '—')}" for a in arms]
        cells += [format_speedup(r, f"{a}_vs_{b}") for a, b, _ in MAP_PAIRS]
        body.append(cells)
    return "\n".join(tables.markdown_rows(head, body)) + "\n"


def vlm_point(name: str, data: ExperimentData, top: float, accuracy: float, streams: stats.Streams,
              n_boot: int = stats.DEFAULT_N_BOOT, ci: float = 0.95) -> dict[str, Any]:
    """One VLM-quality point: the variant's measured MCQ accuracy and the hybrid's speedup over the
    baseline to ``top`` (``data``: the reference regime's baseline runs and the variant's hybrid runs)."""
    per_seed = per_seed_table(data, [top])
    est, test = compare_steps(per_seed, "hybrid", BASELINE, top, streams, n_boot, ci)
    return {"variant": name, "mcq_accuracy": accuracy, "speedup": est.value, "low": est.low, "high": est.high,
            "p": test.p_value, "hybrid_seeds": int((per_seed["arm"] == "hybrid").sum()),
            "baseline_seeds": int((per_seed["arm"] == BASELINE).sum())}


def vlm_figure(points: pd.DataFrame, top: float, regime: str, simulated: bool) -> Figure:
    """The hybrid's speedup over the baseline (with its CI) against the VLM's measured MCQ accuracy."""
    fig = Figure(figsize=(figures.WIDTH_IN, 3.6), layout="constrained")
    ax = fig.subplots()
    for r in points.itertuples(index=False):
        y = r.speedup if math.isfinite(r.speedup) else np.nan
        err = [[y - r.low if math.isfinite(r.low) else 0.0], [r.high - y if math.isfinite(r.high) else 0.0]]
        ax.errorbar([r.mcq_accuracy], [y], yerr=err, fmt="o", capsize=3)
        ax.annotate(str(r.variant), (r.mcq_accuracy, y if math.isfinite(y) else 1.0), fontsize=figures.SMALL,
                    xytext=(4, 4), textcoords="offset points")
    ax.axhline(1.0, color="gray", linestyle="--", linewidth=0.7)
    ax.set_xlabel("MCQ accuracy of the VLM (vlmrl taxonomy, same knobs)", fontsize=figures.SMALL + 1)
    ax.set_ylabel(f"speedup to {top:g}, hybrid / baseline", fontsize=figures.SMALL + 1)
    title = f"VLM quality vs the hybrid's speedup, regime {regime}"
    fig.suptitle(title + (" — SIMULATED VLM, not a real model" if simulated else ""), fontsize=figures.SMALL + 1)
    return fig


def _names(rows: Sequence[dict[str, Any]], key: str, wanted: str) -> list[str]:
    return [f"`{r['regime']}`" for r in rows if r.get(f"{key}.verdict") == wanted]


def summary(rows: Sequence[dict[str, Any]], points: pd.DataFrame, top: float, alpha: float, vlm_regime: str
            ) -> list[str]:
    """The report's opening: what holds, where, and what does not, in sentences made from the numbers."""
    lines = []
    whole, vlm = "hybrid_vs_baseline", "hybrid_vs_kinematic"
    for key, what in ((whole, "**The hybrid vs the baseline**"),
                      (vlm, "**What the VLM itself adds** (hybrid vs kinematic, both with the dense term)")):
        parts = [f"{wanted} in {', '.join(names)}" for wanted in (FASTER, SLOWER, NO_DIFFERENCE, NEITHER, NOT_MEASURED)
                 if (names := _names(rows, key, wanted))]
        lines.append(f"- {what}, steps to {top:g} (censored rank test at {alpha:g}): {'; '.join(parts)}.")
    for r in rows:
        rel = ", ".join(f"{a} {r[f'{a}.reached']}/{r[f'{a}.n']}" for a in order_arms(
            [k.split(".")[0] for k in r if k.endswith(".reliability")]))
        lines.append(f"- `{r['regime']}` ({r['seeds']} seeds per arm): hybrid / baseline "
                     f"{format_speedup(r, whole)}; hybrid / kinematic {format_speedup(r, vlm)}; seeds reaching "
                     f"{top:g}: {rel}.")
    finite = points[np.isfinite(points["speedup"]) & np.isfinite(points["mcq_accuracy"])] if len(points) else points
    if len(finite) >= 3:
        rho = spearman(finite["mcq_accuracy"].to_numpy(), finite["speedup"].to_numpy())
        best, worst = finite.loc[finite["speedup"].idxmax()], finite.loc[finite["speedup"].idxmin()]
        lines.append(f"- **VLM quality** (regime `{vlm_regime}`, {len(finite)} VLM variants): MCQ accuracy "
                     f"{finite['mcq_accuracy'].min():.2f}-{finite['mcq_accuracy'].max():.2f}; the hybrid's speedup "
                     f"ranges from {worst['speedup']:.2f}x ({worst['variant']}) to {best['speedup']:.2f}x "
                     f"({best['variant']}); Spearman rank correlation of speedup with accuracy {rho:.2f} "
                     "(descriptive, over variants).")
    elif len(points):
        lines.append(f"- **VLM quality** (regime `{vlm_regime}`): {len(finite)} variant(s) with a measurable speedup; "
                     "too few for a trend.")
    return lines
