"""The report's text: Table 2's cells and files, and ``report.md`` composed from what ``writer`` computed."""

from __future__ import annotations

import math
from collections.abc import Sequence
from pathlib import Path
from typing import Any

import numpy as np
import pandas as pd

from vlmrl_cli.analysis import censored, multiplicity
from vlmrl_cli.analysis.defaults import DEFAULT_N_PERM
from vlmrl_cli.analysis.load import ExperimentData
from vlmrl_cli.core import tables
from vlmrl_cli.report import attribution, hacking
from vlmrl_cli.report import claims as claims_mod
from vlmrl_cli.report.config import ReportConfig
from vlmrl_cli.report.table2 import NEEDS_BASELINE, Table2, floor_thresholds
from vlmrl_cli.shaping.arms import BASELINE, DENSE, METHOD
from vlmrl_cli.tasks.base import Task


def is_steps(metric: str) -> bool:
    """Whether ``metric`` is a steps-to-threshold row (partial or full window, or the finishers' mean)."""
    return metric.startswith(("steps_", "full_steps_", "finishers_steps_"))


def _isnan(x: Any) -> bool:
    return x is None or (isinstance(x, float) and math.isnan(x))


def _fmt(metric: str, x: Any) -> str:
    if _isnan(x):
        return "—"
    x = float(x)
    if is_steps(metric):
        return f"{x:,.0f}"
    if metric in ("reliability", "eval_success", "eval_success_mean"):
        return f"{100 * x:.0f}%"
    return f"{x:,.1f}"


def format_cell(c: dict[str, Any] | None) -> str:
    """``value [low, high]`` with ``DNF k/n`` for steps and ``k/n`` for reliability."""
    if c is None:
        return "—"
    metric = c["metric"]
    c = {**c, "n": int(c["n"] or 0), "n_reached": None if _isnan(c["n_reached"]) else int(c["n_reached"])}
    if is_steps(metric) and c["n_reached"] == 0:
        return f"DNF {c['n']}/{c['n']}"
    text = _fmt(metric, c["value"])
    if not (_isnan(c["ci_low"]) or _isnan(c["ci_high"])):
        text += f" [{_fmt(metric, c['ci_low'])}, {_fmt(metric, c['ci_high'])}]"
    if is_steps(metric) and c["n_reached"] < c["n"]:
        text += f" (DNF {c['n'] - c['n_reached']}/{c['n']})"
    if metric in ("reliability", "eval_success"):
        text += f" ({c['n_reached']}/{c['n']})"
    if metric == "final_std" or (c["n"] == 1 and metric != "reliability"):
        text += f" (n={c['n']})"
    return text


def format_speedup(s: dict[str, Any] | None) -> str:
    if s is None:
        return ""
    if s["note"] == NEEDS_BASELINE:
        return NEEDS_BASELINE
    if _isnan(s["value"]):
        return "— (" + s["note"] + ")" if s["note"] else "—"
    text = f"{s['value']:.2f}x"
    if not (_isnan(s["ci_low"]) or _isnan(s["ci_high"])):
        text += f" [{s['ci_low']:.2f}, {s['ci_high']:.2f}]"
    if not _isnan(s.get("p_value")):
        text += f" (rank p={s['p_value']:.2g})"
    return text


def format_paper_cell(metric: str, value: Any) -> str:
    """The paper's figure as the paper states it: no interval, and no count of our seeds.

    Example:
        >>> format_paper_cell("reliability", 1.0), format_paper_cell("eval_length", 120.0)
        ('100%', '~120.0')
    """
    if _isnan(value):
        return "—"
    text = _fmt(metric, value)
    return f"~{text}" if metric == "eval_length" else text


def display_frame(table: Table2) -> pd.DataFrame:
    """The wide table as strings: metric rows; our arms, the paper's hybrid/baseline, speedups."""
    ci_pct = f"{100 * table.ci:g}% CI"
    speed_arms = [a for a in table.arms if a != BASELINE] if table.has_baseline else [METHOD]
    records = []
    for metric, label in table.labels.items():
        rec: dict[str, str] = {"Metric": label}
        for arm in table.arms:
            rec[f"{arm} (ours [{ci_pct}])"] = format_cell(table.cell(metric, arm))
        for arm in (METHOD, BASELINE):  # the paper's two arms
            rec[f"{arm} (paper)"] = format_paper_cell(metric, table.paper.get(metric, {}).get(arm))
        partial = metric.startswith("steps_")  # speedups are shown beside the paper's (partial) window
        for arm in speed_arms:
            text = NEEDS_BASELINE if partial else ""
            if partial and table.has_baseline:
                text = format_speedup(table.speedup(float(metric.removeprefix("steps_")), arm))
            rec[f"speedup {arm} (ours)"] = text
        paper_speed = table.paper.get(metric, {}).get("speedup")
        rec["speedup (paper)"] = f"{float(paper_speed):.1f}x" if paper_speed is not None else ""
        records.append(rec)
    return pd.DataFrame(records)


def table2_markdown(table: Table2) -> str:
    """``display_frame`` as Markdown in three narrow blocks (ours, speedups, the paper), empty rows left out."""
    df = display_frame(table)
    first = df.columns[0]
    speed = [c for c in df.columns if "speedup" in c]
    paper = [c for c in df.columns if "(paper)" in c and c not in speed]
    ours = [c for c in df.columns[1:] if c not in speed and c not in paper]
    parts = []
    blocks = (("Ours ([95% CI]; steps: restricted means, a DNF counted at the budget)", ours),
              ("Speedup vs baseline (ours: ratio of restricted means, rank-test p) and the paper's", speed),
              ("The paper", paper))
    for title, cols in blocks:
        block = df[[first, *cols]]
        block = block[block[cols].astype(str).apply(lambda r: any(v.strip() not in ("", "—") for v in r), axis=1)]
        if cols and len(block):
            parts += [f"*{title}*", "", tables.markdown(block), ""]
    return "\n".join(parts)


def table2_latex(table: Table2, caption: str = "Steps to reward thresholds and reliability, ours vs the paper."
                 ) -> str:
    """A ``booktabs`` LaTeX table of ``display_frame``."""
    return tables.latex(display_frame(table), caption) + "\n"


def table2_long(table: Table2) -> pd.DataFrame:
    """Tidy numeric form (CSV): one row per (metric, arm), speedups as ``speedup_<threshold>`` rows."""
    cells = table.cells.copy()
    cells.insert(1, "label", cells["metric"].map(table.labels))
    sp = table.speedups.copy()
    sp.insert(1, "label", "Speedup vs baseline to " + sp["metric"].str.removeprefix("steps_"))
    sp["metric"] = "speedup_" + sp["metric"].str.removeprefix("steps_")
    return pd.concat([cells, sp], ignore_index=True)


TABLE2_CAPTION = "Table 2 (recomputed): steps to reward thresholds and reliability, ours vs the paper."


def write_table2(table: Table2, out: Path, vlm_note: str) -> list[Path]:
    """Write ``table2.md``, ``.csv`` and ``.tex`` under ``out``, ``vlm_note`` (the VLM behind the shaped
    arms) in each; returns their paths."""
    paths = [out / "table2.md", out / "table2.csv", out / "table2.tex"]
    paths[0].write_text(f"**{TABLE2_CAPTION}** {vlm_note}.\n\n" + table2_markdown(table), encoding="utf-8")
    table2_long(table).assign(vlm=vlm_note).to_csv(paths[1], index=False)
    paths[2].write_text(table2_latex(table, caption=f"{TABLE2_CAPTION} {vlm_note}."), encoding="utf-8")
    return paths


def paper_disagreement(label: str, arm: str, c: dict[str, Any] | None) -> str | None:
    """The line of "where we disagree" for one cell of Table 2 whose paper figure lies outside our
    interval (None when it lies inside, or either side is missing): the paper's figure as the
    paper states it, our estimate with its own counts.

    Example:
        >>> cell = {"metric": "reliability", "arm": "hybrid", "value": 0.0, "ci_low": 0.0, "ci_high": 0.66,
        ...         "n": 2, "n_reached": 0, "paper": 1.0, "note": ""}
        >>> paper_disagreement("Final reliability", "hybrid", cell)
        '- Final reliability, hybrid: paper 100%, ours 0% [0%, 66%] (0/2) (outside our CI).'
    """
    if c is None or not np.isfinite(c["paper"]) or not np.isfinite(c["value"]):
        return None
    lo, hi = c["ci_low"], c["ci_high"]
    if np.isfinite(lo) and np.isfinite(hi) and lo <= c["paper"] <= hi:
        return None
    where = "outside our CI" if np.isfinite(lo) else "no CI"
    return (f"- {label}, {arm}: paper {format_paper_cell(c['metric'], c['paper'])}, ours {format_cell(c)} "
            f"({where}).")


def _disagreements(table: Table2, results: Sequence[claims_mod.ClaimResult]) -> list[str]:
    lines = []
    for r in results:
        if r.verdict == claims_mod.NOT_REPRODUCED:
            lines.append(f"- **{r.claim}** ({r.section}): {r.reason}.")
    for metric, label in table.labels.items():
        for arm in table.arms:
            line = paper_disagreement(label, arm, table.cell(metric, arm))
            if line is not None:
                lines.append(line)
    for t in table.thresholds:
        s = table.speedup(t, METHOD)
        if s is not None and np.isfinite(s["paper"]) and np.isfinite(s["value"]):
            lines.append(f"- Speedup to {t:g}: paper {s['paper']:.1f}x, ours {s['value']:.2f}x"
                         + (f" [{s['ci_low']:.2f}, {s['ci_high']:.2f}]" if np.isfinite(s["ci_low"]) else "") + ".")
    return lines


#: The report's family of comparisons, as its Method text names it.
FAMILY_WHAT = "The speedups of the attribution table (every pair and threshold measured)"


def family_reach(cfg: ReportConfig, family: pd.DataFrame, paper_task: bool) -> list[str]:
    """What the family's size and seeds allow (``multiplicity.reach_line``) and, for the paper's task,
    why the lowest threshold's rows stay in the family."""
    if not len(family):
        return []
    alpha, size = 1 - cfg.ci, len(family)
    n_a, n_b = int(family["n_a"].min()), int(family["n_b"].min())
    line = multiplicity.reach_line(cfg.adjust, size, n_a, n_b, alpha) if cfg.adjust != "none" else None
    out = [f"- Reach: {line}"] if line else []
    thresholds = sorted({float(m.removeprefix("speedup_")) for m in family["metric"]})
    if paper_task and line and len(thresholds) > 1:
        low = thresholds[0]
        rest = int((family["metric"] != f"speedup_{low:g}").sum())
        p_min = multiplicity.smallest_exact_p(n_a, n_b)
        out.append(f"- The {low:g} rows stay in the family: the paper claims a speedup to {low:g} (its Table 2), so "
                   "it is tested, even where a floor makes the row measure how fast episodes end (see above). "
                   f"Without them the family would have {rest} tests, whose smallest adjusted p, "
                   f"{rest} x {p_min:.2g} = {min(1.0, rest * p_min):.2g}, is "
                   + ("still not below" if rest * p_min >= alpha else "below") + f" {alpha:g}: dropping them would "
                   + ("not change what this report can conclude." if rest * p_min >= alpha else
                      "let the remaining tests reach significance, which is why the report says so here."))
    return out


def _statistics_md(cfg: ReportConfig, family_size: int = 0, auc_margin: float = 5.0,
                   reach: list[str] | None = None) -> list[str]:
    ci = f"{100 * cfg.ci:g}%"
    alpha = 1 - cfg.ci
    splits = "C(60, 30)" if cfg.n_perm == DEFAULT_N_PERM else f"{cfg.n_perm:,}"  # the rank test's largest exact case
    return [
        "## How the numbers are computed", "",
        "- Unit: every claim is per seed unless it says 'episodes'. A seed counts as a detached success when at "
        f"least {100 * cfg.detached_cut:g}% of its detached evaluation episodes reach the flag (trained policies are "
        "close to all-or-nothing, so the cut rarely matters); the paper's '40% failure' is read as 2 of 5 seeds.",
        f"- Proportions of seeds (reliability, detached success): {ci} Wilson score interval for one arm; for a "
        "difference of two arms Newcombe's hybrid score interval (method 10, Newcombe 1998) and a two-sided Fisher "
        "exact p-value. These never collapse to a point: 5/5 vs 5/5 is 0 [-0.43, 0.43].",
        f"- Steps to a threshold, the one DNF rule of every table and verdict: {censored.RULE}. Restricted means "
        f"with a {ci} percentile bootstrap over seeds ({cfg.n_boot} resamples); a speedup is the ratio of "
        f"restricted means (a lower bound on the true ratio when the slower arm DNFs), its interval "
        f"{censored.RATIO_INTERVAL}. The paper's convention, "
        "the mean over the seeds that finished, is shown as its own row of Table 2 only. Beside each speedup, a "
        "Mann-Whitney U test on all seeds with each DNF censored at the budget (tied with the other DNFs, slower "
        "than every finish; a crossing after the budget is a DNF): an exact permutation p, conditional on the "
        f"ties, when the splits of the seeds number at most {splits} (every split counted; 184,756 at "
        "10 vs 10), else the tie-corrected normal approximation, and then the table's test column says 'asymptotic'.",
        f"- Multiplicity: {multiplicity.family_line(cfg.adjust, family_size, FAMILY_WHAT)}; "
        "the claims about speedups use the same adjusted p-values. Each table shows the raw p beside the adjusted "
        "one. The reliability, detached-success and learning-curve-area differences are secondary measures, "
        f"judged on their own raw p at {alpha:g} and not adjusted.",
        *(reach or []),
        "- Beside the rank test, a log-rank test on the same steps (each DNF censored at its own budget; chi-square, "
        "1 df), adjusted within the same family; where one of the two rejects after adjustment and the other does "
        "not, the table says so. The rank test drives the verdict: it was the declared test of earlier reports, "
        "its p is exact (every split counted) where the log-rank is a large-sample chi-square, "
        "and with one budget per arm it is Gehan's test, which weighs early finishes more, where speed is "
        "measured; the log-rank weighs every finishing step alike and treats different budgets exactly.",
        f"- Verdicts of the attribution table, one rule: faster/slower when the adjusted rank test rejects at "
        f"{alpha:g} and the {ci} interval of the speedup excludes 1 on the same side; "
        f"{censored.equivalent(cfg.margin)} when the {100 * (1 - 2 * alpha):g}% interval of the "
        f"speedup lies inside [1/{cfg.margin:g}, {cfg.margin:g}] (two one-sided tests) and each arm finished on "
        "at least half its seeds; otherwise inconclusive, with 'leans faster' (or slower) when the interval "
        "excludes 1 or the adjusted test rejects and both point one way. Learning-curve area (threshold-free): "
        "per seed the mean native return over the budget, compared by a difference of means and a Mann-Whitney "
        f"test, equivalent when the 90% interval lies within +-{auc_margin:g} return points (the task's margin, "
        "Task.auc_margin).",
        f"- Full window: the 'full {cfg.window}-episode window' rows count a threshold only once {cfg.window} "
        "episodes have completed (no partial window at the start); the plain rows follow SB3's ep_rew_mean "
        f"(partial windows count once {cfg.min_episodes} episode(s) completed), the paper's reading.",
        "- Aggregates: probability of improvement P(final return of a seed of A > one of B), ties half, with a "
        f"{ci} bootstrap over seeds (descriptive: it may collapse when the arms separate completely; the rank test "
        "is the seed-level test); the performance profile plots the share of seeds with final return >= tau.",
        f"- Randomness: each section and metric draws from its own stream of seed {cfg.seed} (keyed by name), so "
        "adding a metric changes no other interval.", ""]


def _hacking_intro(task: Task) -> list[str]:
    """The reward-hacking section's heading and definition for the runs' task."""
    if task.hacking_note:
        heading, why = task.hacking_note
        return [f"## Reward hacking: {heading}", "", f"{why} {hacking.definition(task.hover_from)}", ""]
    return ["## Reward hacking", "",
            "A dense term that pays more per step than finishing can keep an agent from finishing. "
            + hacking.definition(task.hover_from if task.hover_diagnostic else None), ""]


def _intro_md(cfg: ReportConfig, data: ExperimentData, table: Table2, per_seed: pd.DataFrame, note: str,
              task: Task) -> list[str]:
    """The title and what the runs are: the VLM, the task, the arms, the thresholds' rule and floors."""
    assert cfg.window is not None  # resolved to the task's by write_report
    simulated = bool(data.runs["simulated"].any())
    paper_task = task.paper is not None
    title = "Reproduction report" if paper_task else f"Report (task {data.task})"
    parts = [f"# {title}: experiment `{data.experiment_name}`", ""]
    if simulated:
        parts += ["> **SIMULATED VLM.** These runs used a simulated VLM (a pixel-reading stand-in), not a real "
                  "vision-language model. The numbers test the training pipeline, not the paper's VLM.", ""]
    if not paper_task:
        parts += [f"- Task: {task.summary}. The paper reports MountainCar-v0 only: no paper value or claim "
                  f"stands beside these runs, and Table 2 keeps the paper's layout for ours alone. Reference: "
                  f"{task.zoo_reference}.",
                  f"- Thresholds: {', '.join(f'{t:g}' for t in table.thresholds)}; success: the episode terminated "
                  f"(goal reached) within {task.max_steps} steps."]
    parts += [f"- {note}", f"- Arms: {', '.join(table.arms)}; seeds per arm: "
              + ", ".join(f"{a}={int((per_seed['arm'] == a).sum())}" for a in table.arms),
              f"- Steps to a threshold: first global timestep at which the mean native return of the last "
              f"{cfg.window} completed episodes reaches it (partial windows count once {cfg.min_episodes} "
              f"episode(s) completed). {censored.RULE[0].upper()}{censored.RULE[1:]}; DNF = did not reach it "
              "within the budget.",
              *[f"- **Floor at {t:g}:** every seed of every arm crosses {t:g} at its first complete window of "
                f"{cfg.window} episodes, so steps to {t:g} measure how fast episodes end, not learning: read no "
                "speedup into that row." for t in floor_thresholds(per_seed, table.thresholds)],
              f"- Intervals: {100 * cfg.ci:g}% percentile bootstrap over seeds ({cfg.n_boot} resamples, seed "
              f"{cfg.seed}) for means; speedups by the delta method on the log ratio; score intervals for "
              "proportions of seeds (see below).", ""]
    return parts


def report_md(cfg: ReportConfig, data: ExperimentData, table: Table2, results: Sequence[claims_mod.ClaimResult],
              per_seed: pd.DataFrame, note: str, warns: Sequence[str], comparisons: pd.DataFrame,
              hack: pd.DataFrame, task: Task) -> str:
    """The text of ``report.md``."""
    paper_task = task.paper is not None
    parts = _intro_md(cfg, data, table, per_seed, note, task)
    if warns:
        parts += ["## Warnings", "", *[f"- {w}" for w in warns], ""]
    parts += ["## Table 2: ours vs the paper" if paper_task else "## Table 2 (ours)", "", table2_markdown(table)]
    if not table.has_baseline:
        parts += ["Speedups need the `baseline` arm, which this experiment does not have.", ""]
    parts += ["Files: [table2.md](table2.md), [table2.csv](table2.csv), [table2.tex](table2.tex).", ""]
    if paper_task:
        parts += ["## Where ours and the paper disagree", ""]
        dis = _disagreements(table, results)
        parts += (dis or ["- No claim is contradicted by our intervals (see the verdicts below)."]) + [""]
        parts += ["## Claims", "", "Verdict rule: " + claims_mod.VERDICT_RULE, "",
                  claims_mod.claims_markdown(list(results)),
                  "The paper credits its speedup and its detached success to the VLM; rows judged on hybrid vs "
                  "kinematic test that credit (the two arms share the dense kinematic term and differ only by the "
                  "VLM potential).", ""]
    family = comparisons[attribution.is_family(comparisons)] if len(comparisons) else comparisons
    parts += [*_statistics_md(cfg, len(family), task.auc_margin, family_reach(cfg, family, paper_task)),
              "## Attribution: what the VLM and the dense term each add", ""]
    if len(comparisons):
        parts += [attribution.attribution_markdown(comparisons, cfg.ci, cfg.adjust),
                  "Files: [attribution.md](attribution.md), [attribution.csv](attribution.csv).", ""]
    else:
        parts += ["No pair of arms to compare (needs two of hybrid, kinematic, semantic, baseline).", ""]
    if METHOD in table.arms and DENSE not in table.arms:
        parts += ["Without the `kinematic` arm nothing here separates the VLM from the dense term: claims that "
                  "credit the VLM are not tested.", ""]
    parts += ["## Aggregates", "", "![Performance profile](performance_profile.png)", "",
              "Performance profile: share of seeds whose final return (last window) is at least tau, per arm, with a "
              "pointwise Wilson band; probabilities of improvement are the `P(final return higher)` rows above.", "",
              *_hacking_intro(task),
              hacking.hacking_markdown(hack, cfg.ci, task.hover_diagnostic), "![Reward hacking](hacking.png)", "",
              "Reward hacking: detached episode lengths per arm, hover fraction per seed, shaped minus native "
              "return per seed.", "",
              "## Figures", "",
              "![Figure 2](figure2.png)", "", "Figure 2: mean steps to each threshold (hollow diamonds: the paper).",
              "", "![Figure 3](figure3.png)", "", "Figure 3: per-seed training curves.", "",
              "![Figure 4](figure4.png)", "", "Figure 4: mean learning curve per arm with a bootstrap band.", "",
              "## Runs", ""]
    parts += tables.markdown_rows(["arm", "seed", "run id", "config hash", "preset", "budget"],
                                  ([r.arm, r.seed, f"`{r.run_id}`", f"`{r.config_hash}`", r.preset, r.budget]
                                   for r in per_seed.itertuples(index=False)))
    parts += ["", "Per-seed values: [per_seed.csv](per_seed.csv).", ""]
    return "\n".join(parts)
